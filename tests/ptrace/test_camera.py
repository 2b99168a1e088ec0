"""The course camera (docs/course.md#orbit-camera) against the course's table
(docs/course.md#camera-table), and its crop rule."""
import math

import numpy as np
import pytest

import ptrace
from ptrace.camera import course_camera, load_camera_settings
from ptrace.scene import DIFFUSE

from scenes_by_hand import make_scene

# file: (target, R, camera position, hfov, vfov, screen_dist, near, far) from the course's table
TABLE = {
    "sky/bunny.dae": ((0, 0.3824, 0), 3.4953, (0, 1.4877, 3.3160), 49.134, 37.849, 875.0, 0.1, 100),
    "meshedit/cow.dae": ((0, -0.0394, -0.0930), 3.3465, (0, -0.0394, 3.2536),
                         39.598, 30.219, 1111.1, 0.01, 10000),
    "meshedit/maxplanck.dae": ((0, 0, 0), 3.6028, (0, 0, 3.6028),
                               39.598, 30.219, 1111.1, 0.01, 10000),
    "meshedit/beetle.dae": ((0, 0, 0), 2.8191, (0, 0, 2.8191), 39.598, 30.219, 1111.1, 0.01, 10000),
    "meshedit/teapot.dae": ((0, 0, 0), 3.0330, (0, 0, 3.0330), 39.598, 30.219, 1111.1, 0.01, 10000),
    "meshedit/peter.dae": ((0, 0, 0), 3.4050, (0, 0.7338, -3.3250),
                           39.598, 30.219, 1111.1, 0.01, 10000),
    "keenan/banana.dae": ((0, 0.2908, 0), 4.3314, (2.9428, 1.4910, 2.9428),
                          49.134, 37.849, 875.0, 0.1, 100),
    "keenan/building.dae": ((0, 0.1901, 0), 4.2818, (0.0313, 0.9805, -4.2081),
                            54.432, 42.185, 777.8, 0.01, 10000),
    "simple/plane.dae": ((0, 0.25, -0.9957), 3.75, (0, 0.25, 2.7543),
                         49.134, 37.849, 875.0, 0.1, 100),
    "simple/cube.dae": ((-0.1298, 0.0217, -2.5714), 1.1148, (-0.1298, 0.0217, -1.4566),
                        49.134, 37.849, 875.0, 0.1, 100),
}
for name in ["CBbunny", "CBbunny_microfacet_cu", "CBcoil", "CBempty", "CBgems", "CBspheres",
             "CBspheres_lambertian", "CBspheres_microfacet_al_ag", "CBspheres_tex"]:
    z = -4.8023 if name.startswith("CBbunny") else 4.8023
    TABLE[f"sky/{name}.dae"] = ((0, 0.75, 0), 4.8023, (0, 0.75, z), 49.134, 37.849, 875.0, 0.1, 100)
for name in ["bunny_unlit", "bunny_microfacet_cu", "bunny_microfacet_cu_unlit"]:
    TABLE[f"sky/{name}.dae"] = TABLE["sky/bunny.dae"]
for name in ["CBempty", "CBspheres_lambertian", "CBspheres_refract"]:
    TABLE[f"variants_sp23/sky/{name}.dae"] = TABLE["sky/CBspheres.dae"]


def test_table_covers_every_course_file(scenes_dir):
    files = {str(p.relative_to(scenes_dir)) for p in scenes_dir.rglob("*.dae")}
    assert files == set(TABLE)


@pytest.mark.parametrize("relpath", sorted(TABLE))
def test_course_camera_matches_the_table(scenes_dir, relpath):
    target, radius, position, hfov, vfov, dist, near, far = TABLE[relpath]
    camera = course_camera(ptrace.load(scenes_dir / relpath))
    np.testing.assert_allclose(camera.target, target, atol=2e-4)
    np.testing.assert_allclose(np.linalg.norm(camera.position - camera.target), radius, atol=2e-4)
    np.testing.assert_allclose(camera.position, position, atol=2e-4)
    assert camera.hfov == pytest.approx(hfov, abs=2e-3)
    assert camera.vfov == pytest.approx(vfov, abs=2e-3)
    assert camera.screen_dist == pytest.approx(dist, abs=0.1)
    assert (camera.znear, camera.zfar) == pytest.approx((near, far), rel=1e-5)
    # it looks at the target, +Y up: the camera's z axis points back at the camera
    backward = (camera.position - camera.target) / radius
    np.testing.assert_allclose(camera.camera_to_world[:, 2], backward, atol=1e-4)
    assert camera.camera_to_world[1, 1] > 0


