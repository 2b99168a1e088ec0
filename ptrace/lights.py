"""Lights: the file's lights (sample_light, sample_L, docs/course.md#sample-light, as a numba
function of one light index) and emissive geometry as one more light (emitter_arrays,
sample_emitter).

The course applies no distance falloff to point and directional lights (their colour is used as
the radiance reaching every point): ptrace keeps that so course scenes look as the course made
them. The course's spot lights are parsed and, like the course's Sp19 stub, contribute nothing.
Lights of the PHYSICAL model (glTF's KHR_lights_punctual) fall off with the squared distance,
and a spot's cone shapes its light (ptrace.scene.Lights).
Emissive primitives are a light of their own unless they are a file light's visible face
(ptrace.emitters); the course samples
only its <light>s, so a scene lit by emissive geometry alone is black there.
"""
import math

import numpy as np
from numba import njit

from .emitters import _emitters
from .scene import AMBIENT, AREA, DIRECTIONAL, LUMINANCE, PHYSICAL, POINT, SPOT
from .solid_angle import (
    rectangle_pdf,
    rectangle_sample,
    rectangle_sample_row,
    triangle_pdf,
    triangle_sample,
)
from .solid_angle_sphere import sphere_pdf, sphere_sample
from .textures import surface_emission

INF = math.inf


@njit(cache=True, inline="always")
def light_is_delta(kind, model):
    """Lights sampled once per vertex, whatever -l: point and directional lights, and spot
    lights with a cone (the course's stub spot lights keep -l samples of nothing)."""
    return kind == POINT or kind == DIRECTIONAL or (kind == SPOT and model == PHYSICAL)


@njit(cache=True, inline="always")
def spot_falloff(cos_inner, cos_outer, cos_axis):
    """1 inside the inner cone, 0 outside the outer one, and between them the square of the
    linear ramp in cos theta (KHR_lights_punctual's suggested falloff, smooth at the inner
    edge's side)."""
    if cos_axis >= cos_inner:
        return 1.0
    if cos_axis <= cos_outer:
        return 0.0
    ramp = (cos_axis - cos_outer) / max(cos_inner - cos_outer, 1e-9)
    return ramp * ramp


@njit(cache=True, inline="always")
def spot_angular_falloff(cos_inner, cos_outer, cos_axis):
    """Mitsuba 3's spot falloff: 1 inside the beam (cos_inner, the cosine of beam_width), 0
    outside the cutoff (cos_outer, of cutoff_angle), and between them linear in the angle
    from the axis, (cutoff - theta) / (cutoff - beam)."""
    if cos_axis >= cos_inner:
        return 1.0
    if cos_axis <= cos_outer:
        return 0.0
    cutoff = math.acos(cos_outer)
    return (cutoff - math.acos(cos_axis)) / max(cutoff - math.acos(cos_inner), 1e-12)


@njit(cache=True, _nrt=False, forceinline=True)
def sample_area(lights, i, px, py, pz, u1, u2):
    """Area light i (of any record with the area lights' radiance, position, direction, edges
    and area) sampled from p by solid angle (ptrace.solid_angle: spherical rectangles, area
    sampling where the solid angle is too small to be stable): sample_light's values. The light
    is one-sided: nothing reaches a point behind its plane (pdf 0)."""
    return _sample_area(lights, i, px, py, pz, u1, u2, lights.position, False)


@njit(cache=True, _nrt=False, forceinline=True)
def sample_area_row(lights, i, px, py, pz, u1, u2):
    """sample_area, bit for bit, of a record that holds its lights' rectangle_axes_table as
    `axes` (ptrace.kernel.wavefront.AreaLights): the light's own frame is not recomputed."""
    return _sample_area(lights, i, px, py, pz, u1, u2, lights.axes, True)


@njit(cache=True, inline="always")
def _sample_area(lights, i, px, py, pz, u1, u2, axes, ROW):
    position, direction = lights.position, lights.direction
    edge_x, edge_y, radiance = lights.edge_x, lights.edge_y, lights.radiance
    if lights.area[i] <= 0.0 or ((position[i, 0] - px) * direction[i, 0]
                                 + (position[i, 1] - py) * direction[i, 1]
                                 + (position[i, 2] - pz) * direction[i, 2]) >= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
    if ROW:
        qx, qy, qz, pdf = rectangle_sample_row(px, py, pz, position[i, 0], position[i, 1],
                                               position[i, 2], edge_x[i, 0], edge_x[i, 1],
                                               edge_x[i, 2], edge_y[i, 0], edge_y[i, 1],
                                               edge_y[i, 2], axes, i, u1, u2)
    else:
        qx, qy, qz, pdf = rectangle_sample(px, py, pz, position[i, 0], position[i, 1],
                                           position[i, 2], edge_x[i, 0], edge_x[i, 1],
                                           edge_x[i, 2], edge_y[i, 0], edge_y[i, 1],
                                           edge_y[i, 2], u1, u2)
    dx, dy, dz = qx - px, qy - py, qz - pz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dist == 0.0 or not pdf > 0.0:
        return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
    wx, wy, wz = dx / dist, dy / dist, dz / dist
    return radiance[i, 0], radiance[i, 1], radiance[i, 2], wx, wy, wz, dist, pdf


