"""Primitive tests shared by every backend: Möller–Trumbore triangles, analytic spheres; and the
per-ray set-up of the BVH's slab tests.

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


@njit(cache=True, inline="always")
def triangle_edges(vertices, faces, tri):
    """(p0, e1, e2) of triangle `tri`, nine floats: the part of Möller–Trumbore that does not
    depend on the ray (the BVH stores it per triangle, in leaf order)."""
    i0 = faces[tri, 0]
    i1 = faces[tri, 1]
    i2 = faces[tri, 2]
    p0x = vertices[i0, 0]
    p0y = vertices[i0, 1]
    p0z = vertices[i0, 2]
    return (p0x, p0y, p0z,
            vertices[i1, 0] - p0x, vertices[i1, 1] - p0y, vertices[i1, 2] - p0z,
            vertices[i2, 0] - p0x, vertices[i2, 1] - p0y, vertices[i2, 2] - p0z)


@njit(cache=True, inline="always")
def triangle_hit_edges(p0x, p0y, p0z, e1x, e1y, e1z, e2x, e2y, e2z, ox, oy, oz, dx, dy, dz):
    """Möller–Trumbore on a triangle given as (p0, e1, e2): (t, u, v); t = MISS (NaN) on a miss.

    Edges are inclusive (u, v, 1-u-v in [0, 1]); no determinant epsilon and no back-face
    culling (CS184.md 4.2). A ray parallel to the plane (determinant exactly 0) misses.
    """
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
def triangle_hit(vertices, faces, tri, ox, oy, oz, dx, dy, dz):
    """Möller–Trumbore: (t, u, v) of the ray against triangle `tri`; t = MISS (NaN) on a miss.
    The same arithmetic as triangle_hit_edges on triangle_edges, so every backend computes
    bit-identical t, u, v whether it reads the mesh or the BVH's per-triangle copy."""
    p0x, p0y, p0z, e1x, e1y, e1z, e2x, e2y, e2z = triangle_edges(vertices, faces, tri)
    return triangle_hit_edges(p0x, p0y, p0z, e1x, e1y, e1z, e2x, e2y, e2z,
                              ox, oy, oz, dx, dy, dz)


@njit(cache=True, inline="always")
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
def inverse_direction(d):
    """1/d for the slab test; a zero component becomes 1e300 (finite, signed like +0), so
    (plane - o) * inverse is never NaN: a ray parallel to a slab is inside it (t from -1e300
    to +1e300, or up to inf) or outside it (an empty interval), never wrongly culled."""
    if d == 0.0:
        return 1e300
    return 1.0 / d


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
def slab_setup(dx, dy, dz):
    """What a BVH traversal needs of a ray's direction: its inverse_direction() and the near and
    far planes (near_columns)."""
    ix = inverse_direction(dx)
    iy = inverse_direction(dy)
    iz = inverse_direction(dz)
    nx, ny, nz, fx, fy, fz = near_columns(ix, iy, iz)
    return ix, iy, iz, nx, ny, nz, fx, fy, fz


@njit(cache=True, inline="always")
def stored_triangle_hit(tris, i, ox, oy, oz, dx, dy, dz):
    """triangle_hit_edges on row i of an array of triangle_edges rows."""
    return triangle_hit_edges(tris[i, 0], tris[i, 1], tris[i, 2], tris[i, 3], tris[i, 4],
                              tris[i, 5], tris[i, 6], tris[i, 7], tris[i, 8],
                              ox, oy, oz, dx, dy, dz)


@njit(cache=True, inline="always")
def better(t, prim, best_t, best_prim):
    """True if a hit (t, prim) beats the current best: nearer, or as near with a lower id."""
    return t < best_t or (t == best_t and (best_prim == NO_HIT or prim < best_prim))


@njit(cache=True, inline="always")
def spheres_closest(centers, radii, first_id, ox, oy, oz, dx, dy, dz, tmin, best_t, best_prim,
                    best_u, best_v):
    """Fold every sphere into a closest hit found so far (best_t is the current tmax; sphere s
    has primitive id first_id + s, so a tie with a triangle goes to the triangle)."""
    for s in range(centers.shape[0]):
        t = sphere_hit(centers, radii, s, ox, oy, oz, dx, dy, dz, tmin, best_t)
        if t <= best_t and better(t, first_id + s, best_t, best_prim):
            best_t, best_prim, best_u, best_v = t, first_id + s, 0.0, 0.0
    return best_t, best_prim, best_u, best_v


@njit(cache=True, inline="always")
def spheres_any(centers, radii, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """True if any sphere is hit with tmin <= t <= tmax."""
    for s in range(centers.shape[0]):
        if sphere_hit(centers, radii, s, ox, oy, oz, dx, dy, dz, tmin, tmax) <= tmax:
            return True
    return False
