"""The light BVH (ptrace.light_tree): tree_pmf against tree_sample's frequencies (chi-square, and
exactly with evenly spaced u, since each entry owns one interval of u), tree_sample's pmf against
tree_pmf bit for bit, an independent whole-tree distribution (the entries' probabilities and the
dead ends' share sum to 1), bounds that hold every entry, no entry that can light a point left
at probability 0 (brute force over points on real lights), importance sanity, a single entry,
bad input, determinism and build time.

Entries are made from real light shapes: one-sided rectangles, two-sided triangles, spheres,
spot lights and point lights, each with a way to tell whether it can light a point p with
normal n (zero: from every side), by brute force over points on it.
"""
import math
import time

import numpy as np
import pytest
from numba import njit
from scipy import stats

from ptrace.light_tree import tree_pmf, tree_sample
from ptrace.light_tree_build import build_light_tree

RECT, TRI, SPHERE, SPOT, POINT = range(5)


def _unit(v):
    return v / np.linalg.norm(v)


def _frame(n):
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = _unit(np.cross(n, a))
    return x, np.cross(n, x)


def make_lights(rng, count, kinds=(RECT, TRI, SPHERE, SPOT, POINT), spread=4.0):
    """count lights of the given kinds in a cube of half-width spread: (entries as the tuple of
    build_light_tree's arrays, lights as (kind, points on it (Q, 3), normals there (Q, 3),
    axis, cos_theta_e) for the brute-force test)."""
    lower, upper, power, axis, cos_o, cos_e, two, lights = ([] for _ in range(8))
    for _ in range(count):
        kind = kinds[rng.integers(len(kinds))]
        c = rng.uniform(-spread, spread, 3)
        n = _unit(rng.normal(size=3))
        ce = 0.0
        if kind == RECT:
            x, y = _frame(n)
            s = np.linspace(-0.45, 0.45, 5)
            e1, e2 = rng.uniform(0.05, 0.5) * x, rng.uniform(0.05, 0.5) * y
            points = np.array([c + a * e1 + b * e2 for a in s for b in s])
            corners = np.array([c + a * e1 + b * e2 for a in (-0.5, 0.5) for b in (-0.5, 0.5)])
            normals = np.tile(n, (len(points), 1))
        elif kind == TRI:
            v = c + rng.uniform(-0.3, 0.3, (3, 3))
            n = _unit(np.cross(v[1] - v[0], v[2] - v[0]))
            w = [(a, b) for a in np.linspace(0.05, 0.9, 5) for b in np.linspace(0.05, 0.9, 5)
                 if a + b < 0.95]
            points = np.array([v[0] + a * (v[1] - v[0]) + b * (v[2] - v[0]) for a, b in w])
            corners, normals = v, np.tile(n, (len(points), 1))
        elif kind == SPHERE:
            r = rng.uniform(0.02, 0.4)
            k = np.arange(64) + 0.5
            z, phi = 1 - 2 * k / 64, math.pi * (1 + 5 ** 0.5) * k
            normals = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi),
                                z], 1)
            points, corners = c + r * normals, np.array([c - r, c + r])
        else:
            points, corners, normals = c[None], c[None], np.zeros((1, 3))
            ce = math.cos(math.radians(rng.uniform(10, 60))) if kind == SPOT else 0.0
        lower.append(corners.min(0))
        upper.append(corners.max(0))
        power.append(rng.uniform(0.1, 10.0))
        axis.append(n)
        cos_o.append(1.0 if kind in (RECT, TRI, SPOT) else -1.0)
        cos_e.append(ce)
        two.append(kind == TRI)
        lights.append((kind, points, normals, n, ce))
    entries = (np.array(lower), np.array(upper), np.array(power), np.array(axis),
               np.array(cos_o), np.array(cos_e), np.array(two))
    return entries, lights


