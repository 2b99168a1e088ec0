"""Surfaces a ray passes through where their material's alpha says so: glTF's alphaMode MASK
(cut out where alpha is below the material's alphaCutoff) and BLEND (rendered as stochastic
transparency: a ray passes with probability 1 - alpha, so the mean over samples is the blend).

Materials.cutoff holds each material's rule: 0 for opaque (never cut), c in (0, 1] for MASK at
cutoff c, and ptrace.scene.BLEND_CUT (negative) for BLEND. The kernel's record holds no cutoffs
at all (an empty array) when no material is cut, so a scene without them pays one test of an
array's length per ray.

A cut surface is skipped by tracing again from the same origin past the hit, so that the hit
distance stays measured from the ray's origin (the area lights' tests along the ray rely on
it). The loops are their own compiled functions, not inlined into the path loop: they hold one
more traversal, which would otherwise be compiled again at every ray the kernel traces. For the
same reason visible_hit and shadowed are inlined by numba (not compiled alone, then inlined),
and pass their key on as a plain int64: a literal key (the camera ray's 0) would make numba
compile the loops once more for it.
"""
import numpy as np
from numba import njit

from accel.compiled import any_hit, closest_hit

from .sampling import uniform
from .textures import surface_opacity

MAX_LAYERS = 256          # cut surfaces a ray passes at most; the next one stops it
STEP = 1e-6               # past a cut hit: this fraction of the hit's distance or magnitude
DIM_ALPHA = 1 << 22       # BLEND's random numbers, keyed from the ray's own key
NOT_TRACED = -2           # past_cutouts' prim for a ray whose closest hit is not yet traced


@njit(cache=True, _nrt=False, forceinline=True)
def cut(shapes, materials, options, pixel, sample, key, prim, u, v):
    """Whether a ray passes through primitive prim at barycentrics (u, v): its material's alpha
    there is below its cutoff (MASK), or below a random number keyed by (pixel, sample, key)
    (BLEND)."""
    m = shapes.material_index[prim]
    cutoff = materials.cutoff[m]
    if cutoff == 0.0:
        return False
    alpha = surface_opacity(shapes, materials, m, prim, u, v)
    if cutoff > 0.0:
        return alpha < cutoff
    return alpha <= uniform(options.seed, pixel, sample, DIM_ALPHA + key)


@njit(cache=True, _nrt=False)
def past_cutouts(shapes, materials, options, record, scratch, pixel, sample, key, ox, oy, oz,
                 dx, dy, dz, tmin, tmax, t, prim, u, v):
    """The closest hit (t, prim, u, v) in [tmin, tmax] past the surfaces the ray passes
    through, given its closest hit (t, prim, u, v), or prim NOT_TRACED to trace it first; a
    miss if it passes through all of them. Keys of successive layers follow key. (One
    traversal call site: shadow rays come here too.)"""
    for layer in range(MAX_LAYERS):
        if prim != NOT_TRACED:
            if prim < 0 or not cut(shapes, materials, options, pixel, sample, key + layer, prim,
                                   u, v):
                break
            tmin = t + STEP * max(abs(t), shapes.scale[prim])
        t, prim, u, v = closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)
    return t, prim, u, v


@njit(cache=True, _nrt=False, inline="always")
def visible_hit(shapes, materials, options, record, scratch, pixel, sample, key, ox, oy, oz, dx,
                dy, dz, tmin, tmax):
    """closest_hit, past the cut surfaces (the same call where no material is cut)."""
    t, prim, u, v = closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)
    if prim >= 0 and materials.cutoff.shape[0] > 0:
        t, prim, u, v = past_cutouts(shapes, materials, options, record, scratch, pixel, sample,
                                     np.int64(key), ox, oy, oz, dx, dy, dz, tmin, tmax, t, prim,
                                     u, v)
    return t, prim, u, v


@njit(cache=True, _nrt=False, inline="always")
def shadowed(shapes, materials, options, record, scratch, pixel, sample, key, ox, oy, oz, dx, dy,
             dz, tmax):
    """any_hit over [0, tmax], past the cut surfaces (the same call where no material is
    cut)."""
    if not any_hit(record, scratch, ox, oy, oz, dx, dy, dz, 0.0, tmax):
        return False
    if materials.cutoff.shape[0] == 0:
        return True
    return past_cutouts(shapes, materials, options, record, scratch, pixel, sample,
                        np.int64(key), ox, oy, oz, dx, dy, dz, 0.0, tmax, 0.0,
                        np.int64(NOT_TRACED), 0.0, 0.0)[1] >= 0
