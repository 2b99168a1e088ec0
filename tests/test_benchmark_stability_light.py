"""Pins the claims of the light-transport sections of benchmarks/results/stability.md
(`python -m studies.stability_light`): where hemisphere sampling, adaptive sampling, fixed
depths and Russian roulette fail, and what ptrace does there. The measurements are the report's
own helpers, at smaller sizes and with fixed seeds.

A test here that starts failing because a method got *better* is asking for the report to be
rerun and updated. The tests use the studies' own estimators (study.COURSE, study.RR,
study.FIREFLY; see studies/stability_light.py for why each).

The report is written from the measured data alone (study.write_sections): the last tests run the
writer on made-up data and check that the text follows the numbers and that every test it names
(study.PINS) is defined here.
"""
import copy
import math
import pathlib

import numpy as np
import pytest

import ptrace
from benchmarks import report
from ptrace import codes
from ptrace.environment import LUMINANCE
from studies import stability_light as study

import study_checks as check

SHIPPED = pathlib.Path(__file__).resolve().parents[1] / "scenes" / "cornell.dae"
SIZE = (16, 12)


# -- hemisphere sampling against light sampling ----------------------------------------------------
@pytest.fixture(scope="module")
def sweep():
    """{side: row} of the study's sweep (the course's light sampling against -H)."""
    return {r["side"]: r for r in study.hemisphere_sweep([0.5, 0.25, 0.1, 0.05], SIZE, 64)}


def stderr(relvar, mean, spp=64):
    """Standard error of an image mean from relvar (pooled per-sample variance / mean^2)."""
    return mean * math.sqrt(relvar / (SIZE[0] * SIZE[1] * spp))


def test_hemisphere_variance_grows_as_the_light_shrinks(sweep):
    big, small = sweep[0.5], sweep[0.05]
    print({side: (r["light"]["relvar"], r["hemisphere"]["relvar"]) for side, r in sweep.items()})
    # area 100x smaller: about 100x the variance (1 / area); at least 10x
    assert small["hemisphere"]["relvar"] > 10 * big["hemisphere"]["relvar"]
    assert small["hemisphere"]["relvar"] > 100 * small["light"]["relvar"]


def test_light_sampling_variance_does_not_grow_as_the_light_shrinks(sweep):
    largest = sweep[0.5]["light"]["relvar"]
    for side, r in sweep.items():
        assert r["light"]["relvar"] <= 1.5 * largest, side
        for method in ("light", "hemisphere"):
            relvar, mean = r[method]["relvar"], r[method]["mean"]
            # unbiased: within 4 standard errors (plus the quadrature's 0.5%) of the quadrature
            assert abs(mean - r["reference"]) <= 4 * stderr(relvar, mean) + 0.005 * \
                r["reference"], (side, method, mean, r["reference"])


def test_hemisphere_under_a_point_light_warns_and_is_black():
    scene, camera = study.point_light_scene(), study.floor_camera(*SIZE)
    kwargs = dict(camera=camera, resolution=SIZE, spp=4, max_depth=3, **study.COURSE)
    with pytest.warns(RuntimeWarning, match="hemisphere sampling"):
        image = ptrace.render(scene, hemisphere=True, **kwargs)
    assert image.max() == 0.0
    assert ptrace.render(scene, **kwargs).min() > 0
    measured = study.point_light_hemisphere(SIZE)      # what the report quotes
    assert measured["hemisphere_max"] == 0.0 and measured["light_mean"] > 0
    assert any("hemisphere sampling" in message for message in measured["warnings"])


def test_emitter_on_the_light_does_not_shadow_a_wide_floor():
    """Was a bug: shadow rays were aimed from the shading point but started at the spawned
    origin, so when a receiver's coordinates exceeded its distance to the light's plane the
    spawn offset carried the ray's end onto the emissive quad lying on the light and the floor
    went black. Shadow rays now run from the spawned origin to the light's point."""
    means = {r["half"]: r["mean"] for r in study.shadow_bug(halves=(0.75, 2.0))}
    assert means[2.0] == pytest.approx(means[0.75], rel=0.01)


# -- adaptive sampling -----------------------------------------------------------------------------
ADAPTIVE_SPP, TOL = 128, 0.05


