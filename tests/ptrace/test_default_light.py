"""The default light of a mesh file without lights (ptrace.io.default_light): a closed room lit
by its own emissive quad gets none; a model whose emitters are small, or light nothing but
themselves, gets the ambient light beside them; the note says which rule applied;
--no-default-light, load(..., default_light=False) and -e take it away."""
import json

import numpy as np
import pytest
from files_by_hand import gltf

import ptrace
from ptrace.app.cli import MESH_FILE, main
from ptrace.io.default_light import EMITTER_SHARE, NOTE, emitter_share
from ptrace.scene import AMBIENT, ENVIRONMENT


def box_faces(lower, upper, offset=0):
    """The 8 corners and 12 triangles (1-based OBJ indices from offset + 1) of a box."""
    corners = [[(lower, upper)[i >> k & 1][k] for k in range(3)] for i in range(8)]
    faces = []
    for axis in range(3):
        for side in (0, 1):
            a, b, d, c = [i for i in range(8) if (i >> axis & 1) == side]
            faces += [(a, b, c), (a, c, d)]
    return corners, [[offset + i + 1 for i in face] for face in faces]


def write_obj(tmp_path, name, groups, mtl):
    """groups: [(material, corners, faces)] with faces indexing that group's corners."""
    (tmp_path / f"{name}.mtl").write_text(mtl)
    lines, offset = [f"mtllib {name}.mtl"], 0
    for material, corners, faces in groups:
        lines += [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in corners]
        lines.append(f"usemtl {material}")
        lines += ["f " + " ".join(str(offset + i) for i in face) for face in faces]
        offset += len(corners)
    path = tmp_path / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


MTL = "newmtl wall\nKd 0.7 0.7 0.7\nnewmtl lamp\nKe {0} {0} {0}\n"


def room(tmp_path, radiance=10.0, lamp=0.25):
    """A closed 2 x 2 x 2 room and a square lamp of side 2 x lamp just under its ceiling
    (facing down), as an OBJ Cornell box has it."""
    corners, faces = box_faces((-1.0, 0.0, -1.0), (1.0, 2.0, 1.0))
    square = [(-lamp, 1.99, -lamp), (lamp, 1.99, -lamp), (lamp, 1.99, lamp), (-lamp, 1.99, lamp)]
    return write_obj(tmp_path, "room", [("wall", corners, faces),
                                        ("lamp", square, [(1, 3, 2), (1, 4, 3)])],
                     MTL.format(radiance))


def patch(tmp_path):
    """A 2 x 2 x 2 block on a 6 x 6 floor, one tiny emissive triangle (area 0.005) on the
    block's side, facing out: it lights a speck of floor and nothing else."""
    corners, faces = box_faces((-1.0, 0.0, -1.0), (1.0, 2.0, 1.0))
    floor = [(-3, 0, -3), (3, 0, -3), (3, 0, 3), (-3, 0, 3)]
    speck = [(1.001, 1.0, 0.0), (1.001, 1.1, 0.0), (1.001, 1.0, 0.1)]
    return write_obj(tmp_path, "patch", [("wall", corners, faces),
                                         ("wall", floor, [(1, 2, 3), (1, 3, 4)]),
                                         ("lamp", speck, [(1, 2, 3)])], MTL.format(10))


def notes_of(scene):
    return [n for n in scene.notes if n.startswith(NOTE)]


def test_a_room_lit_by_its_own_quad_gets_no_default_light(tmp_path):
    scene = ptrace.load(room(tmp_path))
    assert len(scene.lights) == 0
    note, = notes_of(scene)
    assert "its emissive surfaces light it" in note, note


def test_a_tiny_emissive_patch_gets_the_default_light_and_says_so(tmp_path):
    scene = ptrace.load(patch(tmp_path))
    assert list(scene.lights.kind) == [AMBIENT]
    np.testing.assert_allclose(scene.lights.radiance[0], [1, 1, 1])
    note, = notes_of(scene)
    assert "one ambient light of radiance 1 beside them" in note, note


