"""Embree indexes the geometry's own int32 faces (a uint32 view, not a copy), and they live as
long as its scene: the answers stay the same after every other reference to them is gone."""
import gc

import numpy as np

import accel
from accel import raygen


def mesh(seed=5, n=400):
    """A soup of n small triangles with shared corners (faces in no particular order)."""
    rng = np.random.default_rng(seed)
    vertices = rng.random((n, 3))
    faces = np.stack([rng.permutation(n), rng.permutation(n), rng.permutation(n)], axis=1)
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
                  & (faces[:, 0] != faces[:, 2])]
    return vertices, faces


def test_embree_shares_the_geometry_s_faces_as_its_index_buffer():
    vertices, faces = mesh()
    geometry = accel.Geometry(vertices, faces)
    backend = accel.build("embree", geometry)
    shared = backend._index_buffer
    assert shared.dtype == np.uint32
    assert np.shares_memory(shared, geometry.faces)
    np.testing.assert_array_equal(shared, faces)         # the values Embree reads


def test_the_shared_faces_outlive_every_other_reference():
    """The accelerator alone keeps them: answers after the loader's arrays and the geometry
    are dropped (and memory reused) equal those before, and a float64 naive's prims."""
    vertices, faces = mesh()
    geometry = accel.Geometry(vertices, faces)
    rays = raygen.sphere_rays(geometry, 3000, seed=7)
    reference = accel.build("naive", geometry).intersect(rays)
    backend = accel.build("embree", geometry)
    before = backend.intersect(rays)
    del geometry, vertices, faces
    gc.collect()
    clutter = [np.full((400, 3), -7, np.int32) for _ in range(200)]   # reuse freed memory
    after = backend.intersect(rays)
    del clutter
    np.testing.assert_array_equal(after.prim, before.prim)
    np.testing.assert_array_equal(after.t, before.t)
    hit = reference.prim >= 0
    assert hit.sum() > 0.3 * len(rays)
    assert (after.prim == reference.prim).sum() >= 0.999 * len(rays)
