"""accel.simd's vector tests against the scalar kernels they stand for, lane by lane.

The BVH's exactness (bvh == naive, t for t) rests on each lane of the block tests doing the
scalar test's float64 arithmetic; the slab test must keep the scalar traversal's decisions. These
tests compare them directly, bit for bit, on random and degenerate cases, so a difference shows
here and not only as a rare mismatch on a course mesh.
"""
from fractions import Fraction

import numpy as np
from numba import njit

from accel.bvh import WIDTH, _float32_down, _float32_up, _ray_planes, slab_test
from accel.kernels import (
    moller_trumbore,
    shear_setup,
    watertight,
)
from accel.simd import BLOCK, BLOCK_COLUMNS, moller_trumbore_block, watertight_block


@njit
def _blocks_and_scalars(blocks, origins, directions, lo, hi, out_block, out_scalar):
    """For every ray and block: the block tests' (mask, t, u, v) per lane and the scalar
    kernels' (t, u, v) of the same triangle, for both tests (index 0 watertight, 1 MT)."""
    for r in range(origins.shape[0]):
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        shear = shear_setup(ox, oy, oz, dx, dy, dz)
        kx, ky, kz, px, py, pz, sx, sy, sz = shear
        for b in range(blocks.shape[0]):
            for test in range(2):
                if test == 0:
                    mask, ts, us, vs = watertight_block(blocks, b, shear, lo, hi)
                else:
                    mask, ts, us, vs = moller_trumbore_block(blocks, b, (ox, oy, oz, dx, dy, dz),
                                                             lo, hi)
                for lane in range(BLOCK):
                    p = np.empty((3, 3))
                    for j in range(3):
                        for a in range(3):
                            p[j, a] = blocks[b, (3 * j + a) * BLOCK + lane]
                    if test == 0:
                        t, u, v = watertight(p[0, kx] - px, p[0, ky] - py, p[0, kz] - pz,
                                             p[1, kx] - px, p[1, ky] - py, p[1, kz] - pz,
                                             p[2, kx] - px, p[2, ky] - py, p[2, kz] - pz,
                                             sx, sy, sz)
                    else:
                        t, u, v = moller_trumbore(p[0, 0], p[0, 1], p[0, 2], p[1, 0], p[1, 1],
                                                  p[1, 2], p[2, 0], p[2, 1], p[2, 2],
                                                  ox, oy, oz, dx, dy, dz)
                    out_block[r, b, test, lane, 0] = (mask >> lane) & 1
                    out_block[r, b, test, lane, 1] = ts[lane]
                    out_block[r, b, test, lane, 2] = us[lane]
                    out_block[r, b, test, lane, 3] = vs[lane]
                    out_scalar[r, b, test, lane, 0] = t
                    out_scalar[r, b, test, lane, 1] = u
                    out_scalar[r, b, test, lane, 2] = v


def _block_rows(triangles):
    """(n, 3, 3) triangles -> blocks of BLOCK lanes (NaN in the unused lanes of the last)."""
    n_blocks = -(-len(triangles) // BLOCK)
    blocks = np.full((n_blocks, BLOCK_COLUMNS), np.nan)
    for i, triangle in enumerate(triangles):
        b, lane = divmod(i, BLOCK)
        for j in range(3):
            for a in range(3):
                blocks[b, (3 * j + a) * BLOCK + lane] = triangle[j, a]
    return blocks


def test_block_tests_equal_the_scalar_kernels_lane_by_lane():
    """watertight_block and moller_trumbore_block: every lane's t, u and v equal the scalar
    kernel's exactly (a miss is t = NaN in both), and the mask is exactly lo <= t <= hi, on random
    triangles, triangles seen edge-on, zero-area ones, huge and tiny ones, and NaN lanes."""
    rng = np.random.default_rng(7)
    triangles = list(rng.normal(size=(40, 3, 3)))
    flat = rng.normal(size=(3, 3))
    flat[:, 2] = 0.0                              # in z = 0: edge-on to rays along x or y
    triangles += [flat, np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2.0]]),   # zero area
                  1e6 * rng.normal(size=(3, 3)), 1e-6 * rng.normal(size=(3, 3))]
    triangles.append(rng.normal(size=(3, 3)))    # 45: the last block has three NaN lanes
    blocks = _block_rows(np.array(triangles))
    origins = rng.normal(size=(300, 3)) * 2.0
    directions = rng.normal(size=(300, 3))
    directions[:20, 1:] = 0.0                     # along x: parallel to the flat triangle
    directions[20:30] = 0.0                       # a zero direction misses everything
    corners = np.array(triangles[:40])
    aimed = np.arange(150, 300)
    targets = np.where((aimed % 2)[:, None] == 0, corners[aimed % 40].mean(axis=1),   # centroids
                       corners[aimed % 40, :2].mean(axis=1))                       # edge midpoints
    directions[aimed] = targets - origins[aimed]
    out_block = np.empty((300, len(blocks), 2, BLOCK, 4))
    out_scalar = np.empty((300, len(blocks), 2, BLOCK, 3))
    lo, hi = 0.25, 3.0
    _blocks_and_scalars(blocks, origins, directions, lo, hi, out_block, out_scalar)
    # t, u, v exactly equal (assert_array_equal: NaN where the other is NaN, else ==)
    np.testing.assert_array_equal(out_block[..., 1:], out_scalar)
    t = out_scalar[..., 0]
    np.testing.assert_array_equal(out_block[..., 0], (t >= lo) & (t <= hi))
    assert 0.02 < out_block[..., 0].mean() < 0.5     # the cases hit, and miss


