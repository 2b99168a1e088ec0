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
"""
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from . import budget
from .errors import PtraceError, require_regular_file
from .io.limits import problem
from .io.quiet import library_output

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
FLOOR = 1e-3          # of the table's mean: the density's lower bound (see the docstring)
CONSTANT_SIZE = (32, 64)   # rows, columns of the image a constant environment is made of


@dataclass(eq=False)
class Environment:
    """An environment image: (H, W, 3) linear radiance, row 0 toward +Y (theta = 0)."""
    image: np.ndarray
    name: str = "environment"

    def __post_init__(self):
        image = np.asarray(self.image, dtype=np.float64)
        if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 1:
            raise PtraceError(f"{self.name}: an environment must be an (H, W, 3) image, got "
                              f"shape {image.shape}")
        if not np.isfinite(image).all() or (image < 0).any():
            raise PtraceError(f"{self.name}: the environment has negative, NaN or infinite "
                              f"pixels")
        words = problem(image)    # finite, but every sample it lights would overflow
        if words is not None:
            raise PtraceError(f"{self.name}: the environment's radiance: {words}")
        self.image = np.ascontiguousarray(image)

    @classmethod
    def constant(cls, rgb):
        rows, columns = CONSTANT_SIZE
        return cls(np.broadcast_to(np.asarray(rgb, dtype=np.float64), (rows, columns, 3)).copy(),
                   name=f"constant {tuple(float(c) for c in rgb)}")


def load_environment(spec, max_memory=None):
    """An Environment from a file OpenImageIO reads (.exr, .hdr, .png, ...; its first three
    channels, linear) or from "r,g,b" (or one number): a constant colour. An image whose size
    (read from its header, before any pixel is decoded) would need more than max_memory (as
    ptrace.budget takes it; default half the machine's memory) for its pixels and sampling
    tables is refused (a BudgetError), not downsampled: see ptrace.budget."""
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
        buffer = oiio.ImageBuf(text)
        error = buffer.geterror() if buffer.has_error else None
        spec = buffer.spec()
    if error is not None:
        raise PtraceError(f"{text}: cannot read the environment map "
                          f"({printed.one_line(error) or 'not a readable image'})")
    pixels = spec.width * spec.height
    budget.Budget.of(max_memory).charge(
        text, f"the {spec.width}x{spec.height} environment map", pixels * budget.ENVIRONMENT_BYTES)
    with library_output() as printed:
        pixels = buffer.get_pixels(oiio.FLOAT)
        error = buffer.geterror() if buffer.has_error else None
    if error is not None:
        raise PtraceError(f"{text}: cannot read the environment map "
                          f"({printed.one_line(error) or 'its pixels could not be decoded'})")
    if pixels is None or pixels.ndim != 3 or pixels.shape[2] < 3:
        channels = None if pixels is None else pixels.shape[-1]
        raise PtraceError(f"{text}: an environment map needs 3 colour channels, found {channels}")
    return Environment(pixels[:, :, :3], name=text)


def environment_arrays(environment):
    """(image (H, W, 3), marginal cdf (H + 1), conditional cdfs (H, W + 1), table (H, W) with
    mean 1, so it is the density p over [0, 1)^2) of an Environment, or empty arrays."""
    if environment is None:
        return np.zeros((0, 0, 3)), np.zeros(1), np.zeros((0, 1)), np.zeros((0, 0))
    image = environment.image
    rows, columns = image.shape[:2]
    sin_theta = np.sin((np.arange(rows) + 0.5) / rows * np.pi)
    luminance = image @ LUMINANCE
    # the cell means of the bilinear lookup: wrap around in phi, clamp at the poles
    luminance = 0.75 * luminance + 0.125 * (np.roll(luminance, 1, axis=1)
                                            + np.roll(luminance, -1, axis=1))
    above = np.concatenate([luminance[:1], luminance[:-1]])
    below = np.concatenate([luminance[1:], luminance[-1:]])
    luminance = 0.75 * luminance + 0.125 * (above + below)
    table = luminance * sin_theta[:, None]
    mean = table.mean()
    table = table + FLOOR * (mean if mean > 0 else 1.0)
    table /= table.mean()
    conditional = np.zeros((rows, columns + 1))
    conditional[:, 1:] = np.cumsum(table, axis=1)
    row_sums = conditional[:, -1].copy()
    conditional /= row_sums[:, None]
    conditional[:, -1] = 1.0
    marginal = np.zeros(rows + 1)
    marginal[1:] = np.cumsum(row_sums)
    marginal /= marginal[-1]
    marginal[-1] = 1.0
    return image, marginal, np.ascontiguousarray(conditional), np.ascontiguousarray(table)


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
    rows, columns = table.shape[0], table.shape[1]
    u, v, sin_theta = _image_point(dx, dy, dz)
    if sin_theta <= 0.0:
        return 0.0
    i = min(int(u * columns), columns - 1)
    j = min(int(v * rows), rows - 1)
    return table[j, i] / (2.0 * math.pi * math.pi * sin_theta)


@njit(cache=True, _nrt=False, forceinline=True)
def environment_sample(marginal, conditional, table, u1, u2):
    """A direction by the table's distribution from two numbers in [0, 1): (x, y, z, pdf)."""
    rows, columns = table.shape[0], table.shape[1]
    j = _find(marginal, u2)
    dv = (u2 - marginal[j]) / max(marginal[j + 1] - marginal[j], 1e-300)
    row = conditional[j]
    i = _find(row, u1)
    du = (u1 - row[i]) / max(row[i + 1] - row[i], 1e-300)
    u = (i + min(du, 1.0)) / columns
    v = (j + min(dv, 1.0)) / rows
    theta = v * math.pi
    phi = u * 2.0 * math.pi - math.pi
    sin_theta = math.sin(theta)
    if sin_theta <= 0.0:
        return 0.0, 1.0, 0.0, 0.0
    x = sin_theta * math.cos(phi)
    z = -sin_theta * math.sin(phi)
    return x, math.cos(theta), z, table[j, i] / (2.0 * math.pi * math.pi * sin_theta)
