"""The pass schedule and adaptive sampling's stopping rule (ptrace.rendering.tiles), on hand-made
sums."""
import math

import numpy as np

from ptrace.rendering.settings import Settings
from ptrace.rendering.tiles import Passes, converged


def sums_for(n_pixels):
    return (np.zeros((n_pixels, 3)), np.zeros(n_pixels), np.zeros(n_pixels),
            np.zeros(n_pixels, dtype=np.int64))


def add(sums, pixels, values):
    _, sum_l, sum_l2, count = sums
    for p in pixels:
        for v in values[p]:
            sum_l[p] += v
            sum_l2[p] += v * v
            count[p] += 1


def test_passes_are_whole_batches_and_the_last_takes_the_rest():
    """-s 10 -a 4: passes of 4, 4 and 2 samples while no pixel converges."""
    sums = sums_for(3)
    passes = Passes(Settings(spp=10, adaptive=(4, 1e-9)), sums)
    schedule = []
    rng = np.random.default_rng(0)
    for first, n, active in passes:
        schedule.append((first, n, list(active)))
        add(sums, active, {p: rng.random(n) + 1 for p in active})
    assert schedule == [(0, 4, [0, 1, 2]), (4, 4, [0, 1, 2]), (8, 2, [0, 1, 2])]
    assert list(sums[3]) == [10, 10, 10]


def test_without_adaptive_passes_are_fixed_and_cover_spp():
    passes = Passes(Settings(spp=5), sums_for(2))
    schedule = [(first, n) for first, n, _ in passes]
    assert sum(n for _, n in schedule) == 5
    assert [first for first, _ in schedule] == [0] + list(np.cumsum([n for _, n in schedule]))[:-1]


def test_converged_is_the_courses_rule():
    """1.96 sigma / sqrt(n) <= tolerance * mean, sigma the sample standard deviation."""
    values = np.array([0.5, 1.5, 1.0, 1.2, 0.8, 1.0])
    n = values.size
    mean, sigma = values.mean(), values.std(ddof=1)
    tolerance = 1.96 * sigma / math.sqrt(n) / mean
    sum_l, sum_l2 = np.array([values.sum()]), np.array([(values ** 2).sum()])
    count = np.array([n])
    assert converged(sum_l, sum_l2, count, tolerance * 1.001, 2)[0]
    assert not converged(sum_l, sum_l2, count, tolerance * 0.999, 2)[0]


def test_a_pixel_of_equal_samples_waits_for_two_batches():
    """sigma = 0 (all black, or all the same) stops a pixel only from two batches on."""
    sums = sums_for(2)
    passes = Passes(Settings(spp=64, adaptive=(4, 0.05)), sums)
    seen = []
    for first, n, active in passes:
        seen.append((first, list(active)))
        # pixel 0: always 0.5 (sigma 0); pixel 1: alternating 0 and 1, far from converged
        add(sums, active, {0: [0.5] * n, 1: [float((first + i) % 2) for i in range(n)]})
    assert seen[0] == (0, [0, 1]) and seen[1] == (4, [0, 1])   # not stopped after one batch
    assert seen[2] == (8, [1])                                  # stopped after two
    assert sums[3][0] == 8 and sums[3][1] == 64
