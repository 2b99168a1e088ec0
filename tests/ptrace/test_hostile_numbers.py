"""Extreme numbers from flags and files, library text on stderr (item 2) and
a killed render's temporary file (item 3).

Every number from a flag or a file is finite and within ptrace.io.limits.LIMIT (1e30: its
products stay finite in float64), or it is refused in one line naming the flag, or the file
and the element, with exit code 2: never a traceback, never a message about another flag, never
numpy's own warnings. A value the format allows but that makes nothing visible gets a note.
What OpenImageIO and libpng print themselves is folded into ptrace's one line. A render killed
while it writes leaves a temporary file that the next write into the folder removes; the old
output stays intact."""
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from files_by_hand import QUAD, QUAD_FACES, QUAD_UV_GLTF, gltf

import ptrace
from ptrace.app import cli
from ptrace.image import read_image, write_image
from ptrace.io.limits import LIMIT

from console import SHIPPED, ptrace_command

TINY = ["-r", 32, 24, "-s", 1, "-m", 1, "-t", 1]


def one_line(capsys, *args):
    """(exit code, the one stderr line) of the CLI run in this process; fails on more lines."""
    code = cli.main([str(a) for a in args])
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return code, lines[0]


def in_a_process(*args, cwd=None):
    """(exit code, stderr lines, stdout) of the console script: what C libraries write to file
    descriptor 2 is seen here, which capsys cannot see."""
    result = subprocess.run(ptrace_command() + [str(a) for a in args], capture_output=True,
                            text=True, timeout=300, cwd=cwd, stdin=subprocess.DEVNULL)
    return result.returncode, result.stderr.strip().splitlines(), result.stdout


# --- numbers from files ---------------------------------------------------------------------

def emissive_obj(folder, ke="1e308 1e308 1e308"):
    """A lamp quad (Ke) above a floor, its material in lamp.mtl."""
    (folder / "lamp.mtl").write_text(f"newmtl lamp\nKe {ke}\nnewmtl floor\nKd 0.5 0.5 0.5\n")
    path = folder / "lamp.obj"
    path.write_text("mtllib lamp.mtl\nv -1 1 -1\nv 1 1 -1\nv 1 1 1\nv -1 1 1\n"
                    "v -5 -1 -5\nv 5 -1 -5\nv 5 -1 5\nv -5 -1 5\n"
                    "usemtl lamp\nf 1 3 2\nf 1 4 3\nusemtl floor\nf 5 6 7\nf 5 7 8\n")
    return path


def emissive_gltf(path, strength):
    material = {"name": "glow", "emissiveFactor": [1.0, 1.0, 1.0],
                "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": strength}}}
    gltf(path, [dict(positions=QUAD, indices=QUAD_FACES.reshape(-1), uv=QUAD_UV_GLTF,
                     material=0)], materials=[material],
         document={"extensionsUsed": ["KHR_materials_emissive_strength"]})
    return path


def test_an_mtl_emission_of_1e308_is_refused_naming_the_mtl_and_the_material(tmp_path, capsys):
    """It used to crash the default-light check (its emitter weights overflowed to inf, and
    numpy's choice raised 'Probabilities contain NaN'): a traceback from a finite value."""
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", emissive_obj(tmp_path))
    assert code == 2 and line.startswith("ptrace: error: ") and "lamp.mtl" in line, line
    assert "material 'lamp'" in line and "Ke" in line and "1e+308" in line, line
    assert not (tmp_path / "x.png").exists()


def test_a_gltf_emissive_strength_of_1e308_is_refused_naming_the_file(tmp_path, capsys):
    path = emissive_gltf(tmp_path / "glow.gltf", 1e308)
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and "glow.gltf" in line and "material 'glow'" in line, line
    assert "emissiveStrength" in line and "1e+308" in line, line


def test_emission_at_the_limit_loads_and_its_share_is_finite(tmp_path):
    """The largest emission taken still gives the default-light rule a number, not a NaN."""
    scene = ptrace.load(emissive_obj(tmp_path, ke=f"{LIMIT:g} {LIMIT:g} {LIMIT:g}"))
    assert any("emissive surfaces light it" in note for note in scene.notes), scene.notes


