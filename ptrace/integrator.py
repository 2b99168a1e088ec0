"""What every stage of the path loop shares (ptrace.kernel runs it, as waves of paths through
small stage kernels): the records the kernels take, built once per scene (`scene_records`,
`camera_record`), the camera's rays, the surface at a hit and the spawn of the next ray, the
sampler's dimensions per vertex, the power heuristic, the emission a bounce ray finds with its
weight against light sampling (`emission_found`), the normals integrator's colour and the AOVs
of a hit.

Direct light is estimated by multiple importance sampling (the default; pbrt-v4's and
Mitsuba's path integrators do the same): -l samples of each light, and the BSDF sample that
continues the path, each weighted by the power heuristic, so that emission a BSDF-sampled ray
finds counts too (emission_found). With --direct light it is the course's estimator
(docs/course.md#direct-light): light samples alone, and a bounce ray's emission counts only after
a delta bounce. -H is the course's uniform hemisphere sampling. The lights are the file's
lights plus, as one more light, the emissive primitives that are not a file light's face
(ptrace.lights). Random numbers come from the Sobol' sampler (stratified) or the independent one
(ptrace.sampling), keyed by (seed, pixel, sample, dimension), so the image does not depend on
threads, blocks, waves or backend. Departures from the course are listed in
docs/departures.md.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from accel.compiled import by_class

from .codes import LIGHTS_ALL, LIGHTS_BVH, LIGHTS_POWER, IndependentOptions
from .emitters import EMITTER, emitter_arrays
from .environment import (
    environment_arrays,
    environment_pdf,
    environment_radiance,
)
from .light_bvh import bvh_arrays, bvh_light_pmf, bvh_prim_pmf, no_bvh_arrays
from .light_hits import build_light_hits, next_light, no_light_hits
from .lights import (
    area_light_hit,
    area_light_pdf,
    emitter_pdf,
    light_selection,
    primitive_pdf,
    selection_weights,
)
from .sampling import sobol_1d, sobol_2d, uniform
from .scene import (
    AMBIENT,
    AREA,
    EMISSION,
    ENVIRONMENT,
    GLASS,
    GLTF_PBR,
    REFRACTION,
)
from .textures import surface_emission

OFFSET = 1e-6           # spawn offset, relative to the hit point's (and primitive's) magnitude
SHADOW_SHORTEN = 1e-6   # shadow rays stop this fraction short of the light sample
DIMS_PER_VERTEX = 1 << 24
DIM_BSDF, DIM_GLASS, DIM_RR, DIM_LIGHT = 0, 2, 3, 8
DIM_LENS = 2            # the camera vertex's (vertex 0) lens sample; 0 and 1 are the pixel jitter
DIM_SELECT = 1 << 23    # the independent sampler's dimensions for choosing an emissive primitive
DIM_CHOOSE = 4          # (power, bvh) key offsets from DIM_LIGHT: the choice of light, and
DIM_CHOOSE_PRIM = 5     # (power) the choice of an emissive primitive
# the camera's keys as int64 values, not literals: a literal argument compiles the sampler once
# more for each constant (sample_2d, sobol_2d and uniform each three times, not once)
KEY_JITTER, KEY_LENS = np.int64(0), np.int64(DIM_LENS)
RAY_KEYS = 1 << 8       # a vertex's rays' keys for ptrace.cutouts: the bounce ray 0, light or
#                         hemisphere sample j (from 0) RAY_KEYS * (1 + j), each followed by the
#                         keys of the cut surfaces it passes

SceneArrays = namedtuple("SceneArrays", ["vertices", "faces", "centers", "radii",
                                         "vertex_normals", "material_index", "scale", "uv",
                                         "vertex_colours"])
MaterialArrays = namedtuple("MaterialArrays", ["kind", "albedo", "transmittance", "emission",
                                               "ior", "alpha", "eta", "k", "specular",
                                               "albedo_texture",
                                               "emission_texture", "roughness_texture",
                                               "texels", "tex_offset", "tex_width",
                                               "tex_height", "tex_wrap", "metallic",
                                               "opacity", "alpha_texture", "cutoff",
                                               "normal_texture", "normal_scale"])
LightArrays = namedtuple("LightArrays", ["kind", "radiance", "position", "direction", "edge_x",
                                         "edge_y", "area", "model", "cos_inner",
                                         "cos_outer", "faced", "emitter_prims",
                                         "emitter_cdf", "prim_pdf", "findable", "env_image",
                                         "env_marginal", "env_conditional", "env_table",
                                         "select_cdf", "select_pmf", "tree", "entry_light",
                                         "entry_prim", "light_entry", "prim_entry", "bvh_cdf",
                                         "bvh_pmf", "sky", "hit_lower", "hit_upper",
                                         "hit_skip", "hit_light"],
                         defaults=no_bvh_arrays() + no_light_hits())
CameraArrays = namedtuple("CameraArrays", ["position", "to_world", "half_width", "half_height",
                                           "screen_dist", "znear", "zfar", "width",
                                           "lens_radius", "focal_distance"])


def _f64(array, shape_tail=None):
    array = np.ascontiguousarray(array, dtype=np.float64)
    return array if shape_tail is None else array.reshape((-1,) + shape_tail)


def primitive_scale(geometry):
    """Largest absolute coordinate of each primitive: the magnitude its hit points carry
    (a chunk of triangles at a time: no (F, 3, 3) array of corners)."""
    n_tri = geometry.triangle_count
    scale = np.empty(n_tri + geometry.sphere_count)
    for first in range(0, n_tri, 1 << 16):
        corners = np.abs(geometry.vertices[geometry.faces[first:first + (1 << 16)]])
        corners.max(axis=(1, 2), out=scale[first:first + len(corners)])
    scale[n_tri:] = np.abs(geometry.centers).max(axis=1, initial=0.0) + geometry.radii
    return scale


def scene_records(scene, light_tree=False):
    """(SceneArrays, MaterialArrays, LightArrays) of a scene, with the dtypes the kernel takes;
    with light_tree, the light BVH of --light-sampler bvh too (without it, the kernel chooses
    by power where bvh is asked for)."""
    g, m, lights, tex = scene.geometry, scene.materials, scene.lights, scene.textures
    shapes = SceneArrays(g.vertices, g.faces, g.centers, g.radii, _f64(scene.vertex_normals, (3,)),
                         np.ascontiguousarray(scene.material_index, dtype=np.int64),
                         primitive_scale(g), _f64(scene.uv, (3, 2)),
                         _f64(scene.vertex_colours, (3,)))
    index = lambda array: np.ascontiguousarray(array, dtype=np.int64)
    materials = MaterialArrays(index(m.kind), _f64(m.albedo, (3,)),
                               _f64(m.transmittance, (3,)), _f64(m.emission, (3,)), _f64(m.ior),
                               _f64(m.alpha), _f64(m.eta, (3,)), _f64(m.k, (3,)),
                               _f64(m.specular, np.shape(m.specular)[1:] or (3,)),
                               index(m.albedo_texture), index(m.emission_texture),
                               index(m.roughness_texture),
                               np.ascontiguousarray(tex.texels, dtype=np.float32).reshape(-1, 3),
                               index(tex.offset), index(tex.width), index(tex.height),
                               index(tex.wrap).reshape(-1, 2), _f64(m.metallic),
                               _f64(m.opacity), index(m.alpha_texture),
                               _f64(m.cutoff if np.any(m.cutoff != 0.0) else m.cutoff[:0]),
                               index(m.normal_texture), _f64(m.normal_scale))
    faced, prims, cdf, prim_pdf, prim_power = emitter_arrays(scene, power=True)
    extra = 1 if prims.shape[0] else 0     # one more light: the emissive primitives
    pad = lambda array: np.concatenate([_f64(array, array.shape[1:]),
                                        np.zeros((extra,) + array.shape[1:])])
    light_arrays = LightArrays(
        np.concatenate([np.asarray(lights.kind, dtype=np.int64),
                        np.full(extra, EMITTER, dtype=np.int64)]),
        pad(lights.radiance), pad(lights.position), pad(lights.direction), pad(lights.edge_x),
        pad(lights.edge_y), pad(lights.area),
        np.concatenate([np.asarray(lights.model, dtype=np.int64), np.zeros(extra, np.int64)]),
        pad(lights.cos_inner), pad(lights.cos_outer),
        np.concatenate([faced, np.zeros(extra, np.int64)]),
        prims, cdf, prim_pdf,
        bool(extra or np.isin(lights.kind, [AREA, AMBIENT, ENVIRONMENT]).any()),
        *environment_arrays(scene.environment), *light_selection(scene),
        *(bvh_arrays(scene, prims, prim_power, selection_weights(scene)) if light_tree
          else no_bvh_arrays()),
        np.nonzero(np.isin(lights.kind, [AMBIENT, ENVIRONMENT]))[0].astype(np.int64),
        *build_light_hits(lights.kind, lights.position, lights.edge_x, lights.edge_y))
    return shapes, materials, light_arrays


def camera_record(camera):
    return CameraArrays(_f64(camera.position), _f64(camera.camera_to_world),
                        0.5 * camera.width, 0.5 * camera.height, float(camera.screen_dist),
                        float(camera.znear), float(camera.zfar), int(camera.width),
                        float(camera.lens_radius), float(camera.focal_distance))


@njit(cache=True)
def frame(nx, ny, nz):
    """Orthonormal (x, y, z = n) like the course: h = n with its smallest component set to 1."""
    hx, hy, hz = nx, ny, nz
    ax, ay, az = abs(nx), abs(ny), abs(nz)
    if ax <= ay and ax <= az:
        hx = 1.0
    elif ay <= az:
        hy = 1.0
    else:
        hz = 1.0
    yx, yy, yz = hy * nz - hz * ny, hz * nx - hx * nz, hx * ny - hy * nx
    norm = math.sqrt(yx * yx + yy * yy + yz * yz)
    yx, yy, yz = yx / norm, yy / norm, yz / norm
    return ny * yz - nz * yy, nz * yx - nx * yz, nx * yy - ny * yx, yx, yy, yz


@njit(cache=True, inline="always")
def emits(kind):
    """Whether a material of this kind may emit: an emitter, or glTF's material, which adds its
    emission (zero if it has none) to what it reflects."""
    return kind == EMISSION or kind == GLTF_PBR


@njit(cache=True, _nrt=False, forceinline=True)
def surface(shapes, kinds, ox, oy, oz, dx, dy, dz, t, prim, u, v):
    """What a hit leaves for shading: (material, point, geometric normal, shading normal, spawn
    offset); material -1 on a miss or a zero-area triangle. Opaque surfaces are two-sided: both
    normals turn toward the side the ray came from. Glass and refraction keep the outward normal
    so that wo.z tells inside from outside."""
    vertices, faces, normals = shapes.vertices, shapes.faces, shapes.vertex_normals
    n_tri = faces.shape[0]
    px = py = pz = gx = gy = gz = sx = sy = sz = 0.0
    if prim < 0:
        return -1, px, py, pz, gx, gy, gz, sx, sy, sz, 0.0
    if prim < n_tri:
        a, b, c = faces[prim, 0], faces[prim, 1], faces[prim, 2]
        w = 1.0 - u - v
        px = w * vertices[a, 0] + u * vertices[b, 0] + v * vertices[c, 0]
        py = w * vertices[a, 1] + u * vertices[b, 1] + v * vertices[c, 1]
        pz = w * vertices[a, 2] + u * vertices[b, 2] + v * vertices[c, 2]
        sx = w * normals[a, 0] + u * normals[b, 0] + v * normals[c, 0]
        sy = w * normals[a, 1] + u * normals[b, 1] + v * normals[c, 1]
        sz = w * normals[a, 2] + u * normals[b, 2] + v * normals[c, 2]
        e1x, e1y, e1z = (vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1],
                         vertices[b, 2] - vertices[a, 2])
        e2x, e2y, e2z = (vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1],
                         vertices[c, 2] - vertices[a, 2])
        gx, gy, gz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    else:
        s = prim - n_tri
        centers, radius = shapes.centers, shapes.radii[s]
        sx = ox + t * dx - centers[s, 0]
        sy = oy + t * dy - centers[s, 1]
        sz = oz + t * dz - centers[s, 2]
        length = math.sqrt(sx ** 2 + sy ** 2 + sz ** 2)
        sx, sy, sz = sx / length, sy / length, sz / length
        px = centers[s, 0] + radius * sx
        py = centers[s, 1] + radius * sy
        pz = centers[s, 2] + radius * sz
        gx, gy, gz = sx, sy, sz
    g_len = math.sqrt(gx * gx + gy * gy + gz * gz)
    s_len = math.sqrt(sx ** 2 + sy ** 2 + sz ** 2)
    if g_len == 0.0:
        return -1, px, py, pz, gx, gy, gz, sx, sy, sz, 0.0   # zero area: nothing to shade
    gx, gy, gz = gx / g_len, gy / g_len, gz / g_len
    if s_len == 0.0:
        sx, sy, sz = gx, gy, gz
        s_len = 1.0
    # shading normal on the geometric normal's side
    sign = 1.0 if sx * gx + sy * gy + sz * gz >= 0.0 else -1.0
    m = shapes.material_index[prim]
    kind = kinds[m]
    if kind != GLASS and kind != REFRACTION:
        if gx * dx + gy * dy + gz * dz > 0.0:
            gx, gy, gz = -gx, -gy, -gz   # face the incoming ray
            sign = -sign
    scale = sign / s_len
    magnitude = max(abs(px), abs(py), abs(pz), shapes.scale[prim])
    return m, px, py, pz, gx, gy, gz, sx * scale, sy * scale, sz * scale, OFFSET * magnitude


@njit(cache=True)
def spawn(px, py, pz, gx, gy, gz, offset, wx, wy, wz):
    """Offset the origin along the geometric normal, on the side of the new direction."""
    e = offset if wx * gx + wy * gy + wz * gz >= 0.0 else -offset
    return px + e * gx, py + e * gy, pz + e * gz


@njit(cache=True, inline="always")
def _sobol_1d(options, pixel, sample, index, key, dim):
    return sobol_1d(options.seed, pixel, index, key)


@njit(cache=True, inline="always")
def _independent_1d(options, pixel, sample, index, key, dim):
    return uniform(options.seed, pixel, sample, dim)


@njit(cache=True, inline="always")
def _sobol_2d(options, pixel, sample, index, key, dim):
    return sobol_2d(options.seed, pixel, index, key)


@njit(cache=True, inline="always")
def _independent_2d(options, pixel, sample, index, key, dim):
    return uniform(options.seed, pixel, sample, dim), uniform(options.seed, pixel, sample, dim + 1)


# sample_1d(options, pixel, sample, index, key, dim): one number for (pixel, sample), by the
# sampler the options' class names (ptrace.codes.Options): the Sobol' sampler's point `index`
# of dimension `key`, or the independent sampler's hash of dimension `dim` (its numbers, bit for
# bit, are those of the releases before the Sobol' sampler). sample_2d: two numbers, a 2D Sobol'
# point or the independent dimensions dim and dim + 1. Only the options' sampler compiles.
sample_1d = by_class(IndependentOptions, _independent_1d, _sobol_1d)
sample_2d = by_class(IndependentOptions, _independent_2d, _sobol_2d)


@njit(cache=True, inline="always")
def power_heuristic(pdf, other):
    """The power heuristic's weight (beta 2) of a technique of density pdf against one of
    density other, each density already multiplied by its number of samples."""
    a, b = pdf * pdf, other * other
    return a / (a + b) if a > 0.0 else 0.0


@njit(cache=True, _nrt=False, forceinline=True)
def every_light_samples(options, lights, light, qx, qy, qz, nx, ny, nz):
    """A light's expected light samples at vertex q (shading normal n) when every light is
    sampled: -l."""
    return float(options.light_samples)


@njit(cache=True, _nrt=False, forceinline=True)
def power_samples(options, lights, light, qx, qy, qz, nx, ny, nz):
    """... when one light is chosen by power for each light sample: -l times its probability."""
    return options.light_samples * lights.select_pmf[light]


@njit(cache=True, _nrt=False, forceinline=True)
def tree_samples(options, lights, light, qx, qy, qz, nx, ny, nz):
    """... when the light BVH chooses: -l times the tree's probability of it at q."""
    return options.light_samples * bvh_light_pmf(lights, light, qx, qy, qz, nx, ny, nz)


