"""The path integrator as wavefront passes: numba kernels over arrays of paths, with every ray
batch going through the accelerator (intersect for camera and bounce rays, occluded for shadow
rays). The estimator is CS184.md 4.5-4.6 with the departures listed in the README.

Per wave: emission seen by camera rays; then at each of up to max_depth vertices: direct light
(light sampling, or uniform hemisphere sampling with -H) unless the BSDF is delta; a BSDF sample;
Russian roulette from the second bounce on; the bounce ray; emission seen through a delta bounce.
"""
import math

import numpy as np
from numba import njit, prange


from .bsdf import bsdf_eval, bsdf_sample, is_delta, uniform_hemisphere
from .lights import light_is_delta, sample_light
from .sampling import uniform
from .scene import EMISSION, GLASS, REFRACTION

OFFSET = 1e-6           # spawn offset, relative to the hit point's (and primitive's) magnitude
SHADOW_SHORTEN = 1e-6   # shadow rays stop this fraction short of the light sample
RR_CAP = 0.95           # Russian roulette continuation probability: min(RR_CAP, max(throughput))
DIMS_PER_VERTEX = 1 << 24
DIM_BSDF, DIM_GLASS, DIM_RR, DIM_LIGHT = 0, 2, 3, 8


def primitive_scale(geometry):
    """Largest absolute coordinate of each primitive: the magnitude its hit points carry."""
    corners = np.abs(geometry.vertices[geometry.faces]).max(axis=(1, 2)) if geometry.triangle_count \
        else np.zeros(0)
    spheres = np.abs(geometry.centers).max(axis=1, initial=0.0) + geometry.radii
    return np.ascontiguousarray(np.concatenate([corners, spheres]))


@njit(cache=True, inline="always")
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
def local_frame(normal, directions, i):
    """The shading frame at path i (x, y axes; z = normal) and wo = -direction in it."""
    nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
    xx, xy, xz, yx, yy, yz = frame(nx, ny, nz)
    dx, dy, dz = -directions[i, 0], -directions[i, 1], -directions[i, 2]
    return (xx, xy, xz, yx, yy, yz, nx, ny, nz, dx * xx + dy * xy + dz * xz,
            dx * yx + dy * yy + dz * yz, dx * nx + dy * ny + dz * nz)


@njit(cache=True, parallel=True)
def surfaces(vertices, faces, centers, radii, vertex_normals, material_index, kinds, scale,
             origins, directions, t, prim, u, v, point, geo_normal, normal, material, offset):
    """Hit point (barycentric for triangles, projected onto spheres), geometric and shading
    normals, material and spawn offset of every hit. Opaque surfaces are two-sided: both
    normals are turned toward the side the ray came from. Glass and refraction keep the outward
    normal so that wo.z tells inside from outside."""
    n_tri = faces.shape[0]
    for i in prange(t.shape[0]):
        p = prim[i]
        if p < 0:
            material[i] = -1
            continue
        if p < n_tri:
            a, b, c = faces[p, 0], faces[p, 1], faces[p, 2]
            w = 1.0 - u[i] - v[i]
            for k in range(3):
                point[i, k] = w * vertices[a, k] + u[i] * vertices[b, k] + v[i] * vertices[c, k]
                normal[i, k] = (w * vertex_normals[a, k] + u[i] * vertex_normals[b, k]
                                + v[i] * vertex_normals[c, k])
            e1x, e1y, e1z = (vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1],
                             vertices[b, 2] - vertices[a, 2])
            e2x, e2y, e2z = (vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1],
                             vertices[c, 2] - vertices[a, 2])
            gx, gy, gz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        else:
            s = p - n_tri
            for k in range(3):
                normal[i, k] = origins[i, k] + t[i] * directions[i, k] - centers[s, k]
            length = math.sqrt(normal[i, 0] ** 2 + normal[i, 1] ** 2 + normal[i, 2] ** 2)
            for k in range(3):
                normal[i, k] /= length
                point[i, k] = centers[s, k] + radii[s] * normal[i, k]
            gx, gy, gz = normal[i, 0], normal[i, 1], normal[i, 2]
        g_len = math.sqrt(gx * gx + gy * gy + gz * gz)
        s_len = math.sqrt(normal[i, 0] ** 2 + normal[i, 1] ** 2 + normal[i, 2] ** 2)
        if g_len == 0.0:
            material[i] = -1   # a zero-area triangle: nothing to shade
            continue
        gx, gy, gz = gx / g_len, gy / g_len, gz / g_len
        if s_len == 0.0:
            normal[i, 0], normal[i, 1], normal[i, 2] = gx, gy, gz
            s_len = 1.0
        # shading normal on the geometric normal's side
        sign = 1.0 if normal[i, 0] * gx + normal[i, 1] * gy + normal[i, 2] * gz >= 0.0 else -1.0
        m = material_index[p]
        kind = kinds[m]
        if kind != GLASS and kind != REFRACTION:
            if gx * directions[i, 0] + gy * directions[i, 1] + gz * directions[i, 2] > 0.0:
                gx, gy, gz = -gx, -gy, -gz   # face the incoming ray
                sign = -sign
        geo_normal[i, 0], geo_normal[i, 1], geo_normal[i, 2] = gx, gy, gz
        for k in range(3):
            normal[i, k] *= sign / s_len
        material[i] = m
        magnitude = max(abs(point[i, 0]), abs(point[i, 1]), abs(point[i, 2]), scale[p])
        offset[i] = OFFSET * magnitude


