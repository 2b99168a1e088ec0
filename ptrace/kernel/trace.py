"""The backend's part of the wavefront: closest and any hit over a queue of rays, through the
compiled face (accel.compiled). These small kernels are the only code compiled once per backend;
every other stage is compiled once for all of them. A scene with cut-out materials gets the
variants that trace past the surfaces a ray passes through (ptrace.cutouts), each ray with its
key (ptrace.integrator.RAY_KEYS); the others never compile that code."""
import numpy as np
from numba import njit

from accel.compiled import any_hit, closest_hit

from ..cutouts import shadowed, visible_hit
from .layout import (
    DX,
    DY,
    DZ,
    KEY,
    OX,
    OY,
    OZ,
    PIXEL,
    PRIM,
    SAMPLE,
    SDX,
    SDY,
    SDZ,
    SOX,
    SOY,
    SOZ,
    STMAX,
    TMAX,
    TMIN,
    T,
    U,
    V,
)


@njit(cache=True, nogil=True, _nrt=False)
def closest_stage(record, scratch, floats, ints, queue, n):
    """The closest hit (t, prim, u, v) of each queued path's ray in [tmin, tmax]."""
    for k in range(n):
        i = queue[k]
        t, prim, u, v = closest_hit(record, scratch, floats[OX, i], floats[OY, i], floats[OZ, i],
                                    floats[DX, i], floats[DY, i], floats[DZ, i], floats[TMIN, i],
                                    floats[TMAX, i])
        floats[T, i] = t
        floats[U, i] = u
        floats[V, i] = v
        ints[PRIM, i] = prim


@njit(cache=True, nogil=True, _nrt=False)
def any_stage(record, scratch, shadow, n, blocked):
    """Whether anything lies on each of the first n shadow rays, in [0, its end]."""
    for s in range(n):
        blocked[s] = any_hit(record, scratch, shadow[SOX, s], shadow[SOY, s], shadow[SOZ, s],
                             shadow[SDX, s], shadow[SDY, s], shadow[SDZ, s], 0.0,
                             shadow[STMAX, s])


@njit(cache=True, nogil=True, _nrt=False)
def visible_stage(record, scratch, shapes, materials, options, floats, ints, queue, n):
    """closest_stage past the cut-out surfaces (ptrace.cutouts.visible_hit)."""
    for k in range(n):
        i = queue[k]
        t, prim, u, v = visible_hit(shapes, materials, options, record, scratch, ints[PIXEL, i],
                                    ints[SAMPLE, i], np.int64(ints[KEY, i]), floats[OX, i],
                                    floats[OY, i], floats[OZ, i], floats[DX, i], floats[DY, i],
                                    floats[DZ, i], floats[TMIN, i], floats[TMAX, i])
        floats[T, i] = t
        floats[U, i] = u
        floats[V, i] = v
        ints[PRIM, i] = prim


@njit(cache=True, nogil=True, _nrt=False)
def shadowed_stage(record, scratch, shapes, materials, options, ints, shadow, shadow_path,
                   shadow_key, n, blocked):
    """any_stage past the cut-out surfaces (ptrace.cutouts.shadowed)."""
    for s in range(n):
        i = shadow_path[s]
        blocked[s] = shadowed(shapes, materials, options, record, scratch, ints[PIXEL, i],
                              ints[SAMPLE, i], np.int64(shadow_key[s]), shadow[SOX, s],
                              shadow[SOY, s], shadow[SOZ, s], shadow[SDX, s], shadow[SDY, s],
                              shadow[SDZ, s], shadow[STMAX, s])


@njit(cache=True, nogil=True, _nrt=False)
def probe_stage(record, scratch, shadow, n, probe_prim, probe_uv):
    """(-H) The closest hit (prim, u, v) of each of the first n rays of the shadow queue, which
    holds the hemisphere's rays, in [0, its end]."""
    for s in range(n):
        t, prim, u, v = closest_hit(record, scratch, shadow[SOX, s], shadow[SOY, s],
                                    shadow[SOZ, s], shadow[SDX, s], shadow[SDY, s],
                                    shadow[SDZ, s], 0.0, shadow[STMAX, s])
        probe_prim[s] = prim
        probe_uv[0, s] = u
        probe_uv[1, s] = v


@njit(cache=True, nogil=True, _nrt=False)
def visible_probe_stage(record, scratch, shapes, materials, options, ints, shadow, shadow_path,
                        shadow_key, n, probe_prim, probe_uv):
    """probe_stage past the cut-out surfaces (ptrace.cutouts.visible_hit)."""
    for s in range(n):
        i = shadow_path[s]
        t, prim, u, v = visible_hit(shapes, materials, options, record, scratch, ints[PIXEL, i],
                                    ints[SAMPLE, i], np.int64(shadow_key[s]), shadow[SOX, s],
                                    shadow[SOY, s], shadow[SOZ, s], shadow[SDX, s],
                                    shadow[SDY, s], shadow[SDZ, s], 0.0, shadow[STMAX, s])
        probe_prim[s] = prim
        probe_uv[0, s] = u
        probe_uv[1, s] = v
