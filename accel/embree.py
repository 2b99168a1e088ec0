"""The Embree backend: triangles through Embree 4's C API, called from numba; spheres stay analytic.

Why the C API. embreex's Python `run()` answers a whole batch per call, on float32 copies of the
rays made in Python, and those copies plus the call cost more than Embree's traversal itself;
nor can compiled code reach it. Here numba code calls `rtcIntersect1` / `rtcOccluded1` once per
ray, so Embree is one more compiled face (accel.compiled): the batch face runs it
over a batch, and the path tracer's one compiled loop calls it directly. The two functions are
declared as numba ExternalFunctions taking pointers as integers (intp), resolved by name in the
library loaded with llvmlite's `load_library_permanently`; code calling them stays cacheable
(`cache=True`), which it would not be through ctypes function pointers (addresses baked in).

The library, its ctypes prototypes, the two ray queries as numba externals and the building
of a scene are in accel.embree_lib.

Float32. Embree computes in float32, and float32 keeps about 7 digits of a coordinate, so
geometry far from the origin loses its shape (the cow moved far away disagreed with bvh on a large
share of the rays). So the triangles are re-centred in float64 before rounding, on the per-axis
median of the vertices, and each ray origin is moved by the same offset in float64 before
rounding (t is unchanged by a translation). The median, not the bounding box's centre: a few far
outliers move the box's centre away from where the triangles are, which made a dense cluster with
far outliers disagree on a large share of the rays (studies/stability.py measures all of this,
through the `centre` method). No translation helps a ray whose origin is far from the triangles
(a camera far from the cow disagreed with bvh on many rays: benchmarks/results/stability.md):
its float32 origin loses the ray. So each ray is first clipped, in float64, to the triangles' box in
the re-centred frame (computed at build, padded outward by BOX_PAD of its scale so that no hit on
its faces is lost to rounding): a ray whose [tmin, tmax] misses the box skips Embree (spheres are
still tested), and an origin farther than the box's scale (its largest coordinate plus its diagonal)
from where the ray enters the box is moved forward to that entry point before rounding, Embree's t
being measured from there (the shift added back in float64, tnear and tfar reduced by it). Nearer
origins are not moved: their float32 coordinates are already about as fine as the triangles', and
such rays (a camera in or by the scene, every spawned ray) keep their answers bit for bit.
`clip_to_bounds=False` turns the clipping off, for the stability study and the tests.

Grazing hits. Embree's t is off by about a float32 ulp of the coordinates divided by the cosine
between the ray and the triangle: large where a ray grazes a triangle (a surface ray meeting a
nearby fold). There (cosine below GRAZING_COSINE, judged from Embree's own normal, so the other
hits pay nothing) t, u, v are computed again in float64 on the triangle Embree found, with the
other backends' kernel (accel.kernels). Which triangle is hit still carries float32 noise: a ray
grazing an edge can go either way.

Intervals are inclusive, tmin <= t <= tmax, with Embree's own tnear and tfar (tnear <= t <= tfar,
inclusive too). Embree's t of a hit exactly at tmin can come out an ulp short, so tnear is tmin
less about 8 float32 ulps and tfar is tmax rounded down; a reported t always lies inside
[tmin, tmax]. Embree's segment cannot start behind the origin, so a negative tmin moves the origin
back by tmin instead (unless the box's entry lies beyond that point and far from it: then the
origin goes there). From a moved origin Embree's t carries the float32 noise of the box's
coordinates rather than of t, so there tnear's slack is also at least TNEAR_SLACK of the box's
scale (a hit exactly at tmin is still found). A ray float32 cannot hold (zero direction, an
overflowing coordinate of the direction or of an origin that is not moved) misses the triangles.

Spheres are few and stay analytic (accel.kernels): after the triangle query they are folded in
with tmax cut to the triangle hit, a tie going to the triangle (the lower id); sphere ids follow
the triangles. A geometry without triangles has no Embree scene at all.
"""
import time
import weakref
from collections import namedtuple

import numpy as np
from numba import njit

from . import compiled
from .embree_lib import (  # noqa: F401 - find_library and LIBRARY_PATH, re-exported as before
    LIBRARY_PATH,
    RTC_INVALID_GEOMETRY_ID,
    _build_scene,
    _release,
    find_library,
    rtc_intersect1,
    rtc_occluded1,
)
from .kernels import NO_HIT, spheres_any, spheres_closest, triangle_hit