def _light_sampler(ANGULAR):
    """sample_light of one spot falloff, Mitsuba's (ANGULAR) or glTF's: a constant of its code,
    so numba prunes the other before typing it and a kernel compiles only its scene's. (The
    constant is a bool, not the falloff's function: numba's cache keys a closure on its
    constants pickled, and a function pickles differently in every process.)"""

    @njit(cache=True, _nrt=False, forceinline=True)
    def sample(lights, i, px, py, pz, u1, u2):
        kind, radiance, position, direction = lights.kind[i], lights.radiance, \
            lights.position, lights.direction
        physical = lights.model[i] == PHYSICAL
        if kind == POINT or (kind == SPOT and physical):
            dx, dy, dz = position[i, 0] - px, position[i, 1] - py, position[i, 2] - pz
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            if dist == 0.0:
                return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
            wx, wy, wz = dx / dist, dy / dist, dz / dist
            scale = 1.0 / (dist * dist) if physical else 1.0
            if kind == SPOT:   # direction is the spot's axis, away from the light
                cos_axis = -(wx * direction[i, 0] + wy * direction[i, 1] + wz * direction[i, 2])
                if ANGULAR:
                    scale *= spot_angular_falloff(lights.cos_inner[i], lights.cos_outer[i],
                                                  cos_axis)
                else:
                    scale *= spot_falloff(lights.cos_inner[i], lights.cos_outer[i], cos_axis)
                if scale == 0.0:
                    return 0.0, 0.0, 0.0, wx, wy, wz, dist, 0.0
            return radiance[i, 0] * scale, radiance[i, 1] * scale, radiance[i, 2] * scale, \
                wx, wy, wz, dist, 1.0
        if kind == DIRECTIONAL:
            return radiance[i, 0], radiance[i, 1], radiance[i, 2], direction[i, 0], \
                direction[i, 1], direction[i, 2], INF, 1.0
        if kind == AREA:
            return sample_area(lights, i, px, py, pz, u1, u2)
        if kind == AMBIENT:
            # uniform over the hemisphere about world +Y, pdf 1 / (2 pi)
            y = u1
            r = math.sqrt(max(0.0, 1.0 - y * y))
            phi = 2.0 * math.pi * u2
            return radiance[i, 0], radiance[i, 1], radiance[i, 2], r * math.cos(phi), y, \
                r * math.sin(phi), INF, 1.0 / (2.0 * math.pi)
        return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0   # spot: nothing, like the course

    return sample


sample_light = _light_sampler(False)
sample_light.__doc__ = """Sample light i (of the integrator's LightArrays) as seen from point p.

    Returns (Lr, Lg, Lb, wix, wiy, wiz, distance, pdf): wi is the unit direction toward the
    light sample, distance is inf for lights at infinity, pdf is per unit solid angle (1 for
    delta lights), and pdf 0 means "no contribution" (the course's spot lights, the back of an
    area light, a point outside a spot's cone). A spot falls off as glTF's (spot_falloff)."""
# the same, of a scene whose spots fall off as Mitsuba's (ptrace.scene's ANGULAR); only the
# shading kernels of such a scene call it
sample_light_angular = _light_sampler(True)


@njit(cache=True, _nrt=False, forceinline=True)
def area_light_pdf(lights, i, px, py, pz, wx, wy, wz):
    """The density per unit solid angle with which sample_light, at point p, gives the unit
    direction w toward area light i (the pdf of a BSDF-sampled ray from p that finds it, for
    multiple importance sampling): the same computation as the sampler's."""
    position, edge_x, edge_y = lights.position, lights.edge_x, lights.edge_y
    return rectangle_pdf(px, py, pz, position[i, 0], position[i, 1], position[i, 2],
                         edge_x[i, 0], edge_x[i, 1], edge_x[i, 2], edge_y[i, 0], edge_y[i, 1],
                         edge_y[i, 2], wx, wy, wz)


# -- choosing one light per light sample (--light-sampler power, and bvh's lights at infinity) --

