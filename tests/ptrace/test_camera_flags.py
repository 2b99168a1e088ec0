"""A camera a user points (ptrace.look_at; --eye, --look-at, --up, --fov) and the default camera
of a mesh file (ptrace.framing_camera), which frames the scene's bounds at any resolution: where
rays go, what projects where, what the command line refuses, and that course scenes keep the
course's camera."""
import json
import math
import pathlib

import numpy as np
import pytest

import ptrace
from ptrace.app.cli import main
from ptrace.pointing import front_for

from console import run

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"
LOWER, UPPER = np.array([-1.5, 0.0, -0.5]), np.array([1.5, 2.0, 0.5])


def write_obj(path, vertices, faces):
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices]
    lines += ["f " + " ".join(str(i + 1) for i in face) for face in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def box_obj(tmp_path, lower=LOWER, upper=UPPER):
    """A closed box (12 triangles) spanning lower..upper."""
    corners = [[(lower, upper)[i >> k & 1][k] for k in range(3)] for i in range(8)]
    faces = []
    for axis in range(3):
        for side in (0, 1):
            quad = [i for i in range(8) if (i >> axis & 1) == side]   # 4 corners, a face
            a, b, c, d = quad[0], quad[1], quad[3], quad[2]            # around the face
            faces += [(a, b, c), (a, c, d)]
    return write_obj(tmp_path / "box.obj", corners, faces)


def corners_of(lower, upper):
    return np.array([[(lower, upper)[i >> k & 1][k] for k in range(3)] for i in range(8)])


@pytest.fixture
def box(tmp_path):
    return ptrace.load(box_obj(tmp_path))


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


VIEWS = [((0.0, 1.0, 6.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0)),
         ((-3.0, 4.0, 2.5), (0.5, 0.2, -0.3), (0.0, 1.0, 0.0)),
         ((2.0, -1.0, -5.0), (0.0, 0.5, 0.0), (0.3, 0.2, 1.0)),
         ((0.0, 5.0, 0.001), (0.0, 0.0, 0.0), (0.0, 0.0, -1.0))]


@pytest.mark.parametrize("eye, target, up", VIEWS)
@pytest.mark.parametrize("size", [(64, 48), (48, 64), (33, 33)])
def test_the_centre_ray_points_at_the_target(box, eye, target, up, size):
    camera = ptrace.look_at(box, eye, target, up=up, fov=40, width=size[0], height=size[1])
    ray = camera.directions(np.array([size[0] / 2]), np.array([size[1] / 2]))[0]
    np.testing.assert_allclose(ray, unit(np.subtract(target, eye)), atol=1e-12)
    px, py, depth = camera.project([target])
    np.testing.assert_allclose([px[0], py[0]], [size[0] / 2, size[1] / 2], atol=1e-9)
    assert depth[0] == pytest.approx(np.linalg.norm(np.subtract(target, eye)))
    # -b without -d focuses on the target
    assert camera.focal_distance == pytest.approx(np.linalg.norm(np.subtract(target, eye)))


@pytest.mark.parametrize("eye, target, up", VIEWS)
def test_up_is_up_and_right_is_right(box, eye, target, up):
    """A point above the target (along up's part across the view) projects straight above the
    image's centre (y counted from the bottom); one along view x up projects to its right."""
    camera = ptrace.look_at(box, eye, target, up=up, fov=50, width=64, height=48)
    view = unit(np.subtract(target, eye))
    across = unit(np.asarray(up) - (np.asarray(up) @ view) * view)
    right = unit(np.cross(view, across))
    step = 0.1 * np.linalg.norm(np.subtract(target, eye))   # about 5 pixels
    px, py, _ = camera.project([np.add(target, step * across), np.add(target, step * right)])
    assert py[0] > 24 + 4 and px[0] == pytest.approx(32, abs=1e-9)
    assert px[1] > 32 + 4 and py[1] == pytest.approx(24, abs=1e-9)


@pytest.mark.parametrize("fov", [10.0, 40.0, 90.0, 150.0])
@pytest.mark.parametrize("size", [(64, 48), (48, 64)])
def test_fov_is_vertical_edge_to_edge(box, fov, size):
    """A point fov/2 above (below) the view axis projects onto the image's top (bottom) edge,
    whatever the aspect ratio; the rays through the edges' midpoints are fov apart."""
    width, height = size
    eye, target = np.array([0.3, 1.0, 7.0]), np.array([0.3, 1.0, 0.0])
    camera = ptrace.look_at(box, eye, target, fov=fov, width=width, height=height)
    half = math.radians(fov) / 2
    points = [eye + 5 * np.array([0.0, s * math.sin(half), -math.cos(half)]) for s in (1, -1)]
    px, py, _ = camera.project(points)
    np.testing.assert_allclose(py, [height, 0], atol=1e-9 * height)
    np.testing.assert_allclose(px, [width / 2] * 2, atol=1e-9)
    top, bottom = camera.directions(np.array([width / 2] * 2), np.array([height, 0.0]))
    assert math.degrees(math.acos(top @ bottom)) == pytest.approx(fov, abs=1e-9)
    assert camera.vfov == pytest.approx(fov)


def assert_frames(camera, lower, upper):
    """The bounds' eight corners project inside the frame and touch its edge on one axis."""
    px, py, depth = camera.project(corners_of(lower, upper))
    assert (depth > camera.znear).all()
    x = np.abs(px - camera.width / 2).max() / (camera.width / 2)
    y = np.abs(py - camera.height / 2).max() / (camera.height / 2)
    assert max(x, y) == pytest.approx(1.0, abs=1e-12)
    assert min(x, y) < 1.0
    return x, y


@pytest.mark.parametrize("size", [(160, 120), (120, 160), (800, 600), (300, 40), (7, 500)])
def test_a_mesh_files_default_camera_frames_its_bounds_at_any_resolution(box, size):
    camera = ptrace.default_camera(box, *size)
    assert (camera.width, camera.height) == size
    x, y = assert_frames(camera, LOWER, UPPER)
    # the longer side spans the course's default 49.13434 degrees; the view looks toward -Z
    assert max(camera.hfov, camera.vfov) == pytest.approx(49.13434)
    np.testing.assert_allclose(camera.camera_to_world[:, 2], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(camera.target, 0.5 * (LOWER + UPPER))
    print(f"{size}: x {x:.4f} y {y:.4f}")


@pytest.mark.parametrize("size, touching", [((160, 120), "x"), ((120, 160), "x"),
                                            ((160, 40), "y")])
def test_the_render_fills_the_frame_not_a_centre_crop(box, size, touching):
    """Rendered (normals: the box's pixels are lit, the rest black), the box reaches the image's
    edges on one axis and leaves a margin on the other: not the course's centre crop of the
    800x600 view, which at 160x120 would show the box's middle filling every pixel."""
    image = ptrace.render(box, integrator="normals", resolution=size)
    covered = image.sum(axis=-1) > 0
    columns, rows = covered.any(axis=0), covered.any(axis=1)
    full, margin = (columns, rows) if touching == "x" else (rows, columns)
    assert full.all()
    assert not margin[0] and not margin[-1] and margin.any()


@pytest.mark.parametrize("scale", [1e-5, 1e7])
def test_framing_reaches_a_model_in_any_units(tmp_path, scale):
    """The loader's znear 0.001 and zfar 1e6 would clip a model 3e-5 wide or 3e7 wide away
    entirely; the framing camera's clip planes reach its box."""
    scene = ptrace.load(box_obj(tmp_path, LOWER * scale, UPPER * scale))
    camera = ptrace.default_camera(scene, 16, 12)
    assert_frames(camera, LOWER * scale, UPPER * scale)
    covered = ptrace.render(scene, integrator="normals", resolution=(16, 12)).sum(axis=-1) > 0
    assert covered.any(axis=0).all() and not covered[0].any()


def test_fov_and_up_without_eye_reframe_a_mesh_file(box):
    camera = ptrace.framing_camera(box, 160, 120, fov=20)
    assert camera.vfov == pytest.approx(20)
    assert_frames(camera, LOWER, UPPER)
    wide = ptrace.framing_camera(box, 160, 120, fov=100)
    assert np.linalg.norm(wide.position - wide.target) < np.linalg.norm(
        camera.position - camera.target)
    assert_frames(wide, LOWER, UPPER)


@pytest.mark.parametrize("up, front", [((0, 1, 0), (0, 0, 1)), ((0, 0, 1), (0, -1, 0)),
                                       ((0, -1, 0), (0, 0, -1)), ((1, 0, 0), (0, 0, 1)),
                                       ((0, 0, -1), (0, 1, 0))])
def test_front_for_each_up(up, front):
    np.testing.assert_allclose(front_for(np.array(up, dtype=float)), front, atol=1e-15)


def test_up_z_puts_plus_z_up_in_the_image(tmp_path):
    """A Z-up file of a right triangle standing in the XZ plane, its right angle at (1, 0, 0)
    and its apex at (1, 0, 2): with --up 0,0,1 (seen from -Y) the apex is at the top right and
    the base along the bottom. By default (+Y up, from +Z) the triangle would be edge-on, so
    the default camera looks at it from its plane's normal (+Y: from above)."""
    path = write_obj(tmp_path / "zup.obj", [(-1, 0, 0), (1, 0, 0), (1, 0, 2)], [(0, 1, 2)])
    scene = ptrace.load(path)
    camera = ptrace.framing_camera(scene, 40, 30, up=(0, 0, 1))
    px, py, _ = camera.project([[1, 0, 2], [-1, 0, 0], [1, 0, 0]])
    assert py[0] == pytest.approx(30, abs=1e-9) and py[1] < 15 and px[0] > px[1]
    out = tmp_path / "zup.exr"
    result = run("-q", "--integrator", "normals", "-r", 40, 30, "--up", "0,0,1", "-f", out, path)
    assert result.returncode == 0, result.stderr
    from ptrace.image import read_image
    covered = read_image(out).sum(axis=-1) > 0
    rows = covered.sum(axis=1)      # top row first
    top = np.flatnonzero(rows)[0]
    assert top <= 2 and (np.flatnonzero(covered[top]) > 30).all()   # the apex: top right
    assert rows[-1] > 25 and rows[:10].sum() < rows[-10:].sum() / 2  # the base: the bottom
    default = ptrace.framing_camera(scene, 40, 30)
    np.testing.assert_allclose(default.camera_to_world[:, 2], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(default.camera_to_world[:, 1], [0, 0, -1], atol=1e-12)
    seen = ptrace.render(scene, integrator="normals", resolution=(40, 30))
    assert (seen.sum(axis=-1) > 0).mean() > 0.2      # the triangle, face-on, fills the frame


def test_up_says_the_ambient_light_stays_about_plus_y(tmp_path, capsys):
    path = box_obj(tmp_path)
    note = "--up turns the camera, not the lighting: the ambient light's hemisphere stays " \
        "about world +Y"
    for up, noted in (("0,0,1", True), ("0,3,0", False)):
        assert main(["--info", "--up", up, str(path)]) == 0
        assert (note in json.loads(capsys.readouterr().out)["notes"]) == noted


def test_default_fov_at_800x600_is_the_course_cameras_focal_length():
    """--eye on a course scene without --fov: at 800x600 the course camera's focal length; from
    the course camera's own position and target, the course camera's axes."""
    scene = ptrace.load(SHIPPED)
    course = ptrace.course_camera(scene)
    pointed = ptrace.look_at(scene, course.position, course.target)
    assert pointed.screen_dist == pytest.approx(course.screen_dist, rel=1e-12)
    np.testing.assert_allclose(pointed.camera_to_world, course.camera_to_world, atol=1e-12)
    assert (pointed.znear, pointed.zfar) == (course.znear, course.zfar)
    portrait = ptrace.look_at(scene, course.position, course.target, width=600, height=800)
    assert portrait.vfov == pytest.approx(course.hfov)


def test_render_takes_a_cameras_own_size_and_zfar_reaches_the_scene(box):
    camera = ptrace.look_at(box, (0, 1, 4e6), (0, 1, 0), fov=1e-5, width=12, height=9)
    assert camera.zfar > 4e6
    image = ptrace.render(box, integrator="normals", camera=camera)
    assert image.shape == (9, 12, 3)
    assert (image.sum(axis=-1) > 0).all()   # the box fills this narrow view, 4e6 away


def test_a_course_scene_keeps_the_course_camera_and_takes_a_pointed_one():
    scene = ptrace.load(SHIPPED)
    default, course = ptrace.default_camera(scene, 160, 120), ptrace.course_camera(scene, 160, 120)
    for name in ("position", "target", "camera_to_world", "screen_dist", "width", "height",
                 "znear", "zfar", "lens_radius", "focal_distance"):
        np.testing.assert_array_equal(getattr(default, name), getattr(course, name))
    np.testing.assert_array_equal(
        ptrace.render(scene, integrator="normals", resolution=(16, 12)),
        ptrace.render(scene, integrator="normals", resolution=(16, 12),
                      camera=ptrace.course_camera(scene, 16, 12)))
    pointed = ptrace.look_at(scene, (0.3, 0.9, 2.0), (0.0, 0.5, 0.0), width=16, height=12)
    image = ptrace.render(scene, integrator="normals", camera=pointed)
    assert image.shape == (12, 16, 3) and (image.sum(axis=-1) > 0).any()


@pytest.mark.parametrize("call, message", [
    (dict(eye=(1, 2, 3), target=(1, 2, 3)), "eye and target are the same point"),
    (dict(eye=(0, 1, 0)), "eye is the centre of the scene's bounds"),
    (dict(eye=(0, 5, 0), target=(0, 0, 0)), "up is parallel to the view direction"),
    (dict(eye=(0, 0, 5), target=(0, 0, 0), up=(0, 0, -2)), "up is parallel"),
    (dict(eye=(0, 0, 5), up=(0, 0, 0)), "up must be a direction"),
    (dict(eye=(0, 0, float("nan"))), "eye must be three finite numbers"),
    (dict(eye=(0, 0, 5), target=(1, 2)), "target must be three finite numbers"),
    (dict(eye=(0, 0, 5), fov=0), "fov must be"),
    (dict(eye=(0, 0, 5), fov=180), "fov must be"),
    (dict(eye=(0, 0, 5), fov=float("nan")), "fov must be"),
    (dict(eye=(0, 0, 1.5e308), target=(0, 0, -1.5e308)), "too far apart"),
])
def test_look_at_refuses_what_gives_no_view(box, call, message):
    with pytest.raises(ptrace.PtraceError, match=message):
        ptrace.look_at(box, **call)


REFUSED = [
    (["--eye", "1,2"], "--eye must be three finite numbers"),
    (["--eye", "1,x,3"], "--eye must be three finite numbers"),
    (["--eye", "nan,0,0"], "--eye must be three finite numbers"),
    (["--eye", "0,0,5", "--look-at", "0,inf,0"], "--look-at must be three finite numbers"),
    (["--up", "1,,2"], "--up must be three finite numbers"),
    (["--up", "0,0,0"], "--up must be a direction"),
    (["--eye", "0,0,5", "--look-at", "0,0,-1", "--up", "0,0,3"], "--up is parallel"),
    (["--eye", "-2,-2,-2", "--look-at", "1,1,1", "--up", "-1,-1,-1"], "--up is parallel"),
    (["--eye", "0,-3,0", "--up", "0,1,0"], "--up is parallel"),
    (["--eye", "1,2,3", "--look-at", "1,2,3"], "--eye and --look-at are the same point"),
    (["--eye", "0,1,0"], "--eye is the centre of the scene's bounds"),
    (["--fov", "0"], "--fov must be a number of degrees greater than 0 and less than 180"),
    (["--fov", "180"], "--fov must be"),
    (["--fov", "nan"], "--fov must be"),
    (["--eye", "0,0,5", "--fov", "-30"], "--fov must be"),
    (["--look-at", "0,0,0"], "--look-at needs --eye"),
]


@pytest.mark.parametrize("flags, message", REFUSED)
def test_the_command_line_refuses_in_one_line(tmp_path, capsys, flags, message):
    path = box_obj(tmp_path)
    out = tmp_path / "out.png"
    assert main(["-q", "-r", "8", "6", "-f", str(out), str(path)] + flags) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("ptrace: error: "), captured.err
    assert message in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("flags, message", [
    (["--up", "0,0,1"], "--up without --eye: a course scene (.dae) keeps the course's camera"),
    (["--fov", "30"], "--fov without --eye"),
    (["-c", "camera.txt", "--eye", "1,2,3"], "-c (a camera file) and --eye both give"),
])
def test_course_scene_flag_refusals(tmp_path, capsys, flags, message):
    out = tmp_path / "out.png"
    assert main(["-q", "-r", "8", "6", "-f", str(out), str(SHIPPED)] + flags) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and message in lines[0], lines
    assert not out.exists()


def test_the_console_script_exits_2_on_a_parallel_up(tmp_path):
    result = run("-r", 8, 6, "-f", tmp_path / "out.png", "--eye", "0,5,0", "--look-at",
                 "0,-1,0", box_obj(tmp_path))
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "ptrace: error: --up is parallel to the view direction (from --eye to --look-at), so "
        "it says nothing about which way is up in the image: give an up that points across the "
        "view"]


def test_info_reports_the_flags_camera(tmp_path, capsys):
    path = box_obj(tmp_path)
    assert main(["--info", "-r", "160", "120", "--eye", "-4,3,-5", "--look-at", "0,1,0",
                 "--fov", "35", str(path)]) == 0
    camera = json.loads(capsys.readouterr().out)["camera"]
    np.testing.assert_allclose(camera["position"], [-4, 3, -5])
    np.testing.assert_allclose(camera["target"], [0, 1, 0])
    assert camera["vfov"] == pytest.approx(35)
    assert main(["--info", "-r", "120", "160", str(path)]) == 0
    camera = json.loads(capsys.readouterr().out)["camera"]
    framing = ptrace.default_camera(ptrace.load(path), 120, 160)
    np.testing.assert_allclose(camera["position"], framing.position)
    assert camera["vfov"] == pytest.approx(49.13434)


def test_the_viewer_takes_the_camera_flags(tmp_path):
    """ptrace view points the camera as ptrace does (it read the flags and ignored them)."""
    from ptrace.app import view
    output = str(tmp_path / "v.png")
    scene, _, camera, _ = view.prepare(view.parse(
        [str(SHIPPED), "-r", "64", "48", "-f", output, "--eye", "0,1,-3", "--look-at", "0,1,0"]))
    np.testing.assert_allclose(camera.position, [0.0, 1.0, -3.0])
    np.testing.assert_allclose(camera.target, [0.0, 1.0, 0.0])
    with pytest.raises(ptrace.PtraceError, match="--look-at needs --eye"):
        view.parse([str(SHIPPED), "--look-at", "0,1,0"])
