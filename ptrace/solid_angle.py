"""Solid-angle sampling of a light's shape as seen from a point, each sampler beside its pdf.

From a shading point p, a sampler picks a point q of the shape so that the direction from p to q
is uniform over the solid angle the shape subtends, and returns q and that direction's density
per unit solid angle. The matching *_pdf function gives the density of a unit direction from p (0
if it misses the shape) from the same computation and the same choice of technique, so that
multiple importance sampling weighs a BSDF-sampled ray that finds the shape by the density the
light sampler would have given it.

- Rectangles: Urena, Fajardo and King 2013, "An Area-Preserving Parametrization for Spherical
  Rectangles".
- Triangles: Arvo 1995, "Stratified Sampling of Spherical Triangles", with his q rewritten so
  that 1 - q, and the arcs from A and from B, come without cancelling.
- Spheres: uniform over the cone of directions the sphere subtends (as pbrt-v4's Sphere::Sample);
  from inside the sphere, uniform over its area. They live in ptrace.solid_angle_sphere.

Solid angles come from Van Oosterom and Strackee's formula (tan of half a triangle's solid angle
from a triple product), which keeps its relative precision for tiny and distant shapes, where a
spherical polygon's angle sum less (n - 2) pi cancels. The rectangle's map still loses precision
for tiny solid angles and when seen nearly edge-on (it takes 1 - cos^2 of grazing angles); the
thresholds below were set where
its samples, measured against an exact evaluation of the same map, stay within a millionth of the
rectangle's size (the triangle's rewritten map stayed at float64's limit for storing the point
down to the smallest solid angles measured). Past them a shape is sampled uniformly by area, its
density converted to solid angle; there the two densities differ little.

Shapes are geometric and two-sided here: a direction's density does not depend on which face it
meets (one-sided lights are the caller's to cull). Points and vectors are scalar float64
components; a returned pdf of 0 means no sample (a degenerate shape, or one seen edge-on).
"""
import math

import numpy as np
from numba import njit

from .trig import sincos

# Below these solid angles (steradians) the spherical maps give way to area sampling ...
RECTANGLE_MIN_SOLID_ANGLE = 1e-9
TRIANGLE_MIN_SOLID_ANGLE = 1e-18
# ... and so does a rectangle seen so nearly edge-on that its nearest point lies farther from p's
# foot on its plane than sqrt(RECTANGLE_MAX_GRAZING) times p's distance to that plane, or a
# parallelogram whose edges' cosine exceeds RIGHT_ANGLE_TOLERANCE (the map needs a right angle).
RECTANGLE_MAX_GRAZING = 1e8
RIGHT_ANGLE_TOLERANCE = 1e-7
TWO_PI = 2.0 * math.pi
_PRODUCTS_LOW, _PRODUCTS_HIGH = 1e-140, 1e140   # where the solid angle's products are normal


@njit(cache=True, inline="always")
def _clamp(x, lo, hi):
    return min(max(x, lo), hi)


# -- rectangles ------------------------------------------------------------------------------------

@njit(cache=True, _nrt=False, forceinline=True)
def rectangle_axes(cx, cy, cz, exx, exy, exz, eyx, eyy, eyz):
    """The part of _rectangle_frame that does not depend on p (a light's own, computed once per
    render by rectangle_axes_table): unit axes x, y, z (z the plane's normal, e_x x e_y),
    exl, eyx_, eyl, area, whether it has a right angle (1.0 or 0.0), and the corner
    k = c - e_x/2 - e_y/2; area 0 for a degenerate parallelogram."""
    exl = math.sqrt(exx * exx + exy * exy + exz * exz)
    nx, ny, nz = exy * eyz - exz * eyy, exz * eyx - exx * eyz, exx * eyy - exy * eyx
    area = math.sqrt(nx * nx + ny * ny + nz * nz)
    if area == 0.0:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0)
    xx, xy, xz = exx / exl, exy / exl, exz / exl
    zx, zy, zz = nx / area, ny / area, nz / area
    yx, yy, yz = zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx
    eyx_ = eyx * xx + eyy * xy + eyz * xz
    eyl = area / exl
    right = abs(eyx_) <= RIGHT_ANGLE_TOLERANCE * math.sqrt(eyx_ * eyx_ + eyl * eyl)
    return (xx, xy, xz, yx, yy, yz, zx, zy, zz, exl, eyx_, eyl, area, 1.0 if right else 0.0,
            cx - 0.5 * (exx + eyx), cy - 0.5 * (exy + eyy), cz - 0.5 * (exz + eyz))


