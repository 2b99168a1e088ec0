"""Environment light: radiance from every direction a ray escapes in, from an image (the course's
`-e FILE`, docs/course.md#environment) or a constant colour.

Mapping (the course's): a direction d (unit, world, Y up) is theta = acos(d.y) from +Y and
phi = atan2(-d.z, d.x) + pi, the image point (x, y) = (phi / 2 pi W, theta / pi H) with y down
the image's rows, and the radiance is the bilinear interpolation of the pixels around it (pixel
centres at half-integers, wrapping around in phi and clamped at the poles).

Sampling (as pbrt-v4's PiecewiseConstant2D over the image): a row by the marginal distribution
of the table, a column by that row's conditional distribution, a uniform point in the cell; the
pdf per unit solid angle is p(x, y) / (2 pi^2 sin theta). The table is, per pixel cell, the mean
luminance of the bilinear lookup over the cell (the pixels blurred by [1/8, 3/4, 1/8] along each
axis: a bright pixel's light reaches a quarter of each neighbouring cell) times sin theta, plus a
floor of 1e-3 of its mean. So the density follows what the lookup returns (radiance / pdf stays
bounded: no rare huge samples beside a small sun) and is positive wherever a lookup can be, and
light sampling alone stays unbiased.

The table is not kept: the density of a cell is its row's probability times the rows, times its
step of the row's conditional cdf times the columns, which is what the sampler draws by (so the
pdf it reports is that of the float32 cdf it inverts, not of a table beside it). The conditional
cdfs are one float32 array of W + 1 columns a row: column 0 holds the row's probability times
the rows, columns 1.. W the cdf at each cell's right edge (the last 1; the cdf at the left edge
of cell 0 is 0). An environment costs 16 bytes a pixel: 12 of radiance, 4 of that array.
"""
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from . import budget
from .errors import PtraceError, require_regular_file
from .io.bands import band_rows, read_bands
from .io.limits import problem
from .io.quiet import library_output
from .scene import LUMINANCE

FLOOR = 1e-3          # of the table's mean: the density's lower bound (see the docstring)
CONSTANT_SIZE = (32, 64)   # rows, columns of the image a constant environment is made of


@dataclass(eq=False)
class Environment:
    """An environment image: (H, W, 3) linear radiance, float32, row 0 toward +Y (theta = 0).
    Any (H, W, 3) array is taken; its values are checked (finite, not negative, of magnitude
    at most ptrace.io.limits.LIMIT) before they are rounded to float32."""
    image: np.ndarray
    name: str = "environment"

    def __post_init__(self):
        image = np.asarray(self.image)
        if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 1:
            raise PtraceError(f"{self.name}: an environment must be an (H, W, 3) image, got "
                              f"shape {image.shape}")
        if image.dtype != np.float32 or not image.flags.c_contiguous:
            converted = np.empty(image.shape, np.float32)
        else:
            converted = image
        step = band_rows(image.shape[1])
        for start in range(0, image.shape[0], step):
            band = np.asarray(image[start:start + step], dtype=np.float64)
            if not np.isfinite(band).all() or (band < 0).any():
                raise PtraceError(f"{self.name}: the environment has negative, NaN or infinite "
                                  f"pixels")
            words = problem(band)    # finite, but every sample it lights would overflow
            if words is not None:
                raise PtraceError(f"{self.name}: the environment's radiance: {words}")
            if converted is not image:
                converted[start:start + step] = band
        self.image = converted

    @classmethod
    def constant(cls, rgb):
        rows, columns = CONSTANT_SIZE
        return cls(np.broadcast_to(np.asarray(rgb, dtype=np.float64), (rows, columns, 3)).copy(),
                   name=f"constant {tuple(float(c) for c in rgb)}")

    def mean_luminance(self):
        """The image's mean luminance (every pixel alike, not weighted by solid angle)."""
        mean = np.mean(self.image.reshape(-1, 3), axis=0, dtype=np.float64)
        return float(mean @ LUMINANCE)


