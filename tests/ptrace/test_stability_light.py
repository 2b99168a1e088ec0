"""Pins the claims of the light-transport sections of benchmarks/results/stability.md
(`python -m benchmarks.stability_light`): where hemisphere sampling, adaptive sampling, fixed
depths and Russian roulette fail, and what ptrace does there. The measurements are the report's
own helpers, at smaller sizes and with fixed seeds.

A test here that starts failing because a method got *better* is asking for the report to be
rerun and updated.
"""
import math
import pathlib

import numpy as np
import pytest

import ptrace
from benchmarks import stability_light as study
from ptrace import integrator
from ptrace.integrator import LUMINANCE

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"
SIZE = (16, 12)


# -- hemisphere sampling against light sampling ----------------------------------------------------
@pytest.fixture(scope="module")
def sweep():
    return study.hemisphere_sweep([0.5, 0.25, 0.1, 0.05], SIZE, 64)


def stderr(relvar, mean, spp=64):
    """Standard error of an image mean from relvar (pooled per-sample variance / mean^2)."""
    return mean * math.sqrt(relvar / (SIZE[0] * SIZE[1] * spp))


def test_hemisphere_variance_grows_as_the_light_shrinks(sweep):
    big, small = sweep[0.5], sweep[0.05]
    print({side: (r["light"][0], r["hemisphere"][0]) for side, r in sweep.items()})
    # area 100x smaller: about 100x the variance (1 / area); at least 10x
    assert small["hemisphere"][0] > 10 * big["hemisphere"][0]
    assert small["hemisphere"][0] > 100 * small["light"][0]


def test_light_sampling_variance_does_not_grow_as_the_light_shrinks(sweep):
    largest = sweep[0.5]["light"][0]
    for side, r in sweep.items():
        assert r["light"][0] <= 1.5 * largest, side
        for method in ("light", "hemisphere"):
            relvar, mean = r[method]
            # unbiased: within 4 standard errors (plus the quadrature's 0.5%) of the quadrature
            assert abs(mean - r["reference"]) <= 4 * stderr(relvar, mean) + 0.005 * \
                r["reference"], (side, method, mean, r["reference"])


def test_hemisphere_under_a_point_light_warns_and_is_black():
    scene, camera = study.point_light_scene(), study.floor_camera(*SIZE)
    with pytest.warns(RuntimeWarning, match="hemisphere sampling"):
        image = ptrace.render(scene, camera=camera, resolution=SIZE, spp=4, max_depth=3,
                              hemisphere=True)
    assert image.max() == 0.0
    assert ptrace.render(scene, camera=camera, resolution=SIZE, spp=4, max_depth=3).min() > 0


def test_emitter_on_the_light_does_not_shadow_a_wide_floor():
    """Was a bug: shadow rays were aimed from the shading point but started at the spawned
    origin, so when a receiver's coordinates exceeded its distance to the light's plane the
    spawn offset carried the ray's end onto the emissive quad lying on the light and the floor
    went black. Shadow rays now run from the spawned origin to the light's point."""
    means = study.shadow_bug(halves=(0.75, 2.0))
    assert means[2.0] == pytest.approx(means[0.75], rel=0.01)


# -- adaptive sampling -----------------------------------------------------------------------------
ADAPTIVE_SPP, TOL = 128, 0.05


@pytest.fixture(scope="module")
def adaptive():
    out = {}
    for case in study.CASE_TEXT:
        snapshots, reference, options = study.adaptive_case(case, SIZE, ADAPTIVE_SPP, seed=3)
        out[case] = study.adaptive_table(snapshots, reference, ADAPTIVE_SPP, (16, 32), TOL)
    return out


@pytest.mark.parametrize("case", study.DIM_CASES)
def test_course_rule_stops_dim_pixels_black(adaptive, case):
    course = adaptive[case][16, "course"]
    print(case, course)
    assert course["false"] > 0.2
    assert course["black"] == course["false"] == course["early"]


