"""Where methods fail: light transport (the light-transport half of the stability report).

    python -m studies.stability_light [--quick] [--threads 2] [--output stability_light.md]

Writes benchmarks/results/stability_light.md (or --output, relative to benchmarks/results/),
its PNG charts beside it and the measured data as stability_light.json beside it; a --quick run
without --output goes to a new temporary directory (printed). studies.stability includes the
same sections in benchmarks/results/stability.md (its "light" data). The studies:

1. Hemisphere sampling (-H) against light sampling as an area light shrinks at constant power,
   and hemisphere sampling under a point light (which it cannot see).
2. Adaptive sampling (-a) stopping dim, noisy pixels too early: ptrace's rule against the
   course's, evaluated on the same samples.
3. Russian roulette against fixed depths (bias, variance, cost), and the fireflies of caustic
   paths with what a clamp would cost.

Measuring and writing are apart: measure(quick) returns plain data, one entry per SECTIONS
name (measure_hemisphere, measure_adaptive, measure_roulette, measure_fireflies);
write_sections(data, chart_dir) writes the Markdown sections from that data alone, filling the
named blocks of benchmarks/templates/stability_light.md; the tests they quote are PINS entries.

Estimators. The sections read the error of a mean from the spread of its samples (variance /
spp: relvar, standard errors, sigmas, efficiency, "worse after"), which holds for independent
samples only; a scrambled Sobol' pixel's samples are not independent. So every study passes
sampler="independent". The hemisphere and adaptive studies are of the course's estimator
(light sampling alone, COURSE); roulette and fireflies are of ptrace's own (its default
direct="mis", RR and FIREFLY options).

tests/test_benchmark_stability_light.py pins the claims of the report with the helpers below.
"""
import dataclasses
import json
import math
import time
import warnings
from pathlib import Path

import numba
import numpy as np

import accel
import ptrace
from benchmarks import templating
from benchmarks.rays import scenes_dir
from benchmarks.templating import blocks, fill, join, pinned_ids, plain
from ptrace import codes
from ptrace.camera import Camera, course_camera
from ptrace.rendering import tiles
from ptrace.rendering.settings import Settings
from ptrace.rendering.tiles import TileWork, new_sums
from ptrace.scene import (
    AREA,
    DIFFUSE,
    EMISSION,
    LUMINANCE,
    POINT,
    CameraSpec,
    Lights,
    Materials,
    Scene,
    area_weighted_normals,
)

REPRODUCE = "python -m studies.stability_light"
REPRODUCE_ALL = "python -m studies.stability"
TEMPLATE = "stability_light.md"
TEST = "tests/test_benchmark_stability_light.py"
# claim -> test function of TEST: the tests the report quotes, by the field names of the
# template (`{test[claim]}` prints file::function, `{short[claim]}` ::function)
PINS = {claim: (TEST, name) for claim, name in {
    "hemisphere_grows": "test_hemisphere_variance_grows_as_the_light_shrinks",
    "light_flat": "test_light_sampling_variance_does_not_grow_as_the_light_shrinks",
    "point_light": "test_hemisphere_under_a_point_light_warns_and_is_black",
    "wide_floor": "test_emitter_on_the_light_does_not_shadow_a_wide_floor",
    "course_black": "test_course_rule_stops_dim_pixels_black",
    "ptrace_fewer": "test_ptrace_rule_stops_fewer_falsely",
    "rarely_zero": "test_adaptive_works_where_samples_are_rarely_zero",
    "replay": "test_replay_matches_an_adaptive_render",
    "unbiased": "test_roulette_is_unbiased",
    "biased_low": "test_fixed_depth_without_roulette_is_biased_low",
    "default_cap": "test_default_cap_is_codes_rr_cap",
    "low_cap": "test_low_cap_changes_the_image_but_stays_unbiased",
    "vanishing_cap": "test_a_vanishing_cap_stops_every_path_at_the_second_bounce",
    "caustics": "test_caustic_fireflies",
    "clamp": "test_a_clamp_would_trade_energy_for_variance",
    "sample_radiance": "test_sample_radiance_is_what_render_averages",
}.items()}

# The estimators of the studies (see the module's docstring): Settings options
COURSE = dict(direct="light", sampler="independent")   # the course's: light sampling alone
# ptrace's MIS; standard errors hold; roulette from the second bounce, the rule whose cap this
# study measures (ptrace's default before the error_vs_time measurement moved it to vertex 5)
RR = dict(sampler="independent", rr_depth=2)
FIREFLY = dict(max_depth=5, sampler="independent")     # ptrace's MIS, the course's -m 5

LIGHT_HEIGHT = 1.0        # the area light of the floor scenes, centred over the origin
EYE_HEIGHT = 0.5          # the camera looks straight down from below the light
FLOOR_ALBEDO = 0.5
QUADRATURE = 32           # points per side of the light in the quadrature references


# -- shared helpers ----------------------------------------------------------------------------
def pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def quad(centre, edge_x, edge_y):
    """Four corners and two triangles of the rectangle centre +- edge_x/2 +- edge_y/2."""
    c, ex, ey = (np.asarray(v, dtype=float) for v in (centre, edge_x, edge_y))
    corners = [c - ex / 2 - ey / 2, c + ex / 2 - ey / 2, c + ex / 2 + ey / 2, c - ex / 2 + ey / 2]
    return np.array(corners), np.array([[0, 1, 2], [0, 2, 3]])


