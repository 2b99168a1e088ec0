"""The wavefront's stages that know no material kind and no backend: camera rays, what a hit
leaves (its surface, the emission it finds, and the queue of the paths that go on to shading),
the light that clear shadow rays carry, and the per-pixel sums. Each runs over a queue of path
slots of one wave (ptrace.kernel.layout) and is compiled once, for every backend.

A path's random numbers are keyed by (pixel, sample, dimension) and its light is added in the
order it was found, so a wave renders the same image bit for bit whatever the wave size, the
threads or the order the paths are processed in."""

import numpy as np
from numba import njit

from ..codes import LIGHTS_ALL
from ..environment import environment_radiance
from ..integrator import (
    SHADOW_SHORTEN,
    area_light_crossed,
    camera_ray,
    emission_found,
    emits,
    hit_normal_colour,
    power_heuristic,
    surface,
)
from ..light_hits import next_light
from ..lights import area_light_pdf
from ..scene import EMISSION, LUMINANCE
from ..textures import surface_emission
from .layout import (
    DELTA,
    DX,
    DY,
    DZ,
    GX,
    GY,
    GZ,
    KEY,
    MAT,
    NX,
    NY,
    NZ,
    OFFSET,
    OX,
    OY,
    OZ,
    PDF,
    PIXEL,
    PRIM,
    PX,
    PY,
    PZ,
    QNX,
    QNY,
    QNZ,
    QX,
    QY,
    QZ,
    RAYS,
    SAMPLE,
    SB,
    SDX,
    SDY,
    SDZ,
    SG,
    SR,
    TB,
    TG,
    TMAX,
    TMIN,
    TR,
    VERTEX,
    B,
    G,
    R,
    T,
    U,
    V,
)


@njit(cache=True, nogil=True, _nrt=False)
def camera_stage(camera, options, pixel_x, pixel_y, first_sample, pass_n, start, count, floats,
                 ints, queue):
    """Slots 0 .. count - 1 get the camera rays of the block's paths start .. start + count - 1
    (path b is sample first_sample + b % pass_n of pixel b // pass_n), each with throughput 1,
    no radiance, and one ray traced; the queue lists them."""
    width = camera.width
    for slot in range(count):
        b = start + slot
        k = b // pass_n
        sample = first_sample + b % pass_n
        pixel = pixel_y[k] * width + pixel_x[k]
        ox, oy, oz, dx, dy, dz = camera_ray(camera, options, pixel_x[k], pixel_y[k], pixel,
                                            sample)
        floats[OX, slot], floats[OY, slot], floats[OZ, slot] = ox, oy, oz
        floats[DX, slot], floats[DY, slot], floats[DZ, slot] = dx, dy, dz
        floats[TMIN, slot], floats[TMAX, slot] = camera.znear, camera.zfar
        floats[TR, slot] = floats[TG, slot] = floats[TB, slot] = 1.0
        floats[R, slot] = floats[G, slot] = floats[B, slot] = 0.0
        ints[PIXEL, slot], ints[SAMPLE, slot] = pixel, sample
        ints[VERTEX, slot], ints[RAYS, slot], ints[DELTA, slot], ints[KEY, slot] = 0, 1, 0, 0
        queue[slot] = slot


@njit(cache=True, _nrt=False, forceinline=True)
def area_lights_found(lights, light_samples, delta, bsdf_pdf_, qx, qy, qz, ox, oy, oz, dx, dy,
                      dz, t):
    """The area lights' emission that a bounce ray from q (spawned at o, unit direction d,
    closest hit at t) finds: after a delta bounce whole, but for the lights whose face is
    geometry (which then counts as emissive geometry); after a non-delta bounce of density
    bsdf_pdf_, each weighted by the power heuristic against the -l samples that light sampling
    took of it at q (every light sampled: ptrace.integrator.emission_found under
    --light-sampler all)."""
    r = g = b = 0.0
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
        if not delta:
            weight = power_heuristic(bsdf_pdf_, light_samples * area_light_pdf(
                lights, light, qx, qy, qz, dx, dy, dz))
        r += weight * lights.radiance[light, 0]
        g += weight * lights.radiance[light, 1]
        b += weight * lights.radiance[light, 2]
    return r, g, b


_HIT_STAGES = {}


