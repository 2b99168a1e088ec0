"""Light transport against analytic answers, its invariances, and the shadow-ray rules."""
import math
import pathlib

import numpy as np
import pytest

import ptrace
from ptrace.scene import AREA

from scenes_by_hand import (
    ambient_light,
    directional_light,
    floor_plane,
    furnace,
    looking_down,
    make_scene,
    pixel_hits_on_floor,
    point_light,
)

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"


@pytest.mark.parametrize("depth", [1, 2])
def test_furnace_is_exact_without_roulette(depth):
    albedo, power = 0.5, 2.0
    scene, camera = furnace(albedo, power)
    image = ptrace.render(scene, camera=camera, resolution=(16, 16), spp=2, max_depth=depth)
    expected = albedo * power / math.pi * sum(albedo ** k for k in range(depth))
    np.testing.assert_allclose(image, expected, rtol=1e-5)


def test_roulette_off_runs_every_path_to_max_depth():
    """roulette=False: from the third vertex on paths are no longer cut at random, so a deep
    furnace is exact (every vertex gets the same direct light, no variance) where roulette's
    image is only right on average; the default is roulette on."""
    albedo, power, depth = 0.5, 2.0, 6
    scene, camera = furnace(albedo, power)
    expected = albedo * power / math.pi * sum(albedo ** k for k in range(depth))
    off, on, default = {}, {}, {}
    exact = ptrace.render(scene, camera=camera, resolution=(16, 16), spp=2, max_depth=depth,
                          roulette=False, stats=off)
    np.testing.assert_allclose(exact, expected, rtol=1e-5)
    noisy = ptrace.render(scene, camera=camera, resolution=(16, 16), spp=2, max_depth=depth,
                          roulette=True, stats=on)
    assert np.abs(noisy / expected - 1).max() > 1e-3 and on["rays"] < off["rays"]
    again = ptrace.render(scene, camera=camera, resolution=(16, 16), spp=2, max_depth=depth,
                          stats=default)
    np.testing.assert_array_equal(again, noisy)


@pytest.mark.parametrize("accel_kind", ["bvh", "embree"])
def test_furnace_converges_with_roulette(accel_kind):
    albedo, power = 0.7, 1.0
    scene, camera = furnace(albedo, power)
    stats = {}
    image = ptrace.render(scene, camera=camera, resolution=(16, 16), spp=64, max_depth=100,
                          accel=accel_kind, stats=stats)
    expected = albedo * power / (math.pi * (1 - albedo))
    mean = image.mean()
    print(f"furnace: mean {mean:.5f} expected {expected:.5f}, rays {stats['rays']}")
    assert mean == pytest.approx(expected, rel=0.02)
    assert stats["nonfinite"] == 0


def test_diffuse_plane_under_a_point_light_is_exact():
    albedo, power, height = 0.6, 3.0, 1.0
    scene = make_scene(**floor_plane(albedo), lights=[point_light((0, height, 0), power)])
    camera = looking_down(3.0)
    image = ptrace.render(scene, camera=camera, resolution=(32, 32), max_depth=1)
    hit = pixel_hits_on_floor(camera)
    distance = np.linalg.norm(hit - [0, height, 0], axis=-1)
    expected = albedo / math.pi * power * height / distance   # cos theta, no 1/r^2 (course)
    np.testing.assert_allclose(image[..., 0], expected, rtol=1e-5)
    np.testing.assert_allclose(image[..., 1], image[..., 0])


def test_diffuse_plane_under_a_directional_light_is_exact():
    albedo, power = 0.4, 2.0
    scene = make_scene(**floor_plane(albedo), lights=[directional_light((1, 2, 0), power)])
    image = ptrace.render(scene, camera=looking_down(3.0), resolution=(32, 32), max_depth=1)
    np.testing.assert_allclose(image, albedo / math.pi * power * 2 / math.sqrt(5), rtol=1e-5)


def test_diffuse_plane_under_the_ambient_light():
    albedo, power = 0.5, 1.5
    scene = make_scene(**floor_plane(albedo), lights=[ambient_light(power)])
    image = ptrace.render(scene, camera=looking_down(3.0), resolution=(32, 32), spp=16,
                          light_samples=4, max_depth=1)
    assert image.mean() == pytest.approx(albedo * power, rel=0.02)   # E = pi L, times a / pi