def can_light(light, p, n):
    """Whether some point of the light gives p light (brute force over its points)."""
    kind, points, normals, axis, cos_e = light
    d = p - points                                   # from the light toward p
    ok = np.ones(len(points), dtype=bool) if not n.any() else (d @ n) < 0.0
    if kind == RECT or kind == SPHERE:
        ok &= np.einsum("ij,ij->i", d, normals) > 0.0
    elif kind == TRI:
        ok &= np.einsum("ij,ij->i", d, normals) != 0.0
    elif kind == SPOT:
        ok &= (d @ axis) > cos_e * np.linalg.norm(d, axis=1)
    return bool(ok.any())


def random_point(rng, normal=True, spread=4.5):
    p = rng.uniform(-spread, spread, 3)
    return p, (_unit(rng.normal(size=3)) if normal else np.zeros(3))


# -- compiled helpers (not cached: they would keep an older light_tree's inlined code) ----------

@njit(_nrt=False)
def _counts(tree, p, n, us, counts):
    """tree_sample for each u: counts[entry + 1] += 1 (counts[0]: no entry); returns how many
    samples' pmf differed from tree_pmf of their entry (compared bit for bit)."""
    bad = 0
    for i in range(us.shape[0]):
        entry, pmf = tree_sample(tree, p[0], p[1], p[2], n[0], n[1], n[2], us[i])
        counts[entry + 1] += 1
        if entry >= 0 and pmf != tree_pmf(tree, p[0], p[1], p[2], n[0], n[1], n[2], entry):
            bad += 1
    return bad


@njit
def _pmfs(tree, p, n, count):
    out = np.zeros(count)
    for e in range(count):
        out[e] = tree_pmf(tree, p[0], p[1], p[2], n[0], n[1], n[2], e)
    return out


def distribution(tree, p, n, count):
    """An independent whole-tree walk: each wide node's lanes' probabilities from its own and
    the lanes' importances (ptrace.light_tree.lane_importance, one lane at a time, not the
    walk's vector loop); (per-entry probability, the share lost at wide nodes whose lanes all
    have importance 0)."""
    from ptrace.light_tree import lane_importance
    from ptrace.light_tree_build import LANES
    n = n / np.linalg.norm(n) if n.any() else n
    out, dead = np.zeros(count), 0.0
    prob = np.zeros(len(tree.kid))
    if len(tree.kid):
        prob[0] = 1.0
    for w in range(len(tree.kid)):        # wide nodes: each after the one that holds it
        if prob[w] == 0.0:
            continue
        c = np.array([lane_importance(tree.lanes, w, i, *p, *n, bool(n.any()))
                      for i in range(LANES)])
        if not c.sum() > 0.0:
            dead += prob[w]
            continue
        for i in range(LANES):
            share = prob[w] * (c[i] / c.sum())
            if tree.kid[w, i] >= 0:
                prob[tree.kid[w, i]] += share
            elif c[i] > 0.0:
                out[tree.entry[-1 - tree.kid[w, i]]] += share
    return out, dead


# -- (a) pmfs, frequencies, the whole distribution --------------------------------------------

@pytest.mark.parametrize("count", [1, 2, 3, 17, 1000])
def test_pmf_is_the_sampling_frequency(count):
    rng = np.random.default_rng(count)
    entries, _ = make_lights(rng, count)
    tree = build_light_tree(*entries)
    samples = 60_000
    for trial in range(4):
        p, n = random_point(rng, normal=trial % 2 == 0)
        pmf = _pmfs(tree, p, n, count)
        reference, dead = distribution(tree, p, n, count)
        np.testing.assert_allclose(pmf, reference, rtol=1e-12, atol=1e-300)
        assert pmf.sum() + dead == pytest.approx(1.0, abs=1e-12) or pmf.sum() == dead == 0.0
        counts = np.zeros(count + 1, dtype=np.int64)
        assert _counts(tree, p, n, rng.random(samples), counts) == 0   # (b): bit for bit
        assert counts[1:][pmf == 0.0].sum() == 0                       # never a pmf-0 entry
        expected = samples * np.concatenate([[max(0.0, 1.0 - pmf.sum())], pmf])
        big = expected >= 5.0
        if big.sum() + (expected[~big].sum() > 0) < 2:
            continue        # one outcome: nothing to compare
        observed = np.append(counts[big], counts[~big].sum())
        expect = np.append(expected[big], expected[~big].sum())
        keep = expect > 0
        observed, expect = observed[keep], expect[keep] * observed[keep].sum() / expect[keep].sum()
        assert stats.chisquare(observed, expect).pvalue > 1e-4