def build_scene(parts, materials, lights):
    """A Scene from [(vertices, faces, material)] with no file behind it."""
    vertices, faces, index, base = [], [], [], 0
    for v, f, material in parts:
        vertices.append(v)
        faces.append(f + base)
        index += [material] * len(f)
        base += len(v)
    geometry = accel.Geometry(np.concatenate(vertices), np.concatenate(faces))
    return Scene(path="<stability_light scene>", geometry=geometry,
                 vertex_normals=area_weighted_normals(geometry.vertices, geometry.faces),
                 material_index=np.asarray(index, dtype=np.int32),
                 materials=Materials.from_records(materials), lights=Lights.from_records(lights),
                 camera=CameraSpec(view_point=np.array([0.0, 0.0, -1.0]), position=np.zeros(3)))


FLOOR_HALF = 0.75   # see floor()


def floor():
    """The floor, y = 0, 1.5 wide (the camera sees the middle 1 x 0.75). (Chosen while wider
    floors went black through a shadow-ray bug, since fixed: see shadow_bug.)"""
    return quad((0, 0, 0), (2 * FLOOR_HALF, 0, 0), (0, 0, 2 * FLOOR_HALF))


def area_light_scene(side, power=1.0, floor_half=FLOOR_HALF):
    """A diffuse floor (albedo 0.5, y = 0, 2 x floor_half wide) under a square one-sided area
    light of the given side facing down at y = 1, with an emissive quad lying on it (what -H
    sees). The radiance is
    power / side^2, so the emitted power (pi L A) is the same whatever the side."""
    radiance = power / side ** 2
    lamp_v, lamp_f = quad((0, LIGHT_HEIGHT, 0), (side, 0, 0), (0, 0, side))
    return build_scene(
        [(*quad((0, 0, 0), (2 * floor_half, 0, 0), (0, 0, 2 * floor_half)), 0),
         (lamp_v, lamp_f, 1)],
        [dict(kind=DIFFUSE, albedo=(FLOOR_ALBEDO,) * 3),
         dict(kind=EMISSION, emission=(radiance,) * 3)],
        [dict(kind=AREA, radiance=(radiance,) * 3, position=(0, LIGHT_HEIGHT, 0),
              direction=(0, -1, 0), edge_x=(side, 0, 0), edge_y=(0, 0, side), area=side ** 2)])


REFLECTOR_HEIGHT, REFLECTOR_ALBEDO = 2.0, 0.8


def reflector_scene(side=1.0, light_side=0.2, radiance=25.0):
    """A floor lit only by indirect light: a one-sided area light at y = 1 faces *up* (the floor
    is behind it, so gets no direct light) at a small diffuse reflector (side `side`, albedo 0.8)
    at y = 2, the floor's only light. No emissive geometry: the light is invisible."""
    patch_v, patch_f = quad((0, REFLECTOR_HEIGHT, 0), (side, 0, 0), (0, 0, side))
    return build_scene(
        [(*floor(), 0), (patch_v, patch_f, 1)],
        [dict(kind=DIFFUSE, albedo=(FLOOR_ALBEDO,) * 3),
         dict(kind=DIFFUSE, albedo=(REFLECTOR_ALBEDO,) * 3)],
        [dict(kind=AREA, radiance=(radiance,) * 3, position=(0, LIGHT_HEIGHT, 0),
              direction=(0, 1, 0), edge_x=(light_side, 0, 0), edge_y=(0, 0, light_side),
              area=light_side ** 2)])


def point_light_scene(power=3.0):
    """The floor under a point light only: nothing emissive for -H to find."""
    return build_scene([(*floor(), 0)], [dict(kind=DIFFUSE, albedo=(FLOOR_ALBEDO,) * 3)],
                       [dict(kind=POINT, radiance=(power,) * 3, position=(0, LIGHT_HEIGHT, 0))])


def floor_camera(width, height):
    """Straight down from (0, 0.5, 0), 90 degrees across the width: sees the floor from -0.5 to
    0.5 in x, below the light (camera rays never see the lamp)."""
    axes = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]).T   # right, up, backward
    return Camera(np.array([0.0, EYE_HEIGHT, 0.0]), np.zeros(3), axes, width / 2.0, width,
                  height, 1e-4, 1e4)


def small_course_camera(scene, width, height):
    """The course's 800x600 view of `scene` at a lower resolution (the same picture, not a crop)."""
    camera = course_camera(scene)
    return dataclasses.replace(camera, screen_dist=camera.screen_dist * width / camera.width,
                               width=width, height=height)


def pixel_grid(camera):
    """Pixel coordinates in render's order (rows from the bottom, y counted from the bottom)."""
    ys, xs = np.mgrid[0:camera.height, 0:camera.width]
    return xs.reshape(-1).astype(np.int64), ys.reshape(-1).astype(np.int64)


def floor_points(camera):
    """Where each pixel centre's ray meets y = 0, in render's pixel order."""
    px, py = pixel_grid(camera)
    d = camera.directions(px + 0.5, py + 0.5)
    t = -camera.position[1] / d[:, 1]
    return camera.position + t[:, None] * d


def to_image(values, camera):
    """Per-pixel values in render's order -> (H, W) with the top row first, like render()."""
    values = np.asarray(values)
    return values.reshape(camera.height, camera.width, *values.shape[1:])[::-1]


# -- quadrature references ---------------------------------------------------------------------
def rect_points(centre, edge_x, edge_y, n):
    u = (np.arange(n) + 0.5) / n - 0.5
    c, ex, ey = (np.asarray(v, dtype=float) for v in (centre, edge_x, edge_y))
    q = c + u[:, None, None] * ex + u[None, :, None] * ey
    return q.reshape(-1, 3), float(np.linalg.norm(np.cross(ex, ey))) / n ** 2