# each light sampler's expected samples of a light at a vertex (ptrace.codes' LIGHTS_*)
EXPECTED_SAMPLES = {LIGHTS_ALL: every_light_samples, LIGHTS_POWER: power_samples,
                    LIGHTS_BVH: tree_samples}


@njit(cache=True, _nrt=False, inline="always")
def area_light_crossed(lights, delta, light, ox, oy, oz, dx, dy, dz, t):
    """Whether a bounce ray (spawned at o, unit direction d, closest hit at t) finds area light
    `light`, as emission_found counts it: it crosses the light before t, and the light is not a
    face that a delta bounce sees as geometry."""
    if delta and lights.faced[light]:
        return False
    t_light = area_light_hit(lights.position, lights.direction, lights.edge_x, lights.edge_y,
                             light, ox, oy, oz, dx, dy, dz)
    return t_light * (1.0 - SHADOW_SHORTEN) < t     # (false when t_light is inf)


_EMISSION_FOUND = {}


def emission_found(mode):
    """The function that counts the emission a bounce ray finds, for light sampler `mode`
    (LIGHTS_ALL, LIGHTS_POWER or LIGHTS_BVH: the one the shading kernels used; made once per
    process, cached on disk per mode): a constant of its code, so only the light BVH's
    function compiles the tree's pmfs.

        r, g, b = found(shapes, materials, lights, options, delta, bsdf_pdf_, qx, qy, qz, qnx,
                        qny, qnz, ox, oy, oz, dx, dy, dz, t, prim, u, v, m, gx, gy, gz)

    is the emission a bounce ray from q (shading normal qn; spawned at o, unit direction d,
    closest hit at t on prim at barycentrics (u, v), material m) finds, as (r, g, b), before
    the throughput.

    After a delta bounce (mirror, glass), which light sampling cannot follow, everything it sees
    counts whole: emissive geometry (a light's face included), area lights without a face, and the
    ambient light and the environment if it escapes. After a non-delta bounce, only with multiple
    importance sampling: the area lights (faced or not; the face itself then does not count again),
    the ambient light, the environment and the emissive primitives that are lights, each with its
    power heuristic weight against the light sampling the shading kernel did at q (bsdf_pdf_ is
    this ray's density). Area lights are transparent, as in the course: a ray passes on through
    them. When the shading kernel chose lights by power or by the light BVH, a light's samples
    per vertex are -l times its probability of being chosen (at q, by the tree), and its weight
    says so."""
    if mode in _EMISSION_FOUND:
        return _EMISSION_FOUND[mode]
    SAMPLES = EXPECTED_SAMPLES[mode]
    TREE = mode == LIGHTS_BVH

    @njit(cache=True, _nrt=False, forceinline=True)
    def found(shapes, materials, lights, options, delta, bsdf_pdf_, qx, qy, qz, qnx, qny, qnz,
              ox, oy, oz, dx, dy, dz, t, prim, u, v, m, gx, gy, gz):
        r = g = b = 0.0
        kinds = lights.kind
        # the area lights the ray crosses before its hit, found by ptrace.light_hits' tree
        k = np.int64(0)     # not a literal 0: next_light would compile once more for it
        t_max = t / (1.0 - SHADOW_SHORTEN)
        while True:
            light, k = next_light(lights.hit_lower, lights.hit_upper, lights.hit_skip,
                                  lights.hit_light, k, ox, oy, oz, dx, dy, dz, t_max)
            if light < 0:
                break
            if not area_light_crossed(lights, delta, light, ox, oy, oz, dx, dy, dz, t):
                continue
            weight = 1.0
            if not delta:   # the light's density for this direction from q, as shading samples it
                n = SAMPLES(options, lights, light, qx, qy, qz, qnx, qny, qnz)
                weight = power_heuristic(bsdf_pdf_, n * area_light_pdf(lights, light, qx, qy, qz,
                                                                       dx, dy, dz))
            r += weight * lights.radiance[light, 0]
            g += weight * lights.radiance[light, 1]
            b += weight * lights.radiance[light, 2]
        for j in range(lights.sky.shape[0]):     # the lights at infinity
            light = lights.sky[j]
            kind = kinds[light]
            if kind == ENVIRONMENT and prim < 0:
                weight = 1.0
                if not delta:
                    n = SAMPLES(options, lights, light, qx, qy, qz, qnx, qny, qnz)
                    weight = power_heuristic(bsdf_pdf_, n * environment_pdf(lights.env_table, dx,
                                                                            dy, dz))
                er, eg, eb = environment_radiance(lights.env_image, dx, dy, dz)
                r += weight * er
                g += weight * eg
                b += weight * eb
            elif kind == AMBIENT and prim < 0 and dy > 0.0:
                weight = 1.0
                if not delta:
                    n = SAMPLES(options, lights, light, qx, qy, qz, qnx, qny, qnz)
                    weight = power_heuristic(bsdf_pdf_, n / (2.0 * math.pi))
                r += weight * lights.radiance[light, 0]
                g += weight * lights.radiance[light, 1]
                b += weight * lights.radiance[light, 2]
        if m >= 0 and emits(materials.kind[m]):
            weight = 1.0
            if not delta:
                if lights.prim_pdf[prim] == 0.0:
                    return r, g, b       # a light's face: its light was counted above
                if abs(dx * gx + dy * gy + dz * gz) == 0.0:
                    return r, g, b
                # the emitter sampler's density for this direction from q, as shading samples it
                if TREE:   # this primitive, chosen by the tree
                    density = options.light_samples * bvh_prim_pmf(
                        lights, prim, qx, qy, qz, qnx, qny, qnz) * primitive_pdf(
                        shapes, prim, qx, qy, qz, dx, dy, dz)
                else:   # the emissive primitives' light (the last), then this primitive by power
                    n = SAMPLES(options, lights, kinds.shape[0] - 1, qx, qy, qz, qnx, qny, qnz)
                    density = n * emitter_pdf(shapes, lights.prim_pdf, prim, qx, qy, qz, dx, dy,
                                              dz)
                weight = power_heuristic(bsdf_pdf_, density)
            er, eg, eb = surface_emission(shapes, materials, m, prim, u, v)
            r += weight * er
            g += weight * eg
            b += weight * eb
        return r, g, b

    _EMISSION_FOUND[mode] = found
    return found


