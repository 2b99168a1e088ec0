"""Sine and cosine written out for the kernels: inline polynomials in place of libm's calls.

pip's llvmlite has no vector maths library, so every math.sin, math.cos (LLVM merges a pair into
one sincos) was a call into libm: about 5 % of a course box's render on one thread, plus the
registers a call spills. These are fdlibm's kernels (__kernel_sin, __kernel_cos: minimax
polynomials on [-pi/4, pi/4], under one ulp there) after a Cody-Waite reduction by pi/2 in two
parts (exact for the quadrant counts the kernels meet, |x| < 2**20 pi/2), so they inline, stay
in registers and have no call. Measured against libm (tests/ptrace/test_trig.py): within 1 ulp
of sin and cos (absolute 1.2e-16) over [-100, 100].

sincos_2pi(u) is (cos, sin) of 2 pi u for u a number of the sampler in [0, 1): the reduction is
done on u, where it is exact, so it is no worse than sin(2 pi u) rounded twice.
"""
import math

from numba import njit

_TWO_OVER_PI = 2.0 / math.pi
_PIO2_1 = 1.57079632673412561417e+00      # the first 33 bits of pi/2
_PIO2_1T = 6.07710050650619224932e-11     # pi/2 - _PIO2_1
_PIO2 = 0.5 * math.pi
_S1, _S2, _S3, _S4, _S5, _S6 = (-1.66666666666666324348e-01, 8.33333333332248946124e-03,
                                -1.98412698298579493134e-04, 2.75573137070700676789e-06,
                                -2.50507602534068634195e-08, 1.58969099521155010221e-10)
_C1, _C2, _C3, _C4, _C5, _C6 = (4.16666666666666019037e-02, -1.38888888888741095749e-03,
                                2.48015872894767294178e-05, -2.75573143513906633035e-07,
                                2.08757232129817482790e-09, -1.13596475577881948265e-11)


@njit(cache=True, inline="always")
def _kernel(r):
    """(cos r, sin r) for |r| <= pi/4 (fdlibm's kernels without their tail)."""
    z = r * r
    s = r + r * z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    c6 = z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + z * c6)
    return c, s


@njit(cache=True, inline="always")
def _quadrant(c, s, q):
    """(cos, sin) of r + q pi/2 from (cos r, sin r)."""
    q = q & 3
    if q == 1:
        return -s, c
    if q == 2:
        return -c, -s
    if q == 3:
        return s, -c
    return c, s


@njit(cache=True, inline="always")
def sincos(x):
    """(cos x, sin x) for |x| < 2**20 pi/2 (the angles the samplers make are under 4 pi)."""
    q = math.floor(x * _TWO_OVER_PI + 0.5)
    r = (x - q * _PIO2_1) - q * _PIO2_1T
    c, s = _kernel(r)
    return _quadrant(c, s, int(q))


@njit(cache=True, inline="always")
def sincos_2pi(u):
    """(cos 2 pi u, sin 2 pi u) for |u| < 2**20: quadrants of u taken exactly."""
    q = math.floor(4.0 * u + 0.5)
    c, s = _kernel((u - 0.25 * q) * (4.0 * _PIO2))
    return _quadrant(c, s, int(q))
