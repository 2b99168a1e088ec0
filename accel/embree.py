"""The Embree backend: triangles through embreex (Intel Embree), spheres stay analytic.

embreex facts this module works around (DESIGN.md):
- float32 only: geometry and rays are rounded to float32, so hits can differ from ours in the
  last bits of t, and a ray grazing an edge can go either way. Float32 keeps about 7 digits of
  a coordinate, so geometry far from the origin loses its shape (the cow moved 1e4 away
  disagreed with bvh on about a third of the rays). So the triangles are re-centred in float64
  before rounding, on the per-axis median of the vertices, and each ray origin is moved by
  the same offset (t is unchanged by a translation). The median, not the bounding box's
  centre: a few far outliers move the box's centre away from where the triangles are, which
  made a dense cluster with outliers 1e6 away disagree on a third or more of the rays (see
  benchmarks/stability.py, which measures all of this).
- no tnear: tmin is emulated by starting the ray at origin + tmin * direction and adding tmin
  back to the hit distance.
- an array passed as `dists` may be overwritten, so it is always a fresh array.
- the scene is committed on the first run(), so the constructor runs one ray to commit it
  before any thread shares the scene.
- run() releases the GIL, so a batch is split across threads (numba's thread count).
Spheres use the same analytic kernel as our backends and keep the nearer hit.
"""
import time
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from embreex import mesh_construction, rtcore_scene

from .naive import _intersect_all, _occluded_all
from .types import Hits

MIN_CHUNK = 8192


class EmbreeAccelerator:
    kind = "embree"

    def __init__(self, geometry):
        self.geometry = geometry
        start = time.perf_counter()
        self._scene = None
        self._centre = np.zeros(3)
        if geometry.triangle_count:
            self._centre = np.median(geometry.vertices, axis=0)
            self._scene = rtcore_scene.EmbreeScene(robust=True)
            mesh_construction.TriangleMesh(
                self._scene, (geometry.vertices - self._centre).astype(np.float32),
                geometry.faces.astype(np.int32))
            one = np.zeros((1, 3), dtype=np.float32)
            self._scene.run(one, one + np.float32(1.0), output=1)   # commit the scene now
        self._no_faces = np.zeros((0, 3), dtype=np.int64)
        self._pool, self._pool_size = None, 0
        self._build_seconds = time.perf_counter() - start

    # -- embree part ---------------------------------------------------------------------------
    def _chunks(self, n):
        threads = max(1, numba.get_num_threads())
        count = max(1, min(threads, n // MIN_CHUNK))
        bounds = np.linspace(0, n, count + 1).astype(np.int64)
        return [(bounds[i], bounds[i + 1]) for i in range(count)]

    def _map(self, function, n):
        chunks = self._chunks(n)
        if len(chunks) == 1:
            return [function(*chunks[0])]
        # one pool per accelerator, not per call: this runs once per wave of rays
        if self._pool is None or self._pool_size < len(chunks):
            if self._pool is not None:
                self._pool.shutdown()
            self._pool, self._pool_size = ThreadPoolExecutor(len(chunks)), len(chunks)
        return list(self._pool.map(lambda c: function(*c), chunks))

    def _embree_rays(self, rays, a, b):
        tmin = rays.tmin[a:b]
        # in the re-centred frame of the triangles handed to Embree (see the module docstring)
        origins = ((rays.origins[a:b] - self._centre)
                   + tmin[:, None] * rays.directions[a:b]).astype(np.float32)
        directions = rays.directions[a:b].astype(np.float32)
        dists = (rays.tmax[a:b] - tmin).astype(np.float32)   # a fresh array each call
        return origins, directions, dists

    def _triangles_intersect(self, rays):
        n = len(rays)
        t = np.full(n, np.inf)
        prim = np.full(n, -1, dtype=np.int64)
        u = np.zeros(n)
        v = np.zeros(n)
        if self._scene is None or n == 0:
            return t, prim, u, v

        def run(a, b):
            origins, directions, dists = self._embree_rays(rays, a, b)
            out = self._scene.run(origins, directions, dists=dists, output=1)
            hit = out["primID"] >= 0
            t[a:b] = np.where(hit, out["tfar"].astype(np.float64) + rays.tmin[a:b], np.inf)
            prim[a:b] = np.where(hit, out["primID"], -1)
            u[a:b] = np.where(hit, out["u"], 0.0)
            v[a:b] = np.where(hit, out["v"], 0.0)

        self._map(run, n)
        return t, prim, u, v

    def _triangles_occluded(self, rays):
        n = len(rays)
        out = np.zeros(n, dtype=np.bool_)
        if self._scene is None or n == 0:
            return out

        def run(a, b):
            origins, directions, dists = self._embree_rays(rays, a, b)
            answer = self._scene.run(origins, directions, dists=dists, query="OCCLUDED")
            out[a:b] = answer == 0       # embreex: 0 occluded, -1 clear

        self._map(run, n)
        return out

    # -- the interface -------------------------------------------------------------------------
    def intersect(self, rays):
        rays.validate()
        t, prim, u, v = self._triangles_intersect(rays)
        g = self.geometry
        if g.sphere_count:
            n = len(rays)
            s_t = np.empty(n)
            s_prim = np.empty(n, dtype=np.int64)
            s_u = np.empty(n)
            s_v = np.empty(n)
            # spheres only, with tmax cut to the triangle hit; a tie goes to the triangle (lower id)
            _intersect_all(g.vertices, self._no_faces, g.centers, g.radii, rays.origins,
                           rays.directions, rays.tmin, np.minimum(rays.tmax, t),
                           s_t, s_prim, s_u, s_v)
            nearer = (s_prim >= 0) & (s_t < t)
            t = np.where(nearer, s_t, t)
            prim = np.where(nearer, s_prim + g.triangle_count, prim)
            u = np.where(nearer, 0.0, u)
            v = np.where(nearer, 0.0, v)
        return Hits(t, prim, u, v)

    def occluded(self, rays):
        rays.validate()
        out = self._triangles_occluded(rays)
        g = self.geometry
        if g.sphere_count:
            spheres = np.empty(len(rays), dtype=np.bool_)
            _occluded_all(g.vertices, self._no_faces, g.centers, g.radii, rays.origins,
                          rays.directions, rays.tmin, rays.tmax, spheres)
            out |= spheres
        return out

    def stats(self):
        return {"kind": self.kind, "primitives": self.geometry.primitive_count,
                "triangles": self.geometry.triangle_count, "spheres": self.geometry.sphere_count,
                "build_seconds": self._build_seconds}