def test_the_default_light_rule_survives_an_overflowing_emission():
    """Called with an emission whose luminance x area overflows (not from a file: the loaders
    refuse it), the rule still answers: the emitters light the file."""
    from ptrace.io.default_light import default_lights
    from ptrace.scene import DIFFUSE, EMISSION, Materials
    materials = Materials.from_records([{"kind": EMISSION, "emission": (1e308,) * 3},
                                        {"kind": DIFFUSE, "albedo": (0.5,) * 3}])
    vertices = np.array([[-1, 1, -1], [1, 1, -1], [1, 1, 1], [-1, 1, 1], [-5, -1, -5],
                         [5, -1, -5], [5, -1, 5], [-5, -1, 5]], float) * 1e3
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]])
    lights, note = default_lights(vertices, faces, np.array([0, 0, 1, 1]), materials,
                                  np.zeros((0, 3, 2)), None)
    assert lights == [] and "light it" in note, note


def _textured_quad_obj(folder, vt, map_line="map_Kd t.png", ke=""):
    """A textured triangle whose corners' texture coordinates are `vt` (three "u v" words)."""
    import PIL.Image
    PIL.Image.new("RGB", (8, 8), (255, 255, 255)).save(folder / "t.png")
    (folder / "q.mtl").write_text(f"newmtl m\nKd 1 1 1\n{ke}{map_line}\n")
    path = folder / "q.obj"
    path.write_text("mtllib q.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\n"
                    + "".join(f"vt {c}\n" for c in vt) + "usemtl m\nf 1/1 2/2 3/3\n")
    return path


@pytest.mark.parametrize("vt, words", [
    (["0 0", "1e308 0", "1 1"], "u at corner 2 (after the file's texture transforms): 1e+308 is "
                                "beyond ±1e+12"),
    (["0 0", "0 1", "0 -3e18"], "v at corner 3 (after the file's texture transforms): -3e+18 is "
                                "beyond ±1e+12"),
    (["nan 0", "0 1", "1 1"], "u at corner 1 (after the file's texture transforms): nan is not a "
                              "finite number")])
def test_texture_coordinates_beyond_the_limit_are_refused_naming_the_file_and_triangle(
        tmp_path, capsys, vt, words):
    """A texture lookup makes u x width a 64-bit texel index: past about 9e18 / width it wraps
    and reads an arbitrary texel (a 3e18 coordinate on an 8-texel texture rendered black), so
    coordinates beyond ptrace.io.limits.UV_LIMIT are refused where they enter, on an emitter
    (the default-light rule reads its texture) as on any surface."""
    for ke in ("", "Ke 1 1 1\nmap_Ke t.png\n"):
        path = _textured_quad_obj(tmp_path, vt, ke=ke)
        code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
        assert code == 2 and line == f"ptrace: error: {path}: triangle 1: its texture " \
                                      f"coordinate {words}" + line.split(words)[1], line
        assert not (tmp_path / "x.png").exists()


def test_gltf_texture_coordinates_beyond_the_limit_are_refused_after_its_transform(tmp_path,
                                                                                   capsys):
    """A glTF's TEXCOORD_0 of 3e38 (finite in float32), and coordinates in range that its
    KHR_texture_transform scales past the limit."""
    import io

    import PIL.Image
    stream = io.BytesIO()
    PIL.Image.new("RGB", (4, 4), (200, 100, 50)).save(stream, "PNG")
    for name, uv, transform in (("big", np.full((4, 2), 3e38), None),
                                ("scaled", QUAD_UV_GLTF, {"scale": [1e13, 1.0]})):
        info = {"index": 0}
        if transform:
            info["extensions"] = {"KHR_texture_transform": transform}
        path = tmp_path / f"{name}.gltf"
        gltf(path, [dict(positions=QUAD, indices=QUAD_FACES.reshape(-1), uv=uv, material=0)],
             materials=[{"pbrMetallicRoughness": {"baseColorTexture": info}}],
             images=[stream.getvalue()],
             document={"extensionsUsed": ["KHR_texture_transform"]} if transform else None)
        code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
        assert code == 2 and line.startswith(f"ptrace: error: {path}: triangle ") \
            and "texture coordinate u" in line and "beyond ±1e+12" in line, line