@pytest.fixture(scope="module")
def adaptive():
    """{case: {batch: {rule: false_convergence}}}."""
    out = {}
    for case in study.CASE_TEXT:
        snapshots, reference, options = study.adaptive_case(case, SIZE, ADAPTIVE_SPP, seed=3)
        out[case] = study.by_batch(study.adaptive_table(snapshots, reference, ADAPTIVE_SPP,
                                                        (16, 32), TOL))
    return out


@pytest.mark.parametrize("case", study.DIM_CASES)
def test_course_rule_stops_dim_pixels_black(adaptive, case):
    course = adaptive[case][16]["course"]
    print(case, course)
    assert course["false"] > 0.2
    assert course["black"] == course["false"] == course["early"]


@pytest.mark.parametrize("case", study.DIM_CASES)
def test_ptrace_rule_stops_fewer_falsely(adaptive, case):
    table = adaptive[case]
    print(case, table)
    for batch in (16, 32):
        assert table[batch]["ptrace"]["false"] <= table[batch]["course"]["false"]
    assert table[16]["ptrace"]["false"] < 0.8 * table[16]["course"]["false"]
    # a pixel stops black only after 2 batches of zeros: the course's rule at twice the batch
    assert table[16]["ptrace"]["black"] == table[32]["course"]["black"]
    if case == "reflector":
        assert table[32]["ptrace"]["false"] < 0.05


def test_adaptive_works_where_samples_are_rarely_zero(adaptive):
    for rule in study.RULES:
        direct = adaptive["direct"][16][rule]
        print(rule, direct)
        assert direct["early"] > 0.5
        assert direct["false"] < 0.02


def test_replay_matches_an_adaptive_render():
    """On the study's reflector case, with its options (the course's estimator)."""
    camera = study.floor_camera(*SIZE)
    options = dict(max_depth=2, **study.COURSE)
    snapshots, _ = study.batch_sums(study.reflector_scene(), camera, 64, 8, seed=5, **options)
    mean, samples = study.simulate_adaptive(snapshots, 8, 16, TOL, study.RULES["ptrace"])
    stats = {}
    image = ptrace.render(study.reflector_scene(), camera=camera, resolution=SIZE, spp=64,
                          seed=5, adaptive=(16, TOL), stats=stats, **options)
    assert 0 < (samples < 64).mean() < 1
    np.testing.assert_array_equal(stats["samples"], study.to_image(samples, camera))
    np.testing.assert_allclose(image @ LUMINANCE, study.to_image(mean, camera), rtol=1e-5,
                               atol=1e-9)


# -- Russian roulette and depth --------------------------------------------------------------------
@pytest.fixture(scope="module")
def cornell():
    scene = ptrace.load(SHIPPED)
    camera = study.small_course_camera(scene, *SIZE)
    return scene, camera, study.unlit_by_camera(scene, camera, 64, **study.RR)


def test_roulette_is_unbiased(cornell):
    scene, camera, mask = cornell
    rr = study.depth_run(scene, camera, 64, 100, mask=mask, **study.RR)
    deep = study.depth_run(scene, camera, 64, 16, "off", mask=mask, **study.RR)
    print(rr, deep)
    assert abs(rr["mean"] - deep["mean"]) < 4 * math.hypot(rr["stderr"], deep["stderr"])
    assert rr["rays"] < 0.8 * deep["rays"]


def test_fixed_depth_without_roulette_is_biased_low(cornell):
    scene, camera, mask = cornell
    means = [study.depth_run(scene, camera, 16, d, "off", mask=mask, **study.RR)["mean"]
             for d in (1, 2, 4, 8, 16)]
    print(means)
    # the same seed: a deeper render adds only non-negative terms to the same paths
    assert all(a <= b * (1 + 1e-12) for a, b in zip(means, means[1:]))
    assert means[1] < 0.9 * means[-1]