@pytest.mark.parametrize("count", [3, 17, 1000])
def test_each_entry_owns_an_interval_of_u(count):
    # evenly spaced u: an entry of probability q gets N q of them, give or take one
    rng = np.random.default_rng(100 + count)
    entries, _ = make_lights(rng, count)
    tree = build_light_tree(*entries)
    samples = 100_000
    us = (np.arange(samples) + 0.5) / samples
    for trial in range(3):
        p, n = random_point(rng, normal=trial != 1)
        counts = np.zeros(count + 1, dtype=np.int64)
        assert _counts(tree, p, n, us, counts) == 0
        pmf = _pmfs(tree, p, n, count)
        assert np.abs(counts[1:] - samples * pmf).max() <= 1.01


def test_pmfs_sum_to_one_where_no_node_can_dead_end():
    # lights that face every way, seen from no surface, and the room's floor under ceiling
    # lights facing down: every node that can be reached has a child that gives light
    rng = np.random.default_rng(5)
    for count in (1, 2, 3, 17, 1000):
        entries, _ = make_lights(rng, count, kinds=(SPHERE, POINT))
        tree = build_light_tree(*entries)
        for _ in range(3):
            p, n = random_point(rng, normal=False)
            assert _pmfs(tree, p, n, count).sum() == pytest.approx(1.0, abs=1e-12)
    lower = np.array([[x, 2.9, z] for x in np.arange(-7.0, 8, 2) for z in np.arange(-7.0, 8, 2)])
    count = len(lower)
    tree = build_light_tree(lower, lower + [0.25, 0, 0.25], rng.uniform(1, 64, count),
                            np.tile([0.0, -1, 0], (count, 1)), np.ones(count), np.zeros(count),
                            np.zeros(count, dtype=bool))
    for _ in range(20):
        p = np.array([rng.uniform(-8, 8), 0.0, rng.uniform(-8, 8)])
        pmf = _pmfs(tree, p, np.array([0.0, 1, 0]), count)
        assert pmf.sum() == pytest.approx(1.0, abs=1e-12) and pmf.min() > 0.0


# -- bounds and unbiasedness -------------------------------------------------------------------

def test_every_node_bounds_its_entries():
    rng = np.random.default_rng(11)
    entries, _ = make_lights(rng, 500)
    lower, upper, power, axis, cos_o, _, two = entries
    tree = build_light_tree(*entries)
    below = [[] for _ in tree.child]      # the entries under each node
    for k in range(len(tree.child) - 1, -1, -1):
        below[k] = [tree.entry[k]] if tree.child[k] < 0 else below[k + 1] + below[tree.child[k]]
        assert tree.child[k] < 0 or tree.child[k] > k + 1
        e = np.array(below[k])
        assert np.all(tree.lower[k] <= lower[e]) and np.all(tree.upper[k] >= upper[e])
        assert tree.power[k] == pytest.approx(power[e].sum() / power.sum(), rel=1e-12)
        cos_d = axis[e] @ tree.axis[k]
        if tree.two_sided[k]:
            cos_d = np.abs(cos_d)
        reach = np.arccos(np.clip(cos_d, -1, 1)) + np.arccos(cos_o[e])   # widest angle reached
        # (to 1e-7 radians: arccos of a rounded 1 is 1.5e-8)
        assert np.all(np.minimum(reach, math.pi) <= np.arccos(tree.cos_o[k]) + 1e-7)
        assert np.all(tree.two_sided[k] >= two[e])
    assert sorted(below[0]) == list(range(500))
    assert np.array_equal(tree.entry[tree.entry_node], np.arange(500))