def irradiance(points, normal, sources, source_radiance, source_facing, d_area):
    """Midpoint-rule irradiance at points (receiving about `normal`) from a rectangle sampled at
    `sources`, emitting source_radiance (scalar or per source point) toward source_facing."""
    d = sources[None, :, :] - points[:, None, :]
    r2 = np.einsum("psk,psk->ps", d, d)
    r = np.sqrt(r2)
    cos_p = np.maximum(d @ np.asarray(normal, dtype=float), 0) / r
    cos_q = np.maximum(-(d @ np.asarray(source_facing, dtype=float)), 0) / r
    return (np.broadcast_to(source_radiance, (sources.shape[0],)) * cos_p * cos_q / r2).sum(1) \
        * d_area


def direct_reference(camera, side, power=1.0, n=QUADRATURE):
    """Exact (to quadrature) radiance of the area_light_scene floor at each pixel centre."""
    sources, da = rect_points((0, LIGHT_HEIGHT, 0), (side, 0, 0), (0, 0, side), n)
    e = irradiance(floor_points(camera), (0, 1, 0), sources, power / side ** 2, (0, -1, 0), da)
    return FLOOR_ALBEDO / math.pi * e


def reflector_reference(camera, side=1.0, light_side=0.2, radiance=25.0, n=QUADRATURE):
    """Exact (to quadrature) radiance of the reflector_scene floor: one diffuse bounce off the
    reflector, which the light below it lights."""
    patch, da = rect_points((0, REFLECTOR_HEIGHT, 0), (side, 0, 0), (0, 0, side), n)
    lamp, dl = rect_points((0, LIGHT_HEIGHT, 0), (light_side, 0, 0), (0, 0, light_side), 8)
    patch_radiance = REFLECTOR_ALBEDO / math.pi * irradiance(patch, (0, -1, 0), lamp, radiance,
                                                             (0, 1, 0), dl)
    e = irradiance(floor_points(camera), (0, 1, 0), patch, patch_radiance, (0, -1, 0), da)
    return FLOOR_ALBEDO / math.pi * e




def save_chart(plt, figure, chart_dir, name):
    """Lay out, save into chart_dir and close a chart; return its file name for the report."""
    figure.tight_layout()
    figure.savefig(Path(chart_dir) / name, dpi=110)
    plt.close(figure)
    return name


def label_log_axis(axis, xlabel, ylabel, title):
    """Labels, title, legend and a grid on every decade, for a chart on log axes."""
    axis.set_xlabel(xlabel)
    axis.set_ylabel(ylabel)
    axis.set_title(title)
    axis.legend()
    axis.grid(True, which="both", alpha=0.3)


def settings_text(options):
    """The direct-light estimator and sampler that `options` render with, as render()'s
    keywords (`direct="light", sampler="independent"`), defaults filled in from Settings."""
    chosen = {name: options.get(name, getattr(Settings, name)) for name in ("direct", "sampler")}
    return ", ".join(f"{name}={json.dumps(value)}" for name, value in chosen.items())


def reproduce_line(quick):
    return fill(blocks(TEMPLATE)["reproduce"], reproduce=REPRODUCE, reproduce_all=REPRODUCE_ALL,
                quick_flag=" --quick" if quick else "")


# -- per-pixel sums and per-sample radiance, exactly as render() draws them --------------------
def tile_work(scene, camera, spp, seed=0, **options):
    """The TileWork render(scene, spp=spp, seed=seed, camera=camera, **options) runs (the bvh
    backend, the path integrator): options are Settings' (max_depth, light_samples, hemisphere,
    roulette, rr_cap, ...)."""
    settings = Settings(spp=spp, accel="bvh", integrator="path", seed=seed, **options)
    return TileWork(scene, accel.build(settings.accel, scene.geometry), settings, camera)


def batch_sums(scene, camera, spp, step, seed=0, **options):
    """Trace `spp` samples per pixel in passes of `step`, as render() would; return the
    cumulative per-pixel (sum of illuminance, sum of its square, count) after each pass, as an
    array (spp // step, 3, P) in render's pixel order, and the TileWork (for rays_traced)."""
    work = tile_work(scene, camera, spp, seed, **options)
    px, py = pixel_grid(camera)
    sums = new_sums(px.size)
    rows = np.arange(px.size)
    out = []
    for first in range(0, spp, step):
        work.trace(px, py, first, min(step, spp - first), sums, rows)
        out.append(np.stack([sums[1], sums[2], sums[3].astype(np.float64)]))
    return np.array(out), work


def pixel_stats(sums):
    """(mean, per-sample variance) of illuminance per pixel from one (3, P) snapshot."""
    s, s2, n = sums
    mean = s / n
    variance = np.maximum(s2 - s * s / n, 0.0) / np.maximum(n - 1, 1)
    return mean, variance


def sample_radiance(scene, camera, spp, seed=0, **options):
    """Radiance of every sample, (P, spp, 3), pixels in render's order: the same samples
    render(scene, spp=spp, seed=seed, camera=camera, ...) averages. Non-finite samples are 0.
    One pass of one sample per sample index: a pixel's sums of that pass are the sample's
    radiance (zero, with count 0, if it was non-finite)."""
    work = tile_work(scene, camera, spp, seed, **options)
    px, py = pixel_grid(camera)
    rows = np.arange(px.size)
    out = np.zeros((px.size, spp, 3))
    for sample in range(spp):
        sums = new_sums(px.size)
        work.trace(px, py, sample, 1, sums, rows)
        out[:, sample] = sums[0]
    return out