RECTANGLE_AXES = 17     # rectangle_axes' values, a row of rectangle_axes_table


@njit(cache=True)
def rectangle_axes_table(position, edge_x, edge_y):
    """rectangle_axes of each rectangle c + s e_x + t e_y (rows of position, edge_x, edge_y):
    an (n, RECTANGLE_AXES) array."""
    out = np.zeros((position.shape[0], RECTANGLE_AXES))
    for i in range(position.shape[0]):
        values = rectangle_axes(position[i, 0], position[i, 1], position[i, 2], edge_x[i, 0],
                                edge_x[i, 1], edge_x[i, 2], edge_y[i, 0], edge_y[i, 1],
                                edge_y[i, 2])
        for j in range(RECTANGLE_AXES):
            out[i, j] = values[j]
    return out


@njit(cache=True, inline="always")
def _rectangle_frame(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz):
    """The parallelogram c + s e_x + t e_y (|s|, |t| <= 1/2) in a frame at p: unit axes x (along
    e_x), y (in the plane, normal to x) and z (normal to the plane, pointing from the plane's side
    away from p, so that the plane lies at z = z0 <= 0); the corner c - e_x/2 - e_y/2 at (x0, y0,
    z0); e_x = (exl, 0, 0) and e_y = (eyx_, eyl, 0) in the frame; area; solid angle (that of the
    rectangle [x0, x0 + exl] x [y0, y0 + eyl], the parallelogram itself when it has a right
    angle); the corner's distance; and whether to sample it by solid angle (a right angle, a
    solid angle of at least RECTANGLE_MIN_SOLID_ANGLE, and not too grazing)."""
    (xx, xy, xz, yx, yy, yz, zx, zy, zz, exl, eyx_, eyl, area, right, kx, ky,
     kz) = rectangle_axes(cx, cy, cz, exx, exy, exz, eyx, eyy, eyz)
    return _rectangle_at(px, py, pz, xx, xy, xz, yx, yy, yz, zx, zy, zz, exl, eyx_, eyl, area,
                         right, kx, ky, kz)


@njit(cache=True, _nrt=False, forceinline=True)
def _rectangle_at(px, py, pz, xx, xy, xz, yx, yy, yz, zx, zy, zz, exl, eyx_, eyl, area, right,
                  kx, ky, kz):
    """_rectangle_frame from the rectangle's axes (rectangle_axes)."""
    if area == 0.0:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, 0.0, False)
    sx = kx - px
    sy = ky - py
    sz = kz - pz
    x0, y0, z0 = (sx * xx + sy * xy + sz * xz, sx * yx + sy * yy + sz * yz,
                  sx * zx + sy * zy + sz * zz)
    if z0 > 0.0:
        zx, zy, zz, z0 = -zx, -zy, -zz, -z0
    x1, y1 = x0 + exl, y0 + eyl
    # two triangles, (v00, v10, v11) and (v00, v11, v01), each with |triple product| -z0 exl eyl
    w = z0 * z0
    l00 = math.sqrt(x0 * x0 + y0 * y0 + w)
    l10 = math.sqrt(x1 * x1 + y0 * y0 + w)
    l11 = math.sqrt(x1 * x1 + y1 * y1 + w)
    l01 = math.sqrt(x0 * x0 + y1 * y1 + w)
    triple = -z0 * exl * eyl
    omega = 0.0
    spherical = False
    if triple > 0.0:
        d00_11 = x0 * x1 + y0 * y1 + w
        d1 = (l00 * l10 * l11 + (x0 * x1 + y0 * y0 + w) * l11 + d00_11 * l10
              + (x1 * x1 + y0 * y1 + w) * l00)
        d2 = (l00 * l11 * l01 + d00_11 * l01 + (x0 * x0 + y0 * y1 + w) * l11
              + (x0 * x1 + y1 * y1 + w) * l00)
        # 2 (atan2(triple, d1) + atan2(triple, d2)), in one call where the products stay
        # within float64's range: the sum is the argument of (d1 + i triple) (d2 + i triple),
        # in (0, 2 pi)
        if _PRODUCTS_LOW < max(abs(d1), abs(d2), triple) < _PRODUCTS_HIGH:
            half = math.atan2(triple * (d1 + d2), d1 * d2 - triple * triple)
            if half < 0.0:
                half += TWO_PI
        else:
            half = math.atan2(triple, d1) + math.atan2(triple, d2)
        omega = 2.0 * half
        dx = max(0.0, max(x0, -x1))         # from p's foot to the rectangle, in its plane
        dy = max(0.0, max(y0, -y1))
        spherical = (right != 0.0 and omega >= RECTANGLE_MIN_SOLID_ANGLE
                     and dx * dx + dy * dy <= RECTANGLE_MAX_GRAZING * w)
    return (xx, xy, xz, yx, yy, yz, zx, zy, zz, x0, y0, z0, exl, eyx_, eyl, area, omega, l00,
            spherical)


