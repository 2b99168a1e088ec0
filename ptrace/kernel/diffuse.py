"""The diffuse (Lambertian) material's shading kernel: at each queued vertex, -l light samples
of every area light (each a shadow ray in the wave's shadow queue, carrying the light it would
add, weighted by the power heuristic against the BSDF's sample with multiple importance
sampling), then the cosine-weighted bounce, roulette, and the next ray. The megakernel's
arithmetic (ptrace.integrator.direct_light and trace_path) for this kind and these lights,
with the same random-number keys."""
import math

from numba import njit

from ..bsdf import INV_PI, cosine_hemisphere
from ..integrator import (
    DIM_BSDF,
    DIM_LIGHT,
    DIM_RR,
    DIMS_PER_VERTEX,
    SHADOW_SHORTEN,
    frame,
    power_heuristic,
    sample_1d,
    sample_2d,
    spawn,
)
from ..solid_angle import rectangle_sample
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
    OX,
    OY,
    OZ,
    PDF,
    PIXEL,
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
)


@njit(cache=True, _nrt=False, forceinline=True)
def sample_area(lights, i, px, py, pz, u1, u2):
    """Area light i sampled from p by solid angle: (radiance, unit direction, distance, pdf),
    pdf 0 for a point behind the one-sided light (ptrace.lights.sample_light's rectangle)."""
    position, direction = lights.position, lights.direction
    edge_x, edge_y, radiance = lights.edge_x, lights.edge_y, lights.radiance
    if lights.area[i] <= 0.0 or ((position[i, 0] - px) * direction[i, 0]
                                 + (position[i, 1] - py) * direction[i, 1]
                                 + (position[i, 2] - pz) * direction[i, 2]) >= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
    qx, qy, qz, pdf = rectangle_sample(px, py, pz, position[i, 0], position[i, 1],
                                       position[i, 2], edge_x[i, 0], edge_x[i, 1],
                                       edge_x[i, 2], edge_y[i, 0], edge_y[i, 1],
                                       edge_y[i, 2], u1, u2)
    dx, dy, dz = qx - px, qy - py, qz - pz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dist == 0.0 or not pdf > 0.0:
        return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
    return radiance[i, 0], radiance[i, 1], radiance[i, 2], dx / dist, dy / dist, dz / dist, \
        dist, pdf


@njit(cache=True, nogil=True, _nrt=False)
def diffuse_stage(albedo, lights, options, mis, floats, ints, queue, n, shadow, shadow_path,
                  out):
    """Shade the queued diffuse vertices: their light samples go to the shadow queue (shadow,
    shadow_path), the paths that bounce to out with their next ray. Returns (shadow rays,
    paths that go on)."""
    light_count = lights.radiance.shape[0]
    samples = options.light_samples
    max_depth = options.max_depth
    shadows = 0
    kept = 0
    for k in range(n):
        i = queue[k]
        pixel, sample, vertex, m = ints[PIXEL, i], ints[SAMPLE, i], ints[VERTEX, i], ints[MAT, i]
        px, py, pz = floats[PX, i], floats[PY, i], floats[PZ, i]
        gx, gy, gz = floats[GX, i], floats[GY, i], floats[GZ, i]
        nx, ny, nz = floats[NX, i], floats[NY, i], floats[NZ, i]
        offset = floats[OFFSET, i]
        dx, dy, dz = floats[DX, i], floats[DY, i], floats[DZ, i]
        tr, tg, tb = floats[TR, i], floats[TG, i], floats[TB, i]
        xx, xy, xz, yx, yy, yz = frame(nx, ny, nz)
        woz = -dx * nx - dy * ny - dz * nz
        ar, ag, ab = albedo[m, 0], albedo[m, 1], albedo[m, 2]
        base = vertex * DIMS_PER_VERTEX
        rays = 0
        j = 0
        for light in range(light_count):
            for s in range(samples):
                index = sample * samples + s
                u1, u2 = sample_2d(options, pixel, sample, index, base + DIM_LIGHT + 2 * light,
                                   base + DIM_LIGHT + 2 * j)
                lr, lg, lb, wx, wy, wz, dist, pdf = sample_area(lights, light, px, py, pz, u1,
                                                                u2)
                j += 1
                if pdf < 1e-11:
                    continue
                wiz = wx * nx + wy * ny + wz * nz
                if wiz <= 0.0:
                    continue
                fr = fg = fb = 0.0
                if woz > 0.0 and wiz > 0.0:
                    fr, fg, fb = ar * INV_PI, ag * INV_PI, ab * INV_PI
                scale = wiz / (samples * pdf)
                if options.mis:
                    scale *= power_heuristic(samples * pdf, wiz * INV_PI if (
                        woz > 0.0 and wiz > 0.0) else 0.0)
                ox, oy, oz = spawn(px, py, pz, gx, gy, gz, offset, wx, wy, wz)
                # aim from the spawned origin at the light's point, stopping just short of it
                ax = px + dist * wx - ox
                ay = py + dist * wy - oy
                az = pz + dist * wz - oz
                length = math.sqrt(ax * ax + ay * ay + az * az)
                sdx, sdy, sdz = wx, wy, wz
                if length > 0.0:
                    sdx, sdy, sdz = ax / length, ay / length, az / length
                rays += 1
                shadow[SOX, shadows], shadow[SOY, shadows], shadow[SOZ, shadows] = ox, oy, oz
                shadow[SDX, shadows], shadow[SDY, shadows], shadow[SDZ, shadows] = sdx, sdy, sdz
                shadow[STMAX, shadows] = length * (1.0 - SHADOW_SHORTEN)
                shadow[SR, shadows] = tr * (lr * fr * scale)
                shadow[SG, shadows] = tg * (lg * fg * scale)
                shadow[SB, shadows] = tb * (lb * fb * scale)
                shadow_path[shadows] = i
                shadows += 1
        ints[RAYS, i] += rays
        if vertex == max_depth and not mis:
            continue
        u1, u2 = sample_2d(options, pixel, sample, sample, base + DIM_BSDF, base + DIM_BSDF)
        if woz <= 0.0:
            continue
        wix, wiy, wiz = cosine_hemisphere(u1, u2)
        if wiz <= 0.0:
            continue
        fr, fg, fb, pdf = ar * INV_PI, ag * INV_PI, ab * INV_PI, wiz * INV_PI
        if not pdf > 1e-11 or (fr == 0.0 and fg == 0.0 and fb == 0.0):
            continue
        weight = abs(wiz) / pdf
        tr *= fr * weight
        tg *= fg * weight
        tb *= fb * weight
        if options.roulette and vertex >= options.rr_depth:
            q = min(options.rr_cap, max(tr, tg, tb))
            if not sample_1d(options, pixel, sample, sample, base + DIM_RR, base + DIM_RR) < q:
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
        ints[RAYS, i] += 1
        out[kept] = i
        kept += 1
    return shadows, kept
