"""Normal shading on every backend, seeded sampling, and the shipped scene."""
import pathlib

import numba
import numpy as np
import pytest

import ptrace

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"


@pytest.mark.parametrize("relpath", ["sky/CBspheres_lambertian.dae", "meshedit/cow.dae"])
def test_normals_identical_across_backends(scenes_dir, relpath):
    scene = ptrace.load(scenes_dir / relpath)
    images = {kind: ptrace.render(scene, integrator="normals", accel=kind, resolution=(200, 150))
              for kind in ("naive", "bvh", "embree")}
    np.testing.assert_array_equal(images["bvh"], images["naive"])
    difference = np.abs(images["embree"] - images["bvh"]).max(axis=2)
    print(f"{relpath}: embree vs bvh max {difference.max():.2e}, "
          f"pixels over 1e-3: {(difference > 1e-3).sum()}")
    assert (difference > 1e-3).mean() < 1e-3   # a float32 silhouette pixel may flip, no more
    assert images["bvh"].any(axis=2).mean() > 0.1   # something was hit


def test_normal_colours_are_half_n_plus_half(scenes_dir):
    # 800x600 (a smaller -r only crops the centre); the course's walls are wound with their
    # normals facing out of the box, ours (scenes/cornell.dae) into it
    course = ptrace.render(ptrace.load(scenes_dir / "sky/CBspheres_lambertian.dae"),
                           integrator="normals")
    ours = ptrace.render(ptrace.load(SHIPPED), integrator="normals")
    for image, outward in ((course, 1.0), (ours, -1.0)):
        np.testing.assert_allclose(image[300, 400], [0.5, 0.5, 0.5 - 0.5 * outward], atol=1e-6)
        np.testing.assert_allclose(image[300, 180], [0.5 - 0.5 * outward, 0.5, 0.5], atol=1e-6)
        np.testing.assert_allclose(image[300, 620], [0.5 + 0.5 * outward, 0.5, 0.5], atol=1e-6)
        np.testing.assert_array_equal(image[10, 10], [0, 0, 0])   # a miss is black


def test_same_seed_same_image_whatever_the_threads(scenes_dir):
    scene = ptrace.load(scenes_dir / "sky/CBspheres_lambertian.dae")
    kwargs = dict(integrator="normals", resolution=(64, 48), spp=4, seed=3)
    one = ptrace.render(scene, threads=1, **kwargs)
    assert numba.config.NUMBA_NUM_THREADS >= 2      # tests/conftest.py sees to it
    two = ptrace.render(scene, threads=2, **kwargs)
    np.testing.assert_array_equal(one, two)
    other = ptrace.render(scene, integrator="normals", resolution=(64, 48), spp=4, seed=4)
    assert not np.array_equal(one, other)   # the seed does change the jitter


def test_shipped_scene_renders_normals():
    scene = ptrace.load(SHIPPED)
    assert (scene.triangle_count, scene.sphere_count) == (24, 1)
    stats = {}
    image = ptrace.render(scene, integrator="normals", resolution=(480, 360), stats=stats)
    assert stats["nonfinite"] == 0    # (the image is finite by construction: dropped samples)
    # left wall faces +x: red channel high; right wall faces -x: red channel low
    assert image[180, 10, 0] > 0.9 and image[180, 470, 0] < 0.1