# -- the compiled face ---------------------------------------------------------------------------

# scene: RTCScene handle (0: no triangles), valid while the accelerator lives; centre: the
# re-centring offset; box: the triangles' box in the re-centred frame, padded (lower x, y, z,
# upper x, y, z); scale: its largest coordinate's size plus its diagonal (the size of the
# coordinates Embree sees); clip: whether rays are clipped to the box (EmbreeAccelerator's
# clip_to_bounds); vertices, faces: the float64 triangles (for grazing hits; sphere ids start at
# the number of faces)
EmbreeRecord = namedtuple("EmbreeRecord", ["scene", "centre", "box", "scale", "clip", "vertices",
                                           "faces", "centers", "radii"])

# RTCRayHit, in 4-byte words from its (16-byte aligned) start. RTCRay: org_x, org_y, org_z,
# tnear, dir_x, dir_y, dir_z, time, tfar, mask, id, flags (48 bytes); RTCHit at byte 48: Ng_x,
# Ng_y, Ng_z, u, v, primID, geomID, instID[1], instPrimID[1] (Embree 4.3+), padded to 48 bytes.
_TNEAR, _TIME, _TFAR, _MASK, _ID, _FLAGS = 3, 7, 8, 9, 10, 11
_NG, _U, _V, _PRIM_ID, _GEOM_ID, _INST_ID, _INST_PRIM_ID = 12, 15, 16, 17, 18, 19, 20
# Embree's t of a hit exactly at tmin can come out an ulp short: tnear sits this fraction (about
# 8 float32 ulps) below tmin
TNEAR_SLACK = 2.0 ** -20
# the box rays are clipped to is the triangles' box padded outward by this fraction of its scale:
# thousands of float32 ulps of the coordinates, so neither the rounding of the triangles nor that
# of a moved origin puts a triangle outside it or an origin inside it
BOX_PAD = 2.0 ** -12
# a hit whose cosine to the triangle's normal is below this is computed again in float64
GRAZING_COSINE = 0.1
SCRATCH_FLOATS = 48      # 192 bytes: the 96-byte RTCRayHit at any 4-byte alignment, with room


@njit(cache=True)
def new_scratch(record):
    """(floats, words, k, address): an RTCRayHit at floats[k:], 16-byte aligned at address."""
    floats = np.zeros(SCRATCH_FLOATS, dtype=np.float32)
    base = np.int64(floats.ctypes.data)
    pad = (16 - base % 16) % 16
    return floats, floats.view(np.uint32), pad // 4, base + pad


@njit(cache=True, inline="always")
def _round_down(x):
    f = np.float32(x)
    if f > x:
        f = np.nextafter(f, np.float32(-np.inf))
    return f


@njit(cache=True, inline="always")
def _slab(lower, upper, p, d, enter, leave):
    """(enter, leave) narrowed to the parameters where p + t d lies in [lower, upper] on one axis
    (enter > leave once the ray misses)."""
    if d == 0.0:
        if p < lower or p > upper:
            return np.inf, -np.inf
        return enter, leave
    inverse = 1.0 / d
    a = (lower - p) * inverse
    b = (upper - p) * inverse
    if a > b:
        a, b = b, a
    return max(enter, a), min(leave, b)


