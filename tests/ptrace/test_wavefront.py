"""The wavefront prototype (--loop wavefront, ptrace.kernel) renders the megakernel's image bit for
bit on the scenes it takes (every material kind, textured or not, under any lights), whatever the
backend, the wave size, the threads, adaptive sampling or the crop, and with hemisphere
sampling; its memory does not grow with -s, -m or -l; it compiles a shading kernel only for the
material kinds a scene has."""
import subprocess
import sys

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


def both(scene_camera, **options):
    """(megakernel image, wavefront image) of one render's options."""
    scene, camera = scene_camera
    return (ptrace.render(scene, camera=camera, **options),
            ptrace.render(scene, camera=camera, loop="wavefront", **options))


def assert_same(images):
    mega, wave = images
    assert mega.shape == wave.shape
    assert np.array_equal(mega, wave), f"max difference {np.abs(mega - wave).max()}"
    assert mega.mean() > 0.01     # lit: a black image would match trivially


@pytest.mark.parametrize("kind", ["naive", "bvh", "embree"])
def test_same_image_as_the_megakernel_on_every_backend(cornell, kind):
    assert_same(both(cornell, accel=kind, **SMALL))


@pytest.mark.parametrize("options", [
    dict(direct="light"),
    dict(sampler="independent", seed=5),
    dict(max_depth=0),
    dict(max_depth=1),
    dict(roulette=False, max_depth=3),
    dict(light_samples=1, spp=1),
    dict(adaptive=(2, 0.2), spp=8),
], ids=["light-sampling", "independent", "m0", "m1", "no-roulette", "s1", "adaptive"])
def test_same_image_under_each_setting(cornell, options):
    assert_same(both(cornell, **dict(SMALL, **options)))


def test_same_image_on_the_course_boxes():
    """Mirror, glass and microfacet surfaces beside diffuse ones, each kind through its own
    kernel."""
    for name, eye_z in (("sky/CBspheres.dae", 3.5), ("sky/CBspheres_microfacet_al_ag.dae", 3.5)):
        scene = ptrace.load(str(course_scene(name)))
        assert_same(both((scene, framed(scene, eye_z, 20, 15)), spp=2, light_samples=1,
                         max_depth=4))


def test_same_image_under_every_kind_of_light(tmp_path):
    """A point light, the ambient light, an environment beside an area light, and emissive
    geometry that is no light's face: the stages of any light."""
    from test_default_light import room

    from ptrace.environment import load_environment
    sky = load_environment(str(REPO / "scenes" / "sky.exr"))
    scenes = [(ptrace.load(str(course_scene("sky/CBempty.dae"))), 3.5),
              (ptrace.load(str(course_scene("sky/bunny.dae"))), None),
              (ptrace.load(str(CORNELL)).with_environment(sky), 3.5),
              (ptrace.load(str(room(tmp_path))), 0.9)]
    assert len(scenes[3][0].lights) == 0      # the room is lit by its emissive quad alone
    for scene, eye_z in scenes:
        camera = framed(scene, eye_z) if eye_z is not None else None
        options = dict(SMALL, resolution=(24, 18)) if camera is None else SMALL
        assert_same(both((scene, camera), **options))


@pytest.mark.parametrize("name", ["room.obj", "pbr.glb", "colours.ply"])
def test_same_image_on_mesh_files(name):
    """Albedo, emission and roughness textures (room.obj), glTF's material (pbr.glb), vertex
    colours (colours.ply)."""
    scene = ptrace.load(str(REPO / "scenes" / "files" / name))
    assert_same(both((scene, None), resolution=(24, 18), **SMALL))


def test_same_image_under_every_light_sampler(tmp_path):
    """A room of 5 area lights and 4 emissive tiles: lights chosen by power, and by the light
    BVH (auto's choice for more than four lights)."""
    path = tmp_path / "many.dae"
    subprocess.run([sys.executable, str(REPO / "scenes" / "make_many_lights.py"), "--tiles", "4",
                    "--lights", "5", "-o", str(path)], check=True, capture_output=True)
    scene = ptrace.load(str(path))
    images = {}
    for sampler in ("power", "bvh"):   # ("all": every other test)
        images[sampler] = both((scene, None), resolution=(24, 18), light_sampler=sampler, **SMALL)
        assert_same(images[sampler])
    assert not np.array_equal(images["power"][0], images["bvh"][0])   # two estimators