def test_the_share_follows_the_lamps_power_and_not_the_units(tmp_path):
    """The room's share grows with the lamp's radiance (in proportion) and does not change
    when the file's coordinates are scaled; a dim enough lamp gets the default light."""
    scene = ptrace.load(room(tmp_path, radiance=10.0))
    args = (scene.geometry.vertices, scene.geometry.faces, scene.material_index,
            scene.materials, scene.uv, scene.textures)
    share = emitter_share(*args)
    assert share > EMITTER_SHARE
    scaled = emitter_share(scene.geometry.vertices * 1000.0, *args[1:])
    assert scaled == pytest.approx(share, rel=1e-6)
    (tmp_path / "dim").mkdir()
    dim = ptrace.load(room(tmp_path / "dim", radiance=10.0 * 0.5 * EMITTER_SHARE / share))
    assert list(dim.lights.kind) == [AMBIENT]


def test_a_label_on_a_board_gets_the_default_light(tmp_path):
    """A bright emissive label just in front of a board, facing away from it: half its light
    lands on the board right behind it, which the label hides, and half leaves the scene, so
    the default light is added (light landing nearer than NEAR is not counted)."""
    board = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
    label = [(-0.5, -0.5, 0.001), (0.5, -0.5, 0.001), (0.5, 0.5, 0.001), (-0.5, 0.5, 0.001)]
    path = write_obj(tmp_path, "label", [("wall", board, [(1, 2, 3), (1, 3, 4)]),
                                         ("lamp", label, [(1, 2, 3), (1, 3, 4)])],
                     MTL.format(5))
    scene = ptrace.load(path)
    assert list(scene.lights.kind) == [AMBIENT]


def test_an_emissive_cube_lights_only_itself_and_gets_the_default_light(tmp_path):
    """Every face of a cube emits: its light lands on nothing but emitters (its own inside),
    which nothing sees, so the default light is added (a glTF file, emissiveFactor)."""
    corners, faces = box_faces((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    path = tmp_path / "glow.gltf"
    gltf(path, [dict(positions=corners, indices=np.array(faces).reshape(-1) - 1, material=0)],
         materials=[{"emissiveFactor": [1.0, 1.0, 1.0]}])
    scene = ptrace.load(path)
    assert list(scene.lights.kind) == [AMBIENT]
    note, = notes_of(scene)
    assert "0 %" in note, note


def test_no_default_light_removes_it(tmp_path, capsys):
    path = patch(tmp_path)
    scene = ptrace.load(path, default_light=False)
    assert len(scene.lights) == 0
    note, = notes_of(scene)
    assert "off" in note and "only light" in note, note
    assert main(["--info", "--no-default-light", str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["lights"] == []
    said = f"{path.name}: {NOTE.removeprefix(MESH_FILE)}off"   # (the command names the file)
    assert any(n.startswith(said) for n in info["notes"]), info["notes"]
    assert main(["--info", str(path)]) == 0
    assert [light["type"] for light in json.loads(capsys.readouterr().out)["lights"]] == \
        ["ambient"]


def test_environment_replaces_the_default_light(tmp_path, capsys):
    path = patch(tmp_path)
    assert main(["--info", "-e", "0.5,0.5,0.5", str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert [light["type"] for light in info["lights"]] == ["environment"]
    assert any("-e's environment lights the scene in its place" in n for n in info["notes"]), \
        info["notes"]
    scene = ptrace.load(path).with_environment(ptrace.load_environment("0.5,0.5,0.5"))
    assert set(scene.lights.kind.tolist()) == {AMBIENT, ENVIRONMENT}   # Python: both


def test_a_file_without_emitters_or_lights_keeps_the_default_light(tmp_path):
    path = tmp_path / "tri.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = ptrace.load(path)
    assert list(scene.lights.kind) == [AMBIENT]
    note, = notes_of(scene)
    assert "no light and no emissive surface" in note, note
    assert len(ptrace.load(path, default_light=False).lights) == 0


def test_no_default_light_on_a_course_scene_is_refused(tmp_path, capsys):
    path = tmp_path / "scene.dae"
    path.write_text("<COLLADA/>")
    assert main(["--info", "--no-default-light", str(path)]) == 2
    err = capsys.readouterr().err
    assert "--no-default-light" in err and "course scene" in err and err.count("\n") == 1, err
