"""Choosing lights (--light-sampler): every light at every vertex (the course's estimator), or -l
samples of lights chosen by power. Both are unbiased, so they agree on the image's mean; the
choice follows the estimated power; `auto` is `all` for a few lights and `power` for many."""
import numpy as np
import pytest

import ptrace
from ptrace.codes import AUTO_EVERY_LIGHT
from ptrace.integrator import scene_records
from ptrace.lights import light_selection
from ptrace.scene import AREA, DIFFUSE, EMISSION, PHYSICAL, POINT, SPOT

from scenes_by_hand import looking_down, make_scene, point_light

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def area_light(centre, size, radiance):
    return dict(kind=AREA, radiance=(radiance,) * 3, position=centre, direction=(0, -1, 0),
                edge_x=(size, 0, 0), edge_y=(0, 0, size), area=size * size)


def many_lit_floor(extra_lights=()):
    """A diffuse floor under three area lights of other sizes and radiances, a course point
    light and an emissive sphere (five lights to the integrator: the sphere counts as one)."""
    half = 10.0
    lights = [area_light((-1.0, 1.5, 0.0), 0.5, 6.0), area_light((1.2, 2.0, 0.5), 1.0, 1.0),
              area_light((0.0, 1.0, -1.0), 0.2, 40.0), point_light((0.5, 1.0, 1.0), 0.3),
              *extra_lights]
    return make_scene(
        vertices=[[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]],
        faces=[[0, 2, 1], [0, 3, 2]], centers=[[0.8, 0.6, -0.8]], radii=[0.2],
        materials=[dict(kind=DIFFUSE, albedo=(0.7,) * 3), dict(kind=EMISSION, emission=(4.0,) * 3)],
        material_index=[0, 0, 1], lights=lights)


def render(scene, sampler, **options):
    camera = looking_down(5.0, width=24, screen_dist=7.0)
    return ptrace.render(scene, camera=camera, resolution=(24, 24), light_sampler=sampler,
                         **options)


@pytest.mark.parametrize("direct, depth", [("mis", 1), ("light", 1), ("mis", 3)])
def test_power_and_every_light_agree_on_the_mean(direct, depth):
    """Both estimators are unbiased: the image means agree (to a fraction of a percent at these
    sample counts), and each pixel's mean agrees within its noise."""
    scene = many_lit_floor()
    every = render(scene, "all", spp=64, light_samples=2, max_depth=depth, direct=direct)
    chosen = render(scene, "power", spp=256, light_samples=2, max_depth=depth, direct=direct,
                    seed=1)
    assert abs(chosen.mean() / every.mean() - 1) < 0.01, (chosen.mean(), every.mean())
    assert np.percentile(np.abs(chosen - every) / np.maximum(every, 1e-3), 50) < 0.05


def test_lights_are_chosen_in_proportion_to_their_estimated_irradiance():
    """An area light of four times the radiance (same size and place) is chosen four times as
    often; a course spot light (which gives no light) never; a glTF point light by its
    intensity over the squared scene radius."""
    scene = make_scene(
        vertices=[[-1, 0, -1], [1, 0, -1], [1, 0, 1]], faces=[[0, 2, 1]],
        materials=[dict(kind=DIFFUSE)], material_index=[0],
        lights=[area_light((0, 1, 0), 0.5, 1.0), area_light((0, 1, 0), 0.5, 4.0),
                dict(kind=SPOT, radiance=(9.0,) * 3, position=(0, 1, 0), direction=(0, -1, 0)),
                dict(kind=POINT, radiance=(2.0,) * 3, position=(0, 1, 0), model=PHYSICAL)])
    cdf, pmf = light_selection(scene)
    assert pmf.sum() == pytest.approx(1.0) and cdf[-1] == 1.0
    assert pmf[1] == pytest.approx(4 * pmf[0]) and pmf[2] == 0.0
    assert pmf[3] / pmf[0] == pytest.approx(2.0 / 0.25)   # both over the same r^2


def test_the_emissive_primitives_are_one_light_by_their_power():
    scene = many_lit_floor()
    shapes, materials, lights = scene_records(scene)
    assert lights.kind.shape[0] == 5 and lights.select_pmf.shape[0] == 5
    lower, upper = scene.bounds()
    r2 = (0.5 * np.linalg.norm(upper - lower)) ** 2
    sphere_power = 4.0 * 4 * np.pi * 0.2 ** 2 / r2
    first_area = 6.0 * 0.25 / r2
    assert lights.select_pmf[4] / lights.select_pmf[0] == pytest.approx(sphere_power / first_area)


def test_auto_is_every_light_for_a_few_and_the_light_bvh_for_many():
    """auto renders bit for bit as all up to AUTO_EVERY_LIGHT lights and as bvh above."""
    few = make_scene(vertices=[[-2, 0, -2], [2, 0, -2], [2, 0, 2]], faces=[[0, 2, 1]],
                     materials=[dict(kind=DIFFUSE)], material_index=[0],
                     lights=[area_light((0, 1, 0), 0.5, 2.0)] * AUTO_EVERY_LIGHT)
    options = dict(spp=4, light_samples=1, max_depth=2)
    np.testing.assert_array_equal(render(few, "auto", **options), render(few, "all", **options))
    assert not np.array_equal(render(few, "auto", **options), render(few, "power", **options))
    many = many_lit_floor()   # five
    np.testing.assert_array_equal(render(many, "auto", **options),
                                  render(many, "bvh", **options))
    assert not np.array_equal(render(many, "auto", **options), render(many, "power", **options))


def test_power_sampling_traces_l_shadow_rays_a_vertex_whatever_the_lights():
    """-l 1 under power: one light sample (one shadow ray) at a vertex, where all traces one
    per light."""
    scene = many_lit_floor()
    rays = {}
    for sampler in ("all", "power"):
        stats = {}
        render(scene, sampler, spp=4, light_samples=1, max_depth=1, direct="light", stats=stats)
        rays[sampler] = stats["rays"]
    pixels_spp = 24 * 24 * 4
    assert rays["power"] <= 2 * pixels_spp          # camera ray and at most one shadow ray
    assert rays["all"] > 4 * pixels_spp             # one per light where the floor is hit


def test_an_unknown_light_sampler_is_refused():
    with pytest.raises(ptrace.PtraceError, match="unknown light sampler 'tree'"):
        ptrace.Settings(light_sampler="tree")
