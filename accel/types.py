"""The data that crosses the accel interface: geometry, a batch of rays, a batch of hits.

Everything is a flat, C-contiguous numpy array (structure of arrays), so numba kernels and
Embree can take them as they are.
"""
from dataclasses import dataclass

import numpy as np
from numba import njit

# faces are int32: a mesh indexes at most this many vertices (one dtype for every mesh, so that
# no kernel is compiled twice, and 12 bytes a triangle that Embree shares as its index buffer)
MAX_VERTICES = np.iinfo(np.int32).max


def _checked_array(name, value, shape_tail, dtype=np.float64, rows="N"):
    """`value` as a C-contiguous array of `dtype` and shape (rows, *shape_tail) (an empty one
    reshaped to that), or ValueError naming `name` and the shape it has."""
    array = np.ascontiguousarray(value, dtype=dtype)
    if array.size == 0:
        array = array.reshape((0,) + shape_tail)
    if array.shape[1:] != shape_tail or array.ndim != 1 + len(shape_tail):
        raise ValueError(f"{name} must have shape ({rows}, {', '.join(map(str, shape_tail))})"
                         f" but has shape {array.shape}")
    return array


def _int32_faces(value, n_vertices):
    """`value` as C-contiguous int32 faces of shape (F, 3), each index in 0..n_vertices - 1
    (checked before the cast, which would wrap a larger one), or ValueError."""
    faces = np.asarray(value)
    if faces.dtype != np.int32:
        faces = np.asarray(faces, dtype=np.int64)
    faces = _checked_array("faces", faces, (3,), dtype=faces.dtype, rows="F")
    if faces.size and (faces.min() < 0 or faces.max() >= n_vertices):
        raise ValueError(f"faces index vertices outside 0..{n_vertices - 1}")
    return np.ascontiguousarray(faces, dtype=np.int32)


def _store(instance, **arrays):
    """Set a frozen dataclass's fields to their checked arrays (its __post_init__'s last step)."""
    for name, array in arrays.items():
        object.__setattr__(instance, name, array)


@dataclass(frozen=True, eq=False)
class Geometry:
    """Triangles (vertices, faces) and analytic spheres (centers, radii).

    Primitive ids: triangles 0..F-1, then spheres F..F+S-1. Vertices are float64, faces int32
    (at most MAX_VERTICES vertices).
    """
    vertices: np.ndarray
    faces: np.ndarray
    centers: np.ndarray = None
    radii: np.ndarray = None

    def __post_init__(self):
        if len(self.vertices) > MAX_VERTICES:
            raise ValueError(f"the mesh has {len(self.vertices):,} vertices, more than the "
                             f"{MAX_VERTICES:,} its int32 faces can index")
        vertices = _checked_array("vertices", self.vertices, (3,))
        faces = _int32_faces(self.faces, len(vertices))
        centers = _checked_array("centers",
                                 np.empty((0, 3)) if self.centers is None else self.centers, (3,))
        radii = np.ascontiguousarray(np.empty(0) if self.radii is None else self.radii,
                                     dtype=np.float64).reshape(-1)
        if radii.shape[0] != centers.shape[0]:
            raise ValueError(f"{centers.shape[0]} sphere centers but {radii.shape[0]} radii")
        if not np.isfinite(vertices).all():
            raise ValueError("vertices contain NaN or infinite coordinates")
        if not (np.isfinite(centers).all() and np.isfinite(radii).all()):
            raise ValueError("spheres contain NaN or infinite values")
        if (radii < 0).any():
            raise ValueError("sphere radii must not be negative")
        _store(self, vertices=vertices, faces=faces, centers=centers, radii=radii)

    @property
    def triangle_count(self):
        return self.faces.shape[0]

    @property
    def sphere_count(self):
        return self.centers.shape[0]

    @property
    def primitive_count(self):
        return self.triangle_count + self.sphere_count

    def primitive_bounds(self):
        """(lower, upper) corners of each primitive's box, shape (P, 3) each (computed a chunk
        of triangles at a time: no (F, 3, 3) array of corners)."""
        n_tri, n_sph = self.triangle_count, self.sphere_count
        lower = np.empty((n_tri + n_sph, 3))
        upper = np.empty((n_tri + n_sph, 3))
        for first in range(0, n_tri, 1 << 16):
            corners = self.vertices[self.faces[first:first + (1 << 16)]]
            corners.min(axis=1, out=lower[first:first + len(corners)])
            corners.max(axis=1, out=upper[first:first + len(corners)])
        lower[n_tri:] = self.centers - self.radii[:, None]
        upper[n_tri:] = self.centers + self.radii[:, None]
        return lower, upper

    def bounds(self):
        """(lower, upper) of the whole geometry, or None when it is empty. Computed once (every
        render asks, for its camera); the geometry's arrays are not to be changed in place."""
        if self.primitive_count == 0:
            return None
        cached = self.__dict__.get("_bounds")
        if cached is None:
            lower, upper = self.primitive_bounds()
            cached = (lower.min(axis=0), upper.max(axis=0))
            object.__setattr__(self, "_bounds", cached)
        return cached[0].copy(), cached[1].copy()