@njit(cache=True, _nrt=False, forceinline=True)
def hit_normal_colour(shapes, ox, oy, oz, dx, dy, dz, t, prim, u, v):
    """The course's normal shading of a hit (t, prim, u, v) of the ray o + t d, 0.5 n + 0.5: n
    the barycentric blend of the vertex normals, not renormalised, like the course, or a
    sphere's unit outward normal; black on a miss."""
    if prim < 0:
        return 0.0, 0.0, 0.0
    faces, normals = shapes.faces, shapes.vertex_normals
    if prim < faces.shape[0]:
        w = 1.0 - u - v
        a, b, c = faces[prim, 0], faces[prim, 1], faces[prim, 2]
        nx = w * normals[a, 0] + u * normals[b, 0] + v * normals[c, 0]
        ny = w * normals[a, 1] + u * normals[b, 1] + v * normals[c, 1]
        nz = w * normals[a, 2] + u * normals[b, 2] + v * normals[c, 2]
    else:
        s = prim - faces.shape[0]
        radius = shapes.radii[s]
        nx = (ox + t * dx - shapes.centers[s, 0]) / radius
        ny = (oy + t * dy - shapes.centers[s, 1]) / radius
        nz = (oz + t * dz - shapes.centers[s, 2]) / radius
    return 0.5 * nx + 0.5, 0.5 * ny + 0.5, 0.5 * nz + 0.5