def light_selection(scene):
    """(cdf, pmf) over the integrator's lights by selection_weights: each light's probability
    of being chosen for a light sample (uniform where no light gives any)."""
    weight = selection_weights(scene)
    total = weight.sum()
    if not total > 0.0:   # nothing gives light: choose uniformly (every estimate is zero)
        weight = np.ones_like(weight)
        total = weight.sum()
    pmf = weight / total
    cdf = np.cumsum(pmf)
    if cdf.size:
        cdf[-1] = 1.0
    return cdf, pmf


def selection_weights(scene):
    """An estimate of the irradiance each of the integrator's lights (the file's lights, then
    the emissive primitives as one more light if there are any) gives a point of the scene, as
    a weight >= 0 (finite): its power over the square of the scene's radius r for lights that
    fall off (area lights, glTF's point and spot lights, the emissive primitives), its radiance
    for the course's point lights (which do not fall off) and directional lights, pi times it
    for the ambient light and the environment (a hemisphere of that radiance). A light that can
    give light gets a weight above zero (so choosing by it is unbiased); the course's spot
    lights, which give none, get zero."""
    from .scene import ENVIRONMENT
    lights = scene.lights
    _, prims, _, _, power = _emitters(scene)
    emitted = float(power.sum())
    bounds = scene.bounds()
    radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0])) if bounds is not None else 1.0
    r2 = max(radius * radius, 1e-300)
    luminance = np.asarray(lights.radiance, dtype=np.float64).reshape(-1, 3) @ LUMINANCE
    weight = np.zeros(len(lights) + (1 if prims.shape[0] else 0))
    for i, kind in enumerate(np.asarray(lights.kind).tolist()):
        physical = lights.model[i] == PHYSICAL
        if kind == AREA:
            weight[i] = luminance[i] * lights.area[i] / r2
        elif kind == POINT:
            weight[i] = luminance[i] / r2 if physical else luminance[i]
        elif kind == SPOT:
            weight[i] = luminance[i] / r2 if physical else 0.0
        elif kind == DIRECTIONAL:
            weight[i] = luminance[i]
        elif kind == AMBIENT:
            weight[i] = np.pi * luminance[i]
        elif kind == ENVIRONMENT:
            mean = scene.environment.mean_luminance() if scene.environment is not None \
                else float(np.ones(3) @ LUMINANCE)
            weight[i] = np.pi * luminance[i] * mean
    if prims.shape[0]:
        weight[-1] = emitted / r2
    return np.where(np.isfinite(weight) & (weight > 0.0), weight, 0.0)


@njit(cache=True, inline="always")
def choose(cdf, u):
    """The first index k with u < cdf[k] (cdf ascending, its last value 1)."""
    lo, hi = 0, cdf.shape[0] - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if u < cdf[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit(cache=True, _nrt=False, forceinline=True)
def _primitive_area(shapes, prim):
    """Area of a triangle or sphere primitive."""
    vertices, faces = shapes.vertices, shapes.faces
    if prim < faces.shape[0]:
        a, b, c = faces[prim, 0], faces[prim, 1], faces[prim, 2]
        e1x, e1y, e1z = (vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1],
                         vertices[b, 2] - vertices[a, 2])
        e2x, e2y, e2z = (vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1],
                         vertices[c, 2] - vertices[a, 2])
        nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        return 0.5 * math.sqrt(nx * nx + ny * ny + nz * nz)
    radius = shapes.radii[prim - faces.shape[0]]
    return 4.0 * math.pi * radius * radius


@njit(cache=True, _nrt=False, forceinline=True)
def sample_primitive(shapes, materials, prim, px, py, pz, u1, u2):
    """A point on emissive primitive prim as seen from p, by solid angle (u1, u2: a spherical
    triangle, or a sphere's visible cone; ptrace.solid_angle falls back to area sampling where
    that is not stable): (Lr, Lg, Lb, wix, wiy, wiz, distance, pdf per unit solid angle), pdf 0
    for no sample. Emission is two-sided, like the course's."""
    vertices, faces, centers, radii = shapes.vertices, shapes.faces, shapes.centers, shapes.radii
    n_tri = faces.shape[0]
    wb = wc = 0.0
    if prim < n_tri:
        a, b, c = faces[prim, 0], faces[prim, 1], faces[prim, 2]
        qx, qy, qz, wb, wc, pdf = triangle_sample(
            px, py, pz, vertices[a, 0], vertices[a, 1], vertices[a, 2], vertices[b, 0],
            vertices[b, 1], vertices[b, 2], vertices[c, 0], vertices[c, 1], vertices[c, 2],
            u1, u2)
    else:
        s = prim - n_tri
        qx, qy, qz, pdf = sphere_sample(px, py, pz, centers[s, 0], centers[s, 1],
                                        centers[s, 2], radii[s], u1, u2)
    dx, dy, dz = qx - px, qy - py, qz - pz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dist == 0.0 or not pdf > 0.0:
        return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
    wx, wy, wz = dx / dist, dy / dist, dz / dist
    er, eg, eb = surface_emission(shapes, materials, shapes.material_index[prim], prim, wb, wc)
    return er, eg, eb, wx, wy, wz, dist, pdf