def test_the_texture_coordinate_limit_keeps_the_texel_index_in_range():
    """The kernels' lookup of a one-colour texture, by hand: every coordinate up to UV_LIMIT
    (either sign) reads that colour; 3e18, past it, does not (its index wraps): the limit is
    where it must be, not merely somewhere."""
    from ptrace.io.limits import UV_LIMIT
    from ptrace.textures import texture_lookup
    texels = np.tile(np.float32([0.25, 0.5, 0.75]), (64, 1))
    arrays = (texels, np.zeros(1, np.int64), np.full(1, 8, np.int64), np.full(1, 8, np.int64),
              np.zeros((1, 2), np.int64), 0)
    for s in (0.3, -0.3, 1e6, UV_LIMIT, -UV_LIMIT, UV_LIMIT * (1 - 2 ** -40)):
        for tv in (0.6, s):
            assert texture_lookup(*arrays, s, tv) == pytest.approx((0.25, 0.5, 0.75)), (s, tv)
    assert texture_lookup(*arrays, 3e18, 0.5) != pytest.approx((0.25, 0.5, 0.75))


@pytest.mark.parametrize("coordinate", ["1e308", "-1e308", "1e31"])
def test_an_obj_vertex_beyond_the_limit_is_refused_naming_the_file_and_line(tmp_path, capsys,
                                                                             coordinate):
    """It used to print numpy's overflow warnings, then blame -d (never given): the default
    camera's distance had overflowed."""
    path = tmp_path / "huge.obj"
    path.write_text(f"v -1 -1 0\nv 1 -1 0\nv {coordinate} 1 {coordinate}\nf 1 2 3\n")
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and "huge.obj" in line and "vertex 3 (line 3)" in line, line
    assert "-d" not in line and "warning" not in line and "1e+30" in line, line


def test_a_gltf_vertex_beyond_the_limit_is_refused_naming_the_file(tmp_path, capsys):
    """glTF's float32 positions reach 3.4e38, past the limit."""
    path = tmp_path / "huge.glb"
    gltf(path, [dict(positions=QUAD * 1e38, indices=QUAD_FACES.reshape(-1))])
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and "huge.glb" in line and "vertex" in line and "1e+30" in line, line


def test_gltf_scales_that_multiply_past_float64_are_one_line_naming_the_node(tmp_path,
                                                                            capsys):
    """Eleven nested nodes, each scaling by 1e30 (in range alone): numpy's overflow warnings
    used to come before the error."""
    path = tmp_path / "nested.gltf"
    nodes = [{"scale": [1e30] * 3, "children": [i + 1]} for i in range(11)] + [{"mesh": 0}]
    gltf(path, [dict(positions=QUAD, indices=QUAD_FACES.reshape(-1))], nodes=nodes,
         document={"scenes": [{"nodes": [0]}]})
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and "nested.gltf" in line and "node 10" in line, line
    assert "overflow" in line and "warning" not in line, line


def test_a_collada_sphere_of_radius_1e308_is_refused_naming_the_file_and_node(
        tmp_path, capsys, course_scene):
    """It used to end in an error about the camera's rotation, naming no file."""
    text = course_scene("sky/CBspheres.dae").read_text(encoding="utf-8")
    assert "<radius>.3</radius>" in text
    path = tmp_path / "spheres.dae"
    path.write_text(text.replace("<radius>.3</radius>", "<radius>1e308</radius>", 1))
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and "spheres.dae" in line and "<node" in line and "sphere" in line, line
    assert "rotation" not in line and "1e+308" in line, line


def test_a_collada_colour_beyond_the_limit_is_refused_naming_the_element(tmp_path,
                                                                       course_scene):
    text = (course_scene("simple/plane.dae")).read_text(encoding="utf-8")
    old = '<color sid="color">1 1 1</color>'
    assert old in text
    path = tmp_path / "bright.dae"
    path.write_text(text.replace(old, '<color sid="color">1e31 1 1</color>', 1))
    with pytest.raises(ptrace.SceneError, match=r"bright\.dae: <color.*1e\+31 is beyond"):
        ptrace.load(path)


def test_a_camera_file_beyond_the_limit_is_refused_naming_the_file(tmp_path, capsys):
    numbers = [73.7, 60, 4 / 3, 0.01, 100, 1e308, 0, 0, 0, 0, 0, 1.5708, 1.5708, 5, 1, 50,
               1, 0, 0, 0, 1, 0, 0, 0, 1, 800, 600, 519.6, 5, 0]
    path = tmp_path / "cam.txt"
    path.write_text(" ".join(str(x) for x in numbers))
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", "-c", path, SHIPPED)
    assert code == 2 and "cam.txt" in line and "1e+308" in line, line


