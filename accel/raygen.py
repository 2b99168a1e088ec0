"""Seeded ray batches over a geometry, for tests and benchmarks (not used by rendering).

Three kinds, each deterministic for a given seed:
- sphere_rays: from random points on a sphere around the bounds toward random points inside;
- camera_rays: a pinhole camera outside the bounds looking at the centre, one ray per pixel;
- surface_rays: from random points on random triangles, in random directions, with a small tmin.
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
