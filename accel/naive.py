"""The naive backend: every ray against every primitive. The oracle, and a real backend.

Its compiled face (accel.compiled) loops over the triangles, then the spheres; the batch face
runs that face over the rays in parallel.
"""
import time
from collections import namedtuple

import numpy as np
from numba import njit

from . import compiled
from .kernels import (
    NO_HIT,
    MollerTrumbore,
    better,
    mesh_moller_trumbore,
    mesh_watertight,
    shear_setup,
    spheres_any,
    spheres_closest,
    triangle_test,
)

# the record of the watertight test, and of Möller–Trumbore (accel.kernels.MollerTrumbore)
NaiveRecord = namedtuple("NaiveRecord", ["vertices", "faces", "centers", "radii"])


class NaiveRecordMT(NaiveRecord, MollerTrumbore):
    __slots__ = ()


RECORDS = (NaiveRecord, NaiveRecordMT)   # by accel.kernels.triangle_test


@njit(cache=True, inline="always")
def _watertight(record, tri, shear, ox, oy, oz, dx, dy, dz):
    return mesh_watertight(record.vertices, record.faces, tri, shear)


@njit(cache=True, inline="always")
def _moller_trumbore(record, tri, shear, ox, oy, oz, dx, dy, dz):
    return mesh_moller_trumbore(record.vertices, record.faces, tri, ox, oy, oz, dx, dy, dz)


# the record's triangle test on its triangle `tri`: (t, u, v)
_triangle = compiled.by_class(MollerTrumbore, _moller_trumbore, _watertight)


@njit(cache=True)
def new_scratch(record):
    return np.empty(0)   # nothing to keep between rays


@njit(cache=True, _nrt=False, forceinline=True)
def closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    shear = shear_setup(ox, oy, oz, dx, dy, dz)
    n_tri = record.faces.shape[0]
    best_t = tmax
    best_prim = NO_HIT
    best_u = 0.0
    best_v = 0.0
    for tri in range(n_tri):
        t, u, v = _triangle(record, tri, shear, ox, oy, oz, dx, dy, dz)
        if t >= tmin and t <= best_t and better(t, tri, best_t, best_prim):
            best_t, best_prim, best_u, best_v = t, tri, u, v
    best_t, best_prim, best_u, best_v = spheres_closest(
        record.centers, record.radii, n_tri, ox, oy, oz, dx, dy, dz, tmin, best_t, best_prim,
        best_u, best_v)
    if best_prim == NO_HIT:
        best_t = np.inf
    return best_t, best_prim, best_u, best_v


@njit(cache=True, _nrt=False, forceinline=True)
def any_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    shear = shear_setup(ox, oy, oz, dx, dy, dz)
    for tri in range(record.faces.shape[0]):
        t, u, v = _triangle(record, tri, shear, ox, oy, oz, dx, dy, dz)
        if t >= tmin and t <= tmax:
            return True
    return spheres_any(record.centers, record.radii, ox, oy, oz, dx, dy, dz, tmin, tmax)


for _record in RECORDS:
    compiled.register(_record, new_scratch, closest_hit, any_hit)


class NaiveAccelerator(compiled.CompiledFace):
    kind = "naive"
    record_class = NaiveRecord

    def __init__(self, geometry, triangle="watertight"):
        start = time.perf_counter()
        self.geometry = geometry
        self.triangle = triangle
        record = RECORDS[triangle_test(triangle)]
        self.compiled = record(geometry.vertices, geometry.faces, geometry.centers, geometry.radii)
        self._build_seconds = time.perf_counter() - start

    def stats(self):
        return {**self.geometry_stats(), "triangle": self.triangle}