# -- 1. hemisphere sampling against light sampling as the light shrinks ------------------------
def relative_variance(scene, camera, spp, seed=0, **options):
    """{relvar, mean}: the per-sample variance of illuminance averaged over the pixels, over
    the squared image mean (the spp a pixel needs for 1% noise is 10,000 times relvar), and the
    image mean, of a max_depth=1 render."""
    sums, _ = batch_sums(scene, camera, spp, spp, seed, max_depth=1, **options)
    mean, variance = pixel_stats(sums[-1])
    return dict(relvar=float(variance.mean() / mean.mean() ** 2), mean=float(mean.mean()))


def hemisphere_sweep(sides, size, spp, seed=0, options=COURSE):
    """[{side, area, light: relative_variance, hemisphere: relative_variance (-H), reference:
    the quadrature's image mean}] for each light side."""
    camera = floor_camera(*size)
    out = []
    for side in sides:
        scene = area_light_scene(side)
        out.append(dict(side=side, area=side ** 2,
                        light=relative_variance(scene, camera, spp, seed, **options),
                        hemisphere=relative_variance(scene, camera, spp, seed, hemisphere=True,
                                                     **options),
                        reference=float(direct_reference(camera, side).mean())))
    return out


def point_light_hemisphere(size=(16, 12), spp=4, options=COURSE):
    """-H on the floor under a point light: {warnings: its RuntimeWarning messages,
    hemisphere_max: the -H image's largest value, light_mean: light sampling's image mean}."""
    kwargs = dict(camera=floor_camera(*size), resolution=size, spp=spp, max_depth=3, **options)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        image = ptrace.render(point_light_scene(), hemisphere=True, **kwargs)
        lit = ptrace.render(point_light_scene(), **kwargs)
    messages = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    return dict(warnings=messages, hemisphere_max=float(image.max()), light_mean=float(lit.mean()))


def shadow_bug(halves=(0.75, 0.99, 1.01, 2.0), size=(16, 12), options=COURSE):
    """[{half, mean}]: the image mean of the light-sampled floor of half-width `half` under the
    0.5-wide light with its emissive quad: black once the floor reached further than 1 (the
    light's height) from the origin before the fix (its spawn offset outran the shadow ray's
    shortening); the same at every width since."""
    camera = floor_camera(*size)
    return [dict(half=h, mean=float(ptrace.render(area_light_scene(0.5, floor_half=h),
                                                  camera=camera, resolution=size, spp=4,
                                                  max_depth=1, **options).mean()))
            for h in halves]


def measure_hemisphere(quick):
    sides = [0.5, 0.25, 0.1, 0.05] if quick else [0.5, 0.25, 0.125, 0.1, 0.05, 0.025]
    size, spp = ((32, 24), 128) if quick else ((64, 48), 256)
    return plain(dict(quick=quick, width=size[0], height=size[1], spp=spp, options=COURSE,
                      floor_albedo=FLOOR_ALBEDO, light_height=LIGHT_HEIGHT,
                      quadrature=QUADRATURE, sweep=hemisphere_sweep(sides, size, spp),
                      point_light=point_light_hemisphere(), shadow_bug=shadow_bug()))


def write_hemisphere(data, chart_dir):
    text = blocks(TEMPLATE)
    sweep = data["sweep"]
    rows = [dict(r, ratio=r["hemisphere"]["relvar"] / r["light"]["relvar"],
                 light_spp=10000 * r["light"]["relvar"],
                 hemisphere_spp=10000 * r["hemisphere"]["relvar"]) for r in sweep]
    big, small = rows[0], rows[-1]
    light = [r["light"]["relvar"] for r in sweep]
    warned = data["point_light"]["warnings"]
    return fill(
        text["hemisphere"], data, pinned_ids(PINS), estimator=settings_text(data["options"]),
        rows=join(text["hemisphere_row"], rows), chart=chart_hemisphere(chart_dir, sweep),
        area_ratio=big["area"] / small["area"],
        hemisphere_growth=small["hemisphere"]["relvar"] / big["hemisphere"]["relvar"],
        small=small, light_min=min(light), light_max=max(light),
        warning=warned[0] if warned else "NO WARNING",
        shadow=join(text["shadow_item"], data["shadow_bug"], ", "),
        reproduce=reproduce_line(data["quick"]))


def chart_hemisphere(chart_dir, sweep):
    plt = pyplot()
    figure, axis = plt.subplots(figsize=(6, 4))
    areas = [r["area"] for r in sweep]
    axis.loglog(areas, [r["hemisphere"]["relvar"] for r in sweep], "o-",
                label="hemisphere sampling (-H)")
    axis.loglog(areas, [r["light"]["relvar"] for r in sweep], "s-", label="light sampling")
    a0, v0 = areas[0], sweep[0]["hemisphere"]["relvar"]
    axis.loglog(areas, [v0 * a0 / a for a in areas], ":", color="grey", label="1 / area")
    label_log_axis(axis, "light area (constant emitted power)", "per-sample variance / mean^2",
                   "Direct light on a floor: variance against light size")
    return save_chart(plt, figure, chart_dir, "stability_light_hemisphere.png")