@njit(cache=True, parallel=True)
def add_emission(material, kinds, emission, throughput, mask, radiance):
    """radiance += throughput * Le for paths in mask that hit an emitter (both sides emit)."""
    for i in prange(material.shape[0]):
        m = material[i]
        if mask[i] and m >= 0 and kinds[m] == EMISSION:
            for k in range(3):
                radiance[i, k] += throughput[i, k] * emission[m, k]


@njit(cache=True, inline="always")
def spawn(point, geo_normal, offset, i, wx, wy, wz):
    """Offset the origin along the geometric normal, on the side of the new direction."""
    side = 1.0 if wx * geo_normal[i, 0] + wy * geo_normal[i, 1] + wz * geo_normal[i, 2] >= 0.0 \
        else -1.0
    e = side * offset[i]
    return (point[i, 0] + e * geo_normal[i, 0], point[i, 1] + e * geo_normal[i, 1],
            point[i, 2] + e * geo_normal[i, 2])


@njit(cache=True, parallel=True)
def light_samples(seed, vertex, pixel, sample, directions, point, geo_normal, normal, material,
                  offset, alive, kinds, albedo, alpha, eta, k_cond, light_kind, light_radiance,
                  light_position, light_direction, light_edge_x, light_edge_y, light_area,
                  light_samples_per_area, samples_per_path, out_origin, out_direction, out_tmax,
                  out_weight):
    """One shadow ray per light sample per path: weight = L f cos / (n pdf), the per-light
    average summed over lights (CS184.md 4.5). A sample that cannot contribute gets weight 0 and
    an empty interval (tmax = -1) so the accelerator rejects it at once."""
    n_lights = light_kind.shape[0]
    for i in prange(material.shape[0]):
        m = material[i]
        usable = alive[i] and m >= 0 and not is_delta(kinds[m]) and kinds[m] != EMISSION
        # Defined on every path: inside a prange body a variable assigned only under `if`
        # compiled to an undefined value that LLVM was free to replace, so the frame the
        # microfacet BSDF saw (wo) depended on what else had been compiled first.
        xx = xy = xz = yx = yy = yz = nx = ny = nz = wox = woy = woz = 0.0
        if usable:
            xx, xy, xz, yx, yy, yz, nx, ny, nz, wox, woy, woz = local_frame(normal, directions, i)
        j = 0
        for light in range(n_lights):
            count = 1 if light_is_delta(light_kind[light]) else light_samples_per_area
            for s in range(count):
                r = i * samples_per_path + j
                j += 1
                out_weight[r, 0] = 0.0
                out_weight[r, 1] = 0.0
                out_weight[r, 2] = 0.0
                out_tmax[r] = -1.0
                out_origin[r, 0] = 0.0
                out_origin[r, 1] = 0.0
                out_origin[r, 2] = 0.0
                out_direction[r, 0] = 0.0
                out_direction[r, 1] = 0.0
                out_direction[r, 2] = 1.0
                if not usable:
                    continue
                dim = vertex * DIMS_PER_VERTEX + DIM_LIGHT + 2 * (j - 1)
                u1 = uniform(seed, pixel[i], sample[i], dim)
                u2 = uniform(seed, pixel[i], sample[i], dim + 1)
                lr, lg, lb, wx, wy, wz, dist, pdf = sample_light(
                    light_kind[light], light_radiance, light_position, light_direction,
                    light_edge_x, light_edge_y, light_area, light, point[i, 0], point[i, 1],
                    point[i, 2], u1, u2)
                if pdf < 1e-11:
                    continue
                wiz = wx * nx + wy * ny + wz * nz
                if wiz <= 0.0:
                    continue
                wix = wx * xx + wy * xy + wz * xz
                wiy = wx * yx + wy * yy + wz * yz
                fr, fg, fb = bsdf_eval(kinds[m], albedo, alpha, eta, k_cond, m, wox, woy, woz,
                                       wix, wiy, wiz)
                scale = wiz / (count * pdf)
                out_weight[r, 0] = lr * fr * scale
                out_weight[r, 1] = lg * fg * scale
                out_weight[r, 2] = lb * fb * scale
                ox, oy, oz = spawn(point, geo_normal, offset, i, wx, wy, wz)
                out_origin[r, 0], out_origin[r, 1], out_origin[r, 2] = ox, oy, oz
                if dist == math.inf:   # directional light
                    out_direction[r, 0], out_direction[r, 1], out_direction[r, 2] = wx, wy, wz
                    out_tmax[r] = math.inf
                else:
                    # aim from the spawned origin at the light's point and stop just short of
                    # it: measured from the shading point instead, the spawn offset could carry
                    # the ray's end past the light onto an emitter lying on it
                    dx = point[i, 0] + dist * wx - ox
                    dy = point[i, 1] + dist * wy - oy
                    dz = point[i, 2] + dist * wz - oz
                    length = math.sqrt(dx * dx + dy * dy + dz * dz)
                    if length > 0.0:
                        out_direction[r, 0] = dx / length
                        out_direction[r, 1] = dy / length
                        out_direction[r, 2] = dz / length
                    else:   # the light sits at the origin: nothing can be in between
                        out_direction[r, 0], out_direction[r, 1], out_direction[r, 2] = wx, wy, wz
                    out_tmax[r] = length * (1.0 - SHADOW_SHORTEN)