def hit_stage(general=False, mode=LIGHTS_ALL):
    """The hit stage (made once per process, cached on disk per variant):

        kept = stage(shapes, materials, lights, options, mis, floats, ints, queue, n, out,
                     starts)

    For each queued path whose closest hit is known: the surface it hit (material, point,
    normals, spawn offset); at the camera's vertex, the emission it sees; after a delta bounce,
    or a bounce with multiple importance sampling, the emission its ray found. A path that
    missed, hit an emitter or reached -m ends; the others move to their next vertex and are
    listed in out by material kind: kind c's paths are out[starts[c]:starts[c + 1]] (a counting
    sort, so each kind's shading kernel runs over a queue of its own). Returns how many.
    Without `general` the lights are area lights (wavefront.AreaLights), the emitters their
    faces and the surfaces untextured; with it, the emission is ptrace.integrator's
    emission_found over ptrace.integrator's full records (any light, the environment as the
    background, emissive geometry, emission textures, glTF's emissive material), for light
    sampler `mode` (ptrace.codes' LIGHTS_*: the shading kernels')."""
    key = (general, mode if general else LIGHTS_ALL)
    if key in _HIT_STAGES:
        return _HIT_STAGES[key]
    GENERAL = general
    FOUND = emission_found(key[1])

    @njit(cache=True, nogil=True, _nrt=False)
    def stage(shapes, materials, lights, options, mis, floats, ints, queue, n, out, starts):
        kinds = materials.kind
        light_samples = float(options.light_samples)
        max_depth = options.max_depth
        kinds_count = starts.shape[0] - 1
        for c in range(kinds_count + 1):
            starts[c] = 0
        for k in range(n):
            i = queue[k]
            ox, oy, oz = floats[OX, i], floats[OY, i], floats[OZ, i]
            dx, dy, dz = floats[DX, i], floats[DY, i], floats[DZ, i]
            t, prim, u, v = floats[T, i], ints[PRIM, i], floats[U, i], floats[V, i]
            m, px, py, pz, gx, gy, gz, nx, ny, nz, offset = surface(shapes, kinds, ox, oy, oz,
                                                                    dx, dy, dz, t, prim, u, v)
            vertex = ints[VERTEX, i]
            if vertex == 0:
                if options.hide_emitters:   # (what the camera meets directly is not seen)
                    pass
                elif GENERAL:
                    r = g = b = 0.0
                    if m < 0:
                        if lights.env_image.shape[0] > 0:   # the environment is the background
                            r, g, b = environment_radiance(lights.env_image, dx, dy, dz)
                    elif emits(kinds[m]):
                        r, g, b = surface_emission(shapes, materials, m, prim, u, v)
                    floats[R, i], floats[G, i], floats[B, i] = r, g, b
                elif m >= 0 and kinds[m] == EMISSION:
                    floats[R, i] = materials.emission[m, 0]
                    floats[G, i] = materials.emission[m, 1]
                    floats[B, i] = materials.emission[m, 2]
            else:
                delta = ints[DELTA, i] != 0
                if delta or mis:
                    if GENERAL:
                        er, eg, eb = FOUND(
                            shapes, materials, lights, options, delta, floats[PDF, i],
                            floats[QX, i], floats[QY, i], floats[QZ, i], floats[QNX, i],
                            floats[QNY, i], floats[QNZ, i], ox, oy, oz, dx, dy, dz, t, prim, u, v,
                            m, gx, gy, gz)
                    else:
                        er, eg, eb = area_lights_found(lights, light_samples, delta,
                                                       floats[PDF, i], floats[QX, i],
                                                       floats[QY, i], floats[QZ, i], ox, oy, oz,
                                                       dx, dy, dz, t)
                        if delta and m >= 0 and kinds[m] == EMISSION:
                            er += 1.0 * materials.emission[m, 0]
                            eg += 1.0 * materials.emission[m, 1]
                            eb += 1.0 * materials.emission[m, 2]
                    floats[R, i] += floats[TR, i] * er
                    floats[G, i] += floats[TG, i] * eg
                    floats[B, i] += floats[TB, i] * eb
            if m < 0 or vertex == max_depth or kinds[m] == EMISSION:
                ints[MAT, i] = -1
                continue
            floats[PX, i], floats[PY, i], floats[PZ, i] = px, py, pz
            floats[GX, i], floats[GY, i], floats[GZ, i] = gx, gy, gz
            floats[NX, i], floats[NY, i], floats[NZ, i] = nx, ny, nz
            floats[OFFSET, i] = offset
            ints[MAT, i] = m
            ints[VERTEX, i] = vertex + 1
            starts[kinds[m] + 1] += 1
        for c in range(kinds_count):     # where each kind's paths begin
            starts[c + 1] += starts[c]
        kept = starts[kinds_count]
        for k in range(n):               # (the ends move up to the next kind's start as they fill)
            i = queue[k]
            m = ints[MAT, i]
            if m >= 0:
                c = kinds[m]
                out[starts[c]] = i
                starts[c] += 1
        for c in range(kinds_count, 0, -1):
            starts[c] = starts[c - 1]
        starts[0] = 0
        return kept

    _HIT_STAGES[key] = stage
    return stage


