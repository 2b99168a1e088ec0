"""Solid-angle sampling of a sphere from a point, beside its pdf: uniform over the cone of
directions the sphere subtends (as pbrt-v4's Sphere::Sample), and from inside the sphere uniform
over its area.

Separate from ptrace.solid_angle, which holds the flat shapes (rectangles and triangles) and the
spherical-polygon maps they share; a sphere's visible cone shares none of that, only the
conventions stated there (scalar float64 components, a density per unit solid angle, a pdf of 0
for no sample).
"""
import math

from numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True, _nrt=False, forceinline=True)
def sphere_sample(px, py, pz, cx, cy, cz, radius, u1, u2):
    """A point q of the sphere (centre c) seen from p: (qx, qy, qz, pdf), pdf per unit solid
    angle of the direction from p to q. From outside, uniform over the cone of directions the
    sphere subtends (q on its near side; pdf 1 / (2 pi (1 - cos theta_max))); from inside (or on
    it), uniform over its area, as lights.sample_emitter's (pdf distance^2 / (area cos)).
    pdf 0: no sample."""
    dx, dy, dz = cx - px, cy - py, cz - pz
    d2 = dx * dx + dy * dy + dz * dz
    r2 = radius * radius
    if d2 <= r2:
        nz = 1.0 - 2.0 * u1
        ring = math.sqrt(max(0.0, (1.0 - nz) * (1.0 + nz)))
        phi = TWO_PI * u2
        nx, ny = ring * math.cos(phi), ring * math.sin(phi)
        qx, qy, qz = cx + radius * nx, cy + radius * ny, cz + radius * nz
        wx, wy, wz = qx - px, qy - py, qz - pz
        dist2 = wx * wx + wy * wy + wz * wz
        cos_dist = abs(wx * nx + wy * ny + wz * nz)
        pdf = 0.0
        if cos_dist > 0.0 and r2 > 0.0:
            pdf = dist2 * math.sqrt(dist2) / (2.0 * TWO_PI * r2 * cos_dist)
        return qx, qy, qz, pdf
    s2 = r2 / d2                                         # sin^2 theta_max
    one_minus = s2 / (1.0 + math.sqrt(max(0.0, 1.0 - s2)))   # 1 - cos theta_max
    if one_minus == 0.0:
        return cx, cy, cz, 0.0
    d = math.sqrt(d2)
    zx, zy, zz = dx / d, dy / d, dz / d
    # an orthonormal frame about z (Duff et al. 2017)
    sign = math.copysign(1.0, zz)
    a = -1.0 / (sign + zz)
    b = zx * zy * a
    tx, ty, tz = 1.0 + sign * zx * zx * a, sign * b, -sign * zx
    bx, by, bz = b, sign + zy * zy * a, -zy
    # the direction's angle theta to the axis, and alpha, the angle at c from p's side to q
    f = u1 * one_minus
    cos_theta = 1.0 - f
    sin2_theta = f * (2.0 - f)
    sin_max = math.sqrt(s2)
    ratio = min(sin2_theta / s2, 1.0)
    root = math.sqrt(1.0 - ratio)
    cos_alpha = ratio * sin_max + cos_theta * root
    sin_alpha = math.sqrt(sin2_theta) * (cos_theta - sin_max * root) / sin_max
    phi = TWO_PI * u2
    ex, ey = sin_alpha * math.cos(phi), sin_alpha * math.sin(phi)
    nx = -(ex * tx + ey * bx + cos_alpha * zx)
    ny = -(ex * ty + ey * by + cos_alpha * zy)
    nz = -(ex * tz + ey * bz + cos_alpha * zz)
    return (cx + radius * nx, cy + radius * ny, cz + radius * nz,
            1.0 / (TWO_PI * one_minus))


@njit(cache=True, _nrt=False, forceinline=True)
def sphere_pdf(px, py, pz, cx, cy, cz, radius, wx, wy, wz):
    """Density per unit solid angle with which sphere_sample, from p, gives the unit direction w:
    0 if the ray p + t w (t > 0) misses the sphere."""
    dx, dy, dz = cx - px, cy - py, cz - pz
    d2 = dx * dx + dy * dy + dz * dz
    r2 = radius * radius
    along = wx * dx + wy * dy + wz * dz
    if d2 <= r2:
        if r2 == 0.0:
            return 0.0
        t = along + math.sqrt(max(0.0, along * along + (r2 - d2)))   # where the ray leaves
        hx, hy, hz = t * wx - dx, t * wy - dy, t * wz - dz         # from c to the exit
        cos_r = abs(hx * wx + hy * wy + hz * wz)                   # cos there times radius
        if cos_r == 0.0:
            return 0.0
        return t * t * radius / (2.0 * TWO_PI * r2 * cos_r)
    if not along > 0.0:
        return 0.0
    cx_, cy_, cz_ = dy * wz - dz * wy, dz * wx - dx * wz, dx * wy - dy * wx
    if cx_ * cx_ + cy_ * cy_ + cz_ * cz_ > r2:                      # passes the sphere by
        return 0.0
    s2 = r2 / d2
    one_minus = s2 / (1.0 + math.sqrt(max(0.0, 1.0 - s2)))
    return 1.0 / (TWO_PI * one_minus) if one_minus > 0.0 else 0.0
