"""Seeded ray batches over a geometry, for tests and benchmarks (not used by rendering).

Four kinds, each deterministic for a given seed:
- sphere_rays: from random points on a sphere around the bounds toward random points inside;
- camera_rays: a pinhole camera outside the bounds looking at the centre, one ray per pixel;
- surface_rays: from random points on random triangles, in random directions, with a small tmin;
- shadow_rays: segments from surface_rays' points to random points on a small square light above
  the bounds (or a given parallelogram light), for any-hit (occluded) queries;
- distant_rays: from random points on a sphere of a given (large) radius around the bounds'
  centre toward random points inside: a camera far from the geometry.
"""
import numpy as np

from .types import Rays


def _frame(geometry):
    bounds = geometry.bounds()
    if bounds is None:
        return np.zeros(3), 1.0
    lower, upper = bounds
    centre = 0.5 * (lower + upper)
    radius = 0.5 * float(np.linalg.norm(upper - lower)) or 1.0
    return centre, radius


def _unit_vectors(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def sphere_rays(geometry, n, seed=0):
    rng = np.random.default_rng(seed)
    centre, radius = _frame(geometry)
    origins = centre + 1.5 * radius * _unit_vectors(rng, n)
    lower, upper = geometry.bounds() if geometry.primitive_count else (centre - 1, centre + 1)
    targets = lower + rng.random((n, 3)) * (upper - lower)
    return Rays(origins, targets - origins)


def distant_rays(geometry, n, distance, seed=0):
    """n rays from a sphere of radius `distance` about the bounds' centre, each aimed at a
    random point of the bounds; seed may be a numpy Generator (draws continue from it)."""
    rng = np.random.default_rng(seed)
    lower, upper = geometry.bounds()
    origins = 0.5 * (lower + upper) + distance * _unit_vectors(rng, n)
    targets = lower + rng.random((n, 3)) * (upper - lower)
    return Rays(origins, targets - origins)


def camera_rays(geometry, width, height, seed=0, fov_degrees=40.0):
    rng = np.random.default_rng(seed)
    centre, radius = _frame(geometry)
    direction = _unit_vectors(rng, 1)[0]
    eye = centre + 3.0 * radius * direction
    forward = -direction
    helper = np.array([0.0, 1.0, 0.0]) if abs(forward[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    right = np.cross(forward, helper)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = np.tan(np.radians(fov_degrees) / 2)
    xs = ((np.arange(width) + 0.5) / width * 2 - 1) * half * width / height
    ys = ((np.arange(height) + 0.5) / height * 2 - 1) * half
    gx, gy = np.meshgrid(xs, ys)
    directions = forward + gx.reshape(-1, 1) * right + gy.reshape(-1, 1) * up
    return Rays(np.broadcast_to(eye, directions.shape), directions)


def surface_rays(geometry, n, seed=0, tmin_scale=1e-4):
    """Rays leaving points on triangles (spheres for a sphere-only geometry)."""
    rng = np.random.default_rng(seed)
    centre, radius = _frame(geometry)
    if geometry.triangle_count:
        tri = rng.integers(0, geometry.triangle_count, n)
        a, b = rng.random(n), rng.random(n)
        flip = a + b > 1
        a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
        p = geometry.vertices[geometry.faces[tri]]
        origins = (1 - a - b)[:, None] * p[:, 0] + a[:, None] * p[:, 1] + b[:, None] * p[:, 2]
    elif geometry.sphere_count:
        s = rng.integers(0, geometry.sphere_count, n)
        origins = geometry.centers[s] + geometry.radii[s, None] * _unit_vectors(rng, n)
    else:
        origins = centre + rng.normal(size=(n, 3))
    return Rays(origins, _unit_vectors(rng, n), tmin=tmin_scale * radius)


def light_square(geometry):
    """(centre, edge_x, edge_y) of shadow_rays' default light: a horizontal square facing down,
    centred over the bounds' top face at 1.5 box heights above the box centre along +y (at least
    1.5 quarter-diagonals, so a flat mesh still gets a light above it), side a quarter of the
    box diagonal."""
    centre, radius = _frame(geometry)
    bounds = geometry.bounds()
    height = 0.0 if bounds is None else float(bounds[1][1] - bounds[0][1])
    side = 0.5 * radius                                 # a quarter of the diagonal (2 * radius)
    above = centre + np.array([0.0, 1.5 * max(height, side), 0.0])
    return above, np.array([side, 0.0, 0.0]), np.array([0.0, 0.0, side])


def shadow_rays(geometry, n, seed=0, tmin_scale=1e-4, light=None):
    """Shadow segments from points on the surface to points on a light, for occluded().

    Origins are exactly surface_rays(geometry, n, seed, tmin_scale)'s (points on random
    triangles; spheres for a sphere-only geometry). Each ray aims at a uniform random point
    q = centre + s * edge_x + r * edge_y (s, r in [-1/2, 1/2]) of the parallelogram light
    `light` = (centre, edge_x, edge_y), by default light_square(geometry). The direction is
    q - origin, not normalised, so t in [tmin, tmax] spans the segment, trimmed at both ends by
    the same fraction of its length: tmin = tmin_scale (off the surface) and
    tmax = 1 - tmin_scale (just short of the light, which may be geometry itself). Both are
    scalars, as in the other generators (a per-ray t bound array would be a read-only view
    inside Rays, another numba specialisation of every kernel).
    """
    surface = surface_rays(geometry, n, seed=seed, tmin_scale=tmin_scale)
    centre, edge_x, edge_y = light_square(geometry) if light is None else (
        np.asarray(part, dtype=np.float64) for part in light)
    rng = np.random.default_rng((seed, 1))   # independent of surface_rays' stream
    s, r = rng.random(n) - 0.5, rng.random(n) - 0.5
    targets = centre + s[:, None] * edge_x + r[:, None] * edge_y
    return Rays(surface.origins, targets - surface.origins, tmin=tmin_scale,
                tmax=1.0 - tmin_scale)
