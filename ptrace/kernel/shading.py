"""One shading kernel per material kind, made on demand (shading_stage(kind)) and compiled only for
the kinds a scene has: at each queued vertex, -l samples of every area light unless the kind is
delta (each a shadow ray in the wave's shadow queue, carrying the light it would add, weighted
by the power heuristic against the BSDF's sample with multiple importance sampling), then the
BSDF's sample, roulette, and the next ray. A kernel calls its own kind's BSDF functions
(ptrace.bsdf.BSDFS), so no other kind's code is compiled into it. Random numbers are keyed by
(pixel, sample, dimension), with the dimensions of ptrace.integrator's layout (DIM_*, RAY_KEYS)."""
import math

from numba import njit

from ..bsdf import BSDFS, EXACT_GLASS, MIXED, is_delta, uniform_hemisphere
from ..codes import LIGHTS_ALL, LIGHTS_BVH
from ..environment import environment_radiance, environment_sample
from ..integrator import (
    DIM_BSDF,
    DIM_CHOOSE,
    DIM_CHOOSE_PRIM,
    DIM_GLASS,
    DIM_LIGHT,
    DIM_RR,
    DIM_SELECT,
    DIMS_PER_VERTEX,
    RAY_KEYS,
    SHADOW_SHORTEN,
    frame,
    power_heuristic,
    sample_1d,
    sample_2d,
    spawn,
)
from ..light_bvh import bvh_choose
from ..lights import (
    EMITTER,
    choose,
    light_is_delta,
    sample_area_row,
    sample_emitter,
    sample_light,
    sample_light_angular,
    sample_primitive,
)
from ..scene import ENVIRONMENT, GLASS, GLOSSY, GLTF_PBR, ROUGH_PLASTIC
from ..textures import mapped_normal, surface_albedo
from .guide import folded_pdf, folded_sample, guide_leaf, remember
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
    SOX,
    SOY,
    SOZ,
    SR,
    STMAX,
    TB,
    TG,
    TMAX,
    TMIN,
    TR,
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


_STAGES = {}


