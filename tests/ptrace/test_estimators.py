"""The direct-light estimators (multiple importance sampling, the course's light sampling) and
emissive geometry as a light: unbiased against analytic answers and against each other, less
noisy where they should be, and the rules that decide which emitters are lights."""
import dataclasses
import warnings

import numpy as np
import pytest

import ptrace
from ptrace.codes import IndependentOptions, Options
from ptrace.emitters import EMITTER, emitter_arrays
from ptrace.integrator import scene_records
from ptrace.scene import DIFFUSE, EMISSION, Lights

from scenes_by_hand import looking_down, make_scene, pixel_hits_on_floor

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def glowing_sphere(radiance=3.0, radius=0.5, height=2.0, albedo=0.6):
    """A diffuse floor (y = 0) under an emissive sphere, and no other light."""
    half = 50.0
    vertices = [[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]]
    return make_scene(vertices=vertices, faces=[[0, 2, 1], [0, 3, 2]],
                      centers=[[0.3, height, -0.2]], radii=[radius],
                      materials=[dict(kind=DIFFUSE, albedo=(albedo,) * 3),
                                 dict(kind=EMISSION, emission=(radiance,) * 3)],
                      material_index=[0, 0, 1])


@pytest.mark.parametrize("direct", ["mis", "light"])
def test_a_scene_lit_only_by_an_emissive_sphere_matches_the_analytic_answer(direct):
    """A sphere of radiance L, radius R, centre at distance d from a floor point, wholly above
    its horizon, gives irradiance pi L (R / d)^2 cos(theta): the floor's radiance is
    albedo L R^2 cos(theta) / d^2 (direct light only, -m 1)."""
    radiance, radius, height, albedo = 3.0, 0.5, 2.0, 0.6
    scene = glowing_sphere(radiance, radius, height, albedo)
    camera = looking_down(6.0, width=24, screen_dist=6.0)
    image = ptrace.render(scene, camera=camera, resolution=(24, 24), spp=256, max_depth=1,
                          direct=direct)
    points = pixel_hits_on_floor(camera)
    to_centre = np.array([0.3, height, -0.2]) - points
    distance = np.linalg.norm(to_centre, axis=-1)
    expected = albedo * radiance * radius ** 2 * (to_centre[..., 1] / distance) / distance ** 2
    # pixels whose camera rays may meet the sphere show its emission: leave them out, with a
    # margin of one pixel (a jittered ray of an edge pixel meets it)
    sphere = image[..., 0] > 0.5 * radiance
    near = sphere.copy()
    for axis in (0, 1):
        for step in (-1, 1):
            near |= np.roll(sphere, step, axis=axis)
    floor = ~near
    assert floor.sum() > 400
    ratio = image[..., 0][floor] / expected[floor]
    assert abs(ratio.mean() - 1) < 0.01, ratio.mean()
    assert np.percentile(np.abs(ratio - 1), 90) < 0.08


def test_emissive_geometry_alone_is_a_light_and_not_a_black_image(course_scene):
    """CBspheres_lambertian without its <light>: the emissive quad becomes the light. Light
    sampling, multiple importance sampling and -H hemisphere sampling (which sees emissive
    geometry directly, an independent estimator) agree on the mean."""
    scene = ptrace.load(course_scene("sky/CBspheres_lambertian.dae"))
    scene = dataclasses.replace(scene, lights=Lights.from_records([]))
    kinds = scene_records(scene)[2].kind
    assert list(kinds) == [EMITTER]
    means = {}
    for name, options in (("mis", dict(direct="mis")), ("light", dict(direct="light")),
                          ("hemisphere", dict(hemisphere=True))):
        values = [float((ptrace.render(scene, resolution=(48, 36), spp=64, max_depth=3,
                                       seed=seed, **options) @ LUMINANCE).mean())
                  for seed in range(3)]
        means[name] = (np.mean(values), np.std(values, ddof=1) / np.sqrt(len(values)))
    assert means["mis"][0] > 0.2      # lit, not black apart from the quad
    for name in ("light", "hemisphere"):
        difference = abs(means[name][0] - means["mis"][0])
        error = np.hypot(means[name][1], means["mis"][1])
        # three seeds estimate the spread poorly (the 1 cm slit above the two-sided quad gives
        # light and -H rare bright samples): 5 of those errors, or 2 % (a missing back face or
        # bounce would be tens of percent)
        assert difference < max(5 * error, 0.02 * means["mis"][0]), (name, means)


@pytest.mark.parametrize("path", ["sky/CBspheres_microfacet_al_ag.dae", "sky/bunny.dae",
                                  "sky/CBspheres.dae"])
def test_mis_and_light_sampling_agree_on_the_mean(course_scene, path):
    """Both estimators are unbiased: over four seeds their mean luminances agree within their
    standard errors (glossy metal; the ambient light, which MIS also finds by escaping BSDF
    rays; mirror and glass)."""
    scene = ptrace.load(course_scene(path))
    stats = {}
    for direct in ("mis", "light"):
        values = [float((ptrace.render(scene, resolution=(48, 36), spp=64, max_depth=4,
                                       seed=seed, direct=direct) @ LUMINANCE).mean())
                  for seed in range(4)]
        stats[direct] = (np.mean(values), np.std(values, ddof=1) / 2.0)
    difference = abs(stats["mis"][0] - stats["light"][0])
    assert difference < max(4 * np.hypot(stats["mis"][1], stats["light"][1]),
                            0.002 * stats["light"][0]), stats