# --- numbers from flags ---------------------------------------------------------------------

@pytest.mark.parametrize("args, flag", [
    (["--eye", "1e308,1e308,1e308"], "--eye"),
    (["--eye", "1,2,3", "--look-at", "0,1e31,0"], "--look-at"),
    (["--eye", "1,2,3", "--up", "0,1e308,0"], "--up"),
    (["-b", "1e308"], "-b"),
    (["-b", "nan"], "-b"),
    (["-d", "1e308"], "-d"),
    (["-d", "inf"], "-d"),
    (["-e", "1e308,1e308,1e308"], "-e"),
    (["-e", "1e31"], "-e"),
])
def test_a_flag_beyond_the_limit_is_refused_in_one_line_naming_it(tmp_path, capsys, args,
                                                                  flag):
    """Each used to render a black image with exit code 0 and no word (the viewer refused the
    same --eye; -e's samples were all dropped as non-finite)."""
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", *args, SHIPPED)
    assert code == 2 and line.startswith("ptrace: error: ") and flag in line, line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, words", [
    (["--fov", "1e-300"], "--fov 1e-300: narrower than 1e-09 degrees"),   # was about -d
    (["--max-memory", "-1G"], "got '-1G'")])    # was argparse's "expected one argument"
def test_a_flag_refused_names_itself_and_its_value(tmp_path, capsys, args, words):
    """On a mesh file (whose default camera --fov frames): --fov 1e-300 put the framing camera
    1.1e302 away and was refused as a focal distance (-d) never given."""
    path = tmp_path / "square.obj"
    path.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3\nf 1 3 4\n")
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", *args, path)
    assert code == 2 and line.startswith("ptrace: error: ") and words in line, line
    assert "(-d)" not in line and not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("args", [["-e", "-1,0,0"], ["--environment", "-0.5"],
                                  ["-e=-1,0,0"], ["-e", "1,-.5,1"]])
def test_a_negative_environment_colour_is_refused_naming_the_flag(tmp_path, capsys, args):
    """`-e -1,0,0` used to be argparse's "-e: expected one argument" (a value starting with '-'
    taken for a flag), and `-e=-1,0,0` an error naming "constant (-1.0, 0.0, 0.0)", not -e."""
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", *args, SHIPPED)
    assert code == 2 and line.startswith("ptrace: error: -e ") \
        and "the environment's colour: " in line and "is negative" in line, line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("spec", ["0,0,0", "0", "black.png"])
def test_a_black_environment_is_noted_and_so_is_a_scene_it_leaves_unlit(tmp_path, capsys, spec):
    """-e 0,0,0 (or an image of zeros) on a mesh file takes the default light's place and
    lights nothing: the image was black with exit 0 and no word (the renderer's warning for a
    scene without light counts the environment as a light). On the Cornell box, whose own
    light stays, the note says only that the environment lights nothing. (--info: no render.)"""
    import json

    import PIL.Image
    PIL.Image.new("RGB", (8, 4)).save(tmp_path / "black.png")
    path = tmp_path / "square.obj"
    path.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3\nf 1 3 4\n")
    arg = str(tmp_path / spec) if spec.endswith(".png") else spec
    for scene, alone in ((path, True), (SHIPPED, False)):
        assert cli.main(["--info", "-e", arg, str(scene)]) == 0
        notes = [n for n in json.loads(capsys.readouterr().out)["notes"] if n.startswith("-e ")]
        assert notes == [f"-e {arg}: the environment is black everywhere: it lights nothing"
                         + ("; the scene has no other light and no emissive surface: the image "
                            "will be black" if alone else "")], notes
    assert cli.main(["--info", "-e", "0,0.001,0", str(path)]) == 0
    assert "black everywhere" not in capsys.readouterr().out


def test_an_environment_image_beyond_the_limit_is_refused_naming_it(tmp_path, capsys):
    """A float EXR's 3e38 is finite, but every sample it lights would overflow."""
    import OpenImageIO as oiio
    image = str(tmp_path / "hot.exr")
    out = oiio.ImageOutput.create(image)
    out.open(image, oiio.ImageSpec(8, 4, 3, oiio.FLOAT))
    out.write_image(np.full((4, 8, 3), 3e38, np.float32))
    out.close()
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", "-e", image, SHIPPED)
    assert code == 2 and "hot.exr" in line and "3e+38 is beyond" in line, line