@dataclass(frozen=True, eq=False)
class Rays:
    """A batch of N rays: points origin + t * direction with tmin <= t <= tmax.

    Directions need not be unit length; t is measured in units of the direction. tmin and tmax
    are per ray, or one number for every ray (None: the default).
    """
    origins: np.ndarray
    directions: np.ndarray
    tmin: np.ndarray = 0.0
    tmax: np.ndarray = np.inf

    def __post_init__(self):
        origins = _checked_array("origins", self.origins, (3,))
        directions = _checked_array("directions", self.directions, (3,))
        n = origins.shape[0]
        if directions.shape[0] != n:
            raise ValueError(f"{n} origins but {directions.shape[0]} directions")
        tmin, tmax = (_t_bounds(default if value is None else value, n)
                      for value, default in ((self.tmin, 0.0), (self.tmax, np.inf)))
        _store(self, origins=origins, directions=directions, tmin=tmin, tmax=tmax)

    def __len__(self):
        return self.origins.shape[0]

    def validate(self):
        """Raise ValueError for rays no backend can answer (NaN or infinite parts)."""
        problem = _ray_problem(self.origins, self.directions, self.tmin, self.tmax)
        if problem == 1:
            raise ValueError("rays contain NaN or infinite origins or directions")
        if problem == 2:
            raise ValueError("rays contain NaN t bounds or an infinite tmin")


def _t_bounds(value, n):
    """A t bound as n float64 values: a scalar made an array, an array of n kept as it is (not a
    broadcast view, which numpy makes read-only: a read-only array is another type to numba, and
    every kernel would compile once more for the batches that carry one)."""
    value = np.asarray(value, dtype=np.float64)
    return np.ascontiguousarray(value if value.shape == (n,) else np.broadcast_to(value, (n,)))


@njit(cache=True)
def _ray_problem(origins, directions, tmin, tmax):
    """0 if every ray is answerable, 1 for a non-finite origin or direction, 2 for a NaN t
    bound or an infinite tmin. One pass and no temporaries: every wave of a render is
    validated, and numpy's isfinite/all over each array cost more than the check is worth."""
    for i in range(origins.shape[0]):
        for c in range(3):
            if not (np.isfinite(origins[i, c]) and np.isfinite(directions[i, c])):
                return 1
    for i in range(tmin.shape[0]):
        if not np.isfinite(tmin[i]) or np.isnan(tmax[i]):
            return 2
    return 0


@dataclass(frozen=True, eq=False)
class Hits:
    """Closest hits of a batch of rays.

    t is inf and prim is -1 on a miss; (u, v) are barycentrics with
    hit = (1-u-v)*p0 + u*p1 + v*p2 for triangles and 0 for spheres.
    """
    t: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray

    def disagreement(self, reference, t_tolerance=1e-4):
        """Fractions of rays on which these hits differ from reference's: hit against miss,
        another primitive, t off by more than t_tolerance relative, and any of the three (to
        compare a float32 backend with a float64 one, in tests and benchmarks)."""
        hit_miss = (reference.prim >= 0) != (self.prim >= 0)
        both = (reference.prim >= 0) & (self.prim >= 0)
        other_prim = both & (reference.prim != self.prim)
        relative = np.zeros(len(reference.prim))
        relative[both] = np.abs(self.t[both] - reference.t[both]) / np.abs(reference.t[both])
        far_t = both & (relative > t_tolerance)
        return {"hit_miss": float(hit_miss.mean()), "prim": float(other_prim.mean()),
                "t": float(far_t.mean()), "any": float((hit_miss | other_prim | far_t).mean())}

    @classmethod
    def empty(cls, n):
        return cls(np.full(n, np.inf), np.full(n, -1, dtype=np.int64), np.zeros(n), np.zeros(n))

    def __len__(self):
        return self.t.shape[0]
