"""Emissive geometry as one more light: which emissive primitives are only a file light's visible
face (not sampled again), and the others' selection probabilities by power and area densities,
which the integrator's light EMITTER samples (ptrace.lights.sample_emitter).

Separate from ptrace.lights because this is the scene-side preparation in plain numpy, run once
per render, while ptrace.lights holds the compiled sampling; ptrace.lights re-exports EMITTER
and emitter_arrays.
"""
import numpy as np

EMITTER = 99     # not a scene's light kind: the integrator's one light over emissive primitives
PAIR_TOLERANCE = 1e-4   # relative to the emitter group's size: "lies on the light"


def _emitter_groups(scene):
    """{material: primitive ids} of the emissive materials that primitives use."""
    index = np.asarray(scene.material_index)
    emits = scene.materials.emits()
    return {int(m): np.nonzero(index == m)[0] for m in np.unique(index) if emits[m]}


def _face_of(scene, prims, lights):
    """The file light whose visible face these emissive primitives are, or -1.

    The course's Cornell-box files lay an emissive quad exactly in the plane of their area light
    (docs/course.md#light-faces; in CBempty on the point light): the quad is what the camera and
    mirrors see of the light, not a second light. A group of emissive triangles is a light's face
    when it is planar, the light's centre (or point) lies in its plane and inside its bounding box,
    and an area light faces along the group's normal."""
    from .scene import AREA, POINT
    g = scene.geometry
    if prims.size == 0 or prims.max() >= g.triangle_count:
        return -1          # spheres are never a face
    corners = g.vertices[g.faces[prims]].reshape(-1, 3)
    lower, upper = corners.min(axis=0), corners.max(axis=0)
    tolerance = PAIR_TOLERANCE * max(float(np.linalg.norm(upper - lower)), 1e-300)
    a, b, c = (g.vertices[g.faces[prims[0], k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    length = np.linalg.norm(normal)
    if length == 0.0:
        return -1
    normal = normal / length
    if np.abs((corners - a) @ normal).max() > tolerance:
        return -1          # not planar
    for i in range(len(lights)):
        if lights.kind[i] not in (AREA, POINT):
            continue
        p = lights.position[i]
        if abs(float((p - a) @ normal)) > tolerance:
            continue
        if np.any(p < lower - tolerance) or np.any(p > upper + tolerance):
            continue
        if lights.kind[i] == AREA and abs(float(lights.direction[i] @ normal)) < 0.99:
            continue
        return i
    return -1


def emitter_arrays(scene, power=False):
    """What the integrator needs to treat emissive geometry as a light.

    Returns (faced (L,) int64: 1 where a file light has an emissive face, prims (E,) int64: the
    emissive primitives that are no light's face, cdf (E,) float64: their cumulative selection
    probability (by power, area times mean emission), prim_pdf (F + S,) float64: selection
    probability over area for those primitives, 0 elsewhere: the area density of sampling a
    point there), and with power, each of those primitives' power (E,)."""
    faced, prims, cdf, prim_pdf, prim_power = _emitters(scene)
    return (faced, prims, cdf, prim_pdf) + ((prim_power,) if power else ())


def _emitters(scene):
    """emitter_arrays' four arrays and each of those primitives' power (E,) (area times mean
    emission)."""
    g, lights = scene.geometry, scene.lights
    faced = np.zeros(len(lights), dtype=np.int64)
    sampled = []
    for m, prims in _emitter_groups(scene).items():
        face = _face_of(scene, prims, lights)
        if face >= 0:
            faced[face] = 1
        else:
            sampled.append(prims)
    prim_pdf = np.zeros(g.triangle_count + g.sphere_count)
    if not sampled:
        return faced, np.zeros(0, dtype=np.int64), np.zeros(0), prim_pdf, np.zeros(0)
    prims = np.sort(np.concatenate(sampled)).astype(np.int64)
    areas = np.empty(prims.shape[0])
    triangles = prims < g.triangle_count
    corners = g.vertices[g.faces[prims[triangles]]]
    areas[triangles] = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    radii = g.radii[prims[~triangles] - g.triangle_count]
    areas[~triangles] = 4.0 * np.pi * radii ** 2
    materials, textures = scene.materials, scene.textures
    # a textured emitter's power: its factor times its texture's mean (primitives are chosen
    # by power; the texture's variation over each one is left to the estimator's weights)
    texture_mean = np.ones(len(materials))
    for m in np.nonzero(materials.emission_texture >= 0)[0]:
        t = materials.emission_texture[m]
        start = textures.offset[t]
        end = start + textures.width[t] * textures.height[t]
        texture_mean[m] = float(textures.texels[start:end].mean())
    index = scene.material_index[prims]
    emission = materials.emission[index].mean(axis=1) * texture_mean[index]
    power = areas * np.maximum(emission, 0.0)
    total = power.sum()
    if not total > 0.0:
        return faced, np.zeros(0, dtype=np.int64), np.zeros(0), prim_pdf, np.zeros(0)
    probability = power / total
    cdf = np.cumsum(probability)
    cdf[-1] = 1.0
    nonzero = areas > 0.0
    prim_pdf[prims[nonzero]] = probability[nonzero] / areas[nonzero]
    return faced, prims, cdf, prim_pdf, power