# -- 2. adaptive sampling stopping too early ---------------------------------------------------
def course_converged(sum_l, sum_l2, count, tolerance, batch):
    """The course's rule: stop as soon as 1.96 sigma / sqrt(n) <= tolerance * mu, sigma = 0
    included (so a pixel whose first batch was all black stops at once)."""
    n = count.astype(np.float64)
    mean = sum_l / n
    variance = np.maximum(sum_l2 - sum_l * sum_l / n, 0.0) / np.maximum(n - 1, 1)
    return 1.96 * np.sqrt(variance) / np.sqrt(n) <= tolerance * mean


RULES = {"ptrace": lambda *a: tiles.converged(*a), "course": course_converged}


def simulate_adaptive(snapshots, step, batch, tolerance, rule):
    """Replay render()'s pass schedule (passes of `batch` samples, the test after every pass
    but the last) on cumulative sums taken every `step` samples; return (mean illuminance,
    samples taken) per pixel, as an adaptive render with the same seed would stop."""
    assert batch % step == 0
    every = batch // step
    passes = snapshots.shape[0] // every
    n_pixels = snapshots.shape[2]
    stopped_at = np.full(n_pixels, snapshots.shape[0] - 1)
    active = np.arange(n_pixels)
    for p in range(passes - 1):
        s = snapshots[(p + 1) * every - 1]
        stop = rule(s[0, active], s[1, active], s[2, active].astype(np.int64), tolerance, batch)
        stopped_at[active[stop]] = (p + 1) * every - 1
        active = active[~stop]
    final = snapshots[stopped_at, :, np.arange(n_pixels)]
    return final[:, 0] / final[:, 2], final[:, 2].astype(np.int64)


def false_convergence(mean, samples, spp, reference, tolerance):
    """false: the fraction of the pixels that were stopped before spp with a mean off the
    reference by more than 2 x tolerance x reference (twice what the rule's 95% interval
    allowed); false_of_early: the same over the pixels stopped early only; early: fraction
    stopped early; black: fraction stopped early with a mean of exactly 0."""
    early = samples < spp
    wrong = early & (np.abs(mean - reference) > 2 * tolerance * reference)
    return dict(early=float(early.mean()), false=float(wrong.mean()),
                false_of_early=float(wrong.sum() / max(early.sum(), 1)),
                black=float((early & (mean == 0)).mean()), samples=float(samples.mean()))




def adaptive_case(name, size, spp, seed=0):
    """(snapshots every 8 samples, reference per pixel, options) of one study scene."""
    camera = floor_camera(*size)
    # the course's estimator and random numbers: the study is of the course's adaptive rule
    if name == "reflector":
        options = dict(max_depth=2, **COURSE)
        scene, reference = reflector_scene(), reflector_reference(camera)
    else:   # "hemisphere" (-H) or "direct" (light sampling) under the 0.5-wide light
        options = dict(max_depth=1, hemisphere=name == "hemisphere", **COURSE)
        scene, reference = area_light_scene(0.5), direct_reference(camera, 0.5)
    snapshots, _ = batch_sums(scene, camera, spp, 8, seed, **options)
    return snapshots, reference, options


def adaptive_table(snapshots, reference, spp, batches, tolerance):
    """[{batch, course: false_convergence, ptrace: false_convergence}] for each batch size."""
    out = []
    for batch in batches:
        row = dict(batch=batch)
        for rule_name, rule in RULES.items():
            mean, samples = simulate_adaptive(snapshots, 8, batch, tolerance, rule)
            row[rule_name] = false_convergence(mean, samples, spp, reference, tolerance)
        out.append(row)
    return out


def by_batch(table):
    """{batch: row} of an adaptive_table."""
    return {row["batch"]: row for row in table}


CASE_TEXT = {
    "reflector": ("floor lit only by one bounce off a small reflector (light sampling, "
                  "`max_depth=2`)"),
    "hemisphere": "floor under a 0.5-wide light, hemisphere sampling (-H, `max_depth=1`)",
    "direct": "the same floor and light, light sampling (the control: no sample is 0)",
}
DIM_CASES = ("reflector", "hemisphere")


def measure_adaptive(quick):
    size, spp = ((48, 36), 256) if quick else ((64, 48), 512)
    batches, tolerance = (8, 16, 32, 64), 0.05
    cases = {}
    for case in CASE_TEXT:
        snapshots, reference, options = adaptive_case(case, size, spp)
        # the chance that one sample is 0: the first 8 are all 0 (sum of squares 0) with z^8
        cases[case] = dict(options=options, zero_chance=float(np.mean(snapshots[0][1] == 0)
                                                              ** (1 / 8)),
                           table=adaptive_table(snapshots, reference, spp, batches, tolerance))
    return plain(dict(quick=quick, width=size[0], height=size[1], spp=spp, batches=batches,
                      tolerance=tolerance, options=COURSE, cases=cases))


def write_adaptive(data, chart_dir):
    text = blocks(TEMPLATE)
    cases = data["cases"]
    rows = [dict(row, case=case, c=row["course"], p=row["ptrace"])
            for case, c in cases.items() for row in c["table"]]
    return fill(
        text["adaptive"], data, pinned_ids(PINS), estimator=settings_text(data["options"]),
        cases_text=join(text["case_item"], [dict(case=k, text=v) for k, v in CASE_TEXT.items()],
                        "; "),
        zero_chance=join(text["zero_item"], [dict(case=k, chance=c["zero_chance"])
                                              for k, c in cases.items()], ", "),
        zero={case: c["zero_chance"] for case, c in cases.items()},
        rows=join(text["adaptive_row"], rows), chart=chart_adaptive(chart_dir, data),
        # {table[reflector][16][course][false]}: a rule's figures on a scene at a batch size
        table={case: by_batch(c["table"]) for case, c in cases.items()},
        worst_direct=max(row[rule]["false"] for row in cases["direct"]["table"]
                         for rule in RULES),
        reproduce=reproduce_line(data["quick"]))