@njit(cache=True, _nrt=False, forceinline=True)
def rectangle_solid_angle(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz):
    """Solid angle (steradians) of the rectangle c + s e_x + t e_y, |s|, |t| <= 1/2, from p."""
    return _rectangle_frame(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz)[16]


@njit(cache=True, _nrt=False, forceinline=True)
def _rectangle_spherical(x0, y0, z0, exl, eyl, omega, l00, u1, u2):
    """Urena et al.'s map of (u1, u2) to a point (xu, yv) of the rectangle [x0, x0 + exl] x
    [y0, y0 + eyl] at z = z0 < 0, uniform in the solid angle omega it subtends from the origin."""
    x1, y1 = x0 + exl, y0 + eyl
    w = z0 * z0
    l01 = math.sqrt(x0 * x0 + y1 * y1 + w)
    # the internal angles at (x0, y1) and (x0, y0) as (cos, sin) times a length; the map starts
    # from k = 2 pi - g2 - g3: au = k + u1 omega, its cos and sin by the addition formulas
    c2, s2 = x0 * y1, -z0 * l01
    c3, s3 = -x0 * y0, -z0 * l00
    scale = 1.0 / math.sqrt((c2 * c2 + s2 * s2) * (c3 * c3 + s3 * s3))
    ck, sk = (c2 * c3 - s2 * s3) * scale, -(s2 * c3 + c2 * s3) * scale
    phi = u1 * omega
    cp, sp = sincos(phi)
    s, c = sk * cp + ck * sp, ck * cp - sk * sp
    b0 = -y0 / math.sqrt(w + y0 * y0)
    b1 = y1 / math.sqrt(w + y1 * y1)
    num = c * b0 - b1
    den = math.sqrt(num * num + b0 * b0 * s * s)
    cu = _clamp(math.copysign(1.0, num) * s / den, -1.0, 1.0) if den > 0.0 else 0.0
    rest = 1.0 - cu * cu
    if rest > 0.0:
        xu = _clamp(-cu * z0 / math.sqrt(rest), x0, x1)
    else:
        xu = x1 if cu < 0.0 else x0
    d = math.sqrt(xu * xu + w)
    h0 = y0 / math.sqrt(d * d + y0 * y0)
    h1 = y1 / math.sqrt(d * d + y1 * y1)
    hv = h0 + u2 * (h1 - h0)
    rest = (1.0 - hv) * (1.0 + hv)
    if rest > 0.0:
        yv = _clamp(hv * d / math.sqrt(rest), y0, y1)
    else:
        yv = y1 if hv > 0.0 else y0
    return xu, yv


@njit(cache=True, _nrt=False, forceinline=True)
def rectangle_sample(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz, u1, u2):
    """A point q of the rectangle c + s e_x + t e_y (|s|, |t| <= 1/2: ptrace's area lights, c
    their position) seen from p: (qx, qy, qz, pdf), pdf per unit solid angle of the direction
    from p to q. Uniform in solid angle (pdf 1 / solid angle) unless the thresholds above say
    otherwise; then uniform by area, as lights.sample_light's (pdf distance^2 / (area cos)).
    pdf 0: no sample."""
    (xx, xy, xz, yx, yy, yz, zx, zy, zz, exl, eyx_, eyl, area, right, kx, ky,
     kz) = rectangle_axes(cx, cy, cz, exx, exy, exz, eyx, eyy, eyz)
    return _rectangle_sample(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz, xx, xy, xz,
                             yx, yy, yz, zx, zy, zz, exl, eyx_, eyl, area, right, kx, ky, kz,
                             u1, u2)