def load_environment(spec, max_memory=None):
    """An Environment from a file OpenImageIO reads (.exr, .hdr, .png, ...; its first three
    channels, linear) or from "r,g,b" (or one number): a constant colour. An image whose size
    (read from its header, before any pixel is decoded) would need more than max_memory (as
    ptrace.budget takes it; default half the machine's memory) for its pixels and sampling
    tables is refused (a BudgetError), not downsampled: see ptrace.budget. The pixels are
    decoded a band of rows at a time into the float32 image, so reading it needs little more
    than the image itself."""
    text = str(spec)
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = None
    if values is not None and len(values) in (1, 3):
        return Environment.constant(values * 3 if len(values) == 1 else values)
    if not text.strip():     # OpenImageIO asserts on an empty name (on stderr) before failing
        raise PtraceError("the environment map's file name is empty")
    require_regular_file(text, "environment map")
    import OpenImageIO as oiio
    with library_output() as printed:      # libpng's and OpenImageIO's own lines: folded in
        reader = oiio.ImageInput.open(text)
        error = (oiio.geterror() or "not a readable image") if reader is None else None
    if error is not None:
        raise PtraceError(f"{text}: cannot read the environment map "
                          f"({printed.one_line(error) or 'not a readable image'})")
    try:
        spec = reader.spec()
        if spec.nchannels < 3:
            raise PtraceError(f"{text}: an environment map needs 3 colour channels, found "
                              f"{spec.nchannels}")
        if spec.width < 1 or spec.height < 1:
            raise PtraceError(f"{text}: cannot read the environment map (it has no pixels)")
        budget.Budget.of(max_memory).charge(
            text, f"the {spec.width}x{spec.height} environment map",
            spec.width * spec.height * budget.ENVIRONMENT_BYTES)
        image = _read_bands(text, reader, spec)
    finally:
        reader.close()
    return Environment(image, name=text)


def _read_bands(text, reader, spec):
    """The (H, W, 3) float32 pixels of an open image, decoded a band of rows at a time (a tile
    row at a time for a tiled file)."""
    image = np.empty((spec.height, spec.width, 3), np.float32)
    try:
        for start, pixels in read_bands(reader, spec, 3):
            image[start:start + pixels.shape[0]] = pixels
    except ValueError as error:
        raise PtraceError(f"{text}: cannot read the environment map ({error})") from None
    return image


def environment_arrays(environment):
    """(image (H, W, 3) float32, marginal cdf (H + 1) float64, conditional (H, W + 1) float32,
    table) of an Environment, or empty arrays of the same types: the conditional cdfs with each
    row's density in column 0 (the module docstring), and `table` the same array (what
    environment_pdf reads; the density over [0, 1)^2 of cell (j, i) is environment_density's).
    The density and the cdfs are computed in float64 a band of rows at a time, the density
    first stored (as float32) where its cdf then goes."""
    if environment is None:
        empty = np.zeros((0, 1), np.float32)
        return np.zeros((0, 0, 3), np.float32), np.zeros(1), empty, empty
    image = environment.image
    rows, columns = image.shape[:2]
    step = band_rows(columns)
    conditional = np.empty((rows, columns + 1), np.float32)
    density = conditional[:, 1:]      # the table's cells until each row's cdf replaces them
    total = 0.0
    for start in range(0, rows, step):
        end = min(start + step, rows)
        # the band and a row either side (clamped at the poles)
        index = np.clip(np.arange(start - 1, end + 1), 0, rows - 1)
        luminance = np.asarray(image[index], dtype=np.float64) @ LUMINANCE
        # the cell means of the bilinear lookup: wrap around in phi, clamp at the poles
        luminance = 0.75 * luminance + 0.125 * (np.roll(luminance, 1, axis=1)
                                                + np.roll(luminance, -1, axis=1))
        luminance = 0.75 * luminance[1:-1] + 0.125 * (luminance[:-2] + luminance[2:])
        sin_theta = np.sin((np.arange(start, end) + 0.5) / rows * np.pi)
        band = luminance * sin_theta[:, None]
        total += float(band.sum())
        density[start:end] = band
    mean = total / (rows * columns)
    floor = FLOOR * (mean if mean > 0 else 1.0)
    scale = 1.0 / (mean + floor)     # the table's mean is then 1
    row_sums = np.empty(rows)
    for start in range(0, rows, step):
        end = min(start + step, rows)
        band = (np.asarray(density[start:end], dtype=np.float64) + floor) * scale
        sums = np.cumsum(band, axis=1)
        row_sums[start:end] = sums[:, -1]
        conditional[start:end, 1:] = sums / sums[:, -1:]
        conditional[start:end, -1] = 1.0
    marginal = np.zeros(rows + 1)
    marginal[1:] = np.cumsum(row_sums)
    marginal /= marginal[-1]
    marginal[-1] = 1.0
    conditional[:, 0] = np.diff(marginal) * rows
    return image, marginal, conditional, conditional


