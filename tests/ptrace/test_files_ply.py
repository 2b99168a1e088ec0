"""PLY files (ptrace.io.ply): vertex colours under the names writers use, and files without
faces refused with the reason."""
import numpy as np
import pytest

import ptrace
from ptrace.io.materials import linear_rgb

HEADER = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n" \
         "property float z\n{colour}{faces}end_header\n"
FACE = "element face 1\nproperty list uchar int vertex_indices\n"


def write(tmp_path, colour_properties="", rows=("0 0 0", "1 0 0", "0 1 0"), faces=FACE,
          tail="3 0 1 2\n"):
    colour = "".join(f"property {p}\n" for p in colour_properties)
    path = tmp_path / "mesh.ply"
    path.write_text(HEADER.format(colour=colour, faces=faces) + "\n".join(rows) + "\n" + tail)
    return path


@pytest.mark.parametrize("properties, values", [
    (("uchar red", "uchar green", "uchar blue"), "255 128 0"),
    (("float r", "float g", "float b"), "1.0 0.50196 0.0"),
    (("float red", "float green", "float blue"), "1.0 0.50196 0.0"),
    (("ushort red", "ushort green", "ushort blue"), "65535 32896 0"),
    (("uchar diffuse_red", "uchar diffuse_green", "uchar diffuse_blue"), "255 128 0")])
def test_vertex_colours_under_their_common_names(tmp_path, properties, values):
    """float r g b were dropped without a note; every spelling is the same colour."""
    rows = [f"{p} {values}" for p in ("0 0 0", "1 0 0", "0 1 0")]
    scene = ptrace.load(write(tmp_path, properties, rows))
    expected = linear_rgb(np.array([[[255, 128, 0]]], np.uint8), srgb=True)[0, 0]
    np.testing.assert_allclose(scene.vertex_colours, [expected] * 3, atol=1e-4)
    assert any("vertex colours" in n for n in scene.notes), scene.notes


def test_a_ply_of_points_is_refused_saying_so(tmp_path):
    with pytest.raises(ptrace.SceneError, match="contains only points") as caught:
        ptrace.load(write(tmp_path, faces="", tail=""))
    assert "mesh.ply" in str(caught.value)


def test_a_ply_of_triangle_strips_is_refused_saying_so(tmp_path):
    strips = "element tristrips 1\nproperty list int int vertex_indices\n"
    with pytest.raises(ptrace.SceneError, match="triangle strips are not supported"):
        ptrace.load(write(tmp_path, faces=strips, tail="3 0 1 2\n"))


def test_a_file_that_is_not_ply_says_so(tmp_path):
    path = tmp_path / "mesh.ply"
    path.write_bytes(b"\x00\x01binary junk")
    with pytest.raises(ptrace.SceneError, match="is not a PLY file"):
        ptrace.load(path)


UV_PLY = "ply\nformat ascii 1.0\n{comment}element vertex 3\nproperty float x\n" \
         "property float y\nproperty float z\nproperty float s\nproperty float t\n" \
         "element face 1\nproperty list uchar int vertex_indices\nend_header\n" \
         "0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n"


def test_texture_coordinates_without_a_texture_file_get_the_default_albedo(tmp_path):
    """trimesh gives them its 2 x 2 placeholder texture; ptrace the documented default."""
    path = tmp_path / "uv.ply"
    path.write_text(UV_PLY.format(comment=""))
    scene = ptrace.load(path)
    assert len(scene.textures) == 0
    np.testing.assert_allclose(scene.materials.albedo[0], 0.5)
    assert any("without a material" in n for n in scene.notes), scene.notes


def test_a_texture_file_comment_is_the_albedo_texture(tmp_path):
    from files_by_hand import png_bytes
    (tmp_path / "skin.png").write_bytes(png_bytes("RGB", (0, 0, 255)))
    path = tmp_path / "uv.ply"
    path.write_text(UV_PLY.format(comment="comment TextureFile skin.png\n"))
    scene = ptrace.load(path)
    assert scene.materials.albedo_texture[0] == 0
    np.testing.assert_allclose(scene.textures.texels[0], [0, 0, 1], atol=1e-4)


def test_a_flat_model_edge_on_to_the_default_camera_is_noted(tmp_path):
    """One triangle in the plane x = 0, which the default view along -Z sees edge-on: the
    default camera looks from the plane's normal (+X) instead, and the note says so."""
    path = write(tmp_path, rows=("0 0 0", "0 1 0", "0 0 1"))
    scene = ptrace.load(path)
    assert any("edge-on" in n and "plane's normal" in n for n in scene.notes)
    np.testing.assert_allclose(ptrace.framing_camera(scene).camera_to_world[:, 2], [1, 0, 0],
                               atol=1e-12)
    assert (ptrace.render(scene, integrator="normals", resolution=(16, 12)).sum(-1) > 0).any()
    assert not any("edge-on" in n for n in ptrace.load(write(tmp_path)).notes)


@pytest.mark.parametrize("endian", ["<", ">"])
def test_a_binary_ply_of_positions_reads_as_trimesh_reads_it(tmp_path, monkeypatch, endian):
    """A binary PLY of positions and triangles (with an extra per-vertex property) is read
    straight into the flat arrays, and gives what the trimesh reader gives: the same vertices
    after merging equal positions (first occurrence first), the same faces, the face with a
    NaN corner dropped and counted, the same notes."""
    from ptrace.io import ply
    positions = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 0), (np.nan, 0, 0),
                 (2, 2, 2), (1, 0, 0)]
    vertices = np.zeros(len(positions), [("x", endian + "f4"), ("y", endian + "f4"),
                                         ("z", endian + "f4"), ("quality", endian + "f8")])
    vertices["x"], vertices["y"], vertices["z"] = np.array(positions, np.float32).T
    faces = np.zeros(4, [("n", "u1"), ("i", endian + "i4", 3)])
    faces["n"], faces["i"] = 3, [[0, 1, 2], [4, 3, 2], [5, 1, 3], [7, 3, 4]]
    name = {"<": "binary_little_endian", ">": "binary_big_endian"}[endian]
    header = (f"ply\nformat {name} 1.0\nelement vertex {len(positions)}\nproperty float x\n"
              "property float y\nproperty float z\nproperty double quality\n"
              "element face 4\nproperty list uchar int vertex_indices\nend_header\n")
    path = tmp_path / "mesh.ply"
    path.write_bytes(header.encode() + vertices.tobytes() + faces.tobytes())
    data = path.read_bytes()
    assert ply.read_plain_binary(str(path), data) is not None     # the direct reader's file
    direct = ptrace.load(path)
    monkeypatch.setattr(ply, "read_plain_binary", lambda *args: None)
    through_trimesh = ptrace.load(path)
    assert direct.geometry.vertices.tolist() == through_trimesh.geometry.vertices.tolist()
    assert direct.geometry.faces.tolist() == through_trimesh.geometry.faces.tolist()
    assert direct.geometry.faces.tolist() == [[0, 1, 2], [0, 3, 2], [1, 3, 0]]
    assert direct.notes == through_trimesh.notes
    assert any("dropped 1 face(s)" in note for note in direct.notes), direct.notes