@njit(cache=True, _nrt=False, forceinline=True)   # not inline="always": 50 blocks, 2 callers
def _set_ray(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Write the ray, in the re-centred frame, into the scratch's RTCRay. Returns (usable, shift):
    shift is what to add to Embree's t. A negative tmin moves the origin back by tmin; an origin
    far from the triangles' box is moved forward to where the ray enters it. Not usable: a ray
    float32 cannot hold, or one whose [tmin, tmax] does not meet the box."""
    floats, words, k, address = scratch
    centre = record.centre
    px = ox - centre[0]
    py = oy - centre[1]
    pz = oz - centre[2]
    shift = min(tmin, 0.0)
    moved = False
    floor = 0.0
    if record.clip:
        box = record.box
        enter, leave = -np.inf, np.inf
        enter, leave = _slab(box[0], box[3], px, dx, enter, leave)
        enter, leave = _slab(box[1], box[4], py, dy, enter, leave)
        enter, leave = _slab(box[2], box[5], pz, dz, enter, leave)
        if not max(enter, tmin) <= min(leave, tmax):
            return False, 0.0            # no triangle on [tmin, tmax]: Embree is not asked
        if enter > shift:
            # Only an origin more than the box's scale from where the ray enters the box is
            # moved. Nearer, its coordinates are at most a few times the box's, so its float32
            # rounding is about as fine as the triangles' and moving it gains nothing; and those
            # rays (cameras in or by the scene, every spawned ray) keep their answers bit for bit.
            length2 = dx * dx + dy * dy + dz * dz
            ahead = enter - shift
            if ahead * ahead * length2 > record.scale * record.scale:
                shift = enter
                moved = True
                # Embree's t now carries the float32 noise of the box's coordinates, not of t:
                # tnear's slack is at least TNEAR_SLACK of the box's scale
                floor = TNEAR_SLACK * record.scale / np.sqrt(length2)
    x = np.float32(px + shift * dx)
    y = np.float32(py + shift * dy)
    z = np.float32(pz + shift * dz)
    fx = np.float32(dx)
    fy = np.float32(dy)
    fz = np.float32(dz)
    if moved:
        near = tmin - shift
        tnear = _round_down(max(near - max(near * TNEAR_SLACK, floor), 0.0))
    else:
        tnear = _round_down((tmin - shift) * (1.0 - TNEAR_SLACK))
    tfar = _round_down(tmax - shift)
    usable = (tnear <= tfar and np.isfinite(x) and np.isfinite(y) and np.isfinite(z)
              and np.isfinite(fx) and np.isfinite(fy) and np.isfinite(fz)
              and (fx != 0.0 or fy != 0.0 or fz != 0.0))
    floats[k] = x
    floats[k + 1] = y
    floats[k + 2] = z
    floats[k + _TNEAR] = tnear
    floats[k + 4] = fx
    floats[k + 5] = fy
    floats[k + 6] = fz
    floats[k + _TIME] = 0.0
    floats[k + _TFAR] = tfar
    words[k + _MASK] = np.uint32(0xFFFFFFFF)
    words[k + _ID] = 0
    words[k + _FLAGS] = 0
    return usable, shift


@njit(cache=True, inline="always")
def _grazing(floats, k, dx, dy, dz):
    """True if the ray meets the hit triangle (its normal Ng in the RTCHit) at a cosine below
    GRAZING_COSINE."""
    nx = np.float64(floats[k + _NG])
    ny = np.float64(floats[k + _NG + 1])
    nz = np.float64(floats[k + _NG + 2])
    dot = nx * dx + ny * dy + nz * dz
    return dot * dot < GRAZING_COSINE ** 2 * (nx * nx + ny * ny + nz * nz) * (dx * dx + dy * dy
                                                                           + dz * dz)


@njit(cache=True, _nrt=False, forceinline=True)
def closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    best_t = tmax
    best_prim = NO_HIT
    best_u = 0.0
    best_v = 0.0
    if record.scene != 0:
        usable, shift = _set_ray(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)
        if usable:
            floats, words, k, address = scratch
            words[k + _GEOM_ID] = np.uint32(RTC_INVALID_GEOMETRY_ID)
            words[k + _INST_ID] = np.uint32(RTC_INVALID_GEOMETRY_ID)
            words[k + _INST_PRIM_ID] = np.uint32(RTC_INVALID_GEOMETRY_ID)
            rtc_intersect1(record.scene, address, 0)
            if words[k + _GEOM_ID] != np.uint32(RTC_INVALID_GEOMETRY_ID):
                best_prim = np.int64(words[k + _PRIM_ID])
                best_t = min(max(np.float64(floats[k + _TFAR]) + shift, tmin), tmax)
                best_u = np.float64(floats[k + _U])
                best_v = np.float64(floats[k + _V])
                if _grazing(floats, k, dx, dy, dz):
                    # float32's error in t is magnified by 1/cos here: t, u, v again in float64
                    # on the triangle Embree found, if float64 sees that hit inside the interval
                    t, u, v = triangle_hit(record.vertices, record.faces, best_prim, ox, oy, oz,
                                           dx, dy, dz)
                    if tmin <= t <= tmax:
                        best_t, best_u, best_v = t, u, v
    best_t, best_prim, best_u, best_v = spheres_closest(
        record.centers, record.radii, record.faces.shape[0], ox, oy, oz, dx, dy, dz, tmin, best_t,
        best_prim, best_u, best_v)
    if best_prim == NO_HIT:
        best_t = np.inf
    return best_t, best_prim, best_u, best_v


@njit(cache=True, _nrt=False, forceinline=True)
def any_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    if record.scene != 0:
        usable, shift = _set_ray(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)
        if usable:
            floats, words, k, address = scratch
            rtc_occluded1(record.scene, address, 0)
            if floats[k + _TFAR] == -np.inf:       # Embree's signal for "occluded"
                return True
    return spheres_any(record.centers, record.radii, ox, oy, oz, dx, dy, dz, tmin, tmax)


compiled.register(EmbreeRecord, new_scratch, closest_hit, any_hit)


# -- the accelerator -----------------------------------------------------------------------------


class EmbreeAccelerator(compiled.CompiledFace):
    """The embree backend over one geometry: owns the Embree scene and the float32 buffers it
    shares (released together when the accelerator goes), and pickles as its geometry, rebuilt
    in the other process."""
    kind = "embree"
    record_class = EmbreeRecord

    def __init__(self, geometry, clip_to_bounds=True):
        """clip_to_bounds=False turns off the clipping of rays to the triangles' box (the module
        docstring, Float32): the backend as it was before, for the stability study and the
        tests that measure what the clipping buys; ptrace never turns it off."""
        self.geometry = geometry
        self.clip_to_bounds = bool(clip_to_bounds)
        start = time.perf_counter()
        centre = np.asarray(self.centre(geometry), dtype=np.float64).reshape(3)
        scene = 0
        box = np.zeros(6)
        scale = 0.0
        if geometry.triangle_count:
            vertices = np.zeros(geometry.vertices.size + 4, dtype=np.float32)  # + 16 bytes
            for first in range(0, len(geometry.vertices), 1 << 16):   # no float64 temporary
                rows = geometry.vertices[first:first + (1 << 16)]
                vertices[3 * first:3 * (first + len(rows))] = (rows - centre).reshape(-1)
            # the geometry's int32 faces (each in 0..2**31 - 2) are Embree's uint32 indices as
            # they are: shared, not copied; the geometry outlives the scene (held here)
            indices = geometry.faces.view(np.uint32)
            box, scale = self._box(geometry, centre, vertices[:-4].reshape(-1, 3))
            device, scene = _build_scene(vertices, indices)
            # the shared buffers are owned here and by the finalizer, which lets them go last
            self._vertex_buffer, self._index_buffer = vertices, indices
            self._finalizer = weakref.finalize(self, _release, scene, device, vertices, indices)
        self.compiled = EmbreeRecord(np.int64(scene), centre, box, np.float64(scale),
                                     self.clip_to_bounds, geometry.vertices, geometry.faces,
                                     geometry.centers, geometry.radii)
        self._build_seconds = time.perf_counter() - start

    @staticmethod
    def _box(geometry, centre, rounded):
        """(box, scale): the box of the triangles' corners in the re-centred frame, both as float64
        and as the float32 Embree holds (rounded), padded outward by BOX_PAD x scale; scale is the
        largest coordinate's size plus the diagonal of the unpadded box."""
        used = np.zeros(geometry.vertices.shape[0], dtype=bool)
        used[geometry.faces.reshape(-1)] = True
        exact = geometry.vertices[used] - centre
        rounded = rounded[used].astype(np.float64)
        lower = np.minimum(exact.min(axis=0), rounded.min(axis=0))
        upper = np.maximum(exact.max(axis=0), rounded.max(axis=0))
        scale = float(np.abs(np.concatenate([lower, upper])).max()
                      + np.linalg.norm(upper - lower))
        pad = BOX_PAD * scale
        return np.concatenate([lower - pad, upper + pad]), scale

    def centre(self, geometry):
        """The offset the triangles and ray origins are moved by before rounding to float32:
        the per-axis median of the vertices (see the module docstring)."""
        if geometry.vertices.shape[0] == 0:
            return np.zeros(3)
        return np.median(geometry.vertices, axis=0)

    def __reduce__(self):
        # Embree handles mean nothing in another process: a copy is rebuilt from the geometry
        return type(self), (self.geometry, self.clip_to_bounds)

    def stats(self):
        return self.geometry_stats()
