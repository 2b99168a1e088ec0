"""Geometry at hit points: positions and shading normals, as numba kernels over arrays."""
from numba import njit, prange


@njit(cache=True, parallel=True)
def shading_normals(vertex_normals, faces, centers, radii, origins, directions, t, prim, u, v,
                    out):
    """Shading normal of each hit: for triangles the barycentric blend of the (area-weighted)
    vertex normals, not renormalised, like the course; for spheres the unit outward normal.
    Rays that missed get (0, 0, 0)."""
    n_tri = faces.shape[0]
    for i in prange(t.shape[0]):
        p = prim[i]
        if p < 0:
            out[i, 0] = 0.0
            out[i, 1] = 0.0
            out[i, 2] = 0.0
        elif p < n_tri:
            w = 1.0 - u[i] - v[i]
            for a in range(3):
                out[i, a] = (w * vertex_normals[faces[p, 0], a] + u[i] * vertex_normals[faces[p, 1], a]
                             + v[i] * vertex_normals[faces[p, 2], a])
        else:
            s = p - n_tri
            for a in range(3):
                out[i, a] = (origins[i, a] + t[i] * directions[i, a] - centers[s, a]) / radii[s]
    return out


@njit(cache=True, parallel=True)
def normal_colours(normals, prim, out):
    """The course's normal shading: 0.5 * n + 0.5 on a hit, black on a miss."""
    for i in prange(prim.shape[0]):
        for a in range(3):
            out[i, a] = 0.5 * normals[i, a] + 0.5 if prim[i] >= 0 else 0.0
    return out