def test_no_entry_that_can_light_a_point_has_probability_zero():
    rng = np.random.default_rng(12)
    entries, lights = make_lights(rng, 300)
    tree = build_light_tree(*entries)
    lit = zero = 0
    for trial in range(60):
        p, n = random_point(rng, normal=trial % 3 != 0)
        pmf = _pmfs(tree, p, n, len(lights))
        for light, q in zip(lights, pmf):
            if can_light(light, p, n):
                lit += 1
                assert q > 0.0, (light[0], p, n)
            zero += q == 0.0
    assert lit > 3000 and zero > 1000     # both cases were seen plenty


# -- (c) importance sanity ---------------------------------------------------------------------

def _two(lower, upper, axis, cos_o, cos_e=(0.0, 0.0), two=(False, False)):
    return build_light_tree(np.array(lower, float), np.array(upper, float), np.ones(2),
                            np.array(axis, float), np.array(cos_o, float), np.array(cos_e),
                            np.array(two))


def test_near_light_is_chosen_more_often():
    tree = _two([[1, 0, 0], [6, 0, 0]], [[1.2, 0.2, 0.2], [6.2, 0.2, 0.2]], [[0, 0, 1]] * 2,
                [-1, -1])
    p, n = np.array([0.0, 0.0, 0.0]), np.zeros(3)
    near, far = _pmfs(tree, p, n, 2)
    assert near > 0.9 and far > 0.0 and near + far == pytest.approx(1.0)
    counts = np.zeros(3, dtype=np.int64)
    _counts(tree, p, n, np.random.default_rng(1).random(20_000), counts)
    assert counts[1] > 0.9 * 20_000 > counts[2] > 0


def test_lights_that_cannot_reach_a_point_get_zero():
    p = np.array([0.0, 0.0, 0.0])
    # a one-sided square facing away (+y, above p), beside one facing p (-y)
    tree = _two([[-1, 2, -1], [2, 2, -1]], [[-0.5, 2, -0.5], [2.5, 2, -0.5]],
                [[0, 1, 0], [0, -1, 0]], [1, 1])
    assert list(_pmfs(tree, p, np.zeros(3), 2)) == [0.0, 1.0]
    counts = np.zeros(3, dtype=np.int64)
    _counts(tree, p, np.zeros(3), np.random.default_rng(2).random(5000), counts)
    assert counts[1] == 0 and counts[2] == 5000
    # a light below the shading normal's hemisphere: 0 with that normal, not without one
    tree = _two([[-0.1, -2, -0.1], [0.9, 2, -0.1]], [[0.1, -1.8, 0.1], [1.1, 2.2, 0.1]],
                [[0, 0, 1]] * 2, [-1, -1])
    assert _pmfs(tree, p, np.array([0.0, 1, 0]), 2)[0] == 0.0
    assert _pmfs(tree, p, np.array([0.0, -1, 0]), 2)[1] == 0.0
    assert _pmfs(tree, p, np.zeros(3), 2).min() > 0.0
    # a spot light pointing away (outer cone 30 degrees) and one pointing at p
    tree = _two([[0, 3, 0], [0.5, 3, 0]], [[0, 3, 0], [0.5, 3, 0]], [[0, 1, 0], [0, -1, 0]],
                [1, 1], cos_e=[math.cos(math.radians(30))] * 2)
    assert list(_pmfs(tree, p, np.array([0.0, 1, 0]), 2)) == [0.0, 1.0]
    # nothing can light p: no entry
    assert tree_sample(tree, 3.0, 5.0, 0.0, 0.0, 0.0, 0.0, 0.5) == (-1, 0.0)
    assert tree_sample(tree, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0, 0.5) == (0, 1.0)   # the first can


