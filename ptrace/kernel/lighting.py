"""The light samples of a wave's shading points, one stage for every material kind: for each
queued vertex of a kind that is not delta, -l samples of every light (or, with the power or
bvh light sampler, -l lights chosen), each a shadow ray in the wave's shadow queue with what
the shading kernel of its kind needs to weigh it (ptrace.kernel.shading): the light's radiance,
the sample's direction, its cosine over its density, and that density for multiple importance
sampling. The light sampling code is compiled once per light setup (light_stage: the light
sampler, the spots' falloff), not once per material kind; each vertex's normal is bent by its
normal map here, for every kind, before any light is sampled. A scene of area lights alone and
untextured surfaces (wavefront.simple: the course's) has no light stage: its kinds' kernels
sample the area lights themselves, with shadow_ray and queue_ray, in one pass. Random numbers
are keyed by (pixel, sample, dimension), with the dimensions of ptrace.integrator's layout
(DIM_*, RAY_KEYS)."""
import math

from numba import njit

from ..bsdf import is_delta
from ..codes import LIGHTS_ALL, LIGHTS_BVH
from ..emitters import EMITTER
from ..environment import environment_radiance, environment_sample
from ..integrator import (
    DIM_CHOOSE,
    DIM_CHOOSE_PRIM,
    DIM_LIGHT,
    DIM_SELECT,
    DIMS_PER_VERTEX,
    RAY_KEYS,
    SHADOW_SHORTEN,
    sample_1d,
    sample_2d,
    spawn,
)
from ..light_bvh import bvh_choose
from ..lights import (
    choose,
    light_is_delta,
    sample_emitter,
    sample_light,
    sample_light_angular,
    sample_primitive,
)
from ..scene import ENVIRONMENT
from ..textures import mapped_normal
from .layout import (
    DX,
    DY,
    DZ,
    GX,
    GY,
    GZ,
    MAT,
    NX,
    NY,
    NZ,
    OFFSET,
    PIXEL,
    PRIM,
    PX,
    PY,
    PZ,
    RAYS,
    SAMPLE,
    SB,
    SCOUNT,
    SDX,
    SDY,
    SDZ,
    SFIRST,
    SG,
    SLPDF,
    SOX,
    SOY,
    SOZ,
    SR,
    SSCALE,
    STMAX,
    SWX,
    SWY,
    SWZ,
    VERTEX,
    U,
    V,
)


def _light_samplers(ANGULAR):
    """(any_light, chosen_light) of one spot falloff: with ANGULAR (a constant of their code,
    a bool as ptrace.lights._light_sampler explains) Mitsuba's, ptrace.lights.
    sample_light_angular; without it glTF's, sample_light. Only one is typed into each."""

    @njit(cache=True, _nrt=False, forceinline=True)
    def of_its_kind(shapes, materials, lights, options, pixel, sample, index, light, key, dim,
                    px, py, pz, u1, u2):
        """Light `light` (not a primitive the light BVH chose) sampled from p with (u1, u2),
        by its kind: emissive geometry (its primitive chosen by the sampler's number (key,
        dim): sample_1d's), the environment, or a lamp."""
        light_kind = lights.kind[light]
        if light_kind == EMITTER:
            u0 = sample_1d(options, pixel, sample, index, key, dim)
            return sample_emitter(shapes, materials, lights.emitter_prims,
                                  lights.emitter_cdf, lights.prim_pdf, px, py, pz, u0, u1, u2)
        if light_kind == ENVIRONMENT:
            wx, wy, wz, pdf = environment_sample(lights.env_marginal, lights.env_conditional,
                                                 lights.env_table, u1, u2)
            lr, lg, lb = environment_radiance(lights.env_image, wx, wy, wz)
            return lr, lg, lb, wx, wy, wz, math.inf, pdf
        if ANGULAR:
            return sample_light_angular(lights, light, px, py, pz, u1, u2)
        return sample_light(lights, light, px, py, pz, u1, u2)

    @njit(cache=True, _nrt=False, forceinline=True)
    def any_light(shapes, materials, lights, options, pixel, sample, index, base, light, j,
                  px, py, pz):
        """Sample `index` of light `light` (any kind, of ptrace.integrator's LightArrays) from
        p, the j-th light sample of the vertex: (radiance, unit direction, distance (inf at
        infinity), pdf), with the light sampler `all`'s keys."""
        u1, u2 = sample_2d(options, pixel, sample, index, base + DIM_LIGHT + 2 * light,
                           base + DIM_LIGHT + 2 * j)
        return of_its_kind(shapes, materials, lights, options, pixel, sample, index, light,
                           base + DIM_LIGHT + 2 * light + 1, base + DIM_SELECT + j, px, py, pz,
                           u1, u2)

    @njit(cache=True, _nrt=False, forceinline=True)
    def chosen_light(shapes, materials, lights, options, pixel, sample, index, base, light,
                     prim, outer, px, py, pz):
        """Light sample `outer` of -l at p, of the light (or, with prim >= 0, the emissive
        primitive) that the power or bvh light sampler chose for it: (radiance, unit
        direction, distance, pdf), with those samplers' keys."""
        u1, u2 = sample_2d(options, pixel, sample, index, base + DIM_LIGHT,
                           base + DIM_LIGHT + 4 * outer)
        if prim >= 0:     # (bvh) one emissive primitive, chosen by the tree
            return sample_primitive(shapes, materials, prim, px, py, pz, u1, u2)
        return of_its_kind(shapes, materials, lights, options, pixel, sample, index, light,
                           base + DIM_LIGHT + DIM_CHOOSE_PRIM, base + DIM_LIGHT + 4 * outer + 3,
                           px, py, pz, u1, u2)

    return any_light, chosen_light