def test_hemisphere_and_light_sampling_agree_where_light_and_quad_coincide():
    scene = ptrace.load(SHIPPED)
    kwargs = dict(resolution=(32, 24), spp=64, light_samples=8, max_depth=1)
    lit = ptrace.render(scene, **kwargs)
    hemi = ptrace.render(scene, hemisphere=True, **kwargs)
    print(f"light sampling {lit.mean():.4f}, hemisphere {hemi.mean():.4f}")
    assert hemi.mean() == pytest.approx(lit.mean(), rel=0.02)


def test_the_quad_on_the_area_light_does_not_shadow_it():
    """The shipped scene's emissive quad lies exactly on the area light: every shadow ray to a
    light sample reaches the quad's plane at the sample itself, and must stop short of it.
    With the quad removed the direct light must be the same, sample for sample."""
    scene = ptrace.load(SHIPPED)
    quad = np.nonzero(scene.materials.kind[scene.material_index] == 1)[0]   # emission
    assert quad.size == 2
    keep = np.setdiff1d(np.arange(scene.triangle_count), quad)
    without = make_scene(scene.geometry.vertices, scene.geometry.faces[keep],
                         scene.geometry.centers, scene.geometry.radii, [],
                         np.concatenate([scene.material_index[keep],
                                         scene.material_index[scene.triangle_count:]]), [])
    without.materials, without.lights, without.camera = scene.materials, scene.lights, scene.camera
    kwargs = dict(resolution=(48, 36), spp=4, light_samples=2, max_depth=1)
    with_quad = ptrace.render(scene, **kwargs)
    without_quad = ptrace.render(without, **kwargs)
    visible_quad = np.all(with_quad > 7.9, axis=2)   # pixels that see the emitter itself
    np.testing.assert_array_equal(with_quad[~visible_quad], without_quad[~visible_quad])


def lambert_irradiance(point, corners, radiance):
    """Irradiance at `point` on an upward (+y) surface from a uniform polygonal emitter of the
    given radiance (Lambert's formula: half the sum over edges of the angle each edge subtends
    times the cosine between the normal and that edge's plane), unoccluded."""
    v = corners - point
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    total = 0.0
    for i in range(len(v)):
        a, b = v[i], v[(i + 1) % len(v)]
        cross = np.cross(a, b)
        total += math.acos(np.clip(a @ b, -1, 1)) * cross[1] / np.linalg.norm(cross)
    return 0.5 * radiance * abs(total)


def test_diffuse_plane_under_an_area_light_matches_lamberts_formula():
    """A square area light (side 1, radiance 4) facing down at height 1 over a diffuse floor:
    each pixel is albedo / pi times Lambert's closed-form irradiance, for MIS and for light
    sampling, to 5% per pixel (the grazing ones at the edge are the noisiest) and 0.2% on the
    mean (measured 0.08%; 64 light samples per sample, Sobol')."""
    albedo, radiance, height = 0.5, 4.0, 1.0
    light = dict(kind=AREA, radiance=(radiance,) * 3, position=(0, height, 0),
                 direction=(0, -1, 0), edge_x=(1, 0, 0), edge_y=(0, 0, 1), area=1.0)
    scene = make_scene(**floor_plane(albedo), lights=[light])
    camera = looking_down(3.0)
    corners = np.array([[-0.5, height, -0.5], [0.5, height, -0.5], [0.5, height, 0.5],
                        [-0.5, height, 0.5]])
    hits = pixel_hits_on_floor(camera)
    expected = np.array([[albedo / math.pi * lambert_irradiance(p, corners, radiance)
                          for p in row] for row in hits])
    for direct in ("mis", "light"):
        image = ptrace.render(scene, camera=camera, resolution=(32, 32), spp=4,
                              light_samples=64, max_depth=1, direct=direct)
        np.testing.assert_allclose(image[..., 0], expected, rtol=0.05, err_msg=direct)
        print(direct, image[..., 0].mean() / expected.mean() - 1)
        assert image[..., 0].mean() == pytest.approx(expected.mean(), rel=0.002), direct


