"""Primitive tests shared by every backend: triangles (watertight by default, Möller–Trumbore as an
option), analytic spheres; and which box planes a BVH ray meets first.

All three backends call these same functions, so naive and bvh compute bit-identical t values.
A hit is accepted when tmin <= t <= tmax (both ends inclusive, like the course). Between two
hits at exactly the same t the lower primitive id wins, so the answer does not depend on the
order primitives are visited in.
"""
import numpy as np
from numba import njit

NO_HIT = -1
# A primitive test returns NaN for "no hit": every comparison with NaN is false, so a miss can
# never pass `tmin <= t <= tmax`, even when tmax is infinite.
MISS = np.nan


# The triangle tests (accel.build(kind, geometry, triangle=...) for naive and bvh). A backend
# has one record class per test: the watertight test's, and a subclass of it that also derives
# from MollerTrumbore. The class is part of the record's numba type, so a traversal compiled for
# a record compiles the one test its class names (accel.compiled.by_class) and never the other.
TRIANGLE_TESTS = ("watertight", "moller-trumbore")
WATERTIGHT = 0
MOLLER_TRUMBORE = 1


class MollerTrumbore:
    """A backend record class that also derives from this one has its triangles tested by
    Möller–Trumbore; one that does not, by the watertight test (accel.compiled.by_class)."""
    __slots__ = ()


def triangle_test(name):
    """The record's int for a triangle test's name; ValueError naming the choices otherwise."""
    if name not in TRIANGLE_TESTS:
        raise ValueError(f"unknown triangle test {name!r}; choose one of "
                         f"{', '.join(TRIANGLE_TESTS)}")
    return TRIANGLE_TESTS.index(name)


@njit(cache=True, inline="always")
def moller_trumbore(p0x, p0y, p0z, p1x, p1y, p1z, p2x, p2y, p2z, ox, oy, oz, dx, dy, dz):
    """Möller–Trumbore on the triangle (p0, p1, p2): (t, u, v); t = MISS (NaN) on a miss.

    Edges are inclusive (u, v, 1-u-v in [0, 1]); no determinant epsilon and no back-face
    culling (docs/course.md#intersections). A ray parallel to the plane (determinant exactly 0)
    misses. Not watertight: u and v are computed per triangle from its own edge vectors, so a
    ray through a shared edge can round outside both triangles (benchmarks/results/stability.md,
    section 2).
    """
    e1x = p1x - p0x
    e1y = p1y - p0y
    e1z = p1z - p0z
    e2x = p2x - p0x
    e2y = p2y - p0y
    e2z = p2z - p0z
    # s1 = d x e2
    s1x = dy * e2z - dz * e2y
    s1y = dz * e2x - dx * e2z
    s1z = dx * e2y - dy * e2x
    det = s1x * e1x + s1y * e1y + s1z * e1z
    if det == 0.0:
        return MISS, 0.0, 0.0
    inv = 1.0 / det
    sx = ox - p0x
    sy = oy - p0y
    sz = oz - p0z
    u = (s1x * sx + s1y * sy + s1z * sz) * inv
    if u < 0.0 or u > 1.0:
        return MISS, 0.0, 0.0
    # s2 = s x e1
    s2x = sy * e1z - sz * e1y
    s2y = sz * e1x - sx * e1z
    s2z = sx * e1y - sy * e1x
    v = (s2x * dx + s2y * dy + s2z * dz) * inv
    if v < 0.0 or u + v > 1.0:
        return MISS, 0.0, 0.0
    t = (s2x * e2x + s2y * e2y + s2z * e2z) * inv
    return t, u, v


