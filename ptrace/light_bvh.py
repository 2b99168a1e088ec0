"""The light BVH as the integrator's light sampler (--light-sampler bvh): which lights are the
tree's entries, how the lights it leaves out are chosen beside it, and the probability of
choosing a light or an emissive primitive at a shading point.

Every light with a place in the scene is an entry of a ptrace.light_tree: each area light (its
rectangle, facing along its normal, one-sided), glTF's point and spot lights (a point, whose
light leaves every way, or within a spot's outer cone) and each emissive primitive that
ptrace.lights samples (a triangle flat and two-sided, as its emission; a sphere facing every
way). An entry's power is its largest radiant intensity in luminance (radiance times area for a
flat emitter, times pi r^2 for a sphere; the intensity of a point or spot light), so that the
tree's importance, power times cosine bounds over squared distance, estimates the irradiance an
entry gives whatever its kind.

The lights without a place (directional, ambient, the environment, and the course's point
lights, which do not fall off) are chosen beside the tree by ptrace.lights.selection_weights,
the tree taking the summed weight of the lights it holds: a dim sky does not take half the
samples of a room lit by lamps, as it would if each light at infinity had the tree's share
(pbrt-v4's rule, made for scenes whose infinite lights are few and bright). Every light that
can light a point keeps a probability above zero there (ptrace.light_tree).

bvh_choose picks (light, primitive, probability) for a light sample at p; bvh_light_pmf and
bvh_prim_pmf return that probability for a light or emissive primitive a BSDF-sampled ray
found, the same product of the same numbers, for multiple importance sampling.
"""
import math

import numpy as np
from numba import njit

from .light_tree import tree_pmf, tree_sample
from .light_tree_build import ONE_MINUS_EPSILON, build_light_tree
from .lights import choose
from .scene import AREA, LUMINANCE, PHYSICAL, POINT, SPOT


def _entries(scene, prims, prim_power):
    """The tree's entries: build_light_tree's seven arrays, then each entry's file light (the
    emissive primitives' one light, len(scene.lights), for a primitive) and primitive (-1 for
    a file light)."""
    lights, g = scene.lights, scene.geometry
    rows = []          # (lower, upper, axis, power, cos_o, cos_e, two_sided, light)
    luminance = np.asarray(lights.radiance, dtype=np.float64).reshape(-1, 3) @ LUMINANCE
    for i, kind in enumerate(np.asarray(lights.kind).tolist()):
        physical = lights.model[i] == PHYSICAL
        position = np.asarray(lights.position[i], dtype=np.float64)
        direction = np.asarray(lights.direction[i], dtype=np.float64)
        if kind == AREA:
            half_x, half_y = 0.5 * np.abs(lights.edge_x[i]), 0.5 * np.abs(lights.edge_y[i])
            reach = half_x + half_y
            power = luminance[i] * lights.area[i] if np.any(direction) else 0.0
            rows.append((position - reach, position + reach, direction, power, 1.0, 0.0,
                         False, i))
        elif kind == POINT and physical:
            rows.append((position, position, (0.0, 0.0, 1.0), luminance[i], -1.0, 0.0, False,
                         i))
        elif kind == SPOT and physical and np.any(direction):
            inner = math.acos(min(1.0, max(-1.0, float(lights.cos_inner[i]))))
            outer = math.acos(min(1.0, max(-1.0, float(lights.cos_outer[i]))))
            # the cone's axis spread is the inner cone, its falloff the rest of the outer one
            # (pbrt-v4's spot bounds), below 1 so that a hard-edged spot still lights its cone
            cos_e = min(math.cos(max(0.0, outer - inner)), ONE_MINUS_EPSILON)
            rows.append((position, position, direction, luminance[i], math.cos(inner), cos_e,
                         False, i))
    count = len(rows) + prims.shape[0]
    lower, upper, axis = np.zeros((count, 3)), np.zeros((count, 3)), np.zeros((count, 3))
    power, cos_o, cos_e = np.zeros(count), np.zeros(count), np.zeros(count)
    two_sided = np.zeros(count, dtype=np.bool_)
    entry_light = np.full(count, len(lights), dtype=np.int64)
    entry_prim = np.full(count, -1, dtype=np.int64)
    for e, (lo, hi, ax, pw, co, ce, two, light) in enumerate(rows):
        lower[e], upper[e], axis[e], power[e] = lo, hi, ax, pw
        cos_o[e], cos_e[e], two_sided[e], entry_light[e] = co, ce, two, light
    k = len(rows)
    entry_prim[k:] = prims
    triangles = prims < g.triangle_count
    t = k + np.nonzero(triangles)[0]
    corners = g.vertices[g.faces[prims[triangles]]]
    lower[t], upper[t] = corners.min(axis=1), corners.max(axis=1)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1)
    flat = length > 0.0        # (a zero-area triangle has power 0: left out of the tree)
    normal[flat] /= length[flat, None]
    normal[~flat] = (0.0, 0.0, 1.0)
    axis[t], power[t], cos_o[t], two_sided[t] = normal, prim_power[triangles], 1.0, True
    s = k + np.nonzero(~triangles)[0]
    index = prims[~triangles] - g.triangle_count
    radius = np.asarray(g.radii, dtype=np.float64)[index, None]
    centre = np.asarray(g.centers, dtype=np.float64)[index]
    lower[s], upper[s], axis[s] = centre - radius, centre + radius, (0.0, 0.0, 1.0)
    power[s], cos_o[s] = 0.25 * prim_power[~triangles], -1.0    # 4 pi r^2 L -> pi r^2 L
    power = np.where(np.isfinite(power) & (power > 0.0), power, 0.0)
    return (lower, upper, power, axis, cos_o, cos_e, two_sided), entry_light, entry_prim