@pytest.mark.parametrize("case", study.DIM_CASES)
def test_ptrace_rule_stops_fewer_falsely(adaptive, case):
    table = adaptive[case]
    print(case, table)
    for batch in (16, 32):
        assert table[batch, "ptrace"]["false"] <= table[batch, "course"]["false"]
    assert table[16, "ptrace"]["false"] < 0.8 * table[16, "course"]["false"]
    # a pixel stops black only after 2 batches of zeros: the course's rule at twice the batch
    assert table[16, "ptrace"]["black"] == table[32, "course"]["black"]
    if case == "reflector":
        assert table[32, "ptrace"]["false"] < 0.05


def test_adaptive_works_where_samples_are_rarely_zero(adaptive):
    for rule in study.RULES:
        direct = adaptive["direct"][16, rule]
        print(rule, direct)
        assert direct["early"] > 0.5
        assert direct["false"] < 0.02


def test_replay_matches_an_adaptive_render():
    camera = study.floor_camera(*SIZE)
    snapshots, _ = study.batch_sums(study.reflector_scene(), camera, 64, 8, seed=5, max_depth=2)
    mean, samples = study.simulate_adaptive(snapshots, 8, 16, TOL, study.RULES["ptrace"])
    stats = {}
    image = ptrace.render(study.reflector_scene(), camera=camera, resolution=SIZE, spp=64,
                          seed=5, max_depth=2, adaptive=(16, TOL), stats=stats)
    assert 0 < (samples < 64).mean() < 1
    np.testing.assert_array_equal(stats["samples"], study.to_image(samples, camera))
    np.testing.assert_allclose(image @ LUMINANCE, study.to_image(mean, camera), rtol=1e-5,
                               atol=1e-9)


# -- Russian roulette and depth --------------------------------------------------------------------
@pytest.fixture(scope="module")
def cornell():
    scene = ptrace.load(SHIPPED)
    camera = study.small_course_camera(scene, *SIZE)
    return scene, camera, study.unlit_by_camera(scene, camera, 64)


def test_roulette_is_unbiased(cornell):
    scene, camera, mask = cornell
    rr = study.depth_run(scene, camera, 64, 100, mask=mask)
    deep = study.depth_run(scene, camera, 64, 16, "off", mask=mask)
    print(rr, deep)
    assert abs(rr["mean"] - deep["mean"]) < 4 * math.hypot(rr["stderr"], deep["stderr"])
    assert rr["rays"] < 0.8 * deep["rays"]


def test_fixed_depth_without_roulette_is_biased_low(cornell):
    scene, camera, mask = cornell
    means = [study.depth_run(scene, camera, 16, d, "off", mask=mask)["mean"]
             for d in (1, 2, 4, 8, 16)]
    print(means)
    # the same seed: a deeper render adds only non-negative terms to the same paths
    assert all(a <= b * (1 + 1e-12) for a, b in zip(means, means[1:]))
    assert means[1] < 0.9 * means[-1]


def test_default_cap_is_integrator_rr_cap(cornell):
    """The cap is a setting whose default is ptrace.integrator.RR_CAP: giving that value
    explicitly changes nothing, to the bit (through render() and through the study's runs)."""
    scene, camera, mask = cornell
    kwargs = dict(camera=camera, resolution=SIZE, spp=4, max_depth=100)
    np.testing.assert_array_equal(ptrace.render(scene, rr_cap=integrator.RR_CAP, **kwargs),
                                  ptrace.render(scene, **kwargs))
    default = study.depth_run(scene, camera, 4, 100, mask=mask)
    given = study.depth_run(scene, camera, 4, 100, integrator.RR_CAP, mask=mask)
    assert {k: v for k, v in given.items() if k != "seconds"} == \
        {k: v for k, v in default.items() if k != "seconds"}


