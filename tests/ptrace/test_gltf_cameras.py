"""A glTF file's own cameras (Scene.file_cameras, ptrace.pointing.file_camera, --camera-index):
the default camera of a glTF file is its first perspective camera, placed and turned by its
node; -r's aspect wins over the file's; orthographic cameras are refused when picked and
passed over by default; bad numbers and indices are refused in one line."""
import json
import math

import numpy as np
import pytest
from files_by_hand import gltf

import ptrace
from ptrace.app.cli import main
from ptrace.pointing import default_camera, file_camera, framing_camera

TRIANGLE = dict(positions=[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]],
                indices=[0, 1, 2])
PERSPECTIVE = {"type": "perspective", "name": "front",
               "perspective": {"yfov": 0.6, "znear": 0.05, "zfar": 100.0, "aspectRatio": 1.5}}
ORTHOGRAPHIC = {"type": "orthographic", "name": "flat",
                "orthographic": {"xmag": 1.0, "ymag": 1.0, "znear": 0.0, "zfar": 10.0}}


def quaternion(axis, degrees):
    """glTF's rotation (x, y, z, w) of `degrees` about `axis`."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    half = math.radians(degrees) / 2
    return [*(axis * math.sin(half)), math.cos(half)]


def write(tmp_path, camera_nodes, cameras, name="camera.gltf"):
    """A triangle (node 0) and camera nodes (each a dict of node fields), all roots."""
    path = tmp_path / name
    nodes = [{"mesh": 0}] + list(camera_nodes)
    gltf(path, [TRIANGLE], nodes=nodes, document={"cameras": list(cameras)})
    return path


def test_default_camera_is_the_nodes_camera(tmp_path):
    """A camera node at (0, 0, 5) with no rotation looks down -Z at the triangle: position,
    direction, up, the vertical field of view (yfov at any -r) and clip distances match."""
    path = write(tmp_path, [{"camera": 0, "translation": [0.0, 0.0, 5.0]}], [PERSPECTIVE])
    scene = ptrace.load(path)
    assert len(scene.file_cameras) == 1 and scene.file_cameras[0].kind == "perspective"
    for width, height in ((300, 200), (100, 200)):
        camera = default_camera(scene, width, height)
        np.testing.assert_allclose(camera.position, [0.0, 0.0, 5.0], atol=1e-12)
        np.testing.assert_allclose(camera.camera_to_world, np.eye(3), atol=1e-12)
        assert camera.vfov == pytest.approx(math.degrees(0.6), rel=1e-9)
        assert (camera.znear, camera.zfar) == (pytest.approx(0.05), pytest.approx(100.0))
        # the origin, straight ahead 5 away, lands on the image's centre; the triangle's top
        # corner (0, 1, 0) above it, by the focal length times 1 / 5
        px, py, depth = camera.project(np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
        np.testing.assert_allclose(depth, [5.0, 5.0])
        np.testing.assert_allclose(px, [width / 2, width / 2])
        focal = 0.5 * height / math.tan(0.3)
        np.testing.assert_allclose(py, [height / 2, height / 2 + focal / 5])


def test_a_turned_camera_under_a_parent_node_looks_down_its_world_minus_z(tmp_path):
    """A camera turned 90 degrees about +Y (so looking toward -X), under a parent moved by
    (7, 0, 0) and turned 30 degrees about +Z: its position and axes are the node's world
    matrix's, as glTF defines them (right +X, up +Y, looking down -Z)."""
    turn = quaternion([0, 1, 0], 90)
    parent_turn = quaternion([0, 0, 1], 30)
    nodes = [{"children": [2], "translation": [7.0, 0.0, 0.0], "rotation": parent_turn},
             {"camera": 0, "translation": [1.0, 2.0, 3.0], "rotation": turn}]
    path = tmp_path / "turned.gltf"
    gltf(path, [TRIANGLE], nodes=[{"mesh": 0}] + nodes,
         document={"cameras": [PERSPECTIVE], "scenes": [{"nodes": [0, 1]}]})
    scene = ptrace.load(path)
    camera = default_camera(scene, 160, 120)
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    parent = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    local = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float)    # 90 degrees about +Y
    np.testing.assert_allclose(camera.position, [7, 0, 0] + parent @ [1, 2, 3], atol=1e-6)
    np.testing.assert_allclose(camera.camera_to_world, parent @ local, atol=1e-6)
    forward = -camera.camera_to_world[:, 2]
    np.testing.assert_allclose(forward, parent @ [-1, 0, 0], atol=1e-6)


def test_camera_index_picks_another_and_orthographic_is_refused_when_picked(tmp_path):
    path = write(tmp_path, [{"camera": 0, "translation": [0.0, 0.0, 5.0]},
                            {"camera": 1, "translation": [0.0, 0.0, 9.0]},
                            {"camera": 0, "translation": [0.0, 0.0, 7.0]}],
                 [PERSPECTIVE, ORTHOGRAPHIC])
    scene = ptrace.load(path)
    assert [c.kind for c in scene.file_cameras] == ["perspective", "orthographic",
                                                   "perspective"]
    np.testing.assert_allclose(file_camera(scene, 2, 64, 48).position, [0, 0, 7])
    with pytest.raises(ptrace.PtraceError, match="orthographic"):
        file_camera(scene, 1, 64, 48)