@njit(cache=True, parallel=True)
def hemisphere_samples(seed, vertex, pixel, sample, directions, point, geo_normal, normal,
                       material, offset, alive, kinds, albedo, alpha, eta, k_cond,
                       samples_per_path, out_origin, out_direction, out_tmax, out_weight):
    """-H: samples_per_path uniform hemisphere rays per path, weight f cos / (pdf N); the
    caller multiplies by the emission the ray finds (CS184.md 4.5)."""
    for i in prange(material.shape[0]):
        m = material[i]
        usable = alive[i] and m >= 0 and not is_delta(kinds[m]) and kinds[m] != EMISSION
        # defined on every path, as in light_samples
        xx = xy = xz = yx = yy = yz = nx = ny = nz = wox = woy = woz = 0.0
        if usable:
            xx, xy, xz, yx, yy, yz, nx, ny, nz, wox, woy, woz = local_frame(normal, directions, i)
        for j in range(samples_per_path):
            r = i * samples_per_path + j
            for k in range(3):
                out_weight[r, k] = 0.0
                out_origin[r, k] = 0.0
                out_direction[r, k] = 0.0
            out_direction[r, 2] = 1.0
            out_tmax[r] = -1.0
            if not usable:
                continue
            dim = vertex * DIMS_PER_VERTEX + DIM_LIGHT + 2 * j
            lx, ly, lz = uniform_hemisphere(uniform(seed, pixel[i], sample[i], dim),
                                            uniform(seed, pixel[i], sample[i], dim + 1))
            fr, fg, fb = bsdf_eval(kinds[m], albedo, alpha, eta, k_cond, m, wox, woy, woz,
                                   lx, ly, lz)
            scale = lz * 2.0 * math.pi / samples_per_path
            wx = lx * xx + ly * yx + lz * nx
            wy = lx * xy + ly * yy + lz * ny
            wz = lx * xz + ly * yz + lz * nz
            out_weight[r, 0], out_weight[r, 1], out_weight[r, 2] = fr * scale, fg * scale, fb * scale
            ox, oy, oz = spawn(point, geo_normal, offset, i, wx, wy, wz)
            out_origin[r, 0], out_origin[r, 1], out_origin[r, 2] = ox, oy, oz
            out_direction[r, 0], out_direction[r, 1], out_direction[r, 2] = wx, wy, wz
            out_tmax[r] = math.inf