any_light, chosen_light = _light_samplers(False)
any_light_angular, chosen_light_angular = _light_samplers(True)


@njit(cache=True, _nrt=False, inline="always")
def queue_ray(shadow, shadow_path, shadow_key, s, ox, oy, oz, dx, dy, dz, tmax, r, g, b, path,
              key):
    """Row s of the shadow queue: a ray o + t d, t in [0, tmax], of path `path` with its key,
    carrying the light (r, g, b) it adds if it is clear (with -H: the weight of what it
    finds)."""
    shadow[SOX, s] = ox
    shadow[SOY, s] = oy
    shadow[SOZ, s] = oz
    shadow[SDX, s] = dx
    shadow[SDY, s] = dy
    shadow[SDZ, s] = dz
    shadow[STMAX, s] = tmax
    shadow[SR, s] = r
    shadow[SG, s] = g
    shadow[SB, s] = b
    shadow_path[s] = path
    shadow_key[s] = key


@njit(cache=True, _nrt=False, inline="always")
def shadow_ray(px, py, pz, gx, gy, gz, offset, wx, wy, wz, dist):
    """The shadow ray of a light sample at p (geometric normal g, spawn offset) in unit
    direction w, its light at distance dist (inf: at infinity): (origin, unit direction, tmax),
    spawned off the surface and aimed from there at the light's point, stopping just short."""
    ox, oy, oz = spawn(px, py, pz, gx, gy, gz, offset, wx, wy, wz)
    sdx, sdy, sdz, tmax = wx, wy, wz, math.inf   # a light at infinity
    if dist != math.inf:
        ax = px + dist * wx - ox
        ay = py + dist * wy - oy
        az = pz + dist * wz - oz
        length = math.sqrt(ax * ax + ay * ay + az * az)
        if length > 0.0:
            sdx, sdy, sdz = ax / length, ay / length, az / length
        tmax = length * (1.0 - SHADOW_SHORTEN)
    return ox, oy, oz, sdx, sdy, sdz, tmax


_LIGHT_STAGES = {}