@njit(cache=True, _nrt=False, forceinline=True)
def rectangle_sample_row(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz, axes, i, u1,
                         u2):
    """rectangle_sample with the rectangle's axes read from row i of rectangle_axes_table's
    array: the same numbers, bit for bit, without recomputing them at every point."""
    return _rectangle_sample(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz, axes[i, 0],
                             axes[i, 1], axes[i, 2], axes[i, 3], axes[i, 4], axes[i, 5],
                             axes[i, 6], axes[i, 7], axes[i, 8], axes[i, 9], axes[i, 10],
                             axes[i, 11], axes[i, 12], axes[i, 13], axes[i, 14], axes[i, 15],
                             axes[i, 16], u1, u2)


@njit(cache=True, _nrt=False, forceinline=True)
def _rectangle_sample(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz, xx, xy, xz, yx, yy,
                      yz, zx, zy, zz, exl, eyx_, eyl, area, right, kx, ky, kz, u1, u2):
    (xx, xy, xz, yx, yy, yz, zx, zy, zz, x0, y0, z0, exl, eyx_, eyl, area, omega, l00,
     spherical) = _rectangle_at(px, py, pz, xx, xy, xz, yx, yy, yz, zx, zy, zz, exl, eyx_, eyl,
                                area, right, kx, ky, kz)
    if spherical:
        xu, yv = _rectangle_spherical(x0, y0, z0, exl, eyl, omega, l00, u1, u2)
        a, b = xu - x0, yv - y0
        return kx + a * xx + b * yx, ky + a * xy + b * yy, kz + a * xz + b * yz, 1.0 / omega
    s, t = u1 - 0.5, u2 - 0.5
    qx, qy, qz = cx + s * exx + t * eyx, cy + s * exy + t * eyy, cz + s * exz + t * eyz
    dx, dy, dz = qx - px, qy - py, qz - pz
    dist2 = dx * dx + dy * dy + dz * dz
    cos_dist = abs(dx * zx + dy * zy + dz * zz)     # cos at q times the distance
    if cos_dist == 0.0 or area == 0.0:
        return qx, qy, qz, 0.0
    return qx, qy, qz, dist2 * math.sqrt(dist2) / (area * cos_dist)


@njit(cache=True, _nrt=False, forceinline=True)
def rectangle_pdf(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz, wx, wy, wz):
    """Density per unit solid angle with which rectangle_sample, from p, gives the unit direction
    w: 0 if the ray p + t w (t > 0) misses the rectangle."""
    (xx, xy, xz, yx, yy, yz, zx, zy, zz, x0, y0, z0, exl, eyx_, eyl, area, omega, l00,
     spherical) = _rectangle_frame(px, py, pz, cx, cy, cz, exx, exy, exz, eyx, eyy, eyz)
    wz_ = wx * zx + wy * zy + wz * zz
    if not wz_ < 0.0 or area == 0.0:     # away from the plane, along it, or no rectangle
        return 0.0
    t = z0 / wz_
    hy = t * (wx * yx + wy * yy + wz * yz) - y0     # the hit from the corner, in the frame
    hx = t * (wx * xx + wy * xy + wz * xz) - x0
    b = hy / eyl
    a = (hx - b * eyx_) / exl
    if not (0.0 <= a <= 1.0 and 0.0 <= b <= 1.0):
        return 0.0
    if spherical:
        return 1.0 / omega
    return t * t / (area * -wz_)


# -- triangles -------------------------------------------------------------------------------------