def chart_adaptive(chart_dir, data):
    plt = pyplot()
    batches = data["batches"]
    figure, axis = plt.subplots(figsize=(6, 4))
    for (case, c), colour in zip(data["cases"].items(), ("C0", "C1", "C2")):
        table = by_batch(c["table"])
        for rule, style, marker in (("course", "--", "o"), ("ptrace", "-", "s")):
            axis.plot(batches, [100 * table[b][rule]["false"] for b in batches], color=colour,
                      marker=marker, linestyle=style, label=f"{case}, {rule} rule")
    axis.set_xscale("log", base=2)
    axis.set_xticks(batches, [str(b) for b in batches])
    axis.set_xlabel("batch (samples per pass)")
    axis.set_ylabel("% of pixels falsely converged")
    axis.set_title(f"Adaptive sampling: false convergence (tol {data['tolerance']:g})")
    axis.legend(fontsize=8)
    axis.grid(True, alpha=0.3)
    return save_chart(plt, figure, chart_dir, "stability_light_adaptive.png")


# -- 3. Russian roulette and depth; fireflies --------------------------------------------------
CAPS = (codes.RR_CAP, 0.8, 0.5, 0.25)   # the continuation caps compared at m=100


def roulette_options(rule):
    """render() options of a roulette rule. None: ptrace as is (the default cap,
    ptrace.codes.RR_CAP); "off": no Russian roulette at all (`roulette=False`: paths run to
    max_depth); a float: continue with min(cap, max throughput) (`rr_cap=cap`). The cap is a
    setting (ptrace.rendering.settings.Settings.rr_cap), passed to the compiled path loop with the
    other options, so every rule runs the same kernel."""
    if rule is None:
        return {}
    if isinstance(rule, str):
        if rule != "off":
            raise ValueError(f"unknown roulette rule {rule!r}: None, 'off' or a cap")
        return dict(roulette=False)
    return dict(rr_cap=float(rule))


def unlit_by_camera(scene, camera, spp, seed=0, **options):
    """Pixels none of whose camera rays sees an emitter directly (a max_depth=0 render is 0)."""
    sums, _ = batch_sums(scene, camera, spp, spp, seed, max_depth=0, **options)
    return sums[-1][0] == 0


def depth_run(scene, camera, spp, max_depth, rule=None, seed=0, mask=None, **options):
    """Image mean illuminance, its standard error and relvar per sample over the pixels in mask
    (default all), rays per sample and seconds of one render (one light sample; `options` are
    Settings', e.g. RR) under a roulette rule (see roulette_options)."""
    start = time.perf_counter()
    sums, work = batch_sums(scene, camera, spp, spp, seed, max_depth=max_depth,
                            **roulette_options(rule), **options)
    seconds = time.perf_counter() - start
    mean, variance = pixel_stats(sums[-1])
    rays = work.rays_traced / (mean.size * spp)
    if mask is not None:
        mean, variance = mean[mask], variance[mask]
    n_pixels = mean.size
    image_mean = float(mean.mean())
    stderr = float(math.sqrt(variance.sum() / spp) / n_pixels)
    return dict(mean=image_mean, stderr=stderr, relvar=float(variance.mean() / image_mean ** 2),
                rays=rays, seconds=seconds)


def roulette_study(quick, options=RR):
    """[depth_run + {name, rule: "off" (no roulette), "ptrace" (as is) or the cap given,
    max_depth}] in the report's order, the size, spp and the fraction of pixels kept."""
    scene = ptrace.load(Path(__file__).resolve().parents[1] / "scenes" / "cornell.dae")
    size, spp = ((32, 24), 128) if quick else ((64, 48), 256)
    camera = small_course_camera(scene, *size)
    mask = unlit_by_camera(scene, camera, spp, **options)
    rules = [(f"no RR, m={depth}", "off", depth)
             for depth in ((1, 2, 4, 8, 16) if quick else (1, 2, 4, 8, 16, 32))]
    rules += [(f"RR (ptrace, cap {codes.RR_CAP:g}), m={depth}", "ptrace", depth)
              for depth in (100, 5)]
    # the first cap is ptrace's default, given explicitly as rr_cap
    rules += [(f"RR cap {cap:g}, m=100", cap, 100) for cap in CAPS]
    runs = [dict(name=name, rule=rule, max_depth=depth,
                 **depth_run(scene, camera, spp, depth, None if rule == "ptrace" else rule,
                             mask=mask, **options))
            for name, rule, depth in rules]
    return runs, size, spp, float(mask.mean())


def measure_roulette(quick):
    runs, size, spp, kept = roulette_study(quick)
    return plain(dict(quick=quick, width=size[0], height=size[1], spp=spp, kept=kept,
                      options=RR, default_cap=codes.RR_CAP, runs=runs))


def efficiency(run):
    """1 / (relvar x rays per sample): higher is better."""
    return 1 / (run["relvar"] * run["rays"])


