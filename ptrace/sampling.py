"""Counter-based random numbers and a stratified low-discrepancy sampler.

Every number is a function of (seed, pixel, sample-or-index, dimension) alone: a pixel's samples
then do not depend on thread count, batch size, block size, pass order or backend, and the same
key always gives the same number, bit for bit.

uniform(seed, pixel, sample, dimension) is a hash: written by hand (rather than numpy's Philox or
numba's per-thread generators) because those are sequential streams, which would tie a pixel's
numbers to the order in which work is handed out. The mixer is SplitMix64's finaliser applied to
a key that packs the four counters with distinct odd multipliers.

sobol_2d(seed, pixel, index, dim) -> (x, y) and sobol_1d(seed, pixel, index, dim) -> x are a
stratified sampler: the index-th point of the first two dimensions of the Sobol' sequence (x: van
der Corput, the bit reversal of the index; y: generator v_0 = 2**31, v_(j+1) = v_j ^ (v_j >> 1)),
Owen-scrambled and index-shuffled as in B. Burley, "Practical Hash-based Owen Scrambling", JCGT
9(4), 2020. The Owen scramble is the hash-based nested permutation of Laine and Karras with
N. Vegdahl's constants ("Building a better LK hash", 2021) acting on the bit-reversed value; the
shuffle is the same nested scramble applied to the index (read, like the coordinates, as a binary
fraction with its most significant bit first). The shuffle seed and the scramble seeds of x and
y (and of the 1D sampler, under a different constant) are independent hashes of
(seed, pixel, dim), so `dim` is only a key ("padding", as pbrt-v4's PaddedSobolSampler does with
a per-dimension permutation): distinct keys give statistically independent sequences, the same
key the same numbers. Written by hand because there is no maintained numba-callable library for
it (scipy.stats.qmc.Sobol is a stateful Python object: not callable from a compiled kernel, and
not keyed by pixel and dimension). All arithmetic is 32-bit unsigned, held in uint64 and masked;
values are integer * 2**-32 as float64, so they lie in [0, 1) (never 1.0); indices wrap modulo
2**32.

Promise: the shuffle maps every aligned block of 2**k indices [m 2**k, (m+1) 2**k) onto an aligned
block of 2**k Sobol' indices (bit i of the shuffled index depends only on bits >= i of the index,
so the low k bits are permuted among themselves while the high bits map to a fixed block), and
every aligned block of a (0,2)-sequence is a (0,k,2)-net, which Owen scrambling keeps a net. So
the first 2**k samples of a pixel in any 2D key (and the next 2**k, and so on) put exactly one
point in every elementary interval 2**-a x 2**-(k-a); in 1D, one value in every 2**-k stratum.
Any prefix, power of two or not, is still unbiased: the scrambling makes every single point
uniformly distributed on [0, 1)**2, and a prefix of n <= 2**k samples has at most one point per
elementary interval of the 2**k-net.
"""
import numpy as np
from numba import njit

# SplitMix64's finaliser multipliers, and the key's odd multiplier of each counter
_M1, _M2 = map(np.uint64, (0xBF58476D1CE4E5B9, 0x94D049BB133111EB))
_K_SEED, _K_PIXEL, _K_SAMPLE, _K_DIM = map(np.uint64, (
    0x9E3779B97F4A7C15, 0xD1B54A32D192ED03, 0xABC98388FB8FAC03, 0x8CB92BA72F3D8DD7))
# shift amounts as uint64 too, so that every operand of the bit arithmetic is uint64
_S30, _S27, _S31, _S11 = map(np.uint64, (30, 27, 31, 11))
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


# -- Sobol' (0,2)-sequence, Owen-scrambled and index-shuffled --------------------------------------
_MASK32 = np.uint64(0xFFFFFFFF)
_ONE = np.uint64(1)
_S1, _S2, _S4, _S8, _S16, _S32 = map(np.uint64, (1, 2, 4, 8, 16, 32))
# the 32-bit masks of alternating runs of 1, 2, 4, 8 and 16 bits (_reverse_bits32's swaps)
_B1, _B2, _B4, _B8, _B16 = map(np.uint64, (0x55555555, 0x33333333, 0x0F0F0F0F, 0x00FF00FF,
                                           0x0000FFFF))
# Vegdahl's multipliers for the Laine-Karras-style hash (all even: see _owen_reversed)
_LK1, _LK2, _LK3 = map(np.uint64, (0x3D20ADEA, 0x05526C56, 0x53A22864))
# one constant per use, so that the shuffle and each scramble get an independent seed, and 1D and
# 2D keys with the same dim are independent
_SALT_2D, _SALT_1D, _SALT_SHUFFLE, _SALT_X, _SALT_Y = map(np.uint64, (
    0x632BE59BD9B4E019, 0x85EBCA77C2B2AE63, 0xC2B2AE3D27D4EB4F, 0x27D4EB2F165667C5,
    0x165667B19E3779F9))
_INV_2_32 = 1.0 / 4294967296.0


@njit(cache=True, inline="always")
def _reverse_bits32(x):
    """The 32 low bits of x (a uint64 < 2**32) in reverse order."""
    x = ((x >> _S1) & _B1) | ((x & _B1) << _S1)
    x = ((x >> _S2) & _B2) | ((x & _B2) << _S2)
    x = ((x >> _S4) & _B4) | ((x & _B4) << _S4)
    x = ((x >> _S8) & _B8) | ((x & _B8) << _S8)
    return (x >> _S16) | ((x & _B16) << _S16)