def test_same_image_past_cut_out_surfaces(tmp_path):
    """glTF's BLEND (a ray passes with probability 1 - alpha, by the ray's own key) in front of
    a floor under the sun: the camera's rays and the shadow rays pass the same surfaces."""
    from test_gltf_alpha_normals import render, white, write
    path = write(tmp_path / "blend.gltf", white("BLEND", factor=[1, 1, 1, 0.5]))
    mega, scene = render(path)
    assert scene.materials.cutoff.any()
    assert_same((mega, render(path, loop="wavefront")[0]))


def test_same_image_whatever_the_wave_size_threads_and_crop(cornell, monkeypatch):
    scene, camera = cornell
    reference = ptrace.render(scene, camera=camera, loop="wavefront", threads=2, **SMALL)
    monkeypatch.setattr(wavefront, "WAVE_PATHS", 7)       # waves cut pixels' samples apart
    assert_same((reference, ptrace.render(scene, camera=camera, loop="wavefront", threads=1,
                                          **SMALL)))
    assert_same(both(cornell, crop=(5, 4, 9, 7), **SMALL))


def test_a_wave_holds_the_same_memory_whatever_spp_and_depth_and_bounds_light_samples(cornell):
    cornell, camera = cornell
    sizes = set()
    for spp, depth in ((1, 1), (4096, 10_000)):
        job = RenderJob.build(cornell, Settings(loop="wavefront", spp=spp, max_depth=depth),
                              camera)
        sizes.add((job.wavefront.wave_paths, job.wavefront.shadow_rays))
    assert len(sizes) == 1
    job = RenderJob.build(cornell, Settings(loop="wavefront", light_samples=2 ** 16), camera)
    lights = len(cornell.lights)
    assert job.wavefront.shadow_rays <= wavefront.SHADOW_RAYS
    assert job.wavefront.wave_paths * lights * 2 ** 16 == job.wavefront.shadow_rays
    assert layout.Wave.bytes(job.wavefront.wave_paths, job.wavefront.shadow_rays) < 8 << 20


def test_same_image_with_hemisphere_sampling(cornell, tmp_path):
    """-H: uniform hemisphere rays instead of light samples, each keeping the emission of what
    it hits (the environment's where it escapes), past cut-out surfaces too."""
    from test_gltf_alpha_normals import white, write

    from ptrace.environment import load_environment
    sky = load_environment(str(REPO / "scenes" / "sky.exr"))
    scene, camera = cornell
    for lit in (scene, scene.with_environment(sky)):
        images = both((lit, camera), hemisphere=True, **SMALL)
        assert_same(images)
    assert not np.array_equal(images[0], ptrace.render(lit, camera=camera, **SMALL))
    blend = ptrace.load(str(write(tmp_path / "blend.gltf", white("BLEND",
                                                                 factor=[1, 1, 1, 0.5]))))
    assert blend.materials.cutoff.any()
    assert_same(both((blend.with_environment(sky), None), resolution=(24, 18), hemisphere=True,
                     **SMALL))


def test_same_normals_image_and_no_shading_kernel(cornell):
    scene, camera = cornell
    assert_same(both(cornell, integrator="normals", spp=2))
    job = RenderJob.build(scene, Settings(loop="wavefront", integrator="normals"), camera)
    assert job.wavefront.stages == [] and job.wavefront.hit_stage is None


def test_only_the_kinds_a_scene_has_get_a_kernel(cornell):
    scene, camera = cornell
    job = RenderJob.build(scene, Settings(loop="wavefront"), camera)
    assert [kind for kind, _ in job.wavefront.stages] == [DIFFUSE]
    spheres = ptrace.load(str(course_scene("sky/CBspheres.dae")))
    job = RenderJob.build(spheres, Settings(loop="wavefront"), camera)
    assert [kind for kind, _ in job.wavefront.stages] == [DIFFUSE, MIRROR, GLASS]


def test_same_aovs_as_the_megakernel(cornell):
    """Albedo, normal and distance of each sample's camera hit (a mirror, glass and diffuse
    spheres' box, and the normals integrator's too)."""
    spheres = ptrace.load(str(course_scene("sky/CBspheres.dae")))
    for scene, options in ((spheres, SMALL), (cornell[0], dict(integrator="normals", spp=2))):
        camera = framed(scene, 3.5)
        mega, wave = {}, {}
        images = (ptrace.render(scene, camera=camera, aovs=mega, **options),
                  ptrace.render(scene, camera=camera, aovs=wave, loop="wavefront", **options))
        assert_same(images)
        assert sorted(mega) == sorted(wave) and len(mega) >= 3, sorted(mega)
        for name in mega:
            assert np.array_equal(mega[name], wave[name]), name
        assert mega["albedo"].mean() > 0.05 and mega["depth"].max() > 0