def test_cli_camera_index_and_its_refusals_in_one_line(tmp_path, capsys):
    path = write(tmp_path, [{"camera": 0, "translation": [0.0, 0.0, 5.0]},
                            {"camera": 1, "translation": [0.0, 0.0, 9.0]},
                            {"camera": 0, "translation": [0.0, 0.0, 7.0]}],
                 [PERSPECTIVE, ORTHOGRAPHIC])
    assert main(["--info", "--camera-index", "2", str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(info["camera"]["position"], [0, 0, 7])
    assert any("--camera-index N picks another" in n for n in info["notes"]), info["notes"]
    cases = [(["--camera-index", "3"], "has 3 cameras (indices 0 to 2)"),
             (["--camera-index", "1"], "is orthographic, which ptrace cannot render"),
             (["--camera-index", "x"], "--camera-index must be a whole number"),
             (["--camera-index", "0", "--eye", "1,2,3"], "both give the camera")]
    for flags, words in cases:
        assert main(["--info", *flags, str(path)]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1, err
    obj = tmp_path / "plain.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert main(["--info", "--camera-index", "0", str(obj)]) == 2
    err = capsys.readouterr().err
    assert "has no cameras of its own" in err and err.count("\n") == 1, err


def test_aspect_of_r_wins_and_says_so(tmp_path, capsys):
    """The file's aspect ratio 1.5 at -r 200 100 (2.0): the vertical field of view is kept and
    a note says the aspect differs; at -r 150 100 no such note."""
    path = write(tmp_path, [{"camera": 0, "translation": [0.0, 0.0, 5.0]}], [PERSPECTIVE])
    assert main(["--info", "-r", "200", "100", str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["camera"]["vfov"] == pytest.approx(math.degrees(0.6))
    assert any("aspect ratio 1.5" in n and "-r 200 100" in n for n in info["notes"]), \
        info["notes"]
    assert main(["--info", "-r", "150", "100", str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert not any("aspect ratio" in n for n in info["notes"]), info["notes"]


def test_only_orthographic_cameras_fall_back_to_the_framing_camera(tmp_path):
    path = write(tmp_path, [{"camera": 0, "translation": [0.0, 0.0, 5.0]}], [ORTHOGRAPHIC])
    scene = ptrace.load(path)
    camera = default_camera(scene, 64, 48)
    np.testing.assert_allclose(camera.position, framing_camera(scene, 64, 48).position)
    assert any("orthographic" in n and "frames the bounds instead" in n
               for n in scene.notes), scene.notes


def test_no_camera_keeps_the_framing_camera(tmp_path):
    path = tmp_path / "plain.gltf"
    gltf(path, [TRIANGLE])
    scene = ptrace.load(path)
    assert scene.file_cameras == ()
    np.testing.assert_allclose(default_camera(scene, 64, 48).position,
                               framing_camera(scene, 64, 48).position)


@pytest.mark.parametrize("camera, words", [
    ({"type": "perspective", "perspective": {"yfov": 0.0, "znear": 0.1}}, "yfov 0"),
    ({"type": "perspective", "perspective": {"yfov": 0.5, "znear": -1}}, "znear -1"),
    ({"type": "perspective", "perspective": {"yfov": 0.5}}, "znear is missing"),
    ({"type": "perspective", "perspective": {"yfov": 0.5, "znear": 1, "zfar": 0.5}},
     "zfar 0.5 must be greater"),
    ({"type": "perspective", "perspective": {"yfov": "wide", "znear": 1}}, "'wide'"),
    ({"type": "orthographic", "orthographic": {"xmag": 0, "ymag": 1, "znear": 0,
                                               "zfar": 1}}, "must not be zero"),
])
def test_camera_numbers_the_specification_forbids_are_refused(tmp_path, camera, words):
    path = write(tmp_path, [{"camera": 0}], [camera])
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    message = str(caught.value)
    assert "camera 0" in message and words in message and "\n" not in message, message


def test_a_zfar_that_cuts_off_the_scene_is_kept_and_noted(tmp_path, capsys):
    near = {"type": "perspective", "perspective": {"yfov": 0.6, "znear": 0.1, "zfar": 4.0}}
    path = write(tmp_path, [{"camera": 0, "translation": [0.0, 0.0, 5.0]}], [near])
    assert main(["--info", str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["camera"]["zfar"] == pytest.approx(4.0)
    assert any("zfar 4" in n and "not seen" in n for n in info["notes"]), info["notes"]
    path = write(tmp_path, [{"camera": 0, "translation": [0.0, 0.0, 5.0]}], [PERSPECTIVE],
                 name="far.gltf")
    assert main(["--info", str(path)]) == 0
    assert not any("zfar" in n for n in json.loads(capsys.readouterr().out)["notes"])


def test_a_camera_whose_rays_cannot_reach_the_scene_is_noted_naming_the_file(tmp_path, capsys):
    """A znear beyond the far side of the scene's bounds, or a zfar short of their nearest
    point: nothing of the scene can be seen, and the note says so, naming the file."""
    for name, numbers, words in (("near.gltf", {"znear": 10.0, "zfar": 100.0}, "znear 10"),
                                 ("far.gltf", {"znear": 0.1, "zfar": 4.0}, "zfar 4")):
        camera = {"type": "perspective", "perspective": {"yfov": 0.6, **numbers}}
        path = write(tmp_path, [{"camera": 0, "translation": [0.0, 0.0, 5.0]}], [camera],
                     name=name)
        assert main(["--info", str(path)]) == 0
        notes = [n for n in json.loads(capsys.readouterr().out)["notes"] if words in n]
        assert len(notes) == 1 and str(path) in notes[0], notes
        assert "the scene is not seen" in notes[0]
    path = write(tmp_path, [{"camera": 0, "translation": [0.0, 0.0, 5.0]}], [PERSPECTIVE],
                 name="seen.gltf")
    assert main(["--info", str(path)]) == 0
    assert not any("not seen" in n for n in json.loads(capsys.readouterr().out)["notes"])