def write_roulette(data, chart_dir):
    text = blocks(TEMPLATE)
    runs = data["runs"]
    fixed = {r["max_depth"]: r for r in runs if r["rule"] == "off"}
    ours = {r["max_depth"]: r for r in runs if r["rule"] == "ptrace"}
    caps = [r for r in runs if not isinstance(r["rule"], str)]
    ref, rr = fixed[max(fixed)], ours[100]

    def sigmas(r):
        return (r["mean"] - ref["mean"]) / math.hypot(r["stderr"], ref["stderr"])

    def bias(r):
        return (r["mean"] - ref["mean"]) / ref["mean"]

    rows = [dict(r, bias=bias(r), sigmas=0.0 if r is ref else sigmas(r),
                 efficiency=efficiency(r)) for r in runs]
    # the default cap given explicitly: the same run as the default's, to the bit?
    given = next((r for r in caps if r["rule"] == data["default_cap"]), None)
    cap_given = ""
    if given is not None:
        same_bits = all(given[k] == rr[k] for k in ("mean", "stderr", "relvar", "rays"))
        cap_given = fill(text["cap_given_same" if same_bits else "cap_given_differs"], data,
                         given=given, rr=rr)
    same = [r for r in caps if r["mean"] == rr["mean"] and r["relvar"] == rr["relvar"]]
    cap_verdict = (fill(text["caps_same"], data, caps=join(text["cap_label"], [
        dict(cap=r["rule"]) for r in same], " and ")) if len(same) > 1 else text["caps_differ"])
    return fill(
        text["roulette"], data, pinned_ids(PINS), estimator=settings_text(data["options"]),
        rows=join(text["roulette_row"], rows), chart=chart_roulette(chart_dir, runs, ref),
        deepest=ref["name"], ref=ref, rr=rr, bias={d: bias(r) for d, r in fixed.items()},
        rr5_bias=bias(ours[5]),
        rr_sigmas=sigmas(rr), ref_efficiency=efficiency(ref), rr_efficiency=efficiency(rr),
        cap_given=cap_given, cap_verdict=cap_verdict,
        cap_items=join(text["cap_item"], [dict(r, cap=r["rule"], efficiency=efficiency(r))
                                          for r in caps], ", "),
        reproduce=reproduce_line(data["quick"]))


def chart_roulette(chart_dir, runs, ref):
    plt = pyplot()
    figure, (left, right) = plt.subplots(1, 2, figsize=(9, 3.6))
    fixed = {r["max_depth"]: r for r in runs if r["rule"] == "off"}
    depths = sorted(fixed)
    left.errorbar(depths, [fixed[d]["mean"] for d in depths],
                  yerr=[2 * fixed[d]["stderr"] for d in depths], fmt="o-", label="no RR, fixed m")
    rr = [r for r in runs if r["rule"] != "off" and r["max_depth"] == 100]
    depth_axis(left, rr, "mean", "image mean illuminance (+-2 s.e.)")
    right.plot(depths, [fixed[d]["rays"] for d in depths], "o-", label="no RR: rays / sample")
    depth_axis(right, rr, "rays", "rays per sample")
    figure.suptitle("Cornell box: fixed depth against Russian roulette")
    return save_chart(plt, figure, chart_dir, "stability_light_roulette.png")


def depth_axis(axis, rr, key, ylabel):
    """One panel of the roulette chart, over the fixed-depth series already drawn on it: each
    roulette run's `key` as a dashed line, log2 depths, labels, legend and grid."""
    for r, colour in zip(rr, [f"C{i}" for i in range(1, 9)]):
        axis.axhline(r[key], color=colour, linestyle="--", label=r["name"])
    axis.set_xscale("log", base=2)
    axis.set_xlabel("max depth (vertices)")
    axis.set_ylabel(ylabel)
    axis.legend(fontsize=7)
    axis.grid(True, alpha=0.3)


CLAMPS = (3, 10, 30, 100, 300, 1000)   # clamp thresholds, in multiples of the image mean
OUTLIERS = (10, 30, 100)               # outlier thresholds, in multiples of the image mean
FIREFLY_SCENES = ("CBspheres.dae", "CBspheres_lambertian.dae")   # the course's, in sky/


def diffuse_sample_radiance(scene, camera, spp, seed=0, **options):
    """Per-sample radiance (P, spp, 3) of the paths that touched a diffuse surface: the render
    minus the same render with every diffuse albedo 0, which keeps, sample for sample (the
    same random numbers), only the lamp seen directly or through mirrors and glass."""
    full = sample_radiance(scene, camera, spp, seed, **options)
    m = scene.materials
    dark = dataclasses.replace(m, albedo=np.where((m.kind == DIFFUSE)[:, None], 0.0, m.albedo))
    specular = sample_radiance(dataclasses.replace(scene, materials=dark), camera, spp, seed,
                               **options)
    return np.maximum(full - specular, 0.0)


def firefly_stats(samples, clamps=CLAMPS, outliers=OUTLIERS):
    """Luminance outliers of per-sample radiance (P, spp, 3): {mean, spp, max, outliers: [{k,
    above: the fraction of samples above k x the image mean, energy: their share of its
    energy}], clamps: [{k, what clamping each sample's luminance at k x the image mean would
    do: lost: energy lost (the bias of the image mean), variance: the per-pixel variance kept,
    worse_after: an spp beyond which the clamped image is surely worse (None: never)}]}."""
    lum = samples @ LUMINANCE
    mean = float(lum.mean())
    spp = lum.shape[1]
    var = float(lum.var(axis=1, ddof=1).mean())
    out = dict(mean=mean, spp=spp, max=float(lum.max()), outliers=[], clamps=[])
    for k in outliers:
        out["outliers"].append(dict(k=k, above=float((lum > k * mean).mean()),
                                    energy=float(lum[lum > k * mean].sum() / lum.sum())))
    for k in clamps:
        clamped = np.minimum(lum, k * mean)
        bias = float((lum - clamped).mean())
        var_c = float(clamped.var(axis=1, ddof=1).mean())
        # per pixel, error^2 = bias_p^2 + variance / spp, and mean(bias_p^2) >= bias^2: the
        # clamped image is worse than the unclamped one for every spp above this
        worse_after = (var - var_c) / bias ** 2 if bias > 0 else None
        out["clamps"].append(dict(k=k, lost=bias / mean, variance=var_c / var,
                                  worse_after=worse_after))
    return out