@njit(cache=True, inline="always")
def shear_setup(ox, oy, oz, dx, dy, dz):
    """What the watertight test needs of a ray, once per ray: the axis kz of the direction's
    largest component and kx, ky the next two (cyclically), the origin's components in that
    order, and the shear (sx, sy, sz) that maps the direction to (0, 0, 1). A zero direction
    gets sz = NaN, so every t is NaN: a miss."""
    ax, ay, az = abs(dx), abs(dy), abs(dz)
    if ax > ay and ax > az:
        kz = 0
    elif ay > az:
        kz = 1
    else:
        kz = 2
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    d = (dx, dy, dz)
    o = (ox, oy, oz)
    big = d[kz]
    if big == 0.0:
        return kx, ky, kz, o[kx], o[ky], o[kz], 0.0, 0.0, np.nan
    return kx, ky, kz, o[kx], o[ky], o[kz], -d[kx] / big, -d[ky] / big, 1.0 / big


@njit(cache=True, inline="always")
def watertight(ax, ay, az, bx, by, bz, cx, cy, cz, sx, sy, sz):
    """Woop, Benthin and Wald's watertight test (JCGT 2013; pbrt-v4's IntersectTriangle) on the
    triangle (a, b, c) already translated to the ray's origin and permuted by shear_setup():
    (t, u, v), t = MISS (NaN) on a miss; u and v are the barycentric weights of b and c, as
    Möller–Trumbore's.

    After the shear the ray is the z axis, and the triangle's 2D edge functions decide the hit.
    Two triangles that share an edge compute that edge's function from the same sheared vertices
    in the same float64 operations (a product is the same whichever factor comes first, and
    x - y is exactly -(y - x)), so the two values are exact negatives: a ray through the edge
    is inside one of them or on the edge of both, never outside both. Edges are inclusive (an
    edge function of 0 passes); a triangle seen edge-on (det = 0) misses. pbrt falls back to
    float64 when a float32 edge function is 0; these are float64 already, and the argument
    above does not need a fallback: the shared edge's two values stay exact negatives.
    """
    ax += sx * az
    ay += sy * az
    bx += sx * bz
    by += sy * bz
    cx += sx * cz
    cy += sy * cz
    e0 = bx * cy - by * cx
    e1 = cx * ay - cy * ax
    e2 = ax * by - ay * bx
    if (e0 < 0.0 or e1 < 0.0 or e2 < 0.0) and (e0 > 0.0 or e1 > 0.0 or e2 > 0.0):
        return MISS, 0.0, 0.0
    det = e0 + e1 + e2
    if det == 0.0:
        return MISS, 0.0, 0.0
    inv = 1.0 / det
    t = (e0 * az + e1 * bz + e2 * cz) * sz * inv
    return t, e1 * inv, e2 * inv


@njit(cache=True, inline="always")
def mesh_watertight(vertices, faces, tri, shear):
    """The watertight test on triangle `tri` of a mesh (shear is shear_setup() of the ray). The
    BVH runs the same arithmetic four triangles at a time on its copy of the coordinates
    (accel.simd's block tests), so every backend computes bit-identical t, u, v."""
    i0 = faces[tri, 0]
    i1 = faces[tri, 1]
    i2 = faces[tri, 2]
    kx, ky, kz, px, py, pz, sx, sy, sz = shear
    return watertight(vertices[i0, kx] - px, vertices[i0, ky] - py, vertices[i0, kz] - pz,
                      vertices[i1, kx] - px, vertices[i1, ky] - py, vertices[i1, kz] - pz,
                      vertices[i2, kx] - px, vertices[i2, ky] - py, vertices[i2, kz] - pz,
                      sx, sy, sz)


@njit(cache=True, inline="always")
def mesh_moller_trumbore(vertices, faces, tri, ox, oy, oz, dx, dy, dz):
    """Möller–Trumbore on triangle `tri` of a mesh, as mesh_watertight."""
    i0 = faces[tri, 0]
    i1 = faces[tri, 1]
    i2 = faces[tri, 2]
    return moller_trumbore(vertices[i0, 0], vertices[i0, 1], vertices[i0, 2],
                           vertices[i1, 0], vertices[i1, 1], vertices[i1, 2],
                           vertices[i2, 0], vertices[i2, 1], vertices[i2, 2],
                           ox, oy, oz, dx, dy, dz)


