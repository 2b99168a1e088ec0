"""The path loop's wavefront (ptrace.kernel) gives the same image bit for bit whatever the wave
size, the threads or the crop, and `bvh` the same as `naive`; its memory does not grow with -s,
-m or -l; it compiles a shading kernel only for the material kinds a scene has, and none for
the normals integrator. (What the images should be is checked against analytic answers and
Mitsuba's references elsewhere: test_estimators, test_light_transport, test_per_pixel.)"""
import numpy as np
import pytest

import ptrace
from ptrace.kernel import layout, wavefront
from ptrace.rendering.settings import Settings
from ptrace.rendering.tiles import RenderJob
from ptrace.scene import DIFFUSE, GLASS, MIRROR

from conftest import REPO, course_scene

CORNELL = REPO / "scenes" / "cornell.dae"
SMALL = dict(spp=3, light_samples=2, max_depth=5, rr_depth=2)


def framed(scene, eye_z, width=24, height=18):
    """A camera that sees the whole box (the course's camera at this size sees a crop)."""
    return ptrace.look_at(scene, eye=(0.0, 0.75, eye_z), target=(0.0, 0.75, 0.0), fov=50,
                          width=width, height=height)


@pytest.fixture(scope="module")
def cornell():
    scene = ptrace.load(str(CORNELL))
    return scene, framed(scene, 3.5)


def assert_same(first, second):
    assert first.shape == second.shape
    assert np.array_equal(first, second), f"max difference {np.abs(first - second).max()}"
    assert first.mean() > 0.01     # lit: a black image would match trivially


def test_bvh_gives_naives_image_and_embree_its_light(cornell):
    scene, camera = cornell
    images = {kind: ptrace.render(scene, camera=camera, accel=kind, **SMALL)
              for kind in ("naive", "bvh", "embree")}
    assert_same(images["naive"], images["bvh"])
    assert images["embree"].mean() == pytest.approx(images["bvh"].mean(), rel=0.02)


@pytest.mark.parametrize("options", [dict(), dict(hemisphere=True), dict(integrator="normals")],
                         ids=["path", "hemisphere", "normals"])
def test_same_image_whatever_the_wave_size_threads_and_crop(cornell, monkeypatch, options):
    scene, camera = cornell
    options = dict(SMALL, **options)
    reference = ptrace.render(scene, camera=camera, threads=2, **options)
    monkeypatch.setattr(wavefront, "WAVE_PATHS", 7)       # waves cut pixels' samples apart
    assert_same(reference, ptrace.render(scene, camera=camera, threads=1, **options))
    crop = ptrace.render(scene, camera=camera, crop=(5, 4, 9, 7), **options)   # y from the bottom
    assert_same(crop, reference[18 - 4 - 7:18 - 4, 5:5 + 9])


def test_a_wave_holds_the_same_memory_whatever_spp_and_depth_and_bounds_light_samples(cornell):
    cornell, camera = cornell
    sizes = set()
    for spp, depth in ((1, 1), (4096, 10_000)):
        job = RenderJob.build(cornell, Settings(spp=spp, max_depth=depth), camera)
        sizes.add((job.wavefront.wave_paths, job.wavefront.shadow_rays))
    assert len(sizes) == 1
    job = RenderJob.build(cornell, Settings(light_samples=2 ** 16), camera)
    lights = len(cornell.lights)
    assert job.wavefront.shadow_rays <= wavefront.SHADOW_RAYS
    assert job.wavefront.wave_paths * lights * 2 ** 16 == job.wavefront.shadow_rays
    assert layout.Wave.bytes(job.wavefront.wave_paths, job.wavefront.shadow_rays) < 8 << 20


def test_the_normals_integrator_compiles_no_shading_kernel(cornell):
    scene, camera = cornell
    job = RenderJob.build(scene, Settings(integrator="normals"), camera)
    assert job.wavefront.stages == [] and job.wavefront.hit_stage is None


def test_only_the_kinds_a_scene_has_get_a_kernel(cornell):
    scene, camera = cornell
    job = RenderJob.build(scene, Settings(), camera)
    assert [kind for kind, _ in job.wavefront.stages] == [DIFFUSE]
    spheres = ptrace.load(str(course_scene("sky/CBspheres.dae")))
    job = RenderJob.build(spheres, Settings(), camera)
    assert [kind for kind, _ in job.wavefront.stages] == [DIFFUSE, MIRROR, GLASS]