def test_default_cap_is_codes_rr_cap(cornell):
    """The cap is a setting whose default is ptrace.codes.RR_CAP: giving that value
    explicitly changes nothing, to the bit (through render() and through the study's runs)."""
    scene, camera, mask = cornell
    kwargs = dict(camera=camera, resolution=SIZE, spp=4, max_depth=100)
    np.testing.assert_array_equal(ptrace.render(scene, rr_cap=codes.RR_CAP, **kwargs),
                                  ptrace.render(scene, **kwargs))
    default = study.depth_run(scene, camera, 4, 100, mask=mask, **study.RR)
    given = study.depth_run(scene, camera, 4, 100, codes.RR_CAP, mask=mask, **study.RR)
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
    low = study.depth_run(scene, camera, 64, 100, 0.25, mask=mask, **study.RR)
    ours = study.depth_run(scene, camera, 64, 100, mask=mask, **study.RR)
    deep = study.depth_run(scene, camera, 64, 16, "off", mask=mask, **study.RR)
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
    kwargs = dict(camera=camera, resolution=SIZE, spp=4, direct="light", rr_depth=2)
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
        samples = study.diffuse_sample_radiance(scene, camera, 16, **study.FIREFLY)
        out[name] = study.firefly_stats(samples)
    return out


def test_caustic_fireflies(fireflies):
    glass, diffuse = fireflies["CBspheres.dae"], fireflies["CBspheres_lambertian.dae"]
    print({k: {m: v for m, v in r.items() if m != "clamps"} for k, r in fireflies.items()})
    outliers = study.by_k(glass["outliers"])
    # roulette from vertex 5 (rr_depth) boosts fewer paths than it did from vertex 2, so the
    # largest sample is smaller (109x the mean at 16 spp, 406x with the old rule at 256 spp);
    # the contrast is the point: glass has samples the diffuse spheres' 80x bound excludes
    assert glass["max"] > 80 * glass["mean"]
    assert outliers[100]["above"] > 0
    assert outliers[30]["energy"] > 0.05
    assert diffuse["max"] < 80 * diffuse["mean"]


def test_a_clamp_would_trade_energy_for_variance(fireflies):
    clamp = study.by_k(fireflies["CBspheres.dae"]["clamps"])[30]
    print(fireflies["CBspheres.dae"]["clamps"])
    assert clamp["lost"] > 0.03
    assert clamp["variance"] < 0.5
    assert study.by_k(fireflies["CBspheres_lambertian.dae"]["clamps"])[30]["lost"] < 0.005


# -- the report: written from the data alone -------------------------------------------------------
def test_every_pinned_test_exists():
    """The report names the tests of study.PINS: each is a test function of this file, so
    renaming one of them fails this test until PINS follows."""
    for path, function in study.PINS.values():
        assert path == study.TEST and callable(globals().get(function)), function


def convergence(false):
    return dict(early=false, false=false, false_of_early=1.0, black=false, samples=100.0)


def synthetic_data():
    """Made-up measurements with the shape of study.measure's, and a run."""
    sweep = [dict(side=side, area=side ** 2, light=dict(relvar=0.02, mean=0.12),
                  hemisphere=dict(relvar=0.05 / side ** 2, mean=0.12), reference=0.12)
             for side in (0.5, 0.05)]
    table = [dict(batch=batch, course=convergence(4.8 / batch), ptrace=convergence(2.4 / batch))
             for batch in (8, 16, 32, 64)]

    def run(name, rule, depth, mean):
        return dict(name=name, rule=rule, max_depth=depth, mean=mean, stderr=0.0002,
                    relvar=1.5, rays=1 + depth / 100, seconds=0.1)

    fixed = {1: 0.03, 2: 0.04, 4: 0.05, 8: 0.054, 16: 0.06}
    runs = [run(f"no RR, m={depth}", "off", depth, mean) for depth, mean in fixed.items()]
    runs += [run("RR (ptrace, cap 0.95), m=100", "ptrace", 100, 0.0601),
             run("RR (ptrace, cap 0.95), m=5", "ptrace", 5, 0.057)]
    runs += [run(f"RR cap {cap:g}, m=100", cap, 100, 0.0601 if cap >= 0.8 else 0.059)
             for cap in (0.95, 0.8, 0.5, 0.25)]

    def firefly(top):
        return dict(mean=0.06, spp=64, max=top,
                    outliers=[dict(k=k, above=0.01 / k, energy=0.1 / k) for k in study.OUTLIERS],
                    clamps=[dict(k=k, lost=0.3 / k, variance=min(1.0, k / 100),
                                 worse_after=None if k >= 1000 else 100.0 * k)
                            for k in study.CLAMPS])

    quick = dict(quick=True, width=32, height=24, spp=64)
    return {
        "run": dict(quick=True, threads=2, seconds=7.0),
        "hemisphere": dict(quick, options=study.COURSE, floor_albedo=0.5, light_height=1.0,
                           quadrature=32, sweep=sweep, point_light=dict(
                               warnings=["hemisphere sampling (-H) sees nothing"],
                               hemisphere_max=0.0, light_mean=0.45),
                           shadow_bug=[dict(half=0.75, mean=0.12), dict(half=2.0, mean=0.12)]),
        "adaptive": dict(quick, batches=[8, 16, 32, 64], tolerance=0.05, options=study.COURSE,
                         cases={case: dict(options=dict(max_depth=1, **study.COURSE),
                                           zero_chance=0.9, table=copy.deepcopy(table))
                                for case in study.CASE_TEXT}),
        "roulette": dict(quick, kept=0.99, options=study.RR, default_cap=0.95, runs=runs),
        "fireflies": dict(quick, options=study.FIREFLY,
                          scenes={"CBspheres.dae": firefly(22.0),
                                  "CBspheres_lambertian.dae": firefly(2.4)})}


