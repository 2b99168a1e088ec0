"""Counter-based random numbers: every number is a hash of (seed, pixel, sample, dimension).

A pixel's samples then do not depend on thread count, batch size, pass order or backend: the
same key always gives the same number. Written by hand (rather than numpy's Philox or numba's
per-thread generators) because those are sequential streams: they would tie a pixel's numbers to
the order in which work is handed out. The mixer is SplitMix64's finaliser applied to a key that
packs the four counters with distinct odd multipliers.
"""
import numpy as np
from numba import njit

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_K_SEED = np.uint64(0x9E3779B97F4A7C15)
_K_PIXEL = np.uint64(0xD1B54A32D192ED03)
_K_SAMPLE = np.uint64(0xABC98388FB8FAC03)
_K_DIM = np.uint64(0x8CB92BA72F3D8DD7)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV_2_53 = 1.0 / 9007199254740992.0


@njit(cache=True, inline="always")
def _mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, _nrt=False, forceinline=True)
def uniform(seed, pixel, sample, dimension):
    """A number in [0, 1) determined only by the four counters."""
    key = _mix(np.uint64(seed) * _K_SEED + _mix(np.uint64(pixel) * _K_PIXEL
                                                 + np.uint64(sample) * _K_SAMPLE)
               + np.uint64(dimension) * _K_DIM)
    key = _mix(key)
    return np.float64(key >> _S11) * _INV_2_53


@njit(cache=True)
def uniform_array(seed, pixels, samples, dimension):
    """uniform() for arrays of pixels and samples (for tests and vectorised callers)."""
    out = np.empty(pixels.shape[0])
    for i in range(pixels.shape[0]):
        out[i] = uniform(seed, pixels[i], samples[i], dimension)
    return out