@pytest.mark.slow
def test_low_cap_changes_the_image_but_stays_unbiased(cornell):
    """A cap that binds (0.25: below the box's albedos) gives another image, not ptrace's with
    a new name, and roulette with it stays unbiased against a deep render without roulette."""
    scene, camera, mask = cornell
    kwargs = dict(camera=camera, resolution=SIZE, spp=8, max_depth=100)
    assert not np.array_equal(ptrace.render(scene, rr_cap=0.25, **kwargs),
                              ptrace.render(scene, **kwargs))
    low = study.depth_run(scene, camera, 64, 100, 0.25, mask=mask)
    ours = study.depth_run(scene, camera, 64, 100, mask=mask)
    deep = study.depth_run(scene, camera, 64, 16, "off", mask=mask)
    print(low, ours, deep)
    assert low["mean"] != ours["mean"]
    assert abs(low["mean"] - deep["mean"]) < 4 * math.hypot(low["stderr"], deep["stderr"])


def test_a_vanishing_cap_stops_every_path_at_the_second_bounce(cornell):
    """Roulette from the second bounce continues with probability min(cap, throughput): with a
    cap of 1e-9 no path survives it, so at m=100 every path ends where m=2 without roulette
    ends it (the same vertices, the same random numbers): the same image and rays, to the bit.
    A cap that did not reach the path loop would leave ptrace's m=100 image, far brighter."""
    scene, camera, _ = cornell
    # light sampling alone: with MIS, m=2 also traces vertex 2's BSDF ray for the light it
    # finds, which a path that roulette ends at vertex 2 never traces
    kwargs = dict(camera=camera, resolution=SIZE, spp=4, direct="light")
    stats_cap, stats_m2 = {}, {}
    capped = ptrace.render(scene, max_depth=100, rr_cap=1e-9, stats=stats_cap, **kwargs)
    two = ptrace.render(scene, max_depth=2, roulette=False, stats=stats_m2, **kwargs)
    np.testing.assert_array_equal(capped, two)
    assert stats_cap["rays"] == stats_m2["rays"]
    many = dict(kwargs, spp=64)
    assert ptrace.render(scene, max_depth=100, **many).mean() > \
        1.1 * ptrace.render(scene, max_depth=2, **many).mean()


# -- fireflies -------------------------------------------------------------------------------------
def test_sample_radiance_is_what_render_averages(cornell):
    scene, camera, _ = cornell
    samples = study.sample_radiance(scene, camera, 4, seed=2, max_depth=3)
    image = ptrace.render(scene, camera=camera, resolution=SIZE, spp=4, seed=2, max_depth=3)
    np.testing.assert_allclose(image, study.to_image(samples.mean(axis=1), camera), rtol=1e-5,
                               atol=1e-6)


@pytest.fixture(scope="module")
def fireflies(course_scene):
    out = {}
    for name in ("CBspheres.dae", "CBspheres_lambertian.dae"):
        scene = ptrace.load(course_scene(f"sky/{name}"))
        camera = study.small_course_camera(scene, 32, 24)
        samples = study.diffuse_sample_radiance(scene, camera, 16, max_depth=5)
        out[name] = study.firefly_stats(samples)
    return out


def test_caustic_fireflies(fireflies):
    glass, diffuse = fireflies["CBspheres.dae"], fireflies["CBspheres_lambertian.dae"]
    print({k: {m: v for m, v in r.items() if m != "clamps"} for k, r in fireflies.items()})
    assert glass["max"] > 150 * glass["mean"]
    assert glass["above"][100] > 0
    assert glass["energy"][30] > 0.05
    assert diffuse["max"] < 80 * diffuse["mean"]


def test_a_clamp_would_trade_energy_for_variance(fireflies):
    clamp = fireflies["CBspheres.dae"]["clamps"][30]
    print(fireflies["CBspheres.dae"]["clamps"])
    assert clamp["lost"] > 0.03
    assert clamp["variance"] < 0.5
    assert fireflies["CBspheres_lambertian.dae"]["clamps"][30]["lost"] < 0.005