def environment_density(table):
    """The (H, W) density over [0, 1)^2 (mean 1) that the sampler draws cells by, from the
    conditional array of environment_arrays: for tests and studies."""
    cdf = np.asarray(table[:, 1:], dtype=np.float64)
    steps = np.diff(cdf, axis=1, prepend=0.0)
    return steps * (table.shape[1] - 1) * np.asarray(table[:, :1], dtype=np.float64)


@njit(cache=True, inline="always")
def _cell(row, i):
    """(cdf at the left edge, at the right edge) of cell i of a conditional row, in float64."""
    return (np.float64(row[i]) if i > 0 else 0.0), np.float64(row[i + 1])


@njit(cache=True, inline="always")
def _find_cell(row, u):
    """The cell i of a conditional row (column 0 its density, not its cdf) whose cdf interval
    holds u: cdf(i) <= u < cdf(i + 1), cdf(0) being 0."""
    lo, hi = 0, row.shape[0] - 2
    while lo < hi:
        mid = (lo + hi + 1) // 2     # at least 1: column 0 is never read as a cdf
        if row[mid] <= u:
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(cache=True, inline="always")
def _find(cdf, u):
    """The interval i with cdf[i] <= u < cdf[i + 1] (cdf increasing from 0 to 1)."""
    lo, hi = 0, cdf.shape[0] - 2
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if cdf[mid] <= u:
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(cache=True, inline="always")
def _image_point(dx, dy, dz):
    """(x / W, y / H) in [0, 1]^2 of a unit direction, and sin theta."""
    theta = math.acos(min(1.0, max(-1.0, dy)))
    phi = math.atan2(-dz, dx) + math.pi
    return phi / (2.0 * math.pi), theta / math.pi, math.sin(theta)


@njit(cache=True, _nrt=False, forceinline=True)
def environment_radiance(image, dx, dy, dz):
    """Bilinear radiance of the environment in unit direction d."""
    rows, columns = image.shape[0], image.shape[1]
    u, v, _ = _image_point(dx, dy, dz)
    x = u * columns - 0.5
    y = v * rows - 0.5
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx, fy = x - x0, y - y0
    i0 = int(x0) % columns
    i1 = (i0 + 1) % columns
    j0 = min(max(int(y0), 0), rows - 1)
    j1 = min(max(int(y0) + 1, 0), rows - 1)
    w00, w10, w01, w11 = (1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy
    r = w00 * image[j0, i0, 0] + w10 * image[j0, i1, 0] + w01 * image[j1, i0, 0] \
        + w11 * image[j1, i1, 0]
    g = w00 * image[j0, i0, 1] + w10 * image[j0, i1, 1] + w01 * image[j1, i0, 1] \
        + w11 * image[j1, i1, 1]
    b = w00 * image[j0, i0, 2] + w10 * image[j0, i1, 2] + w01 * image[j1, i0, 2] \
        + w11 * image[j1, i1, 2]
    return r, g, b


@njit(cache=True, _nrt=False, forceinline=True)
def environment_pdf(table, dx, dy, dz):
    """Density per unit solid angle with which environment_sample returns unit direction d."""
    rows, columns = table.shape[0], table.shape[1] - 1
    u, v, sin_theta = _image_point(dx, dy, dz)
    if sin_theta <= 0.0:
        return 0.0
    i = min(int(u * columns), columns - 1)
    j = min(int(v * rows), rows - 1)
    left, right = _cell(table[j], i)
    return table[j, 0] * (right - left) * columns / (2.0 * math.pi * math.pi * sin_theta)


@njit(cache=True, _nrt=False, forceinline=True)
def environment_sample(marginal, conditional, table, u1, u2):
    """A direction by the table's distribution from two numbers in [0, 1): (x, y, z, pdf).
    `table` is `conditional` (environment_arrays), taken for the callers' sake."""
    rows, columns = conditional.shape[0], conditional.shape[1] - 1
    j = _find(marginal, u2)
    dv = (u2 - marginal[j]) / max(marginal[j + 1] - marginal[j], 1e-300)
    row = conditional[j]
    i = _find_cell(row, u1)
    left, right = _cell(row, i)
    du = (u1 - left) / max(right - left, 1e-300)
    u = (i + min(du, 1.0)) / columns
    v = (j + min(dv, 1.0)) / rows
    theta = v * math.pi
    phi = u * 2.0 * math.pi - math.pi
    sin_theta = math.sin(theta)
    if sin_theta <= 0.0:
        return 0.0, 1.0, 0.0, 0.0
    x = sin_theta * math.cos(phi)
    z = -sin_theta * math.sin(phi)
    return x, math.cos(theta), z, \
        row[0] * (right - left) * columns / (2.0 * math.pi * math.pi * sin_theta)
