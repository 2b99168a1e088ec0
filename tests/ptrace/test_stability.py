"""Where methods break: no non-finite pixel anywhere in the seed's flag space, and spawned rays
never re-hit the surface they leave, at any scale, on any backend."""
import numpy as np
import pytest

import accel
import ptrace
from ptrace.integrator import OFFSET, spawn

SEED_FLAGS = [
    dict(max_depth=0), dict(max_depth=1), dict(max_depth=1, hemisphere=True),
    dict(max_depth=2, light_samples=4), dict(max_depth=6, light_samples=16),
    dict(max_depth=6, light_samples=8, hemisphere=True), dict(max_depth=100, light_samples=4),
    dict(max_depth=5, light_samples=1, adaptive=(2, 0.05)),
]


@pytest.mark.slow
def test_no_non_finite_pixel_in_any_course_scene(scenes_dir):
    import warnings
    files = sorted(scenes_dir.rglob("*.dae"))
    assert len(files) == 25
    for path in files:
        scene = ptrace.load(path)
        for flags in SEED_FLAGS:
            stats = {}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)   # -H on delta-lit scenes
                ptrace.render(scene, spp=4, resolution=(16, 12), stats=stats, **flags)
            assert stats["nonfinite"] == 0, (path.name, flags, stats["nonfinite"])


def spawned_rays(scale, count=4000, seed=0):
    """Random triangles whose coordinates are about `scale`, and rays leaving random points on
    them by ptrace's rule: offset OFFSET x the largest coordinate along the geometric normal,
    toward a random direction on that side."""
    rng = np.random.default_rng(seed)
    centres = scale * (rng.random((count, 3)) - 0.5) * 2
    corners = centres[:, None, :] + scale * 0.01 * rng.normal(size=(count, 3, 3))
    geometry = accel.Geometry(corners.reshape(-1, 3), np.arange(3 * count).reshape(count, 3))
    a, b = rng.random(count), rng.random(count)
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    points = (1 - a - b)[:, None] * corners[:, 0] + a[:, None] * corners[:, 1] \
        + b[:, None] * corners[:, 2]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    side = np.where(rng.random(count) < 0.5, 1.0, -1.0)[:, None]
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    direction *= np.sign(np.sum(direction * normal * side, axis=1))[:, None]
    magnitude = np.maximum(np.abs(points).max(axis=1), np.abs(corners).max(axis=(1, 2)))
    return geometry, accel.Rays(spawned(points, normal, OFFSET * magnitude, direction),
                                direction), np.arange(count)


def spawned(points, normals, offsets, directions):
    """The path loop's own spawn (ptrace.integrator.spawn: along the geometric normal, on the
    side of the new direction) of each ray."""
    return np.array([spawn(*p, *g, e, *w) for p, g, e, w in zip(points, normals, offsets,
                                                                  directions)])


@pytest.mark.parametrize("kind", accel.KINDS)
def test_spawned_rays_never_rehit_their_own_triangle(kind):
    rates = {}
    for scale in (1e-8, 1e-3, 1.0, 1e3, 1e8):
        geometry, rays, own = spawned_rays(scale)
        hits = accel.build(kind, geometry).intersect(rays)
        rates[scale] = float(np.mean(hits.prim == own))
    print(f"{kind}: self-hit rate by scale {rates}")
    assert all(rate == 0.0 for rate in rates.values())


@pytest.mark.parametrize("kind", accel.KINDS)
def test_spawned_rays_leave_spheres(kind):
    rng = np.random.default_rng(1)
    for scale in (1e-6, 1.0, 1e6):
        centres = scale * rng.normal(size=(500, 3))
        radii = scale * (0.01 + rng.random(500))
        geometry = accel.Geometry(np.zeros((0, 3)), np.zeros((0, 3), dtype=int), centres, radii)
        normal = rng.normal(size=(500, 3))
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        points = centres + radii[:, None] * normal
        side = np.where(rng.random(500) < 0.5, 1.0, -1.0)[:, None]   # outside or inside
        direction = rng.normal(size=(500, 3))
        direction *= np.sign(np.sum(direction * normal * side, axis=1))[:, None]
        magnitude = np.maximum(np.abs(points).max(axis=1), np.abs(centres).max(axis=1) + radii)
        origins = spawned(points, normal, OFFSET * magnitude, direction)
        hits = accel.build(kind, geometry).intersect(accel.Rays(origins, direction))
        own = np.arange(500)
        # leaving outward: never the own sphere; leaving inward: the own sphere's far side only
        outward = side[:, 0] > 0
        assert not np.any(hits.prim[outward] == own[outward]), (kind, scale)
        inward_own = hits.prim[~outward] == own[~outward]
        far = hits.t[~outward][inward_own] > radii[~outward][inward_own] * 1e-3
        assert far.all(), (kind, scale)
