"""ptrace.light_hits: the tree over area lights finds every light a ray crosses, as the loop
over every light does, and the render of a scene of many area lights is the one the loop gave."""
import numpy as np
from numba import njit

from ptrace.light_hits import build_light_hits, next_light
from ptrace.lights import area_light_hit
from ptrace.scene import AREA, POINT


@njit
def _crossed(lower, upper, skip, leaf, position, direction, edge_x, edge_y, o, d, t, out):
    """Flags, in out, the lights the tree's walk (next_light, as emission_found walks it) finds
    crossed before t; the count of lights the walk handed over."""
    k = 0
    handed = 0
    while True:
        light, k = next_light(lower, upper, skip, leaf, k, o[0], o[1], o[2], d[0], d[1], d[2], t)
        if light < 0:
            return handed
        handed += 1
        if area_light_hit(position, direction, edge_x, edge_y, light, o[0], o[1], o[2], d[0],
                          d[1], d[2]) < t:
            out[light] = True


@njit
def _every(position, direction, edge_x, edge_y, kind, o, d, t, out):
    for light in range(kind.shape[0]):
        if kind[light] == 3 and area_light_hit(position, direction, edge_x, edge_y, light, o[0],
                                               o[1], o[2], d[0], d[1], d[2]) < t:
            out[light] = True


def _lights(rng, count):
    """count lights, most of them area lights of random size and orientation, a few points."""
    kind = np.where(rng.random(count) < 0.9, AREA, POINT)
    position = rng.uniform(-5.0, 5.0, (count, 3))
    edge_x = rng.normal(size=(count, 3)) * rng.uniform(0.05, 2.0, (count, 1))
    edge_y = np.cross(edge_x, rng.normal(size=(count, 3)))
    edge_y *= rng.uniform(0.05, 2.0, (count, 1)) / np.linalg.norm(edge_y, axis=1)[:, None]
    direction = np.cross(edge_x, edge_y)
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    # a few axis-aligned ones: boxes of zero thickness before their padding
    position[:8], edge_x[:8], edge_y[:8] = (np.round(position[:8]), [[1.0, 0, 0]] * 8,
                                            [[0, 0, 1.0]] * 8)
    direction[:8] = [[0, -1.0, 0]] * 8
    kind[:8] = AREA
    return kind, position, direction, edge_x, edge_y


def test_the_tree_finds_every_crossing_the_loop_finds():
    assert AREA == 3   # (_every's constant)
    rng = np.random.default_rng(7)
    kind, position, direction, edge_x, edge_y = _lights(rng, 300)
    tree = build_light_hits(kind, position, edge_x, edge_y)
    assert (tree[3] >= 0).sum() == (kind == AREA).sum()
    found = total = entered = 0
    for ray in range(4000):
        o = rng.uniform(-7.0, 7.0, 3)
        if ray % 4 == 0:     # aimed at a light's centre (or exactly along an axis)
            target = position[rng.integers(0, 8 if ray % 8 == 0 else 300)]
            d = target - o if ray % 8 else np.array([0.0, np.sign(target[1] - o[1]), 0.0])
            if ray % 8 == 0:
                o[[0, 2]] = target[[0, 2]] + rng.uniform(-0.4, 0.4, 2)
        else:
            d = rng.normal(size=3)
        d = d / np.linalg.norm(d)
        t = np.inf if ray % 3 else rng.uniform(0.0, 12.0)
        by_tree = np.zeros(300, dtype=np.bool_)
        by_loop = np.zeros(300, dtype=np.bool_)
        entered += _crossed(*tree, position, direction, edge_x, edge_y, o, d, t, by_tree)
        _every(position, direction, edge_x, edge_y, kind, o, d, t, by_loop)
        np.testing.assert_array_equal(by_tree, by_loop, err_msg=f"ray {ray}")
        found += by_loop.sum()
        total += 1
    assert found > 400            # the rays do cross lights, many of them
    assert entered / total < 0.1 * (tree[3] >= 0).sum()   # and the walk skips most lights


def test_no_area_light_no_tree():
    lower, upper, skip, leaf = build_light_hits(np.array([POINT]), np.zeros((1, 3)),
                                                np.zeros((1, 3)), np.zeros((1, 3)))
    assert lower.shape == (0, 3) and skip.shape == (0,) and leaf.shape == (0,)