@njit(cache=True, inline="always")
def concentric_disk(u1, u2):
    """A point of the unit disc from [0, 1)^2 by Shirley and Chiu's concentric map (as pbrt's
    SampleUniformDiskConcentric): uniform over the disc like the course's (sqrt(u1), 2 pi u2),
    and it keeps the sampler's strata together (nearby (u1, u2), nearby points)."""
    a, b = 2.0 * u1 - 1.0, 2.0 * u2 - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if abs(a) > abs(b):
        r, phi = a, 0.25 * math.pi * (b / a)
    else:
        r, phi = b, 0.5 * math.pi - 0.25 * math.pi * (a / b)
    return r * math.cos(phi), r * math.sin(phi)


@njit(cache=True, _nrt=False, forceinline=True)
def camera_ray(camera, options, pixel_x, pixel_y, pixel, sample):
    """Origin and direction (unit) of a camera ray through the pixel: its centre when spp is 1,
    else a jitter uniform over the pixel (docs/course.md#camera-rays; stratified over the
    pixel's samples by the Sobol sampler). (x - W/2) / screen_dist rather than
    (2u - 1) tan(hfov/2): a pixel of a W x H window gets bit-identical rays to the same pixel of
    the 800 x 600 view. With a thin lens (the course's 3-2 Part 4) the ray leaves a point of the
    lens disc, uniform over it, toward where the pinhole ray meets the focal plane (at the focal
    distance along the optical axis); a lens of radius 0 is the pinhole, bit for bit."""
    if options.spp == 1:
        sx, sy = pixel_x + 0.5, pixel_y + 0.5
    else:
        jx, jy = sample_2d(options, pixel, sample, sample, KEY_JITTER, KEY_JITTER)
        sx, sy = pixel_x + jx, pixel_y + jy
    sx = (sx - camera.half_width) / camera.screen_dist
    sy = (sy - camera.half_height) / camera.screen_dist
    m = camera.to_world
    ox, oy, oz = camera.position[0], camera.position[1], camera.position[2]
    if camera.lens_radius > 0.0:
        u1, u2 = sample_2d(options, pixel, sample, sample, KEY_LENS, KEY_LENS)
        lx, ly = concentric_disk(u1, u2)
        lx *= camera.lens_radius
        ly *= camera.lens_radius
        d = camera.focal_distance
        ox += lx * m[0, 0] + ly * m[0, 1]
        oy += lx * m[1, 0] + ly * m[1, 1]
        oz += lx * m[2, 0] + ly * m[2, 1]
        # camera space: from (lx, ly, 0) to (sx d, sy d, -d) on the focal plane
        sx, sy = sx * d - lx, sy * d - ly
        x = sx * m[0, 0] + sy * m[0, 1] - d * m[0, 2]
        y = sx * m[1, 0] + sy * m[1, 1] - d * m[1, 2]
        z = sx * m[2, 0] + sy * m[2, 1] - d * m[2, 2]
    else:
        x = sx * m[0, 0] + sy * m[0, 1] - m[0, 2]
        y = sx * m[1, 0] + sy * m[1, 1] - m[1, 2]
        z = sx * m[2, 0] + sy * m[2, 1] - m[2, 2]
    norm = np.sqrt(x * x + y * y + z * z)
    return ox, oy, oz, x / norm, y / norm, z / norm