def test_the_python_api_refuses_the_same_numbers():
    scene = ptrace.load(SHIPPED)
    camera = ptrace.course_camera(scene, 8, 6)
    for lens in (dict(lens_radius=1e308), dict(focal_distance=1e308)):
        with pytest.raises(ptrace.PtraceError, match="1e\\+30"):
            camera.with_lens(**lens)
    from ptrace.environment import Environment, load_environment
    with pytest.raises(ptrace.PtraceError, match="beyond"):
        Environment.constant((1e308, 1e308, 1e308))
    with pytest.raises(ptrace.PtraceError, match="empty"):
        load_environment("")


def test_flags_at_the_limit_are_taken():
    """The limit itself is not refused (the render's image is another matter: see the notes)."""
    args = cli.parse(cli.build_parser(), ["-b", f"{LIMIT:g}", "-d", f"{LIMIT:g}", "-e",
                                          f"{LIMIT:g},0,0", "--eye", f"{-LIMIT:g},0,0",
                                          str(SHIPPED)])
    assert args.lens_radius == LIMIT and args.focal_distance == LIMIT


# --- a value that makes nothing visible: a note ------------------------------------------------

SUN = {"extensions": {"KHR_lights_punctual": {"lights": [{"type": "directional",
                                                          "intensity": 2.0}]}},
       "extensionsUsed": ["KHR_lights_punctual"]}


def cut_quad_over_a_floor(path, cutoff):
    """A white quad (alphaMode MASK, alphaCutoff `cutoff`) over a red floor the sun lights."""
    floor = dict(positions=QUAD * [2.0, 2.0, 0.0] + [0.0, 0.0, -1.0],
                 indices=QUAD_FACES.reshape(-1), uv=QUAD_UV_GLTF, material=0)
    front = dict(positions=QUAD, indices=QUAD_FACES.reshape(-1), uv=QUAD_UV_GLTF, material=1)
    red = {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1.0],
                                                     "metallicFactor": 0.0}}
    white = {"name": "front", "alphaMode": "MASK", "alphaCutoff": cutoff,
             "pbrMetallicRoughness": {"metallicFactor": 0.0}}
    gltf(path, [floor, front], materials=[red, white],
         nodes=[{"mesh": 0}, {"mesh": 1}, {"extensions": {"KHR_lights_punctual": {"light": 0}}}],
         extensions=SUN)
    return path


def test_an_alpha_cutoff_above_one_is_noted_once_and_the_rest_still_renders(tmp_path, capsys):
    """alphaCutoff 2 is valid glTF, but no alpha reaches it: every texel is cut away. It used
    to render so without a word."""
    path = cut_quad_over_a_floor(tmp_path / "cut.gltf", 2.0)
    output = tmp_path / "x.exr"
    code = cli.main([str(a) for a in TINY + ["-f", output, path]])
    err = capsys.readouterr().err.strip().splitlines()
    said = [line for line in err if "alphaCutoff" in line]
    assert code == 0 and len(said) == 1, err
    assert said[0].startswith("ptrace: note: <material 'front'>") and "invisible" in said[0]
    assert read_image(output)[..., 0].max() > 0   # the floor, seen where the quad was


def test_an_alpha_cutoff_within_range_has_no_such_note(tmp_path):
    scene = ptrace.load(cut_quad_over_a_floor(tmp_path / "fine.gltf", 0.5))
    assert not any("alphaCutoff" in note for note in scene.notes), scene.notes


def small_obj(folder):
    path = folder / "small.obj"
    path.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nf 1 2 3\n")
    return path


@pytest.mark.parametrize("args, words", [
    (["--eye", "1e6,1e6,1e6"], "of a pixel"),
    (["--eye", "1e29,1e29,1e29"], "float64"),
    (["-b", "1e29"], "lens's edge"),
    (["--eye", "0,0,5", "--look-at", "0,0,10"], "behind the camera"),
    (["--eye", "20,0,5", "--look-at", "20,0,0"], "outside the image"),
])
def test_a_camera_that_shows_nothing_of_the_scene_is_noted_once(tmp_path, capsys, args,
                                                                 words):
    """Numbers within range that still show nothing (the scene far smaller than a pixel, a
    lens or an eye so far that float64 cannot place the hits, the scene behind the camera or
    beside the image) used to give a black image without a word."""
    code = cli.main([str(a) for a in TINY + ["-f", tmp_path / "x.png"] + args
                     + [small_obj(tmp_path)]])
    err = capsys.readouterr().err.strip().splitlines()
    said = [line for line in err if "shows nothing" in line]
    assert code == 0 and len(said) == 1 and words in said[0], err
    assert said[0].startswith("ptrace: note: the camera shows nothing of the scene: ")