# -- (d) one entry; entries left out; bad input -------------------------------------------------

def test_single_entry_has_pmf_one_where_it_can_give_light():
    tree = build_light_tree(np.array([[0.0, 2, 0]]), np.array([[1.0, 2, 1]]), np.array([3.0]),
                            np.array([[0.0, -1, 0]]), np.ones(1), np.zeros(1), np.zeros(1, bool))
    for u in (0.0, 0.3, 0.999999):
        assert tree_sample(tree, 0.5, 0.0, 0.5, 0.0, 1.0, 0.0, u) == (0, 1.0)
    assert tree_pmf(tree, 5.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0) == 1.0
    assert tree_pmf(tree, 0.5, 3.0, 0.5, 0.0, 0.0, 0.0, 0) == 0.0        # behind it
    assert tree_sample(tree, 0.5, 3.0, 0.5, 0.0, 0.0, 0.0, 0.5) == (-1, 0.0)
    assert tree_pmf(tree, 0.5, 0.0, 0.5, 0.0, 1.0, 0.0, 1) == 0.0        # no such entry


def test_entries_of_power_zero_are_left_out():
    rng = np.random.default_rng(3)
    entries, _ = make_lights(rng, 40)
    entries[2][::3] = 0.0
    tree = build_light_tree(*entries)
    assert np.all(tree.entry_node[::3] == -1) and len(tree.child) == 2 * 26 - 1
    p, n = random_point(rng, normal=False)
    assert np.all(_pmfs(tree, p, n, 40)[::3] == 0.0)
    entries[2][:] = 0.0
    empty = build_light_tree(*entries)
    assert len(empty.child) == 0
    assert tree_sample(empty, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5) == (-1, 0.0)
    assert tree_pmf(empty, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0) == 0.0


@pytest.mark.parametrize("change, message", [
    (lambda e: e.__setitem__(1, e[1][:-1]), "bounds_upper has shape"),
    (lambda e: e.__setitem__(2, -e[2]), "power must be >= 0"),
    (lambda e: e[0].__setitem__((0, 0), np.nan), "bounds_lower holds values that are not finite"),
    (lambda e: e.__setitem__(0, e[1] + 1.0), "bounds_lower is above"),
    (lambda e: e[3].__setitem__(0, 0.0), "axis is zero"),
])
def test_bad_entries_are_refused_in_one_line(change, message):
    entries = list(make_lights(np.random.default_rng(4), 5, kinds=(RECT,))[0])
    change(entries)
    with pytest.raises(ValueError, match=message):
        build_light_tree(*entries)


# -- (e) determinism and build time ------------------------------------------------------------

def test_build_is_deterministic_and_fast():
    rng = np.random.default_rng(6)
    build_light_tree(*make_lights(rng, 20)[0])      # compiled (or loaded from the cache) first
    count = 100_000
    c = rng.uniform(-50, 50, (count, 3))
    half = rng.uniform(0, 0.3, (count, 3))
    kinds = rng.integers(0, 3, count)
    entries = (c - half, c + half, rng.uniform(0.1, 10, count), rng.normal(size=(count, 3)),
               np.where(kinds == 2, -1.0, 1.0), np.zeros(count), kinds == 1)
    start = time.perf_counter()
    tree = build_light_tree(*entries)
    seconds = time.perf_counter() - start
    print(f"\nlight tree: built over {count} entries in {seconds:.3f} s")
    assert seconds < 5.0
    again = build_light_tree(*(np.copy(a) for a in entries))
    for name, a, b in zip(tree._fields, tree, again):
        assert np.array_equal(a, b), name
    assert len(tree.child) == 2 * count - 1