@njit(cache=True, inline="always")
def triangle_hit(vertices, faces, tri, ox, oy, oz, dx, dy, dz):
    """The default (watertight) test of the ray against triangle `tri`, for a single query (a
    traversal calls shear_setup once per ray and mesh_watertight per triangle instead)."""
    return mesh_watertight(vertices, faces, tri, shear_setup(ox, oy, oz, dx, dy, dz))


@njit(cache=True, _nrt=False, forceinline=True)
def sphere_hit(centers, radii, sphere, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Nearest root of the ray against `sphere` inside [tmin, tmax]; MISS (NaN) if none.

    Like the course: the nearer root if it is in range, else the farther one (so a ray that
    starts inside hits the far side). The discriminant is computed from the ray's closest
    approach to the centre rather than from b^2 - 4ac, which loses every digit when the
    origin is far away compared with the radius (Ray Tracing Gems, ch. 7).
    """
    fx = ox - centers[sphere, 0]
    fy = oy - centers[sphere, 1]
    fz = oz - centers[sphere, 2]
    r = radii[sphere]
    a = dx * dx + dy * dy + dz * dz
    if a == 0.0:
        return MISS
    b_half = fx * dx + fy * dy + fz * dz
    # f minus its projection on d: the vector from the centre to the closest approach
    k = b_half / a
    lx = fx - k * dx
    ly = fy - k * dy
    lz = fz - k * dz
    disc = a * (r * r - (lx * lx + ly * ly + lz * lz))   # = b_half^2 - a*c
    if disc < 0.0:
        return MISS
    c = fx * fx + fy * fy + fz * fz - r * r
    root = np.sqrt(disc)
    q = -(b_half + root) if b_half >= 0.0 else -(b_half - root)
    if q == 0.0:  # origin on the sphere, tangent direction: a double root at 0
        t0 = 0.0
        t1 = 0.0
    else:
        t0 = q / a
        t1 = c / q
    if t0 > t1:
        t0, t1 = t1, t0
    if tmin <= t0 <= tmax:
        return t0
    if tmin <= t1 <= tmax:
        return t1
    return MISS


@njit(cache=True, inline="always")
def near_columns(ix, iy, iz):
    """The near and far box planes (0, 1, 2: lower x, y, z; 3, 4, 5: upper x, y, z) of a ray
    with inverse direction (ix, iy, iz): the lower plane is near where the inverse is
    positive, else the upper one."""
    nx = 0 if ix > 0.0 else 3
    ny = 1 if iy > 0.0 else 4
    nz = 2 if iz > 0.0 else 5
    return nx, ny, nz, (nx + 3) % 6, (ny + 3) % 6, (nz + 3) % 6


@njit(cache=True, inline="always")
def better(t, prim, best_t, best_prim):
    """True if a hit (t, prim) beats the current best: nearer, or as near with a lower id."""
    return t < best_t or (t == best_t and (best_prim == NO_HIT or prim < best_prim))


@njit(cache=True, _nrt=False, forceinline=True)
def spheres_closest(centers, radii, first_id, ox, oy, oz, dx, dy, dz, tmin, best_t, best_prim,
                    best_u, best_v):
    """Fold every sphere into a closest hit found so far (best_t is the current tmax; sphere s
    has primitive id first_id + s, so a tie with a triangle goes to the triangle)."""
    for s in range(centers.shape[0]):
        t = sphere_hit(centers, radii, s, ox, oy, oz, dx, dy, dz, tmin, best_t)
        if t <= best_t and better(t, first_id + s, best_t, best_prim):
            best_t, best_prim, best_u, best_v = t, first_id + s, 0.0, 0.0
    return best_t, best_prim, best_u, best_v


@njit(cache=True, _nrt=False, forceinline=True)
def spheres_any(centers, radii, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """True if any sphere is hit with tmin <= t <= tmax."""
    for s in range(centers.shape[0]):
        if sphere_hit(centers, radii, s, ox, oy, oz, dx, dy, dz, tmin, tmax) <= tmax:
            return True
    return False