@pytest.mark.parametrize("focus, noted", [("1e-320", True), ("1e-8", True), ("1e-6", False),
                                          ("4.7", False)])
def test_a_lens_far_wider_than_its_focal_distance_is_noted(tmp_path, capsys, focus, noted):
    """-b 0.1 -d 1e-320 (any -d far below -b) sends every lens ray out nearly in the lens's
    plane: the render was black with exit 0 and no word. The rule (more than 1e6 times) by
    hand: -d 1e-8 is 1e7 times below -b 0.1, noted; 1e-6 is 1e5 times, not. (--info: no
    render.)"""
    import json
    code = cli.main(["--info", "-b", "0.1", "-d", focus, str(small_obj(tmp_path))])
    notes = [n for n in json.loads(capsys.readouterr().out)["notes"]
             if n.startswith("the lens radius")]
    assert code == 0 and len(notes) == int(noted), notes
    if noted:
        assert "more than 1e+06 times the focal distance" in notes[0] \
            and "all but black" in notes[0], notes


@pytest.mark.parametrize("args", [[], ["--eye", "0,0,5"], ["--eye", "0.5,0,0.5"],
                                  ["-b", "0.1"]])
def test_a_camera_that_shows_the_scene_has_no_such_note(tmp_path, capsys, args):
    code = cli.main([str(a) for a in TINY + ["-f", tmp_path / "x.png"] + args
                     + [small_obj(tmp_path)]])
    err = capsys.readouterr().err
    assert code == 0 and "shows nothing" not in err, err


def test_a_texture_beyond_the_limit_is_a_note_and_not_applied(tmp_path):
    """A float image's 3e38 (finite in float32) would make an emission of inf."""
    import OpenImageIO as oiio
    image = str(tmp_path / "hot.exr")
    out = oiio.ImageOutput.create(image)
    out.open(image, oiio.ImageSpec(4, 4, 3, oiio.FLOAT))
    out.write_image(np.full((4, 4, 3), 3e38, np.float32))
    out.close()
    (tmp_path / "hot.mtl").write_text("newmtl m\nKe 1 1 1\nmap_Ke hot.exr\n")
    path = tmp_path / "hot.obj"
    path.write_text("mtllib hot.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n"
                    "usemtl m\nf 1/1 2/2 3/3\n")
    scene = ptrace.load(path)
    notes = [n for n in scene.notes if "hot.exr" in n]
    assert len(notes) == 1 and "3e+38 is beyond" in notes[0], scene.notes
    assert scene.textures.names == [] or "hot.exr" not in scene.textures.names


# --- library text on stderr --------------------------------------------------------------------

def test_an_empty_environment_name_is_one_line_without_openimageio_s_assertion(tmp_path):
    code, err, _ = in_a_process(*TINY, "-f", tmp_path / "x.png", "-e", "", SHIPPED)
    assert code == 2 and len(err) == 1 and err[0].startswith("ptrace: error: -e"), err