@njit(cache=True, _nrt=False, forceinline=True)
def _triangle_frame(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Corners from p (a, b, c) and their lengths, edges e1 = B - A and e2 = C - A, the normal
    e1 x e2 (length twice the area), a . (e1 x e2) = a . (b x c), and the solid angle."""
    vax, vay, vaz = ax - px, ay - py, az - pz
    vbx, vby, vbz = bx - px, by - py, bz - pz
    vcx, vcy, vcz = cx - px, cy - py, cz - pz
    la = math.sqrt(vax * vax + vay * vay + vaz * vaz)
    lb = math.sqrt(vbx * vbx + vby * vby + vbz * vbz)
    lc = math.sqrt(vcx * vcx + vcy * vcy + vcz * vcz)
    e1x, e1y, e1z = bx - ax, by - ay, bz - az
    e2x, e2y, e2z = cx - ax, cy - ay, cz - az
    nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    triple = vax * nx + vay * ny + vaz * nz
    omega = 0.0
    if triple != 0.0:       # Van Oosterom and Strackee 1983
        omega = 2.0 * math.atan2(abs(triple), la * lb * lc
                                 + (vax * vbx + vay * vby + vaz * vbz) * lc
                                 + (vax * vcx + vay * vcy + vaz * vcz) * lb
                                 + (vbx * vcx + vby * vcy + vbz * vcz) * la)
    return (vax, vay, vaz, la, vbx, vby, vbz, lb, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz,
            triple, omega)


@njit(cache=True, _nrt=False, forceinline=True)
def triangle_solid_angle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Solid angle (steradians) of the triangle ABC from p."""
    return _triangle_frame(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)[18]


@njit(cache=True, _nrt=False, forceinline=True)
def _triangle_spherical(vax, vay, vaz, la, vbx, vby, vbz, lb, e1x, e1y, e1z, e2x, e2y, e2z,
                        triple, omega, u1, u2):
    """Arvo's map of (u1, u2) to a unit direction inside the spherical triangle of the corners
    a, b = a + e1, c = a + e2 (from the origin), uniform in its solid angle omega."""
    ax, ay, az = vax / la, vay / la, vaz / la
    # the angle at A: between the planes (a, b) and (a, c), normals a x e1 and a x e2
    n1x, n1y, n1z = vay * e1z - vaz * e1y, vaz * e1x - vax * e1z, vax * e1y - vay * e1x
    n2x, n2y, n2z = vay * e2z - vaz * e2y, vaz * e2x - vax * e2z, vax * e2y - vay * e2x
    alpha = math.atan2(abs(triple) * la, n1x * n2x + n1y * n2y + n1z * n2z)
    sin_alpha = math.sin(alpha)
    # A - B as unit vectors, from the edge: a/la - b/lb = (a (lb - la) / la - e1) / lb, where
    # lb - la = e1 . (a + b) / (la + lb)
    k = (e1x * (vax + vbx) + e1y * (vay + vby) + e1z * (vaz + vbz)) / (la * (la + lb))
    abx, aby, abz = (k * vax - e1x) / lb, (k * vay - e1y) / lb, (k * vaz - e1z) / lb
    one_minus_cos_c = 0.5 * (abx * abx + aby * aby + abz * abz)     # 1 - A . B
    # Arvo: the sub-triangle A B C' of solid angle u1 omega has C' on the arc from A to C, at
    # cos q from A; his q, rewritten so that 1 - q comes without cancelling:
    # 1 - q = 2 sin^2(A'/2) (1 + cos c) / (2 sin^2(A'/2) + sin(alpha - A') sin alpha (1 - cos c))
    half = 0.5 * u1 * omega
    sin2_half = 2.0 * math.sin(half) ** 2
    den = sin2_half + math.sin(alpha - 2.0 * half) * sin_alpha * one_minus_cos_c
    one_minus_q = _clamp(sin2_half * (2.0 - one_minus_cos_c) / den, 0.0, 2.0) if den > 0.0 \
        else 0.0
    # C - (C . A) A, from the edge e2 (C's offset from A) rather than from the nearly equal c, a
    k = e2x * ax + e2y * ay + e2z * az
    px_, py_, pz_ = e2x - k * ax, e2y - k * ay, e2z - k * az
    lp = math.sqrt(px_ * px_ + py_ * py_ + pz_ * pz_)
    sq = math.sqrt(one_minus_q * (2.0 - one_minus_q))
    if lp > 0.0:
        sq /= lp
    # C' - B = (A - B) + (C' - A)
    dx = abx - one_minus_q * ax + sq * px_
    dy = aby - one_minus_q * ay + sq * py_
    dz = abz - one_minus_q * az + sq * pz_
    bx, by, bz = vbx / lb, vby / lb, vbz / lb
    # along the arc from B to C', 1 - cos uniform in [0, 1 - B . C']
    one_minus_z = u2 * 0.5 * (dx * dx + dy * dy + dz * dz)
    z = 1.0 - one_minus_z
    k = dx * bx + dy * by + dz * bz
    ox, oy, oz = dx - k * bx, dy - k * by, dz - k * bz             # C' - (C' . B) B
    lo = math.sqrt(ox * ox + oy * oy + oz * oz)
    r = math.sqrt(max(0.0, one_minus_z * (2.0 - one_minus_z)))
    if lo > 0.0:
        r /= lo
    return z * bx + r * ox, z * by + r * oy, z * bz + r * oz


@njit(cache=True, _nrt=False, forceinline=True)
def triangle_sample(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz, u1, u2):
    """A point q of the triangle ABC seen from p: (qx, qy, qz, wb, wc, pdf), where q = A + wb (B -
    A) + wc (C - A) (wb, wc: the barycentrics of B and C, as lights.sample_emitter's) and pdf is
    per unit solid angle of the direction from p to q. Uniform in solid angle (pdf 1 / solid
    angle) when the triangle subtends at least TRIANGLE_MIN_SOLID_ANGLE; else uniform by area, as
    lights.sample_emitter's (pdf distance^2 / (area cos)). pdf 0: no sample."""
    (vax, vay, vaz, la, vbx, vby, vbz, lb, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, triple,
     omega) = _triangle_frame(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)
    if omega >= TRIANGLE_MIN_SOLID_ANGLE:
        wx, wy, wz = _triangle_spherical(vax, vay, vaz, la, vbx, vby, vbz, lb, e1x, e1y, e1z,
                                         e2x, e2y, e2z, triple, omega, u1, u2)
        # where the ray p + t w crosses the plane (Moller and Trumbore), from p - A = -a
        s1x, s1y, s1z = wy * e2z - wz * e2y, wz * e2x - wx * e2z, wx * e2y - wy * e2x
        divisor = s1x * e1x + s1y * e1y + s1z * e1z
        if divisor != 0.0:
            s2x, s2y, s2z = vaz * e1y - vay * e1z, vax * e1z - vaz * e1x, vay * e1x - vax * e1y
            wb = -(vax * s1x + vay * s1y + vaz * s1z) / divisor
            wc = (wx * s2x + wy * s2y + wz * s2z) / divisor
        else:
            wb = wc = 1.0 / 3.0
        wb, wc = _clamp(wb, 0.0, 1.0), _clamp(wc, 0.0, 1.0)
        if wb + wc > 1.0:
            total = wb + wc
            wb, wc = wb / total, wc / total
        pdf = 1.0 / omega
    else:
        root = math.sqrt(u1)
        wb, wc = root * (1.0 - u2), root * u2
        pdf = -1.0
    qx = ax + wb * e1x + wc * e2x
    qy = ay + wb * e1y + wc * e2y
    qz = az + wb * e1z + wc * e2z
    if pdf < 0.0:
        dx, dy, dz = qx - px, qy - py, qz - pz
        dist2 = dx * dx + dy * dy + dz * dz
        cos_dist = abs(dx * nx + dy * ny + dz * nz)    # cos at q times distance times 2 area
        pdf = 2.0 * dist2 * math.sqrt(dist2) / cos_dist if cos_dist > 0.0 else 0.0
    return qx, qy, qz, wb, wc, pdf


@njit(cache=True, _nrt=False, forceinline=True)
def triangle_pdf(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz, wx, wy, wz):
    """Density per unit solid angle with which triangle_sample, from p, gives the unit direction
    w: 0 if the ray p + t w (t > 0) misses the triangle."""
    (vax, vay, vaz, la, vbx, vby, vbz, lb, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, triple,
     omega) = _triangle_frame(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)
    cos_n = wx * nx + wy * ny + wz * nz         # cos at the hit times 2 area
    if cos_n == 0.0:
        return 0.0
    t = triple / cos_n                         # distance to the plane along w
    if not t > 0.0:
        return 0.0
    # barycentrics of the hit A + wb e1 + wc e2, from its offset -a + t w
    hx, hy, hz = t * wx - vax, t * wy - vay, t * wz - vaz
    ux, uy, uz = hy * e2z - hz * e2y, hz * e2x - hx * e2z, hx * e2y - hy * e2x    # h x e2
    vx, vy, vz = e1y * hz - e1z * hy, e1z * hx - e1x * hz, e1x * hy - e1y * hx    # e1 x h
    wb = (ux * nx + uy * ny + uz * nz) / (nx * nx + ny * ny + nz * nz)
    wc = (vx * nx + vy * ny + vz * nz) / (nx * nx + ny * ny + nz * nz)
    if not (wb >= 0.0 and wc >= 0.0 and wb + wc <= 1.0):
        return 0.0
    if omega >= TRIANGLE_MIN_SOLID_ANGLE:
        return 1.0 / omega
    return 2.0 * t * t / abs(cos_n)
