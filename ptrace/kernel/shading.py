"""One shading kernel per material kind, made on demand (shading_stage(kind)) and compiled only for
the kinds a scene has: at each queued vertex, the light samples the light stage took there
(ptrace.kernel.lighting; none for a delta kind) weighed by the kind's BSDF, with the power
heuristic against the BSDF's sample (multiple importance sampling), then the BSDF's sample,
roulette, and the next ray. A kernel calls its own kind's BSDF functions (ptrace.bsdf.BSDFS),
so no other kind's code is compiled into it, and no code of the general lights: that is the
light stage's, compiled once for every kind. A scene of area lights alone and untextured
surfaces has no light stage: its kernels sample the area lights themselves, in the same pass.
Random numbers are keyed by (pixel, sample, dimension), with the dimensions of
ptrace.integrator's layout (DIM_*, RAY_KEYS)."""
import math

from numba import njit

from ..bsdf import BSDFS, EXACT_GLASS, MIXED, is_delta, uniform_hemisphere
from ..emitters import EMITTER
from ..integrator import (
    DIM_BSDF,
    DIM_GLASS,
    DIM_LIGHT,
    DIM_RR,
    DIMS_PER_VERTEX,
    RAY_KEYS,
    frame,
    power_heuristic,
    sample_1d,
    sample_2d,
    spawn,
)
from ..lights import sample_area_row
from ..scene import GLASS, GLOSSY, GLTF_PBR, ROUGH_PLASTIC
from ..textures import surface_albedo
from .guide import guide_node, guide_pdf, guide_sample, guide_turn, normal_bucket, remember
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
    SCOUNT,
    SFIRST,
    SG,
    SLPDF,
    SR,
    SSCALE,
    SWX,
    SWY,
    SWZ,
    TB,
    TG,
    TMAX,
    TMIN,
    TR,
    VERTEX,
    U,
    V,
)
from .lighting import queue_ray, shadow_ray

_STAGES = {}