def light_stage(mode=LIGHTS_ALL, hemisphere=False, angular=False):
    """The light stage of one light setup (a scene whose lights are not area lights alone, or
    whose surfaces are textured: wavefront.simple's other scenes, whose kinds' kernels sample
    their area lights themselves), made once per process and cached on disk per setup:

        shadows = stage(shapes, materials, lights, options, floats, ints, queue, n, shadow,
                        shadow_path, shadow_key, shadows)

    For each of the n queued vertices (a wave's shading points, sorted by kind): its shading
    normal bent by its normal map (when the bent normal keeps the incoming ray on its side),
    written back to its NX, NY, NZ rows; then, unless its kind is delta or -H is on
    (`hemisphere`: the hemisphere's rays are its kind's kernel's), its light samples appended to
    the shadow queue from row `shadows` on, their first row and count in its SFIRST and SCOUNT
    rows. A row holds the shadow ray, its light's radiance (SR, SG, SB), the unit direction to
    the light (SWX, SWY, SWZ), its cosine over its density and weight (SSCALE) and that density
    times the weight for multiple importance sampling (SLPDF; negated for a delta light, which
    is not weighed). Returns the new count. The lights are any of ptrace.integrator's lights and
    emissive geometry; mode: the light sampler (ptrace.codes' LIGHTS_*); with `angular`, spots
    fall off as Mitsuba's (ptrace.lights.sample_light_angular), else as glTF's."""
    angular = bool(angular)
    if hemisphere:   # normals alone: no light sampling code
        mode, angular = LIGHTS_ALL, False
    key = (mode, hemisphere, angular)
    if key in _LIGHT_STAGES:
        return _LIGHT_STAGES[key]
    MODE, HEMI, ANGULAR = mode, hemisphere, angular
    CHOOSE = mode != LIGHTS_ALL   # one light per light sample, by power or by the tree
    any_light_, chosen_light_ = ((any_light_angular, chosen_light_angular) if ANGULAR else
                                 (any_light, chosen_light))

    @njit(cache=True, nogil=True, _nrt=False)
    def stage(shapes, materials, lights, options, floats, ints, queue, n, shadow, shadow_path,
              shadow_key, shadows):
        light_count = lights.radiance.shape[0]
        samples = options.light_samples
        for k in range(n):
            i = queue[k]
            m = ints[MAT, i]
            nx, ny, nz = floats[NX, i], floats[NY, i], floats[NZ, i]
            # a bent normal that keeps the incoming ray on its side
            dx, dy, dz = floats[DX, i], floats[DY, i], floats[DZ, i]
            sx, sy, sz = mapped_normal(shapes, materials, m, ints[PRIM, i], floats[U, i],
                                       floats[V, i], nx, ny, nz)
            if (sx != nx or sy != ny or sz != nz) and \
                    (dx * sx + dy * sy + dz * sz) * (dx * nx + dy * ny + dz * nz) > 0.0:
                nx, ny, nz = sx, sy, sz
                floats[NX, i], floats[NY, i], floats[NZ, i] = nx, ny, nz
            ints[SFIRST, i] = shadows
            ints[SCOUNT, i] = 0
            if HEMI or is_delta(materials.kind[m]):
                continue
            pixel, sample, vertex = ints[PIXEL, i], ints[SAMPLE, i], ints[VERTEX, i]
            px, py, pz = floats[PX, i], floats[PY, i], floats[PZ, i]
            gx, gy, gz = floats[GX, i], floats[GY, i], floats[GZ, i]
            offset = floats[OFFSET, i]
            base = vertex * DIMS_PER_VERTEX
            rays = 0
            j = 0
            for outer in range(samples if CHOOSE and light_count else light_count):
                light = outer
                if CHOOSE:   # light sample `outer` of -l: one light, by power or the tree
                    index = sample * samples + outer
                    u0 = sample_1d(options, pixel, sample, index, base + DIM_LIGHT + DIM_CHOOSE,
                                   base + DIM_LIGHT + 4 * outer + 2)
                    light_prim = -1
                    if MODE == LIGHTS_BVH:
                        light, light_prim, chosen = bvh_choose(lights, u0, px, py, pz, nx, ny,
                                                               nz)
                        if light < 0:
                            continue
                    else:
                        light = choose(lights.select_cdf, u0)
                        chosen = lights.select_pmf[light]
                count = samples
                delta_light = light_is_delta(lights.kind[light], lights.model[light])
                if delta_light or CHOOSE:
                    count = 1
                for s in range(count):
                    if CHOOSE:   # weight: the light's expected samples at this vertex
                        weight = samples * chosen
                        lr, lg, lb, wx, wy, wz, dist, pdf = chosen_light_(
                            shapes, materials, lights, options, pixel, sample, index, base,
                            light, light_prim, outer, px, py, pz)
                    else:
                        weight = count
                        index = sample * count + s
                        lr, lg, lb, wx, wy, wz, dist, pdf = any_light_(
                            shapes, materials, lights, options, pixel, sample, index, base,
                            light, j, px, py, pz)
                    j += 1
                    if pdf < 1e-11:
                        continue
                    if lights.kind[light] == EMITTER and dist <= offset:
                        # a point of p's own emissive surface: within rounding of p its
                        # direction is noise, and no light leaves a surface into itself
                        continue
                    wiz = wx * nx + wy * ny + wz * nz
                    if wiz <= 0.0:
                        continue
                    ox, oy, oz, sdx, sdy, sdz, tmax = shadow_ray(px, py, pz, gx, gy, gz, offset,
                                                                 wx, wy, wz, dist)
                    rays += 1
                    queue_ray(shadow, shadow_path, shadow_key, shadows, ox, oy, oz, sdx, sdy, sdz,
                              tmax, lr, lg, lb, i, base + RAY_KEYS * j)
                    shadow[SWX, shadows] = wx
                    shadow[SWY, shadows] = wy
                    shadow[SWZ, shadows] = wz
                    shadow[SSCALE, shadows] = wiz / (weight * pdf)
                    shadow[SLPDF, shadows] = -1.0 if delta_light else weight * pdf
                    shadows += 1
            ints[SCOUNT, i] = rays
            ints[RAYS, i] += rays
        return shadows

    _LIGHT_STAGES[key] = stage
    return stage
