"""The naive backend: every ray against every primitive. The oracle, and a real backend."""
import time

import numpy as np
from numba import njit, prange

from .kernels import NO_HIT, better, sphere_hit, triangle_hit
from .types import Hits


@njit(cache=True, parallel=True)
def _intersect_all(vertices, faces, centers, radii, origins, directions, tmin, tmax,
                   out_t, out_prim, out_u, out_v):
    n_tri = faces.shape[0]
    n_sph = centers.shape[0]
    for r in prange(origins.shape[0]):
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        lo = tmin[r]
        best_t = tmax[r]
        best_prim = NO_HIT
        best_u = 0.0
        best_v = 0.0
        for tri in range(n_tri):
            t, u, v = triangle_hit(vertices, faces, tri, ox, oy, oz, dx, dy, dz)
            if t >= lo and t <= best_t and better(t, tri, best_t, best_prim):
                best_t, best_prim, best_u, best_v = t, tri, u, v
        for s in range(n_sph):
            t = sphere_hit(centers, radii, s, ox, oy, oz, dx, dy, dz, lo, best_t)
            if t <= best_t and better(t, n_tri + s, best_t, best_prim):
                best_t, best_prim, best_u, best_v = t, n_tri + s, 0.0, 0.0
        if best_prim == NO_HIT:
            best_t = np.inf
        out_t[r] = best_t
        out_prim[r] = best_prim
        out_u[r] = best_u
        out_v[r] = best_v


@njit(cache=True, parallel=True)
def _occluded_all(vertices, faces, centers, radii, origins, directions, tmin, tmax, out):
    n_tri = faces.shape[0]
    n_sph = centers.shape[0]
    for r in prange(origins.shape[0]):
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        lo = tmin[r]
        hi = tmax[r]
        hit = False
        for tri in range(n_tri):
            t, u, v = triangle_hit(vertices, faces, tri, ox, oy, oz, dx, dy, dz)
            if t >= lo and t <= hi:
                hit = True
                break
        if not hit:
            for s in range(n_sph):
                if sphere_hit(centers, radii, s, ox, oy, oz, dx, dy, dz, lo, hi) <= hi:
                    hit = True
                    break
        out[r] = hit


class NaiveAccelerator:
    kind = "naive"

    def __init__(self, geometry):
        start = time.perf_counter()
        self.geometry = geometry
        self._build_seconds = time.perf_counter() - start

    def intersect(self, rays):
        rays.validate()
        n = len(rays)
        hits = Hits(np.empty(n), np.empty(n, dtype=np.int64), np.empty(n), np.empty(n))
        g = self.geometry
        _intersect_all(g.vertices, g.faces, g.centers, g.radii, rays.origins, rays.directions,
                       rays.tmin, rays.tmax, hits.t, hits.prim, hits.u, hits.v)
        return hits

    def occluded(self, rays):
        rays.validate()
        out = np.empty(len(rays), dtype=np.bool_)
        g = self.geometry
        _occluded_all(g.vertices, g.faces, g.centers, g.radii, rays.origins, rays.directions,
                      rays.tmin, rays.tmax, out)
        return out

    def stats(self):
        return {"kind": self.kind, "primitives": self.geometry.primitive_count,
                "triangles": self.geometry.triangle_count, "spheres": self.geometry.sphere_count,
                "build_seconds": self._build_seconds}