@njit(cache=True, inline="always")
def _owen_reversed(x, seed):
    """A seeded bijection of 32-bit x in which bit i of the result depends only on bits 0..i of x
    (adding the seed carries upwards; multiplying by an odd number or xoring with x times an even
    number only involves lower bits): on a bit-reversed value, a nested uniform (Owen) scramble."""
    x ^= (x * _LK1) & _MASK32
    x = (x + seed) & _MASK32
    x = (x * ((seed >> _S16) | _ONE)) & _MASK32
    x ^= (x * _LK2) & _MASK32
    x ^= (x * _LK3) & _MASK32
    return x


@njit(cache=True, inline="always")
def _owen(x, seed):
    """Nested uniform scramble of x read as a binary fraction, most significant bit first: bit i of
    the result depends only on bits i..31 of x."""
    return _reverse_bits32(_owen_reversed(_reverse_bits32(x), seed))


@njit(cache=True, inline="always")
def _sobol_y_reversed(index):
    """Second Sobol' dimension of a 32-bit index, bit-reversed (bit r = the fraction's digit r+1).
    Its generators are the rows of Pascal's triangle mod 2: digit r of v_j is C(j, r) mod 2, which
    by Lucas's theorem is 1 exactly when the bits of r are a subset of those of j. So digit r is
    the parity of the index bits j that are supersets of r: a superset xor over the five bits of
    the bit position, done here in five branch-free steps (bit j takes bit j + 2**b's value for
    every j with bit b clear) instead of a loop over the 32 generators."""
    a = index
    a ^= (a >> _S1) & _B1
    a ^= (a >> _S2) & _B2
    a ^= (a >> _S4) & _B4
    a ^= (a >> _S8) & _B8
    a ^= (a >> _S16) & _B16
    return a


@njit(cache=True, inline="always")
def _sobol_y(index):
    """Second Sobol' dimension of a 32-bit index as a 32-bit integer (generator v_0 = 2**31,
    v_(j+1) = v_j ^ (v_j >> 1): the xor of the generators of the index's set bits)."""
    return _reverse_bits32(_sobol_y_reversed(index))


@njit(cache=True, inline="always")
def _key(seed, pixel, dim, salt):
    """64-bit hash of (seed, pixel, dim) under a per-sampler salt."""
    return _mix(np.uint64(seed) * _K_SEED
                + _mix(np.uint64(pixel) * _K_PIXEL + np.uint64(dim) * _K_DIM) + salt)


@njit(cache=True, inline="always")
def _seed32(key, salt):
    """An independent 32-bit seed per use of one key."""
    return _mix(key + salt) >> _S32


@njit(cache=True, _nrt=False, forceinline=True)
def sobol_2d(seed, pixel, index, dim):
    """The index-th point (x, y) in [0, 1)**2 of pixel's Owen-scrambled, shuffled Sobol' sequence
    under key dim; its first 2**k points form a (0, k, 2)-net."""
    key = _key(seed, pixel, dim, _SALT_2D)
    i = _owen(np.uint64(index) & _MASK32, _seed32(key, _SALT_SHUFFLE))
    # _owen(_reverse_bits32(v), s) == _reverse_bits32(_owen_reversed(v, s)): skip two reversals
    x = _reverse_bits32(_owen_reversed(i, _seed32(key, _SALT_X)))
    y = _reverse_bits32(_owen_reversed(_sobol_y_reversed(i), _seed32(key, _SALT_Y)))
    return np.float64(x) * _INV_2_32, np.float64(y) * _INV_2_32


@njit(cache=True, _nrt=False, forceinline=True)
def sobol_1d(seed, pixel, index, dim):
    """The index-th value in [0, 1) of pixel's Owen-scrambled, shuffled van der Corput sequence
    under key dim (independent of sobol_2d's key dim); its first 2**k values are one per 2**-k."""
    key = _key(seed, pixel, dim, _SALT_1D)
    i = _owen(np.uint64(index) & _MASK32, _seed32(key, _SALT_SHUFFLE))
    return np.float64(_reverse_bits32(_owen_reversed(i, _seed32(key, _SALT_X)))) * _INV_2_32


@njit(cache=True)
def _numbers(seed, pixels, counters, dim):
    """(N, 4): for each (pixel, counter) pair, uniform(seed, pixel, counter, dim),
    sobol_1d(seed, pixel, counter, dim) and sobol_2d's (x, y)."""
    out = np.empty((pixels.shape[0], 4))
    for n in range(pixels.shape[0]):
        out[n, 0] = uniform(seed, pixels[n], counters[n], dim)
        out[n, 1] = sobol_1d(seed, pixels[n], counters[n], dim)
        out[n, 2], out[n, 3] = sobol_2d(seed, pixels[n], counters[n], dim)
    return out


def uniform_array(seed, pixels, samples, dimension):
    """uniform() for arrays of pixels and samples (for tests)."""
    return _numbers(seed, np.asarray(pixels), np.asarray(samples), dimension)[:, 0]


def sobol_1d_array(seed, pixels, indices, dim):
    """sobol_1d() for arrays of pixels and indices (for tests)."""
    return _numbers(seed, np.asarray(pixels), np.asarray(indices), dim)[:, 1]


def sobol_2d_array(seed, pixels, indices, dim):
    """sobol_2d() for arrays of pixels and indices: an (N, 2) array (for tests)."""
    return _numbers(seed, np.asarray(pixels), np.asarray(indices), dim)[:, 2:]
