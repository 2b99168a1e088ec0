"""accel.simd's vector tests against the scalar kernels they stand for, lane by lane.

The BVH's exactness (bvh == naive, t for t) rests on each lane of the block tests doing the
scalar test's float64 arithmetic; the slab test must keep the scalar traversal's decisions. These
tests compare them directly, bit for bit, on random and degenerate cases, so a difference shows
here and not only as a rare mismatch on a course mesh.
"""
import numpy as np
from numba import njit

from accel.bvh import WIDTH, slab_test
from accel.kernels import (
    inverse_direction,
    moller_trumbore,
    near_columns,
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
def _slab_both(nodes, origins, directions, lo, hi, out_vector, out_scalar):
    """slab_test's (mask, entries) per ray and row, and the scalar traversal's formula for the
    same planes (the 4-wide code it replaced: max/min over the near and far planes' t and the
    tolerance t0 <= t1 + |t1| 4e-16)."""
    for r in range(origins.shape[0]):
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        ix = inverse_direction(directions[r, 0])
        iy = inverse_direction(directions[r, 1])
        iz = inverse_direction(directions[r, 2])
        nx, ny, nz, fx, fy, fz = near_columns(ix, iy, iz)
        planes = (nx * WIDTH, ny * WIDTH, nz * WIDTH, fx * WIDTH, fy * WIDTH, fz * WIDTH)
        for row in range(nodes.shape[0]):
            mask, entries = slab_test(nodes, row, planes, (ox, oy, oz, ix, iy, iz), lo, hi)
            for c in range(WIDTH):
                t0 = max(lo, (np.float64(nodes[row, nx * WIDTH + c]) - ox) * ix,
                         (np.float64(nodes[row, ny * WIDTH + c]) - oy) * iy,
                         (np.float64(nodes[row, nz * WIDTH + c]) - oz) * iz)
                t1 = min(hi, (np.float64(nodes[row, fx * WIDTH + c]) - ox) * ix,
                         (np.float64(nodes[row, fy * WIDTH + c]) - oy) * iy,
                         (np.float64(nodes[row, fz * WIDTH + c]) - oz) * iz)
                out_scalar[r, row, c] = t0 if t0 <= t1 + abs(t1) * 4e-16 else np.inf
                out_vector[r, row, c] = entries[c]
                out_vector[r, row, WIDTH + c] = (mask >> c) & 1


def test_slab_test_equals_the_scalar_slab_test():
    """slab_test: each child's entry t is bit for bit the scalar formula's (inf where missed),
    the mask is set exactly where it is finite, and an empty slot (lower +inf, upper -inf) is
    always missed: on random boxes, flat ones, rays along axes (a zero direction component) and
    rays starting inside boxes."""
    rng = np.random.default_rng(11)
    rows = 30
    nodes = np.zeros((rows, 64), dtype=np.float32)
    low = rng.normal(size=(rows, 3, WIDTH))
    high = low + rng.random((rows, 3, WIDTH)) * 2.0
    high[:5, 2] = low[:5, 2]                      # flat boxes
    low[5, :, 5:], high[5, :, 5:] = np.inf, -np.inf   # empty slots
    nodes[:, :3 * WIDTH] = low.reshape(rows, -1)
    nodes[:, 3 * WIDTH:6 * WIDTH] = high.reshape(rows, -1)
    origins = rng.normal(size=(200, 3))
    directions = rng.normal(size=(200, 3))
    directions[:30, 0] = 0.0
    directions[30:40, :2] = 0.0
    out_vector = np.empty((200, rows, 2 * WIDTH))
    out_scalar = np.empty((200, rows, WIDTH))
    for lo, hi in ((0.0, np.inf), (0.5, 2.0)):
        _slab_both(nodes, origins, directions, lo, hi, out_vector, out_scalar)
        np.testing.assert_array_equal(out_vector[..., :WIDTH], out_scalar)
        np.testing.assert_array_equal(out_vector[..., WIDTH:], np.isfinite(out_scalar))
        assert not out_vector[:, 5, WIDTH + 5:].any()   # empty slots: never entered
        assert 0.02 < out_vector[..., WIDTH:].mean() < 0.95   # boxes entered, and missed
