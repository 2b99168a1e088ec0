"""The thin-lens camera (the course's Project 3-2 Part 4; -b APERTURE_RADIUS -d FOCAL_DISTANCE):
a pinhole at radius 0, a point on the focal plane stays sharp, and a point off it spreads into
the blur circle thin-lens optics predicts."""
import math
import pathlib

import numpy as np
import pytest

import ptrace
from ptrace.camera import Camera
from ptrace.scene import EMISSION

from scenes_by_hand import make_scene

SIZE, SCREEN = 160, 400.0   # image side and focal length in pixels


def point_at(depth, radius=0.002):
    """A tiny emissive sphere on the optical axis, `depth` in front of a camera at the origin
    looking down -z (the only thing in the scene)."""
    return make_scene(centers=[[0.0, 0.0, -depth]], radii=[radius],
                      materials=[dict(kind=EMISSION, emission=(1.0, 1.0, 1.0))],
                      material_index=[0])


def camera(lens_radius=0.0, focal_distance=1.0):
    return Camera(np.zeros(3), np.array([0.0, 0.0, -1.0]), np.eye(3), SCREEN, SIZE, SIZE, 1e-3,
                  1e3, lens_radius=lens_radius, focal_distance=focal_distance)


def spot_radius(image):
    """The radius of a uniform disc with the spot's intensity-weighted second moment about its
    centroid (for a disc of radius r the mean squared distance is r^2 / 2)."""
    weights = image[..., 0].astype(np.float64)
    assert weights.sum() > 0
    rows, cols = np.indices(weights.shape)
    total = weights.sum()
    cy, cx = (rows * weights).sum() / total, (cols * weights).sum() / total
    second = (((rows - cy) ** 2 + (cols - cx) ** 2) * weights).sum() / total
    return math.sqrt(2 * second), (cx + 0.5, cy + 0.5)


def test_a_zero_aperture_is_the_pinhole_bit_for_bit():
    scene = ptrace.load(pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae")
    kwargs = dict(resolution=(40, 30), spp=4, light_samples=2, max_depth=3, seed=2)
    pinhole = ptrace.render(scene, **kwargs)
    course = ptrace.course_camera(scene, 40, 30)
    assert course.lens_radius == 0.0
    np.testing.assert_array_equal(
        ptrace.render(scene, camera=course.with_lens(0.0, 2.5), **kwargs), pinhole)
    assert not np.array_equal(
        ptrace.render(scene, camera=course.with_lens(0.05, 2.5), **kwargs), pinhole)


def test_a_point_on_the_focal_plane_stays_sharp():
    depth = 4.0
    sharp, centre = spot_radius(ptrace.render(point_at(depth), camera=camera(0.0, depth),
                                              resolution=(SIZE, SIZE), spp=64))
    focused, centre_lens = spot_radius(ptrace.render(point_at(depth), camera=camera(0.2, depth),
                                                     resolution=(SIZE, SIZE), spp=64))
    print(f"pinhole spot {sharp:.3f} px, thin lens focused on it {focused:.3f} px")
    assert focused < 1.0 and focused < 1.5 * sharp + 0.1
    np.testing.assert_allclose(centre_lens, (SIZE / 2, SIZE / 2), atol=0.25)   # within a pixel


@pytest.mark.parametrize("depth, focus, lens", [(2.0, 4.0, 0.1), (8.0, 4.0, 0.2),
                                               (3.0, 6.0, 0.05)])
def test_an_off_focus_point_spreads_into_the_predicted_blur_circle(depth, focus, lens):
    """The ray from lens point L through the point P at depth z meets the focal plane (depth
    d) at L (1 - d/z): a point's image is a disc of radius R = screen_dist * b |1 - d/z| / d
    pixels about its pinhole image. The emitter is a small sphere whose pinhole image is a disc
    of radius r (4 px), and pixels are squares: second moments add, so the spot's radius (by
    its second moment) is sqrt(R^2 + r^2 + 2/3), to 3%."""
    size = 0.01 * depth
    blur = SCREEN * lens * abs(1 - focus / depth) / focus
    expected = math.sqrt(blur ** 2 + (SCREEN * size / depth) ** 2 + 2 / 3)
    radius, centre = spot_radius(ptrace.render(point_at(depth, size), camera=camera(lens, focus),
                                               resolution=(SIZE, SIZE), spp=256))
    print(f"z {depth} d {focus} b {lens}: blur radius {blur:.3f} px, spot {radius:.3f} px, "
          f"predicted {expected:.3f}")
    assert radius == pytest.approx(expected, rel=0.03)
    np.testing.assert_allclose(centre, (SIZE / 2, SIZE / 2), atol=0.1)


@pytest.mark.parametrize("bad", [dict(lens_radius=-0.1), dict(lens_radius=math.nan),
                                 dict(lens_radius=0.1, focal_distance=0.0),
                                 dict(focal_distance=math.inf)])
def test_the_lens_settings_are_checked(bad):
    with pytest.raises(ptrace.PtraceError, match="lens radius|focal distance"):
        camera().with_lens(**bad)


def test_the_command_line_and_a_camera_file_set_the_lens(tmp_path):
    """-b and -d reach the camera (a focused render differs from the pinhole one, -b 0 equals
    it), and a course camera dump's trailing focalDistance lensRadius are read."""
    from ptrace.app import cli
    from ptrace.camera import load_camera_settings
    from ptrace.image import read_image
    shipped = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"
    images = {}
    for name, flags in [("pinhole", []), ("zero", ["-b", "0"]), ("lens", ["-b", "0.1", "-d", "2"])]:
        output = tmp_path / f"{name}.exr"
        assert cli.main(["-q", "-s", "2", "-r", "32", "24", "-f", str(output), *flags,
                         str(shipped)]) == 0
        images[name] = read_image(output)
    np.testing.assert_array_equal(images["zero"], images["pinhole"])
    assert not np.array_equal(images["lens"], images["pinhole"])
    dump = tmp_path / "cam.txt"
    dump.write_text("50 40 1.33 0.1 100 0 1 4 0 1 0 0 0 4 1 10 1 0 0 0 1 0 0 0 1 800 600 700 "
                    "3.5 0.2")
    loaded = load_camera_settings(dump, 800, 600)
    assert (loaded.focal_distance, loaded.lens_radius) == (3.5, 0.2)
