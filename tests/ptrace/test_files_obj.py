"""OBJ files as real exporters and hand-written files have them (ptrace.io.obj, ptrace.io.mtl):
relative indices, tabs, backslash paths, vertex colours, missing or unreadable pieces (each a
note), texture coordinates without a material, NaN in a material. Each test writes its files."""
import re

import numpy as np
import pytest
from files_by_hand import png_bytes, rgb16_png

import ptrace
from ptrace.app.cli import grouped_notes
from ptrace.io.materials import linear_rgb
from ptrace.scene import DIFFUSE

BOX = """# two unit quads, each written with indices relative to the vertices read so far
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
f -4/-4 -3/-3 -2/-2 -1/-1
v 0 0 5
v 1 0 5
v 1 1 5
v 0 1 5
f -4/-4 -3/-3 -2/-2 -1/-1
"""


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_negative_indices_count_back_from_the_vertices_read_so_far(tmp_path):
    """The OBJ specification: -1 is the latest vertex read before the face. trimesh 5 counts
    from the end of the file, which collapsed every OBJ Cornell box tried."""
    scene = ptrace.load(write(tmp_path, "box.obj", BOX))
    assert scene.triangle_count == 4
    lower, upper = scene.bounds()
    np.testing.assert_allclose(lower, [0, 0, 0])
    np.testing.assert_allclose(upper, [1, 1, 5])
    corners = scene.geometry.vertices[scene.geometry.faces]
    np.testing.assert_allclose(np.sort(corners[:2, :, 2].ravel()), 0.0)
    np.testing.assert_allclose(np.sort(corners[2:, :, 2].ravel()), 5.0)


def test_tab_separated_statements_are_read(tmp_path):
    scene = ptrace.load(write(tmp_path, "tabs.obj",
                              "v\t0 0 0\nv\t2\t0\t0\nv 0\t3 0\nf\t1\t2\t3\n"))
    assert scene.triangle_count == 1
    np.testing.assert_allclose(scene.bounds()[1], [2, 3, 0])


def test_an_index_past_the_vertices_read_is_refused_in_one_line(tmp_path):
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(write(tmp_path, "bad.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n"))
    message = str(caught.value)
    assert "bad.obj" in message and "line 3" in message and "vertex -3" in message
    assert "\n" not in message


def test_texture_coordinates_without_a_material_get_the_default_albedo(tmp_path):
    """Not trimesh's 2 x 2 placeholder texture: the documented diffuse 0.5, with the note."""
    scene = ptrace.load(write(tmp_path, "uv.obj", BOX))
    assert list(scene.materials.kind) == [DIFFUSE]
    np.testing.assert_allclose(scene.materials.albedo[0], 0.5)
    assert len(scene.textures) == 0 and scene.materials.albedo_texture[0] == -1
    assert any("without a material" in note for note in scene.notes), scene.notes


def textured(tmp_path, reference, image=None, obj_body=BOX, extra_mtl=""):
    """box.obj using material 'skin' whose map_Kd is `reference`; `image` written as
    tex/skin.png when given."""
    if image is not None:
        (tmp_path / "tex").mkdir(exist_ok=True)
        (tmp_path / "tex" / "skin.png").write_bytes(image)
    (tmp_path / "box.mtl").write_text(f"newmtl skin\nKd 1 1 1\nmap_Kd {reference}\n{extra_mtl}")
    return write(tmp_path, "box.obj", "mtllib box.mtl\nusemtl skin\n" + obj_body)


def test_a_backslash_texture_path_is_read(tmp_path):
    scene = ptrace.load(textured(tmp_path, r".\tex\skin.png", png_bytes("RGB", (0, 255, 0))))
    assert scene.materials.albedo_texture[0] == 0
    np.testing.assert_allclose(scene.textures.texels[0], [0, 1, 0], atol=1e-4)