def shading_stage(kind, general=False, mode=LIGHTS_ALL, hemisphere=False, guided=False,
                  angular=False, exact=False):
    """The shading kernel of material kind `kind` (one of ptrace.scene's BSDF codes but
    EMISSION), made once per process and cached on disk per kind:

        shadows, kept = stage(shapes, materials, lights, options, mis, floats, ints, queue, n,
                              shadow, shadow_path, shadow_key, shadows, out, kept, guide,
                              history, depth)

    shades the n queued vertices, appending their shadow rays to the shadow queue from row
    `shadows` on and the paths that bounce to out from `kept` on; returns both new counts.
    Without `general` the lights are area lights and the surfaces untextured
    (wavefront.AreaLights and SurfaceArrays); with it, any of ptrace.integrator's lights and
    emissive geometry, and textured albedo, roughness, metallic and normals, from its full
    records (shapes, materials, lights). mode: the light sampler (ptrace.codes: LIGHTS_ALL,
    or LIGHTS_POWER or LIGHTS_BVH, which need `general`). With `hemisphere` (-H, which needs
    `general`), the shadow queue gets the course's uniform hemisphere rays instead of light
    samples: -l for each light that is not emissive geometry (at least -l), each carrying
    f cos / (pdf n) times the throughput, the weight of the emission it will find
    (stages.probe_found_stage).

    With `guided` (a kind that is not delta, without -H), the bounce is drawn from the guide
    (ptrace.kernel.guide.GuideArrays), folded above the surface (every such kind only
    reflects), with probability guide.alpha x guide.share of the vertex's spatial leaf (the
    first bounce sample's u1 split at it) and from the BSDF otherwise, and weighted by the
    mixture's pdf; the MIS weights between the light samples and the bounce's emission take the
    BSDF's pdf alone (no guide lookup per light sample); guide.alpha 0 skips the guide.
    With guide.record set, each bounce is remembered in `history` (its first `depth` vertices)
    for the guide's records. Without it, guide, history and depth are not read.

    With `angular`, the scene's spots fall off as Mitsuba's
    (ptrace.lights.sample_light_angular); without it, as glTF's. With `exact`, a GLASS kind
    reflects with the exact Fresnel reflectance (ptrace.bsdf.EXACT_GLASS), not Schlick's."""
    exact = bool(exact) and kind == GLASS
    key = (kind, general, mode, hemisphere, guided, bool(angular), exact)
    if key in _STAGES:
        return _STAGES[key]
    # this kind's alone: no other compiles
    BSDF_SAMPLE, BSDF_EVAL, BSDF_PDF = EXACT_GLASS if exact else BSDFS[kind]
    GENERAL, MODE, HEMI = general, mode, hemisphere
    CHOOSE = mode != LIGHTS_ALL   # one light per light sample, by power or by the tree
    DELTA_KIND = bool(getattr(is_delta, "py_func", is_delta)(kind))   # (NUMBA_DISABLE_JIT)
    MIXED_KIND = kind in MIXED    # a delta lobe beside a non-delta one (ptrace.bsdf.MIXED)
    LOBES = kind in (GLASS, GLOSSY, GLTF_PBR, ROUGH_PLASTIC) or MIXED_KIND   # one more number
    GUIDED = guided and not DELTA_KIND and not MIXED_KIND and not hemisphere
    ANGULAR = bool(angular)   # its light samplers: Mitsuba's spot falloff (_light_samplers)
    LIT = not DELTA_KIND     # light samples (a constant: a delta kind's code has none)

    @njit(cache=True, nogil=True, _nrt=False)
    def stage(shapes, materials, lights, options, mis, floats, ints, queue, n, shadow,
              shadow_path, shadow_key, shadows, out, kept, guide, history, depth):
        light_count = lights.radiance.shape[0] if not DELTA_KIND else 0
        samples = options.light_samples
        max_depth = options.max_depth
        for k in range(n):
            i = queue[k]
            pixel, sample, vertex = ints[PIXEL, i], ints[SAMPLE, i], ints[VERTEX, i]
            m = ints[MAT, i]
            px, py, pz = floats[PX, i], floats[PY, i], floats[PZ, i]
            gx, gy, gz = floats[GX, i], floats[GY, i], floats[GZ, i]
            nx, ny, nz = floats[NX, i], floats[NY, i], floats[NZ, i]
            offset = floats[OFFSET, i]
            dx, dy, dz = floats[DX, i], floats[DY, i], floats[DZ, i]
            tr, tg, tb = floats[TR, i], floats[TG, i], floats[TB, i]
            xx, xy, xz, yx, yy, yz = frame(nx, ny, nz)
            wox = -dx * xx - dy * xy - dz * xz
            woy = -dx * yx - dy * yy - dz * yz
            woz = -dx * nx - dy * ny - dz * nz
            if GENERAL:     # textures: a bent normal, the albedo, roughness and metallic
                prim, u, v = ints[PRIM, i], floats[U, i], floats[V, i]
                sx, sy, sz = mapped_normal(shapes, materials, m, prim, u, v, nx, ny, nz)
                if (sx != nx or sy != ny or sz != nz) and \
                        (dx * sx + dy * sy + dz * sz) * (dx * nx + dy * ny + dz * nz) > 0.0:
                    # a bent normal that keeps wo on its side (else the unbent one shades)
                    nx, ny, nz = sx, sy, sz
                    xx, xy, xz, yx, yy, yz = frame(nx, ny, nz)
                    wox = -dx * xx - dy * xy - dz * xz
                    woy = -dx * yx - dy * yy - dz * yz
                    woz = -dx * nx - dy * ny - dz * nz
                ar, ag, ab, alpha, metallic = surface_albedo(shapes, materials, m, prim, u, v)
            else:
                ar, ag, ab = (materials.albedo[m, 0], materials.albedo[m, 1],
                              materials.albedo[m, 2])
                alpha, metallic = materials.alpha[m], materials.metallic[m]
            base = vertex * DIMS_PER_VERTEX
            rays = 0
            mix = 0.0
            leaf = 0
            if GUIDED and guide.alpha > 0.0:   # (alpha 0: the guide is off, and skipped)
                leaf = guide_leaf(guide.axis, guide.split, guide.child, guide.root, px, py, pz)
                mix = guide.alpha * guide.share[leaf]
            if LIT:   # (a delta kind's kernel has no light sampling code at all)
                if HEMI and light_count:    # -H: the course's uniform hemisphere sampling
                    count = 0
                    for light in range(light_count):
                        count += lights.kind[light] != EMITTER
                    count = max(count, 1) * samples
                    for j in range(count):
                        u1, u2 = sample_2d(options, pixel, sample, sample * count + j,
                                           base + DIM_LIGHT, base + DIM_LIGHT + 2 * j)
                        lx, ly, lz = uniform_hemisphere(u1, u2)
                        fr, fg, fb = BSDF_EVAL(ar, ag, ab, alpha, metallic, materials.eta,
                                               materials.k, materials.specular, m, wox, woy, woz,
                                               lx, ly, lz)
                        scale = lz * 2.0 * math.pi / count
                        wx = lx * xx + ly * yx + lz * nx
                        wy = lx * xy + ly * yy + lz * ny
                        wz = lx * xz + ly * yz + lz * nz
                        ox, oy, oz = spawn(px, py, pz, gx, gy, gz, offset, wx, wy, wz)
                        rays += 1
                        queue_ray(shadow, shadow_path, shadow_key, shadows, ox, oy, oz, wx, wy, wz,
                                  math.inf, tr * (fr * scale), tg * (fg * scale), tb * (fb * scale),
                                  i, base + RAY_KEYS * (1 + j))
                        shadows += 1
                j = 0
                lit = 0 if HEMI else light_count     # (-H takes no light samples)
                for outer in range(samples if CHOOSE and lit else lit):
                    light = outer
                    if CHOOSE:   # light sample `outer` of -l: one light, by power or the tree
                        index = sample * samples + outer
                        u0 = sample_1d(options, pixel, sample, index,
                                       base + DIM_LIGHT + DIM_CHOOSE,
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
                    delta_light = False
                    if GENERAL:
                        delta_light = light_is_delta(lights.kind[light], lights.model[light])
                        if delta_light or CHOOSE:
                            count = 1
                    for s in range(count):
                        if CHOOSE:   # weight: the light's expected samples at this vertex
                            weight = samples * chosen
                            if ANGULAR:
                                lr, lg, lb, wx, wy, wz, dist, pdf = chosen_light_angular(
                                    shapes, materials, lights, options, pixel, sample, index,
                                    base, light, light_prim, outer, px, py, pz)
                            else:
                                lr, lg, lb, wx, wy, wz, dist, pdf = chosen_light(
                                    shapes, materials, lights, options, pixel, sample, index,
                                    base, light, light_prim, outer, px, py, pz)
                        elif GENERAL:
                            weight = count
                            index = sample * count + s
                            if ANGULAR:
                                lr, lg, lb, wx, wy, wz, dist, pdf = any_light_angular(
                                    shapes, materials, lights, options, pixel, sample, index,
                                    base, light, j, px, py, pz)
                            else:
                                lr, lg, lb, wx, wy, wz, dist, pdf = any_light(
                                    shapes, materials, lights, options, pixel, sample, index,
                                    base, light, j, px, py, pz)
                        else:
                            weight = count
                            index = sample * count + s
                            u1, u2 = sample_2d(options, pixel, sample, index,
                                               base + DIM_LIGHT + 2 * light,
                                               base + DIM_LIGHT + 2 * j)
                            lr, lg, lb, wx, wy, wz, dist, pdf = sample_area_row(lights, light,
                                                                                px, py, pz, u1,
                                                                                u2)
                        j += 1
                        if pdf < 1e-11:
                            continue
                        if GENERAL:
                            if lights.kind[light] == EMITTER and dist <= offset:
                                # a point of p's own emissive surface: within rounding of p its
                                # direction is noise, and no light leaves a surface into itself
                                continue
                        wiz = wx * nx + wy * ny + wz * nz
                        if wiz <= 0.0:
                            continue
                        wix = wx * xx + wy * xy + wz * xz
                        wiy = wx * yx + wy * yy + wz * yz
                        fr, fg, fb = BSDF_EVAL(ar, ag, ab, alpha, metallic, materials.eta,
                                               materials.k, materials.specular, m, wox, woy, woz,
                                               wix, wiy, wiz)
                        scale = wiz / (weight * pdf)
                        if options.mis and not delta_light:
                            other = BSDF_PDF(ar, ag, ab, alpha, metallic, materials.eta,
                                             materials.k, materials.specular, m, wox, woy, woz,
                                             wix, wiy, wiz)
                            scale *= power_heuristic(weight * pdf, other)
                        ox, oy, oz = spawn(px, py, pz, gx, gy, gz, offset, wx, wy, wz)
                        sdx, sdy, sdz, tmax = wx, wy, wz, math.inf   # a light at infinity
                        if dist != math.inf:
                            # aim from the spawned origin at the light's point, stopping just short
                            ax = px + dist * wx - ox
                            ay = py + dist * wy - oy
                            az = pz + dist * wz - oz
                            length = math.sqrt(ax * ax + ay * ay + az * az)
                            if length > 0.0:
                                sdx, sdy, sdz = ax / length, ay / length, az / length
                            tmax = length * (1.0 - SHADOW_SHORTEN)
                        rays += 1
                        queue_ray(shadow, shadow_path, shadow_key, shadows, ox, oy, oz, sdx, sdy,
                                  sdz, tmax, tr * (lr * fr * scale), tg * (lg * fg * scale),
                                  tb * (lb * fb * scale), i, base + RAY_KEYS * j)
                        shadows += 1
            ints[RAYS, i] += rays
            if vertex == max_depth and not (DELTA_KIND or MIXED_KIND or mis):
                continue
            u1, u2 = sample_2d(options, pixel, sample, sample, base + DIM_BSDF, base + DIM_BSDF)
            u3 = 0.0
            if LOBES:
                u3 = sample_1d(options, pixel, sample, sample, base + DIM_GLASS,
                               base + DIM_GLASS)
            guided = False
            if GUIDED and mix > 0.0:
                # the choice between the guide and the BSDF splits u1 (Müller et al.'s code),
                # so each keeps a stratified share of the 2D points
                if u1 < mix:
                    guided = True
                    u1 = min(u1 / mix, 0.9999999999999999)
                else:
                    u1 = min((u1 - mix) / (1.0 - mix), 0.9999999999999999)
            if guided:
                # the guide's direction, weighted by the mixture's pdf
                wx, wy, wz, guided_pdf = folded_sample(guide, leaf, u1, u2, nx, ny, nz)
                wix = wx * xx + wy * xy + wz * xz
                wiy = wx * yx + wy * yy + wz * yz
                wiz = wx * nx + wy * ny + wz * nz
                fr, fg, fb = BSDF_EVAL(ar, ag, ab, alpha, metallic, materials.eta,
                                       materials.k, materials.specular, m, wox, woy, woz, wix,
                                       wiy, wiz)
                bsdf_pdf = BSDF_PDF(ar, ag, ab, alpha, metallic, materials.eta, materials.k,
                                    materials.specular, m, wox, woy, woz, wix, wiy, wiz)
                pdf = mix * guided_pdf + (1.0 - mix) * bsdf_pdf
            else:
                wix, wiy, wiz, fr, fg, fb, pdf = BSDF_SAMPLE(
                    ar, ag, ab, materials.transmittance, materials.ior, alpha, metallic,
                    materials.eta, materials.k, materials.specular, m, wox, woy, woz, u1, u2,
                    u3)
                bsdf_pdf = pdf
                if GUIDED and mix > 0.0 and pdf > 1e-11:
                    wx = wix * xx + wiy * yx + wiz * nx
                    wy = wix * xy + wiy * yy + wiz * ny
                    wz = wix * xz + wiy * yz + wiz * nz
                    length = math.sqrt(wx * wx + wy * wy + wz * wz)
                    pdf = (1.0 - mix) * pdf + mix * folded_pdf(guide, leaf, wx / length,
                                                               wy / length, wz / length, nx, ny,
                                                               nz)
            delta = DELTA_KIND
            if MIXED_KIND:   # a delta lobe's sample: its probability negated
                delta = pdf < 0.0
                pdf = abs(pdf)
            if not pdf > 1e-11 or (fr == 0.0 and fg == 0.0 and fb == 0.0):
                continue
            weight = abs(wiz) / pdf
            mr, mg, mb = fr * weight, fg * weight, fb * weight
            tr *= mr
            tg *= mg
            tb *= mb
            if options.roulette and vertex >= options.rr_depth:
                q = min(options.rr_cap, max(tr, tg, tb))
                if not sample_1d(options, pixel, sample, sample, base + DIM_RR,
                                 base + DIM_RR) < q:
                    continue
                tr /= q
                tg /= q
                tb /= q
            wx = wix * xx + wiy * yx + wiz * nx
            wy = wix * xy + wiy * yy + wiz * ny
            wz = wix * xz + wiy * yz + wiz * nz
            length = math.sqrt(wx * wx + wy * wy + wz * wz)
            dx, dy, dz = wx / length, wy / length, wz / length
            ox, oy, oz = spawn(px, py, pz, gx, gy, gz, offset, dx, dy, dz)
            floats[QX, i], floats[QY, i], floats[QZ, i] = px, py, pz
            floats[QNX, i], floats[QNY, i], floats[QNZ, i] = nx, ny, nz
            floats[OX, i], floats[OY, i], floats[OZ, i] = ox, oy, oz
            floats[DX, i], floats[DY, i], floats[DZ, i] = dx, dy, dz
            floats[TMIN, i], floats[TMAX, i] = 0.0, math.inf
            floats[TR, i], floats[TG, i], floats[TB, i] = tr, tg, tb
            floats[PDF, i] = pdf
            if GUIDED and mix > 0.0:
                # the MIS weights of the light samples and of this bounce's emission take the
                # BSDF's pdf (no guide lookup per light sample): the two weights still sum to 1,
                # and the bounce's estimate still divides by the mixture's pdf
                floats[PDF, i] = bsdf_pdf
            if GUIDED and guide.record:
                remember(history, depth, i, vertex, px, py, pz, dx, dy, dz, pdf, tr, tg, tb,
                         mr, mg, mb, bsdf_pdf, nx, ny, nz)
            ints[DELTA, i] = delta
            ints[KEY, i] = base
            ints[RAYS, i] += 1
            out[kept] = i
            kept += 1
        return shadows, kept

    _STAGES[key] = stage
    return stage