def shading_stage(kind, general=False, hemisphere=False, guided=False, exact=False):
    """The shading kernel of material kind `kind` (one of ptrace.scene's BSDF codes but
    EMISSION), made once per process and cached on disk per kind:

        shadows, kept = stage(shapes, materials, lights, options, mis, floats, ints, queue, n,
                              shadow, shadow_path, shadow_key, shadows, out, kept, guide,
                              history, depth)

    shades the n queued vertices, whose light samples the light stage has queued (the shadow
    rows each vertex's SFIRST and SCOUNT name: each row's light is multiplied by the BSDF, its
    MIS weight and the path's throughput), and appends the paths that bounce to out from `kept`
    on; returns the shadow queue's count and the new kept count. Without `general` the lights
    are area lights and the surfaces untextured (wavefront.AreaLights and SurfaceArrays), and the
    kernel takes -l samples of each area light itself, appending them to the shadow queue from
    row `shadows` on (there is no light stage); with it, textured albedo, roughness and metallic
    from the full records (shapes, materials, lights). With `hemisphere` (-H, which needs
    `general`), it appends to the shadow queue, from row `shadows` on, the course's uniform
    hemisphere rays instead: -l for each light that is not emissive geometry (at least -l),
    each carrying f cos / (pdf n) times the throughput, the weight of the emission it will find
    (stages.probe_found_stage).

    With `guided` (a kind that is not delta, without -H), the bounce is drawn from the guide
    (ptrace.kernel.guide.GuideArrays), turned by its spatial leaf's parallax frame at the
    vertex (one below the surface gets nothing: every such kind only reflects), with
    probability guide.alpha x guide.share of the vertex's spatial leaf (the first bounce
    sample's u1 split at it) and from the BSDF otherwise, and weighted by the mixture's pdf;
    the MIS weights between the light samples and the bounce's emission take the BSDF's pdf
    alone (no guide lookup per light sample); guide.alpha 0 skips the guide, and so does the
    last vertex (-m), whose bounce only finds direct light, which the guide does not learn.
    With guide.record set, each bounce but the last vertex's is remembered in `history` (its
    first `depth` vertices) for the guide's records. Without it, guide, history and depth are
    not read.

    With `exact`, a GLASS kind reflects with the exact Fresnel reflectance
    (ptrace.bsdf.EXACT_GLASS), not Schlick's."""
    exact = bool(exact) and kind == GLASS
    DELTA_KIND = bool(getattr(is_delta, "py_func", is_delta)(kind))   # (NUMBA_DISABLE_JIT)
    MIXED_KIND = kind in MIXED    # a delta lobe beside a non-delta one (ptrace.bsdf.MIXED)
    hemisphere = bool(hemisphere) and not DELTA_KIND   # (a delta kind takes no light samples)
    guided = bool(guided) and not DELTA_KIND and not MIXED_KIND and not hemisphere
    # the key names the code: setups whose difference the code does not read share a kernel
    key = (kind, general, hemisphere, guided, exact)
    if key in _STAGES:
        return _STAGES[key]
    # this kind's alone: no other compiles
    BSDF_SAMPLE, BSDF_EVAL, BSDF_PDF = EXACT_GLASS if exact else BSDFS[kind]
    GENERAL, HEMI, GUIDED = general, hemisphere, guided
    LOBES = kind in (GLASS, GLOSSY, GLTF_PBR, ROUGH_PLASTIC) or MIXED_KIND   # one more number
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
            if GENERAL:     # textures: the albedo, roughness and metallic (the normal is bent)
                ar, ag, ab, alpha, metallic = surface_albedo(shapes, materials, m, ints[PRIM, i],
                                                             floats[U, i], floats[V, i])
            else:
                ar, ag, ab = (materials.albedo[m, 0], materials.albedo[m, 1],
                              materials.albedo[m, 2])
                alpha, metallic = materials.alpha[m], materials.metallic[m]
            base = vertex * DIMS_PER_VERTEX
            rays = 0
            mix = 0.0
            leaf = 0
            vx = vy = vz = 0.0
            vc = 1.0
            # (alpha 0: the guide is off, and skipped; at the last vertex the bounce only finds
            # direct light, which the guide does not learn: the BSDF alone, nothing recorded)
            if GUIDED and guide.alpha > 0.0 and vertex < max_depth:
                node = guide_node(guide.axis, guide.split, guide.child, px, py, pz,
                                  normal_bucket(nx, ny, nz))
                leaf = guide.root[node]
                mix = guide.alpha * guide.share[leaf]
                vx, vy, vz, vc = guide_turn(guide, node, px, py, pz)   # (its parallax frame)
            if LIT and HEMI and light_count:    # -H: the course's uniform hemisphere sampling
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
            elif LIT and not GENERAL:   # area lights alone: -l samples of each, taken here
                j = 0
                for light in range(light_count):
                    for s in range(samples):
                        index = sample * samples + s
                        u1, u2 = sample_2d(options, pixel, sample, index,
                                           base + DIM_LIGHT + 2 * light, base + DIM_LIGHT + 2 * j)
                        lr, lg, lb, wx, wy, wz, dist, pdf = sample_area_row(lights, light, px, py,
                                                                            pz, u1, u2)
                        j += 1
                        if pdf < 1e-11:
                            continue
                        wiz = wx * nx + wy * ny + wz * nz
                        if wiz <= 0.0:
                            continue
                        wix = wx * xx + wy * xy + wz * xz
                        wiy = wx * yx + wy * yy + wz * yz
                        fr, fg, fb = BSDF_EVAL(ar, ag, ab, alpha, metallic, materials.eta,
                                               materials.k, materials.specular, m, wox, woy, woz,
                                               wix, wiy, wiz)
                        scale = wiz / (samples * pdf)
                        if options.mis:
                            other = BSDF_PDF(ar, ag, ab, alpha, metallic, materials.eta,
                                             materials.k, materials.specular, m, wox, woy, woz,
                                             wix, wiy, wiz)
                            scale *= power_heuristic(samples * pdf, other)
                        ox, oy, oz, sdx, sdy, sdz, tmax = shadow_ray(px, py, pz, gx, gy, gz,
                                                                     offset, wx, wy, wz, dist)
                        rays += 1
                        queue_ray(shadow, shadow_path, shadow_key, shadows, ox, oy, oz, sdx, sdy,
                                  sdz, tmax, tr * (lr * fr * scale), tg * (lg * fg * scale),
                                  tb * (lb * fb * scale), i, base + RAY_KEYS * j)
                        shadows += 1
            elif LIT:   # the light samples the light stage took here, weighed by the BSDF
                first = ints[SFIRST, i]
                for s in range(first, first + ints[SCOUNT, i]):
                    wx, wy, wz = shadow[SWX, s], shadow[SWY, s], shadow[SWZ, s]
                    wiz = wx * nx + wy * ny + wz * nz
                    wix = wx * xx + wy * xy + wz * xz
                    wiy = wx * yx + wy * yy + wz * yz
                    fr, fg, fb = BSDF_EVAL(ar, ag, ab, alpha, metallic, materials.eta,
                                           materials.k, materials.specular, m, wox, woy, woz,
                                           wix, wiy, wiz)
                    scale = shadow[SSCALE, s]
                    light_pdf = shadow[SLPDF, s]
                    if options.mis and light_pdf > 0.0:   # (a delta light's is negative)
                        other = BSDF_PDF(ar, ag, ab, alpha, metallic, materials.eta,
                                         materials.k, materials.specular, m, wox, woy, woz,
                                         wix, wiy, wiz)
                        scale *= power_heuristic(light_pdf, other)
                    shadow[SR, s] = tr * (shadow[SR, s] * fr * scale)
                    shadow[SG, s] = tg * (shadow[SG, s] * fg * scale)
                    shadow[SB, s] = tb * (shadow[SB, s] * fb * scale)
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
                wx, wy, wz, guided_pdf = guide_sample(guide, leaf, u1, u2, vx, vy, vz, vc)
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
                    pdf = (1.0 - mix) * pdf + mix * guide_pdf(guide, leaf, wx / length,
                                                              wy / length, wz / length, vx, vy,
                                                              vz, vc)
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
            if options.roulette and vertex >= options.rr_depth and not (
                    delta and vertex == max_depth):
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
            if GUIDED and guide.record and vertex < max_depth:
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