@njit
def _slab_vector(nodes, origins, directions, lo, hi, out):
    """slab_test's (mask bit, entry t) per ray, row and child, as the traversal calls it (the
    entry on the ray's own scale: plus the shift of a negative lo, rounded down)."""
    for r in range(origins.shape[0]):
        planes, ray, lo32, hi32, shift, _ = _ray_planes(
            origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0], directions[r, 1],
            directions[r, 2], lo, hi)
        for row in range(nodes.shape[0]):
            mask, entries = slab_test(nodes, row, planes, ray, lo32, hi32)
            for c in range(WIDTH):
                out[r, row, c, 0] = (mask >> c) & 1
                out[r, row, c, 1] = np.nextafter(entries[c] + shift, -np.inf)


def _exact_interval(low, high, origin, direction, lo, hi):
    """(t0, t1) of the ray's segment [lo, hi] in the box, in exact rational arithmetic: the box
    is met where t0 <= t1 (an axis the ray is parallel to keeps everything or nothing)."""
    t0, t1 = (Fraction(lo) if np.isfinite(lo) else lo), (Fraction(hi) if np.isfinite(hi) else hi)
    for a in range(3):
        lower, upper, o, d = (Fraction(float(x)) for x in (low[a], high[a], origin[a],
                                                             direction[a]))
        if d == 0:
            if not lower <= o <= upper:
                return 1, 0
            continue
        ta, tb = (lower - o) / d, (upper - o) / d
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    return t0, t1


def _slab_cases(rng):
    """Rows of random boxes (some flat, two empty slots) and rays: random ones, rays parallel to
    one or two axes (some from origins on box planes), far origins, and rays grazing a box:
    aimed at a point of a box's edge, so float64 rounding puts them just inside or just outside
    it."""
    rows = 12
    nodes = np.zeros((rows, 64), dtype=np.float32)
    low = rng.normal(size=(rows, 3, WIDTH)).astype(np.float32)
    high = low + (rng.random((rows, 3, WIDTH)) * 2.0).astype(np.float32)
    high[:2, 2] = low[:2, 2]                      # flat boxes
    low[2, :, 6:], high[2, :, 6:] = np.inf, -np.inf   # empty slots
    nodes[:, :3 * WIDTH] = low.reshape(rows, -1)
    nodes[:, 3 * WIDTH:6 * WIDTH] = high.reshape(rows, -1)
    n = 240
    origins = rng.normal(size=(n, 3)) * 3.0
    directions = rng.normal(size=(n, 3))
    directions[:20, 0] = 0.0
    directions[20:30, :2] = 0.0
    directions[30:50, 1] = 0.0
    origins[30:50, 1] = low[3, 1, :].repeat(3)[:20]   # on box planes of that axis
    origins[50:60] += 1e7 * directions[50:60]
    directions[50:60] *= -1.0
    for r in range(60, n):   # grazing: through a point on an edge of a random box
        row, c = rng.integers(3, rows), rng.integers(WIDTH)
        edge = rng.permutation(3)
        point = np.empty(3)
        point[edge[0]] = low[row, edge[0], c] if rng.random() < 0.5 else high[row, edge[0], c]
        point[edge[1]] = low[row, edge[1], c] if rng.random() < 0.5 else high[row, edge[1], c]
        point[edge[2]] = rng.uniform(low[row, edge[2], c], high[row, edge[2], c])
        origins[r] = point - rng.uniform(0.6, 1.9) * directions[r]
    return nodes, low, high, origins, directions