@njit(cache=True, nogil=True, _nrt=False)
def normals_stage(shapes, floats, ints, n):
    """The normals integrator's colour of each of the first n paths' camera hit (the course's
    normal shading, ptrace.integrator.hit_normal_colour): 0.5 n + 0.5, n the barycentric blend
    of the vertex normals (not renormalised, like the course) or a sphere's unit outward
    normal; black on a miss."""
    for i in range(n):
        r, g, b = hit_normal_colour(shapes, floats[OX, i], floats[OY, i], floats[OZ, i],
                                    floats[DX, i], floats[DY, i], floats[DZ, i], floats[T, i],
                                    ints[PRIM, i], floats[U, i], floats[V, i])
        floats[R, i], floats[G, i], floats[B, i] = r, g, b


@njit(cache=True, nogil=True, _nrt=False)
def shadow_stage(floats, shadow, shadow_path, blocked, n):
    """Each clear shadow ray's light, added to its path's radiance, in queue order (a path's
    light samples in the order it took them)."""
    for s in range(n):
        if not blocked[s]:
            i = shadow_path[s]
            floats[R, i] += shadow[SR, s]
            floats[G, i] += shadow[SG, s]
            floats[B, i] += shadow[SB, s]


@njit(cache=True, nogil=True, _nrt=False)
def probe_found_stage(shapes, materials, lights, floats, shadow, shadow_path, probe_prim,
                      probe_uv, n):
    """(-H) The emission each hemisphere ray found (the environment's radiance where it escaped),
    times its weight, added to its path's radiance in queue order. materials, lights: the full
    records (ptrace.integrator's MaterialArrays, LightArrays)."""
    env = lights.env_image.shape[0] > 0
    for s in range(n):
        prim = probe_prim[s]
        if prim < 0:
            if not env:
                continue
            er, eg, eb = environment_radiance(lights.env_image, shadow[SDX, s], shadow[SDY, s],
                                              shadow[SDZ, s])
        else:
            e = shapes.material_index[prim]
            if not emits(materials.kind[e]):
                continue
            er, eg, eb = surface_emission(shapes, materials, e, prim, probe_uv[0, s],
                                          probe_uv[1, s])
        i = shadow_path[s]
        floats[R, i] += shadow[SR, s] * er
        floats[G, i] += shadow[SG, s] * eg
        floats[B, i] += shadow[SB, s] * eb


@njit(cache=True, nogil=True, _nrt=False)
def fold_stage(floats, ints, start, count, pass_n, sums, counts, features, feature_sums):
    """The wave's finished paths added to their block pixel's sums (radiance, illuminance and
    its square; counts: finite samples) in path order, which is sample order; with AOVs
    (feature_sums has rows), each kept sample's features too, and the camera ray traced again
    for them. Returns (non-finite samples dropped, rays traced)."""
    aovs = feature_sums.shape[0] > 0
    l0, l1, l2 = LUMINANCE[0], LUMINANCE[1], LUMINANCE[2]
    dropped = 0
    rays = 0
    for slot in range(count):
        k = (start + slot) // pass_n
        rays += ints[RAYS, slot]
        x, y, z = floats[R, slot], floats[G, slot], floats[B, slot]
        if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(z)):
            dropped += 1
            continue
        value = x * l0 + y * l1 + z * l2
        sums[k, 0] += x
        sums[k, 1] += y
        sums[k, 2] += z
        sums[k, 3] += value
        sums[k, 4] += value * value
        counts[k] += 1
        if aovs:
            rays += 1
            for f in range(8):
                feature_sums[k, f] += features[f, slot]
    return dropped, rays


@njit(cache=True, nogil=True, _nrt=False)
def add_stage(sums, counts, rows, sum_rgb, sum_l, sum_l2, count, feature_sums, features):
    """A block's per-pixel sums (and AOV sums, if feature_sums has rows) added to the render's
    at their rows."""
    for k in range(rows.shape[0]):
        if feature_sums.shape[0] > 0:
            for f in range(8):
                features[rows[k], f] += feature_sums[k, f]
        row = rows[k]
        sum_rgb[row, 0] += sums[k, 0]
        sum_rgb[row, 1] += sums[k, 1]
        sum_rgb[row, 2] += sums[k, 2]
        sum_l[row] += sums[k, 3]
        sum_l2[row] += sums[k, 4]
        count[row] += counts[k]


