"""The range every number from a flag or a file must lie in, and the one check of it.

A coordinate, size, distance, radius, colour, emission or light intensity is taken if it is a
finite number of magnitude at most LIMIT = 1e30, and refused otherwise, in one line naming the
flag, or the file and the element. Why 1e30: ptrace computes in float64 (largest 1.8e308), and
what it forms from such numbers stays far below that: differences of two coordinates 2e30,
their cross products and squared lengths 4e60, a triangle's area times an emission 4e90, the
fourth powers of a solid angle's area over a squared distance 1e120, and a sum of those over
2^31 triangles or samples 1e130. An image's radiance of 1e30 also fits the float32 of an .exr
(3.4e38). A value of 1e308, finite as it is, overflows at the first product: a default camera
at an infinite distance, emitter weights of inf, samples all dropped as non-finite. Nothing a
real scene holds comes near 1e30 (the observable universe is 1e27 metres across).
"""
import math

import numpy as np

LIMIT = 1e30
LIMIT_WORDS = f"beyond ±{LIMIT:g}, the largest magnitude ptrace takes (so that its arithmetic " \
              f"cannot overflow)"
# Texture coordinates: a texture lookup turns u x width into a 64-bit integer texel index, which
# wraps past 9.2e18, so a coordinate of 1e30 (let alone 3e38) reads an arbitrary texel. At 1e12
# even a 1048576-texel-wide texture's index stays below 1.1e18; and no texture repeats 1e12
# times across a surface (a float64 coordinate there has no fraction left finer than 1e-4).
UV_LIMIT = 1e12
UV_WORDS = f"beyond ±{UV_LIMIT:g}, the largest texture coordinate ptrace takes (beyond it a " \
           f"texel's index overflows)"


def first_outside(values, limit=LIMIT):
    """The first of the values that is NaN, infinite or of magnitude above `limit`, or None
    when every one is a finite number within it (values: a number or any array of them)."""
    array = np.asarray(values)
    if array.dtype.kind not in "fiub":
        array = array.astype(np.float64)
    if array.size == 0 or (array.min() >= -limit and array.max() <= limit):  # NaN: False
        return None      # the common case, without a temporary array of an image's size
    array = array.reshape(-1)
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(array) <= limit)
    if not bad.any():
        return None
    return float(array[int(np.argmax(bad))])


def problem(values, limit=LIMIT):
    """None when every value is a finite number of magnitude at most `limit`; else words for
    the first that is not: "nan is not a finite number", "1e+308 is beyond ±1e+30, ..."."""
    value = first_outside(values, limit)
    if value is None:
        return None
    if not math.isfinite(value):
        return f"{value:g} is not a finite number"
    return f"{value:g} is " + (LIMIT_WORDS if limit == LIMIT else f"beyond ±{limit:g}")


def is_float(word):
    """Whether a word of a file reads as a number (float() takes it)."""
    try:
        float(word)
        return True
    except ValueError:
        return False