def test_slab_test_never_misses_a_box_the_ray_meets():
    """The float32 slab test against exact rational arithmetic: every child box that the ray's
    segment [lo, hi] meets, grazing edges included, is hit, with an entry t at most the exact
    one; an empty slot is never hit; and a box missed by more than a relative 1e-5 is missed
    (except by a ray from a box plane it is parallel to, which culls less). Float32 rounding
    alone loses some of the grazing boxes: this fails without the origins moved outward."""
    rng = np.random.default_rng(11)
    nodes, low, high, origins, directions = _slab_cases(rng)
    out = np.empty((len(origins), nodes.shape[0], WIDTH, 2))
    on_plane = np.zeros(len(origins), dtype=bool)
    on_plane[30:50] = True
    met = missed = grazing_met = grazing_missed = 0
    for lo, hi in ((0.0, np.inf), (0.5, 2.0), (-1.0, 3.0)):
        _slab_vector(nodes, origins, directions, lo, hi, out)
        for r in range(len(origins)):
            for row in range(nodes.shape[0]):
                for c in range(WIDTH):
                    hit, entry = out[r, row, c]
                    if not np.isfinite(low[row, 0, c]):
                        assert not hit, "an empty slot was hit"
                        continue
                    t0, t1 = _exact_interval(low[row, :, c], high[row, :, c], origins[r],
                                             directions[r], lo, hi)
                    if t0 <= t1:
                        met += 1
                        grazing_met += r >= 60
                        assert hit, f"ray {r} misses row {row} child {c}, which it meets"
                        assert entry <= t0
                    else:
                        missed += 1
                        scale = max(abs(float(t0)), abs(float(t1)), 1.0)
                        if float(t0) - float(t1) > 1e-5 * scale:
                            grazing_missed += r >= 60
                            if not on_plane[r]:
                                assert not hit, f"ray {r} hits row {row} child {c}: far off"
    assert met > 500 and missed > 5000
    assert grazing_met > 100 and grazing_missed > 100


@njit
def _rounded(values, out):
    for i in range(values.shape[0]):
        out[i, 0] = _float32_down(values[i])
        out[i, 1] = _float32_up(values[i])


def test_float32_rounding_down_and_up():
    """_float32_down / _float32_up (bit steps, no branches) against numpy's nextafter: the
    nearest float32 at or below / at or above each value, on random values of every magnitude,
    exact float32 values, zeros, subnormals, values beyond float32's range and infinities."""
    rng = np.random.default_rng(5)
    f32 = np.finfo(np.float32)
    values = np.concatenate([
        rng.normal(size=2000) * 10.0 ** rng.integers(-45, 39, size=2000),
        rng.normal(size=200).astype(np.float32).astype(np.float64),
        [0.0, -0.0, 1e-46, -1e-46, 7e-46, -7e-46, 1.4e-45, float(f32.max), -float(f32.max),
         float(f32.max) * (1 + 1e-12), -float(f32.max) * (1 + 1e-12), 1e39, -1e39,
         np.inf, -np.inf]])
    out = np.empty((len(values), 2), dtype=np.float32)
    _rounded(values, out)
    with np.errstate(over="ignore"):   # beyond float32's range: inf, stepped back where needed
        nearest = values.astype(np.float32)
        down = np.where(nearest.astype(np.float64) > values,
                        np.nextafter(nearest, np.float32(-np.inf)), nearest)
        up = np.where(nearest.astype(np.float64) < values,
                      np.nextafter(nearest, np.float32(np.inf)), nearest)
    np.testing.assert_array_equal(out[:, 0], down)
    np.testing.assert_array_equal(out[:, 1], up)
    assert (out[:, 0].astype(np.float64) <= values).all()
    assert (out[:, 1].astype(np.float64) >= values).all()