def test_resolution_keeps_the_focal_length(scenes_dir):
    scene = ptrace.load(scenes_dir / "sky/CBspheres.dae")
    camera = course_camera(scene, 480, 360)
    assert camera.screen_dist == pytest.approx(875.0, abs=0.1)
    assert camera.hfov == pytest.approx(30.676, abs=2e-3)
    assert camera.vfov == pytest.approx(23.249, abs=2e-3)


def test_a_480x360_render_is_the_central_window_of_the_800x600_one(scenes_dir):
    scene = ptrace.load(scenes_dir / "sky/CBspheres_lambertian.dae")
    full = ptrace.render(scene, integrator="normals")
    window = ptrace.render(scene, integrator="normals", resolution=(480, 360))
    assert full.shape == (600, 800, 3) and window.shape == (360, 480, 3)
    np.testing.assert_array_equal(window, full[120:480, 160:640])


def test_crop_cell_is_the_same_window_y_from_the_bottom(scenes_dir):
    scene = ptrace.load(scenes_dir / "meshedit/cow.dae")
    full = ptrace.render(scene, integrator="normals", resolution=(160, 120), spp=2)
    cell = ptrace.render(scene, integrator="normals", resolution=(160, 120), spp=2,
                         crop=(40, 10, 50, 30))
    # cell rows y = 10..39 from the bottom are rows 120-40 .. 120-10 from the top
    np.testing.assert_array_equal(cell, full[80:110, 40:90])


def test_camera_settings_file_round_trip(tmp_path, scenes_dir):
    scene = ptrace.load(scenes_dir / "sky/CBspheres_lambertian.dae")
    camera = course_camera(scene)
    numbers = [camera.hfov, camera.vfov, 4 / 3, camera.znear, camera.zfar,
               *camera.position, *camera.target, 0, 0, 4.8, 1, 10,
               *camera.camera_to_world.reshape(-1), 800, 600, camera.screen_dist, 4.7, 0.0]
    path = tmp_path / "cam.txt"
    path.write_text(" ".join(repr(float(x)) for x in numbers))
    loaded = load_camera_settings(path, 800, 600)
    np.testing.assert_allclose(loaded.camera_to_world, camera.camera_to_world)
    image = ptrace.render(scene, integrator="normals", resolution=(64, 48), camera=loaded)
    reference = ptrace.render(scene, integrator="normals", resolution=(64, 48))
    np.testing.assert_array_equal(image, reference)
    path.write_text("1 2 3")
    with pytest.raises(ptrace.PtraceError, match="28 numbers"):
        load_camera_settings(path, 800, 600)


def test_a_hand_written_course_camera_dump_places_a_known_point(tmp_path):
    """A camera file written by hand as the course's `D` key writes it (docs/course.md#camera-file:
    hFov vFov aspect near far / pos target / phi theta r minR maxR / the camera-to-world rotation,
    row major / screenW screenH screenDist / focalDistance lensRadius): at (5, 0, 0) looking down -x
    with +y up, so the camera's right is world -z, and a 60 degree vertical field of view. A small
    sphere at (0, 0, -1) is 1 right of the axis at depth 5: its image centre is pixel x = 400 + 0.2
    * screenDist, y = 300 (from the bottom)."""
    screen_dist = 300 / math.tan(math.radians(30))
    rotation = [0, 0, 1, 0, 1, 0, -1, 0, 0]      # columns: right (0,0,-1), up, back (1,0,0)
    numbers = [73.7, 60, 4 / 3, 0.01, 100, 5, 0, 0, 0, 0, 0, 1.5708, 1.5708, 5, 1, 50,
               *rotation, 800, 600, screen_dist, 5, 0]
    path = tmp_path / "hand_cam_settings.txt"
    lines = [numbers[:5], numbers[5:11], numbers[11:16], numbers[16:25], numbers[25:28],
             numbers[28:]]
    path.write_text("".join(" ".join(str(x) for x in line) + "\n" for line in lines))
    camera = load_camera_settings(path, 800, 600)
    np.testing.assert_allclose(camera.position, [5, 0, 0])
    scene = make_scene(centers=[[0.0, 0.0, -1.0]], radii=[0.05],
                       materials=[dict(kind=DIFFUSE, albedo=(0.5,) * 3)], material_index=[0])
    image = ptrace.render(scene, integrator="normals", resolution=(800, 600), camera=camera)
    rows, cols = np.nonzero(image.sum(axis=2) > 0)
    assert 50 < rows.size < 5000
    x = (cols + 0.5).mean()
    y = (600 - (rows + 0.5)).mean()
    assert x == pytest.approx(400 + 0.2 * screen_dist, abs=0.5)
    assert y == pytest.approx(300, abs=0.5)