@pytest.mark.parametrize("mode, colour, expected", [
    ("P", (255, 0, 0), (255, 0, 0)), ("L", 128, (128, 128, 128)),
    ("LA", 128, (128, 128, 128)), ("I;16", 65535 // 2, (0.5, 0.5, 0.5)),
    ("RGBA", (0, 0, 255), (0, 0, 255)), ("1", 1, (255, 255, 255))])
def test_every_png_colour_type_is_read_as_its_colour(tmp_path, mode, colour, expected):
    """A palette PNG is its palette's colours (not its indices), grey is grey in every channel,
    16-bit is scaled by 65535."""
    scene = ptrace.load(textured(tmp_path, "tex/skin.png", png_bytes(mode, colour)))
    expected = np.asarray(expected, float)
    expected = expected / 255 if expected.max() > 1 else expected
    want = linear_rgb(np.round(expected * 65535).astype(np.uint16)[None, None], srgb=True)
    np.testing.assert_allclose(scene.textures.texels[0], want[0, 0], atol=2e-3)


def test_a_16_bit_rgb_png_is_read_at_16_bits(tmp_path):
    (tmp_path / "tex").mkdir()
    rgb16_png(tmp_path / "tex" / "skin.png", (65535, 32768, 1000))
    scene = ptrace.load(textured(tmp_path, "tex/skin.png"))
    want = linear_rgb(np.array([[[65535, 32768, 1000]]], np.uint16), srgb=True)[0, 0]
    np.testing.assert_allclose(scene.textures.texels[0], want, rtol=1e-5)


@pytest.mark.parametrize("reference, image, words", [
    ("tex/none.png", None, "was not found"),
    ("tex/skin.png", b"\x89PNG but not really", "could not be read as an image")])
def test_a_missing_or_unreadable_texture_is_a_note(tmp_path, reference, image, words):
    scene = ptrace.load(textured(tmp_path, reference, image))
    assert len(scene.textures) == 0
    np.testing.assert_allclose(scene.materials.albedo[0], 1.0)      # Kd alone
    assert any(words in note and "map_Kd" in note for note in scene.notes), scene.notes


def test_a_missing_mtl_is_a_note_and_its_faces_get_the_default(tmp_path):
    scene = ptrace.load(write(tmp_path, "box.obj", "mtllib gone.mtl\nusemtl skin\n" + BOX))
    np.testing.assert_allclose(scene.materials.albedo[0], 0.5)
    notes = scene.notes
    assert any("gone.mtl" in n and "was not found" in n for n in notes), notes
    assert any("skin" in n and "defined in no .mtl" in n for n in notes), notes


def test_faces_without_texture_coordinates_do_not_take_the_texture(tmp_path):
    """Their texture coordinates would all be (0, 0): one texel as the colour. They get the
    material without its texture, noted."""
    body = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\nf 1 3 2\n"
    scene = ptrace.load(textured(tmp_path, "tex/skin.png", png_bytes("RGB"), obj_body=body))
    with_texture = scene.materials.albedo_texture[scene.material_index]
    assert sorted(with_texture.tolist()) == [-1, 0]
    assert any("without texture coordinates" in n for n in scene.notes), scene.notes


def test_nan_in_a_material_is_refused_naming_it(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl paint\nKd nan 0.5 0.5\n")
    path = write(tmp_path, "m.obj", "mtllib m.mtl\nusemtl paint\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                    "f 1 2 3\n")
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    message = str(caught.value)
    assert "m.mtl" in message and "'paint'" in message and "Kd" in message and "NaN" in message


def test_thirty_materials_give_one_note_line_per_kind(tmp_path):
    """Every material has an ignored Ka and a missing texture: two kinds, two lines."""
    mtl = "".join(f"newmtl m{i}\nKa 0 0 0\nKd 0.5 0.5 0.5\nmap_Kd gone{i}.png\n"
                  for i in range(30))
    (tmp_path / "many.mtl").write_text(mtl)
    faces = "".join(f"usemtl m{i}\nf 1/1 2/2 3/3\n" for i in range(30))
    path = write(tmp_path, "many.obj", "mtllib many.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                       "vt 0 0\nvt 1 0\nvt 0 1\n" + faces)
    lines = grouped_notes(ptrace.load(path).notes)
    about = [line for line in lines if "m0" in line or "m1" in line]
    assert len(about) == 2, lines
    assert any("30 places" in line and "was not found" in line for line in about), lines


def test_vertex_colours_after_the_coordinates_are_read(tmp_path):
    scene = ptrace.load(write(tmp_path, "c.obj", "v 0 0 0 1 0 0\nv 1 0 0 1 0 0\n"
                                                 "v 0 1 0 1 0 0\nf 1 2 3\n"))
    np.testing.assert_allclose(scene.vertex_colours, [[1, 0, 0]] * 3, atol=1e-4)
    np.testing.assert_allclose(scene.bounds()[1], [1, 1, 0])


@pytest.mark.parametrize("content, words", [
    (bytes(range(256)) * 4, "binary data"),
    (b"\xfe\xe3\"y\xf2 \xbc\x82f\xa7R\xc0\n\x95Q\xf2", "not an OBJ file"),
    (b"v 0 0 0\nv 1 0 0\n", "only points"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "is not of the form"),
    (b"v 0 0 0\nv 1 0 zero\nv 0 1 0\nf 1 2 3\n", "where a number belongs")])
def test_bad_obj_files_are_one_line_in_words(tmp_path, content, words):
    path = tmp_path / "bad.obj"
    path.write_bytes(content)
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    message = str(caught.value)
    assert "bad.obj" in message and words in message and "\n" not in message, message
    assert "Error" not in message, message


def test_a_file_whose_emitter_lights_nothing_gets_the_default_light_and_says_so(tmp_path):
    """A lone emissive triangle lights no other surface: the default light is added beside it
    (ptrace.io.default_light; tests/ptrace/test_default_light.py has the rule's cases)."""
    (tmp_path / "lamp.mtl").write_text("newmtl lamp\nKe 5 5 5\n")
    path = write(tmp_path, "lamp.obj", "mtllib lamp.mtl\nusemtl lamp\nv 0 0 0\nv 1 0 0\n"
                                       "v 0 1 0\nf 1 2 3\n")
    scene = ptrace.load(path)
    assert len(scene.lights) == 1
    assert any("its emissive surfaces send" in n and "beside them" in n
               for n in scene.notes), scene.notes


CUBE = "".join(f"v {x} {y} {z}\n" for x in (0, 1) for y in (0, 1) for z in (0, 1)) + """
vn -1 0 0
vn 1 0 0
vn 0 -1 0
vn 0 1 0
vn 0 0 -1
vn 0 0 1
f 1//1 2//1 4//1 3//1
f 5//2 7//2 8//2 6//2
f 1//3 5//3 6//3 2//3
f 3//4 4//4 8//4 7//4
f 1//5 3//5 7//5 5//5
f 2//6 6//6 8//6 4//6
"""


def test_hard_edges_where_the_file_gives_a_corner_several_normals(tmp_path):
    """The file's normals are not read, but where it gives one position several normals (a
    cube's corners) the faces do not share the vertex: flat faces, not a smoothed blob."""
    scene = ptrace.load(write(tmp_path, "cube.obj", CUBE))
    assert scene.triangle_count == 12 and len(scene.geometry.vertices) == 24
    corners = scene.geometry.vertices[scene.geometry.faces]
    face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face_normals /= np.linalg.norm(face_normals, axis=1, keepdims=True)
    at_corners = scene.vertex_normals[scene.geometry.faces]
    np.testing.assert_allclose(at_corners, np.repeat(face_normals[:, None], 3, axis=1),
                               atol=1e-9)
    smooth = ptrace.load(write(tmp_path, "smooth.obj", re.sub(r"//\d+", "", CUBE)))
    assert len(smooth.geometry.vertices) == 8


@pytest.mark.parametrize("smoothing, vertices", [("s off\n", 24), ("s 1\n", 8), ("", 8)])
def test_smoothing_groups_decide_shared_vertices_without_normals(tmp_path, smoothing,
                                                                  vertices):
    """Without vn: `s off` makes every face flat (the OBJ specification); a smoothing group,
    or no `s` at all (the course's rule), shares the corners."""
    text = smoothing + re.sub(r"//\d+", "", CUBE)
    scene = ptrace.load(write(tmp_path, "cube.obj", text))
    assert len(scene.geometry.vertices) == vertices