def bvh_arrays(scene, prims, prim_power, weights):
    """LightArrays' fields of the bvh sampler: (tree, entry_light, entry_prim, light_entry,
    prim_entry, bvh_cdf, bvh_pmf). prims and prim_power are ptrace.lights' emissive primitives
    and their power, weights selection_weights over the integrator's lights. bvh_pmf has one
    value per light and one more, last, for the tree: a light in the tree gets 0 there (the
    tree's share is its lights' summed weight), and all are 0 where no light gives any."""
    lights, g = scene.lights, scene.geometry
    arrays, entry_light, entry_prim = _entries(scene, prims, prim_power)
    tree = build_light_tree(*arrays)
    light_entry = np.full(weights.shape[0], -1, dtype=np.int64)
    prim_entry = np.full(g.triangle_count + g.sphere_count, -1, dtype=np.int64)
    in_tree = tree.entry_node >= 0
    light_entry[entry_light[in_tree & (entry_prim < 0)]] = np.nonzero(
        in_tree & (entry_prim < 0))[0]
    prim_entry[entry_prim[in_tree & (entry_prim >= 0)]] = np.nonzero(
        in_tree & (entry_prim >= 0))[0]
    pmf = np.append(weights, 0.0)
    held = light_entry >= 0
    if prims.shape[0]:
        held[len(lights)] = bool(np.any(prim_entry >= 0))
    pmf[-1] = pmf[:-1][held].sum()
    pmf[:-1][held] = 0.0
    total = pmf.sum()
    pmf = pmf / total if total > 0.0 else np.zeros_like(pmf)
    cdf = np.cumsum(pmf)
    positive = np.nonzero(pmf > 0.0)[0]
    if positive.shape[0]:
        cdf[positive[-1]:] = 1.0
    return tree, entry_light, entry_prim, light_entry, prim_entry, cdf, pmf


@njit(cache=True, _nrt=False, forceinline=True)
def bvh_choose(lights, u, px, py, pz, nx, ny, nz):
    """One light for a light sample at p (shading normal n) by u, uniform in [0, 1): (light,
    primitive, probability); the primitive is the emissive primitive chosen (light is then
    the emissive primitives' light), else -1; light -1 for no choice (nothing gives light, or
    the tree's walk ended where no entry can light p)."""
    cdf, pmf = lights.bvh_cdf, lights.bvh_pmf
    k = choose(cdf, u)
    chosen = pmf[k]
    if not chosen > 0.0:
        return -1, -1, 0.0
    if k < pmf.shape[0] - 1:
        return k, -1, chosen
    low = cdf[k - 1] if k > 0 else 0.0
    entry, p = tree_sample(lights.tree, px, py, pz, nx, ny, nz, (u - low) / chosen)
    if entry < 0:
        return -1, -1, 0.0
    return lights.entry_light[entry], lights.entry_prim[entry], chosen * p


@njit(cache=True, _nrt=False, forceinline=True)
def bvh_light_pmf(lights, light, px, py, pz, nx, ny, nz):
    """The probability that bvh_choose, at p (shading normal n), chooses file light `light`."""
    p = lights.bvh_pmf[light]
    entry = lights.light_entry[light]
    if entry >= 0:
        p += lights.bvh_pmf[lights.bvh_pmf.shape[0] - 1] * tree_pmf(lights.tree, px, py, pz,
                                                                     nx, ny, nz, entry)
    return p


@njit(cache=True, _nrt=False, forceinline=True)
def bvh_prim_pmf(lights, prim, px, py, pz, nx, ny, nz):
    """The probability that bvh_choose, at p (shading normal n), chooses emissive primitive
    prim (0 for one it never chooses: a light's face)."""
    entry = lights.prim_entry[prim]
    if entry < 0:
        return 0.0
    return lights.bvh_pmf[lights.bvh_pmf.shape[0] - 1] * tree_pmf(lights.tree, px, py, pz, nx,
                                                                  ny, nz, entry)


def no_bvh_arrays():
    """The bvh fields of records built without the tree (the integrator then chooses by power
    where bvh is asked for)."""
    empty = np.zeros((0, 3))
    tree = build_light_tree(empty, empty, np.zeros(0), empty, np.zeros(0), np.zeros(0),
                            np.zeros(0, dtype=np.bool_))
    none = np.zeros(0, dtype=np.int64)
    return tree, none, none, none, none, np.zeros(0), np.zeros(0)