def check_report(text):
    """Every table row has as many cells as its header; the tests named are those of PINS."""
    check.tables(text)
    assert set(check.quoted_tests(text)) == set(study.PINS.values())


def test_report_follows_the_data(tmp_path, monkeypatch):
    monkeypatch.setattr(report, "RESULTS", tmp_path)
    data = synthetic_data()
    _, text = check.written(study.write_report, data, "light.md")
    check.charts(tmp_path, [f"stability_light_{chart}.png"
                            for chart in ("hemisphere", "adaptive", "roulette", "fireflies")])
    check_report(text)
    # the figures are the data's
    check.says(text,
               "over a 100x smaller area -H's relvar grew 100x",
               'light samples alone with independent random numbers (`direct="light", '
               'sampler="independent"`)',
               "with batches of 16 it left 30% (*reflector*) and 30% (*hemisphere*)",
               "-16.7% at 4 vertices, -10.00% at 8 in this box",
               "(`direct=\"mis\", sampler=\"independent\"`: the standard errors",
               "given explicitly, 0.95 reproduced the default run to the bit",
               "Caps 0.95 and 0.8 gave the same image",
               "on CBspheres the largest sample was 367x the mean",
               "a clamp at 30x keeps 30% of it", "1.0% at 30x here",
               "| 1000 x mean | 0.03% | 1.00 | never |",
               "Total time 7 s.")
    # ... and a changed number changes the report
    changed = copy.deepcopy(data)
    changed["adaptive"]["cases"]["reflector"]["table"][1]["course"]["false"] = 0.5
    changed["fireflies"]["scenes"]["CBspheres.dae"]["max"] = 30.0
    changed["roulette"]["runs"][7]["mean"] = 0.0602       # the default cap given explicitly
    again = study.write_report(changed, "changed.md").read_text()
    check.says(again, "with batches of 16 it left 50% (*reflector*) and 30% (*hemisphere*)",
               "on CBspheres the largest sample was 500x the mean",
               "GIVEN EXPLICITLY, 0.95 DID NOT REPRODUCE the default run (mean 0.06020 against "
               "0.06010)")
    assert "Caps 0.95 and 0.8" not in again


def test_a_renamed_test_stops_the_report(tmp_path, monkeypatch):
    check.renamed_pin_stops(monkeypatch, study.PINS, "replay",
                            lambda: study.write_sections(synthetic_data(), tmp_path))


@pytest.mark.slow
def test_quick_report_writes_markdown_json_and_charts(tmp_path, monkeypatch):
    text = check.quick_run(study.main, tmp_path / "light.md")
    check_report(text)
    assert "DID NOT REPRODUCE" not in text and "NO WARNING" not in text
    # the report is a function of the JSON beside it: written again from it, the same text
    data = check.written_again(monkeypatch, study.write_report, tmp_path / "light.md")
    assert set(data) == {"run", *(name for name, _, _ in study.SECTIONS)}