def by_k(rows):
    """{k: row} of firefly_stats' outliers or clamps."""
    return {row["k"]: row for row in rows}


def measure_fireflies(quick, options=FIREFLY):
    size, spp = ((48, 36), 64) if quick else ((64, 48), 256)
    scenes = {}
    for name in FIREFLY_SCENES:
        scene = ptrace.load(scenes_dir() / "sky" / name)
        samples = diffuse_sample_radiance(scene, small_course_camera(scene, *size), spp,
                                          **options)
        scenes[name] = firefly_stats(samples)
    return plain(dict(quick=quick, width=size[0], height=size[1], spp=spp, options=options,
                      scenes=scenes))


def write_fireflies(data, chart_dir):
    text = blocks(TEMPLATE)
    # {glass[above][100]}: the fraction of CBspheres' samples above 100x its mean
    stats = {name: dict(s, ratio=s["max"] / s["mean"],
                        above={k: r["above"] for k, r in by_k(s["outliers"]).items()},
                        energy={k: r["energy"] for k, r in by_k(s["outliers"]).items()},
                        clamp=by_k(s["clamps"]))
             for name, s in data["scenes"].items()}
    glass, diffuse = (stats[name] for name in FIREFLY_SCENES)
    clamp_rows = []
    for k in glass["clamp"]:
        cells = {}
        for key, s in (("glass", glass), ("diffuse", diffuse)):
            c = s["clamp"][k]
            cells[key] = dict(c, worse="never" if c["worse_after"] is None
                              else format(c["worse_after"], ",.0f"))
        clamp_rows.append(dict(k=k, **cells))
    return fill(
        text["fireflies"], data, pinned_ids(PINS), estimator=settings_text(data["options"]),
        scene_rows=join(text["firefly_row"], [dict(s, name=name) for name, s in stats.items()]),
        clamp_rows=join(text["clamp_row"], clamp_rows), glass=glass, diffuse=diffuse,
        chart=chart_fireflies(chart_dir, data["scenes"][FIREFLY_SCENES[0]]),
        reproduce=reproduce_line(data["quick"]))


def chart_fireflies(chart_dir, stats):
    plt = pyplot()
    figure, axis = plt.subplots(figsize=(6, 4))
    ks = [c["k"] for c in stats["clamps"]]
    axis.semilogx(ks, [100 * c["lost"] for c in stats["clamps"]], "o-",
                  label="energy lost (bias), %")
    axis.semilogx(ks, [100 * c["variance"] for c in stats["clamps"]], "s-",
                  label="variance kept, %")
    label_log_axis(axis, "clamp threshold (x image mean)", "%",
                   "CBspheres: what a per-sample clamp would cost")
    return save_chart(plt, figure, chart_dir, "stability_light_fireflies.png")


# -- the report --------------------------------------------------------------------------------
# (data key, measure(quick) -> plain data, write(data, chart dir) -> a Markdown section)
SECTIONS = [("hemisphere", measure_hemisphere, write_hemisphere),
            ("adaptive", measure_adaptive, write_adaptive),
            ("roulette", measure_roulette, write_roulette),
            ("fireflies", measure_fireflies, write_fireflies)]


def measure(quick):
    """{section name: its data} for every section of SECTIONS."""
    data = {}
    for name, measure_section, _ in SECTIONS:
        start = time.perf_counter()
        data[name] = measure_section(quick)
        print(f"{name}: {time.perf_counter() - start:.0f} s", flush=True)
    return data


def write_sections(data, chart_dir):
    """The light-transport sections of data (what measure returns) as Markdown strings (each
    starts with '## '); charts are saved into chart_dir and named relative to it."""
    chart_dir = Path(chart_dir)
    chart_dir.mkdir(parents=True, exist_ok=True)
    return [write(data[name], chart_dir) for name, _, write in SECTIONS]


def report_text(data, chart_dir):
    """The stand-alone report of data ({"run": ..., section name: data})."""
    text = blocks(TEMPLATE)
    run = data["run"]
    notes = text["intro_quick"] + " " if run["quick"] else ""
    return templating.study_text(text, run, REPRODUCE, notes, write_sections(data, chart_dir))


def write_report(data, output="stability_light.md"):
    """Write data's stand-alone report to output, its charts and JSON beside it (write_study)."""
    return templating.write_study(data, output, report_text)


def main(argv=None):
    args = templating.study_arguments(argv, __doc__.splitlines()[0],
                                      "smaller images, fewer samples", "stability_light.md")
    start = time.perf_counter()
    data = {"run": dict(quick=args.quick, threads=numba.get_num_threads())}
    data.update(measure(args.quick))
    data["run"]["seconds"] = time.perf_counter() - start
    path = write_report(plain(data), args.output)
    print(f"wrote {path} and {path.with_suffix('.json').name} beside it")
    return 0


if __name__ == "__main__":
    main()