@njit(cache=True, _nrt=False, forceinline=True)
def sample_emitter(shapes, materials, prims, cdf, prim_pdf, px, py, pz, u0, u1, u2):
    """A point on the emissive primitives as seen from p, the primitive chosen by power (u0)
    and the point by sample_primitive (u1, u2): (Lr, Lg, Lb, wix, wiy, wiz, distance, pdf per
    unit solid angle, the choice's probability included)."""
    prim = prims[choose(cdf, u0)]
    er, eg, eb, wx, wy, wz, dist, pdf = sample_primitive(shapes, materials, prim, px, py, pz,
                                                         u1, u2)
    if not pdf > 0.0:
        return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
    return er, eg, eb, wx, wy, wz, dist, prim_pdf[prim] * _primitive_area(shapes, prim) * pdf


@njit(cache=True, _nrt=False, forceinline=True)
def primitive_pdf(shapes, prim, px, py, pz, wx, wy, wz):
    """The density per unit solid angle with which sample_primitive, at point p, gives the
    unit direction w toward emissive primitive prim: the same computation as the sampler's."""
    vertices, faces = shapes.vertices, shapes.faces
    if prim < faces.shape[0]:
        a, b, c = faces[prim, 0], faces[prim, 1], faces[prim, 2]
        return triangle_pdf(px, py, pz, vertices[a, 0], vertices[a, 1], vertices[a, 2],
                            vertices[b, 0], vertices[b, 1], vertices[b, 2], vertices[c, 0],
                            vertices[c, 1], vertices[c, 2], wx, wy, wz)
    s = prim - faces.shape[0]
    return sphere_pdf(px, py, pz, shapes.centers[s, 0], shapes.centers[s, 1],
                      shapes.centers[s, 2], shapes.radii[s], wx, wy, wz)


@njit(cache=True, _nrt=False, forceinline=True)
def emitter_pdf(shapes, prim_pdf, prim, px, py, pz, wx, wy, wz):
    """The density per unit solid angle with which sample_emitter, at point p, gives the unit
    direction w toward emissive primitive prim (the choice's probability included; 0 for a
    primitive it never chooses): the same computation as the sampler's."""
    chosen = prim_pdf[prim]
    if chosen == 0.0:
        return 0.0
    pdf = primitive_pdf(shapes, prim, px, py, pz, wx, wy, wz)
    return chosen * _primitive_area(shapes, prim) * pdf


@njit(cache=True, _nrt=False, forceinline=True)
def area_light_hit(position, direction, edge_x, edge_y, i, ox, oy, oz, dx, dy, dz):
    """Distance along the ray to area light i's front face (inf if the ray misses it): the
    rectangle position + s E_x + t E_y, |s|, |t| <= 1/2, that sample_light draws from."""
    nx, ny, nz = direction[i, 0], direction[i, 1], direction[i, 2]
    facing = dx * nx + dy * ny + dz * nz
    if facing >= 0.0:          # behind the one-sided light, or along it
        return INF
    cx, cy, cz = position[i, 0] - ox, position[i, 1] - oy, position[i, 2] - oz
    t = (cx * nx + cy * ny + cz * nz) / facing
    if not t > 0.0:
        return INF
    qx, qy, qz = t * dx - cx, t * dy - cy, t * dz - cz     # the hit point, from the centre
    ax, ay, az = edge_x[i, 0], edge_x[i, 1], edge_x[i, 2]
    bx, by, bz = edge_y[i, 0], edge_y[i, 1], edge_y[i, 2]
    aa, ab, bb = (ax * ax + ay * ay + az * az, ax * bx + ay * by + az * bz,
                  bx * bx + by * by + bz * bz)
    qa, qb = qx * ax + qy * ay + qz * az, qx * bx + qy * by + qz * bz
    det = aa * bb - ab * ab
    if det <= 0.0:
        return INF
    s = (qa * bb - qb * ab) / det
    r = (qb * aa - qa * ab) / det
    if abs(s) <= 0.5 and abs(r) <= 0.5:
        return t
    return INF