def test_mis_takes_the_noise_out_of_glossy_highlights(course_scene):
    """On the near-mirror microfacet sphere (alpha 0.025) light sampling rarely hits the lobe:
    its pixels' spread across seeds is several times MIS's."""
    scene = ptrace.load(course_scene("sky/CBspheres_microfacet_al_ag.dae"))
    spread = {}
    for direct in ("mis", "light"):
        images = np.stack([ptrace.render(scene, resolution=(48, 36), spp=16, max_depth=2,
                                         seed=seed, direct=direct) @ LUMINANCE
                           for seed in range(4)])
        spread[direct] = float(images.var(axis=0, ddof=1).mean())
    assert spread["light"] > 3 * spread["mis"], spread


def test_the_course_quads_are_their_lights_faces_not_second_lights(course_scene):
    """Every sp19 Cornell box's emissive quad lies on its <light> (docs/course.md#light-faces): it
    is that light's face (seen by the camera and mirrors), not sampled again; CBempty's lies on its
    point light."""
    for path in ("sky/CBspheres_lambertian.dae", "sky/CBcoil.dae", "sky/CBbunny.dae",
                 "sky/CBempty.dae", "sky/CBspheres.dae"):
        scene = ptrace.load(course_scene(path))
        faced, prims, cdf, prim_pdf = emitter_arrays(scene)
        assert list(faced) == [1] and prims.size == 0 and not prim_pdf.any(), path


def test_an_emitter_off_the_light_is_a_light_of_its_own(course_scene):
    """The same quad moved 0.2 down from the light's plane is no longer its face."""
    scene = ptrace.load(course_scene("sky/CBspheres_lambertian.dae"))
    quad = np.nonzero(scene.materials.kind[scene.material_index] == EMISSION)[0]
    vertices = scene.geometry.vertices.copy()
    moved = np.unique(scene.geometry.faces[quad])
    vertices[moved, 1] -= 0.2
    geometry = dataclasses.replace(scene.geometry, vertices=vertices)
    faced, prims, cdf, prim_pdf = emitter_arrays(dataclasses.replace(scene, geometry=geometry))
    assert list(faced) == [0] and sorted(prims) == sorted(quad)
    np.testing.assert_allclose(cdf[-1], 1.0)
    area = prim_pdf[quad] ** -1 * np.diff(np.concatenate([[0.0], cdf]))   # area of each
    np.testing.assert_allclose(area.sum(), 0.48, rtol=1e-4)


def test_delta_bounces_see_an_area_light_without_a_face(course_scene):
    """Without a quad (the sp23 files) the light itself is what the mirror sphere reflects and
    the glass sphere focuses: pixels brighter than any lit wall appear; with light sampling
    alone the same (both estimators share the rule)."""
    scene = ptrace.load(course_scene("variants_sp23/sky/CBspheres_refract.dae"))
    for direct in ("mis", "light"):
        image = ptrace.render(scene, resolution=(240, 180), spp=4, max_depth=3, direct=direct)
        assert (image @ LUMINANCE > 5).sum() > 20, direct


def test_a_scene_without_any_light_or_emitter_is_warned_of():
    scene = make_scene(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]],
                       materials=[dict(kind=DIFFUSE)], material_index=[0])
    with pytest.warns(RuntimeWarning, match="no light and no emissive surface"):
        ptrace.render(scene, resolution=(4, 4))
    lit = glowing_sphere()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ptrace.render(lit, resolution=(4, 4))


def test_estimator_and_sampler_settings_are_checked():
    with pytest.raises(ptrace.PtraceError, match="direct-light estimator"):
        ptrace.Settings(direct="bdpt")
    with pytest.raises(ptrace.PtraceError, match="sampler"):
        ptrace.Settings(sampler="halton")
    with pytest.raises(ptrace.PtraceError, match="roulette depth"):
        ptrace.Settings(rr_depth=0)
    options = ptrace.Settings(direct="light", sampler="independent", rr_depth=5).kernel_options()
    assert (options.mis, type(options), options.rr_depth) == (False, IndependentOptions, 5)
    assert ptrace.Settings().kernel_options().mis
    assert type(ptrace.Settings().kernel_options()) is Options   # the Sobol' sampler


def test_bvh_split_setting():
    from accel.bvh import SPLITS
    from ptrace.rendering.settings import BVH_SPLITS
    assert BVH_SPLITS == SPLITS
    with pytest.raises(ptrace.PtraceError, match="BVH split"):
        ptrace.Settings(bvh_split="median")
    with pytest.raises(ptrace.PtraceError, match="only to the bvh"):
        ptrace.Settings(accel="naive", bvh_split="sah")
    assert ptrace.Settings(bvh_split="sah").accel_options() == {"split": "sah"}
    assert ptrace.Settings(accel="embree").accel_options() == {}