def truncated_png():
    import io

    import PIL.Image
    noise = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    stream = io.BytesIO()
    PIL.Image.fromarray(noise).save(stream, "PNG")
    data = stream.getvalue()
    return data[:len(data) // 2]   # cut in its pixel data (IDAT)


def test_a_truncated_png_texture_is_one_note_line_without_libpng_s(tmp_path):
    (tmp_path / "cut.png").write_bytes(truncated_png())
    (tmp_path / "scene.mtl").write_text("newmtl m\nKd 1 1 1\nmap_Kd cut.png\n")
    path = tmp_path / "scene.obj"
    path.write_text("mtllib scene.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    code, err, out = in_a_process("--info", path)
    assert code == 0 and err == [], err     # nothing from libpng on the terminal
    import json
    notes = [n for n in json.loads(out)["notes"] if "cut.png" in n]
    assert len(notes) == 1 and "\n" not in notes[0] and "libpng" not in notes[0], notes
    assert "could not be read as an image" in notes[0], notes


def test_a_truncated_png_environment_is_one_error_line(tmp_path):
    (tmp_path / "sky.png").write_bytes(truncated_png())
    code, err, _ = in_a_process(*TINY, "-f", tmp_path / "x.png", "-e", tmp_path / "sky.png",
                                SHIPPED)
    assert code == 2 and len(err) == 1 and "sky.png" in err[0], err
    assert "libpng" not in err[0], err


# --- a render killed while it writes -------------------------------------------------------

KILLED_WRITER = textwrap.dedent("""
    import sys, time
    import numpy as np
    import ptrace.image as image

    def stuck(temporary, *args):     # half an image in the temporary file, then killed
        with open(temporary, "wb") as handle:
            handle.write(b"partial")
        print("writing", flush=True)
        time.sleep(600)
    image._write_temporary = stuck
    if sys.argv[2] == "named":       # as on a filesystem without O_TMPFILE
        image._unnamed = lambda directory: None
    image.write_image(sys.argv[1], np.zeros((4, 5, 3)))
""")


def killed_while_writing(target, kind):
    """The pid of a process killed (SIGKILL) while it wrote target's temporary file."""
    child = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(target), kind],
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "writing"   # its readiness signal
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=60)
    return child.pid


def test_a_render_killed_while_it_writes_leaves_nothing(tmp_path):
    """kill -9 while the image is written into a file without a name (O_TMPFILE): nothing is
    left beside the old file, which stays whole."""
    from ptrace.image import _unnamed
    probe = _unnamed(str(tmp_path))
    if probe is None:
        pytest.skip("this filesystem has no O_TMPFILE: the next test covers it")
    os.close(probe)
    target = tmp_path / "out.exr"
    write_image(target, np.full((4, 5, 3), 0.25))
    before = target.read_bytes()
    killed_while_writing(target, "unnamed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]
    assert target.read_bytes() == before


def test_a_named_temporary_file_of_a_killed_render_goes_at_the_next_write(tmp_path):
    """Without O_TMPFILE the killed process's temporary file (named with its host and pid)
    stays until the next write into the folder removes it; the old file stays whole."""
    target = tmp_path / "out.exr"
    write_image(target, np.full((4, 5, 3), 0.25))
    before = target.read_bytes()
    pid = killed_while_writing(target, "named")
    left = [p.name for p in tmp_path.iterdir() if p.name != "out.exr"]
    assert len(left) == 1 and left[0].startswith(".ptrace-") and f"-{pid}-" in left[0], left
    assert target.read_bytes() == before
    write_image(tmp_path / "other.png", np.full((4, 5, 3), 0.5))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.png", "out.exr"]
    assert target.read_bytes() == before


def test_an_unnamed_write_replaces_an_old_file_and_makes_a_new_one(tmp_path):
    """Both ways a file without a name gets one: over an old file (a temporary name, then the
    rename) and where there was none (linked at its path)."""
    old, new = tmp_path / "old.exr", tmp_path / "new.exr"
    write_image(old, np.full((4, 5, 3), 0.25))
    write_image(old, np.full((4, 5, 3), 0.75))
    write_image(new, np.full((4, 5, 3), 0.5))
    np.testing.assert_allclose(read_image(old), 0.75)
    np.testing.assert_allclose(read_image(new), 0.5)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.exr", "old.exr"]
    assert oct(os.stat(new).st_mode & 0o777) == oct(0o644)


def test_only_temporaries_of_ended_processes_of_this_host_are_removed(tmp_path):
    from ptrace.image import _host, remove_dead_temporaries
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                           capture_output=True, text=True, check=True)
    dead = int(ended.stdout)
    names = {f".ptrace-{_host()}-{dead}-abc.exr": False,        # removed
             f".ptrace-{_host()}-{os.getpid()}-abc.exr": True,  # this process: running
             f".ptrace-{_host()}x-{dead}-abc.exr": True,         # another host's
             ".ptrace-abc.exr": True, "picture.exr": True}
    for name in names:
        (tmp_path / name).write_bytes(b"")
    assert remove_dead_temporaries(tmp_path) == [f".ptrace-{_host()}-{dead}-abc.exr"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(n for n, k in names.items() if k)
