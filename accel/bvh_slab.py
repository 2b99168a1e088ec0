"""What the BVH's float32 slab test needs of a ray: its plane columns, and its origin, inverse
direction and interval rounded outward, so that rounding can only keep a box, never lose one.

Separate from accel.bvh's traversal because it is one self-contained argument about float32
rounding (the margins below and _ray_planes' proof, which tests/accel/test_simd.py checks against
exact arithmetic), read once per ray before the walk begins.
"""
import numpy as np
from numba import njit

from .bvh_wide import WIDTH, _float32_down, _float32_up
from .kernels import near_columns

# The float32 slab test's margins (see _ray_planes). Float32 rounds a plane's difference from the
# origin, its product with the inverse and the inverse itself (2^-24 each, relative), so near
# inverses are shrunk and far ones grown by SLAB_SCALE: a near t can only come out smaller than
# the exact one, a far t larger. The origins are moved ahead (near) and behind (far) by
# SLAB_SHIFT * |o| (plus 2^-40), more than rounding them to float32 (and float64's rounding of
# o + lo d, for a negative lo) can move them.
SLAB_SCALE = 4.0 * 2.0 ** -24
SLAB_SHIFT = 2.0 * 2.0 ** -24 + 2.0 ** -52


@njit(cache=True, inline="always")
def _inverse32(d):
    """A direction component's near and far inverses for the float32 slab test (1/d shrunk and
    grown by SLAB_SCALE), and whether float32 holds them: +inf for 0 (parallel: each t is then
    +-inf by the sign of plane - origin, or NaN where they are equal, which culls nothing),
    scaled 1/d where |1/d| is within [2^-100, 2^100]."""
    if d == 0.0:
        return np.float32(np.inf), np.float32(np.inf), True
    q = 1.0 / d
    return (np.float32(q * (1.0 - SLAB_SCALE)), np.float32(q * (1.0 + SLAB_SCALE)),
            2.0 ** -100 <= abs(q) <= 2.0 ** 100)


@njit(cache=True, inline="always")
def _origins32(o, d, shift, inverse):
    """A ray origin coordinate's float32 near and far origins for the slab test, the origin
    being o + shift * d: the near one ahead of it along the axis's direction, the far one behind
    it, each by SLAB_SHIFT of |o| + |shift * d| (at least its magnitude, and enough to cover
    float64's rounding of o + shift * d too) plus 2^-40."""
    step = shift * d
    start = o + step
    move = SLAB_SHIFT * (abs(o) + abs(step)) + 2.0 ** -40
    if inverse > 0:
        return np.float32(start + move), np.float32(start - move)
    return np.float32(start - move), np.float32(start + move)


@njit(cache=True, forceinline=True)   # not inline="always": numba copies its IR per call
def _ray_planes(ox, oy, oz, dx, dy, dz, lo, hi):
    """What slab_test needs of a ray: its near and far plane columns; its float32 near and far
    origins and inverses; its float32 lo and hi (rounded down and up); the t its slab t's are
    counted from (0, or lo if lo < 0: the slab test's origin is then o + lo d, so that only t's
    >= 0 matter to it); and whether float32
    cannot invert one of the direction's components (0 < |d| < 2^-100 or |d| > 2^100, which no
    renderer makes: the traversal then visits every node and leaf, bvh._every_child).

    Why the slab test never misses a box the ray meets within [lo, hi] (tests/accel/test_simd.py
    checks it against exact arithmetic): with lo32 <= the slab's lo (0 or lo) and hi32 >= its hi,
    a box is met exactly when max(lo, near t's) <= min(hi, far t's), and then every far t is
    >= 0. A near or far difference plane - origin errs outward, its sign included (the origins
    are moved by more than their rounding); where it is >= 0 (a far t always, a near t whenever
    it can exceed lo) the shrunk or grown inverse outweighs the three roundings of 2^-24, so the
    computed near t is at most the exact one and the far t at least; a negative near t is below
    lo32 and changes nothing."""
    shift = min(lo, 0.0)
    (nix, fix, x_ok), (niy, fiy, y_ok), (niz, fiz, z_ok) = (
        _inverse32(dx), _inverse32(dy), _inverse32(dz))
    nx, ny, nz, fx, fy, fz = near_columns(nix, niy, niz)
    planes = (nx * WIDTH, ny * WIDTH, nz * WIDTH, fx * WIDTH, fy * WIDTH, fz * WIDTH)
    near_x, far_x = _origins32(ox, dx, shift, nix)
    near_y, far_y = _origins32(oy, dy, shift, niy)
    near_z, far_z = _origins32(oz, dz, shift, niz)
    ray = (near_x, near_y, near_z, far_x, far_y, far_z, nix, niy, niz, fix, fiy, fiz)
    lo32, hi32 = _float32_down(lo - shift), _hi32(hi, shift)
    return planes, ray, lo32, hi32, shift, not (x_ok and y_ok and z_ok)


@njit(cache=True, inline="always")
def _hi32(t, shift):
    """A float32 at or above t - shift, for the slab test's hi (t - shift rounded up)."""
    return _float32_up((t - shift) * (1.0 + 2.0 ** -52))