@njit(cache=True, parallel=True)
def gather(weight, visible, emission_kind, material_of_ray, kinds, emission, samples_per_path,
           throughput, radiance):
    """radiance[i] += throughput[i] * sum over its samples of weight * (1 or Le of the hit).

    visible[r] says whether sample r counts (a shadow ray that was not occluded); with
    emission_kind the weight is also multiplied by the emission of the primitive ray r hit."""
    for i in prange(throughput.shape[0]):
        for j in range(samples_per_path):
            r = i * samples_per_path + j
            if not visible[r]:
                continue
            if emission_kind:
                m = material_of_ray[r]
                if m < 0 or kinds[m] != EMISSION:
                    continue
                for k in range(3):
                    radiance[i, k] += throughput[i, k] * weight[r, k] * emission[m, k]
            else:
                for k in range(3):
                    radiance[i, k] += throughput[i, k] * weight[r, k]


@njit(cache=True, parallel=True)
def bounce(seed, vertex, pixel, sample, directions, point, geo_normal, normal, material,
           offset, alive, kinds, albedo, transmittance, ior, alpha, eta, k_cond, throughput,
           roulette, out_origin, out_direction, out_delta):
    """Sample each live path's BSDF, update its throughput (Russian roulette from the second
    bounce on: continue with q = min(RR_CAP, max throughput), divide by q) and write the bounce
    ray. Paths that stop are marked dead."""
    for i in prange(material.shape[0]):
        m = material[i]
        if not alive[i] or m < 0:
            alive[i] = False
            continue
        xx, xy, xz, yx, yy, yz, nx, ny, nz, wox, woy, woz = local_frame(normal, directions, i)
        base = vertex * DIMS_PER_VERTEX
        u1 = uniform(seed, pixel[i], sample[i], base + DIM_BSDF)
        u2 = uniform(seed, pixel[i], sample[i], base + DIM_BSDF + 1)
        u3 = uniform(seed, pixel[i], sample[i], base + DIM_GLASS)
        wix, wiy, wiz, fr, fg, fb, pdf = bsdf_sample(kinds[m], albedo, transmittance, ior,
                                                     alpha, eta, k_cond, m, wox, woy, woz,
                                                     u1, u2, u3)
        if not pdf > 1e-11 or (fr == 0.0 and fg == 0.0 and fb == 0.0):
            alive[i] = False
            continue
        weight = abs(wiz) / pdf
        throughput[i, 0] *= fr * weight
        throughput[i, 1] *= fg * weight
        throughput[i, 2] *= fb * weight
        if roulette:
            q = min(RR_CAP, max(throughput[i, 0], throughput[i, 1], throughput[i, 2]))
            if not uniform(seed, pixel[i], sample[i], base + DIM_RR) < q:
                alive[i] = False
                continue
            for k in range(3):
                throughput[i, k] /= q
        wx = wix * xx + wiy * yx + wiz * nx
        wy = wix * xy + wiy * yy + wiz * ny
        wz = wix * xz + wiy * yz + wiz * nz
        length = math.sqrt(wx * wx + wy * wy + wz * wz)
        wx, wy, wz = wx / length, wy / length, wz / length
        ox, oy, oz = spawn(point, geo_normal, offset, i, wx, wy, wz)
        out_origin[i, 0], out_origin[i, 1], out_origin[i, 2] = ox, oy, oz
        out_direction[i, 0], out_direction[i, 1], out_direction[i, 2] = wx, wy, wz
        out_delta[i] = is_delta(kinds[m])


@njit(cache=True)
def retire_and_compact(alive, owner, pixel, sample, throughput, radiance, delta, origins,
                       directions, out, keep_owner, keep_pixel, keep_sample, keep_throughput,
                       keep_radiance, keep_delta, keep_origins, keep_directions):
    """Add each finished path's radiance to out[owner] (its radiance is final) and copy the live
    paths' state, in order, to the keep_* arrays; return how many live. One serial pass instead
    of a dozen numpy gathers over the wave: at 2^16 paths those cost more than the kernels."""
    j = 0
    for i in range(alive.shape[0]):
        if not alive[i]:
            for c in range(3):
                out[owner[i], c] += radiance[i, c]
            continue
        keep_owner[j] = owner[i]
        keep_pixel[j] = pixel[i]
        keep_sample[j] = sample[i]
        keep_delta[j] = delta[i]
        for c in range(3):
            keep_throughput[j, c] = throughput[i, c]
            keep_radiance[j, c] = radiance[i, c]
            keep_origins[j, c] = origins[i, c]
            keep_directions[j, c] = directions[i, c]
        j += 1
    return j
