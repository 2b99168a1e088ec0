"""Russian roulette follows its rule exactly, path by path, through the compiled stages.

In the furnace (tests/ptrace/scenes_by_hand.furnace: a diffuse sphere of albedo a seen from
inside, a point light at its centre) every BSDF sample multiplies the throughput by exactly a,
and every vertex receives the same direct light a P / pi times its throughput. A path that
reaches V vertices traces V (light samples + 1) rays, so the kernel's own counts tell each path's
length, and its radiance must be (a P / pi) * sum of the rule's throughputs T_1 .. T_V:
T_1 = 1, T_{k+1} = T_k a / q_k with q_k = min(rr_cap, T_k a) from vertex rr_depth on (else 1).
So the weights are checked exactly, and the survival rate at each vertex against q_k with a
binomial bound. A deep furnace checks the whole estimator against its closed form.
"""
import math

import numpy as np
import pytest

import accel
import ptrace
from accel.compiled import new_scratch
from ptrace.kernel import layout
from ptrace.rendering.settings import Settings
from ptrace.rendering.tiles import RenderJob

from scenes_by_hand import furnace

ALBEDO, POWER = 0.9, 2.0


def run_paths(n, **options):
    """n paths of pixel 0 (samples 0 .. n - 1) from the sphere's centre, straight up, through
    the wavefront's stages: each path's radiance and the rays it traced."""
    scene, camera = furnace(ALBEDO, POWER)
    settings = Settings.from_options(accel="naive", max_depth=40, **options)
    job = RenderJob(scene, accel.build("naive", scene.geometry), settings, camera)
    wavefront = job.wavefront
    radiance, rays = np.empty(n), np.empty(n, dtype=np.int64)
    wave, scratch = wavefront.new_wave(), new_scratch(job.accel)
    for start in range(0, n, wave.size):
        size = min(wave.size, n - start)
        slots = np.arange(size)
        floats, ints = wave.floats, wave.ints
        floats[:, :size] = 0.0
        floats[[layout.DY, layout.TMAX, layout.TR, layout.TG, layout.TB], :size] = (
            [[1.0], [math.inf], [1.0], [1.0], [1.0]])
        ints[:, :size] = 0
        ints[layout.SAMPLE, :size] = start + slots
        ints[layout.RAYS, :size] = 1
        wave.queue[:size] = slots
        wavefront.paths(wave, scratch, size)
        radiance[start:start + size] = floats[layout.R, :size]
        rays[start:start + size] = ints[layout.RAYS, :size]
    return radiance, rays, settings


def rule(settings, vertices):
    """The throughputs T_1 .. T_vertices and the continuation probabilities q_1 .. q_vertices the
    rule gives (q = 1 where roulette does not act)."""
    throughput, ts, qs = 1.0, [], []
    for vertex in range(1, vertices + 1):
        ts.append(throughput)
        throughput *= ALBEDO
        q = 1.0
        if settings.roulette and vertex >= settings.rr_depth:
            q = min(settings.rr_cap, throughput)
            throughput /= q
        qs.append(q)
    return np.array(ts), np.array(qs)


@pytest.mark.parametrize("options", [dict(), dict(rr_cap=0.7, rr_depth=2)],
                         ids=["default", "cap 0.7 from vertex 2"])
def test_each_paths_weight_is_the_rules(options):
    radiance, rays, settings = run_paths(4000, **options)
    light_samples = settings.light_samples   # a point light takes one shadow ray per sample
    lengths = rays // (light_samples + 1)
    assert (lengths * (light_samples + 1) == rays).all()
    assert lengths.min() >= min(settings.rr_depth, settings.max_depth)
    assert lengths.max() > settings.rr_depth + 2          # roulette let some paths go on
    ts, _ = rule(settings, settings.max_depth)
    expected = ALBEDO * POWER / math.pi * np.cumsum(ts)[lengths - 1]
    np.testing.assert_allclose(radiance, expected, rtol=1e-9)


@pytest.mark.parametrize("options", [dict(), dict(rr_cap=0.7, rr_depth=2)],
                         ids=["default", "cap 0.7 from vertex 2"])
def test_survival_at_each_vertex_is_q(options):
    """Of the paths that reach vertex k (k >= rr_depth), the fraction that reaches k + 1 is
    q_k = min(cap, throughput): a two-sided binomial bound of 5 standard deviations."""
    n = 20000
    _, rays, settings = run_paths(n, **options)
    lengths = rays // (settings.light_samples + 1)
    _, qs = rule(settings, settings.max_depth)
    checked = 0
    for k in range(settings.rr_depth, settings.max_depth):
        reached = int((lengths >= k).sum())
        if reached < 500:
            break
        survived = int((lengths >= k + 1).sum())
        q = qs[k - 1]
        sd = math.sqrt(reached * q * (1 - q))
        assert abs(survived - reached * q) < 5 * sd + 1, (k, survived / reached, q)
        checked += 1
    assert checked >= 5


def test_roulette_off_and_on_agree_with_the_rule_before_rr_depth():
    """Before rr_depth no path ends (every path reaches rr_depth vertices), with or without
    roulette; without it every path reaches max_depth."""
    _, rays_off, settings = run_paths(200, roulette=False)
    assert (rays_off == settings.max_depth * (settings.light_samples + 1)).all()
    _, rays_on, settings = run_paths(2000)
    assert (rays_on // (settings.light_samples + 1) >= settings.rr_depth).all()


def test_deep_furnace_is_exact_within_its_standard_error():
    """Albedo 0.9, depth 100: the image mean is a P / pi (1 - a^100) / (1 - a) within 4
    standard errors, the standard error measured from the spread of the pixels (each pixel
    averages its own independent paths)."""
    scene, camera = furnace(ALBEDO, POWER)
    image = ptrace.render(scene, camera=camera, resolution=(16, 16), spp=64, max_depth=100)
    pixels = image[..., 0].ravel()
    expected = ALBEDO * POWER / math.pi * (1 - ALBEDO ** 100) / (1 - ALBEDO)
    stderr = pixels.std(ddof=1) / math.sqrt(pixels.size)
    print(f"deep furnace: mean {pixels.mean():.5f} expected {expected:.5f} stderr {stderr:.5f}")
    assert stderr > 0
    assert abs(pixels.mean() - expected) < 4 * stderr