def test_cornell_walls_are_lit(scenes_dir):
    """Direct light (-m 1) on the walls: the red wall is red, the blue wall blue, the back
    wall lit, and MIS and light sampling agree on each wall to 3% (the level itself is pinned
    by the analytic area-light test above and the per-pixel Mitsuba tests)."""
    scene = ptrace.load(scenes_dir / "variants_sp23/sky/CBspheres_lambertian.dae")
    regions = {}
    for direct in ("mis", "light"):
        image = ptrace.render(scene, resolution=(480, 360), spp=4, light_samples=2,
                              max_depth=1, direct=direct)
        regions[direct] = (image[150:250, 5:25], image[150:250, 455:475], image[100:200, 200:280])
    for direct, (left, right, back) in regions.items():
        assert left[..., 0].mean() > 2 * left[..., 2].mean() > 0, direct     # red wall, lit
        assert right[..., 2].mean() > 2 * right[..., 0].mean() > 0, direct   # blue wall, lit
        assert back.mean() > 0.05, direct
    for k, wall in enumerate(("left", "right", "back")):
        np.testing.assert_allclose(regions["light"][k].mean(axis=(0, 1)),
                                   regions["mis"][k].mean(axis=(0, 1)), rtol=0.03, err_msg=wall)


def test_same_seed_same_image_whatever_threads_chunks_and_backend(monkeypatch):
    """The README's promise: the same seed gives the same image whatever the thread count or
    batch size, naive and bvh give bit-identical images, embree differs only where float32
    moves a hit, and another seed gives another image."""
    from ptrace.rendering import tiles
    scene = ptrace.load(SHIPPED)
    kwargs = dict(resolution=(40, 30), spp=4, light_samples=2, max_depth=4, seed=7)
    reference = ptrace.render(scene, threads=1, **kwargs)
    assert np.array_equal(ptrace.render(scene, threads=2, **kwargs), reference)
    assert np.array_equal(ptrace.render(scene, accel="naive", **kwargs), reference)
    monkeypatch.setattr(tiles, "BLOCK_PATHS", 7)   # blocks of one pixel (4 samples each)
    assert np.array_equal(ptrace.render(scene, **kwargs), reference)
    embree = ptrace.render(scene, accel="embree", **kwargs)
    assert np.abs(embree - reference).mean() < 0.01 * reference.mean()
    assert not np.array_equal(ptrace.render(scene, **dict(kwargs, seed=8)), reference)


def test_non_finite_samples_are_counted_not_written():
    """The README's promise: non-finite samples are counted (the summary's and stats'
    nonfinite), never written into the image."""
    # an infinitely bright light makes every lit sample infinite (or NaN, inf * 0)
    scene = make_scene(**floor_plane(0.5), lights=[point_light((0, 1, 0), math.inf)])
    stats = {}
    image = ptrace.render(scene, camera=looking_down(3.0), resolution=(8, 8), spp=2,
                          max_depth=1, stats=stats)
    assert np.isfinite(image).all()
    assert stats["nonfinite"] == 8 * 8 * 2
    assert (stats["samples"] == 0).all()


PEAK_MEMORY = """
import resource, sys, ptrace
scene = ptrace.load(sys.argv[1])
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
ptrace.render(scene, resolution=(int(sys.argv[5]), int(sys.argv[6])), spp=int(sys.argv[2]),
              light_samples=int(sys.argv[3]), max_depth=int(sys.argv[4]), roulette=False,
              threads=2)
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before)
"""


def test_memory_does_not_grow_with_samples_light_samples_or_depth():
    """The README's memory promise: a thread keeps one wave of paths, whose size -l can only
    shrink, so the peak memory of a render (beyond the scene, the accelerator and the per-pixel
    sums) does not grow with -s, -l or -m. Measured as the growth of the process's peak RSS during a
    render in a fresh process (the kernels come from numba's cache), small against large, and
    at -s 16 -l 8192 (where the wavefront renderer once sent batches of 131,072 rays past its
    65,536 bound) on a small window."""
    import subprocess
    import sys

    def growth_kb(spp, light_samples, max_depth, width=32, height=24):
        result = subprocess.run([sys.executable, "-c", PEAK_MEMORY, str(SHIPPED), str(spp),
                                 str(light_samples), str(max_depth), str(width), str(height)],
                                capture_output=True, text=True, timeout=600, check=True)
        return int(result.stdout.split()[-1])

    ptrace.render(ptrace.load(SHIPPED), resolution=(4, 3), max_depth=2)   # compile once, here
    small = growth_kb(1, 1, 1)
    large = growth_kb(8, 256, 6)   # up to 8 x 256 x 6 shadow rays per pixel
    assert large - small < 16 * 1024, (small, large)
    small_window = growth_kb(1, 1, 1, 4, 3)
    many_light_samples = growth_kb(16, 8192, 2, 4, 3)
    assert many_light_samples - small_window < 16 * 1024, (small_window, many_light_samples)
