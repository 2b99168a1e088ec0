"""The AOVs' kernels (ptrace.features is their Python side): what a camera ray's first hit is,
as a denoiser's guides want it, taken by the wavefront when a render asks for AOVs. Apart from
the path's stages because it reads the BSDFs' parameters (a conductor's reflectance): an edit to
the BSDFs then recompiles the shading kernels and this, not the stages that know no material."""
import math

from numba import njit

from ..bsdf import conductor_fresnel
from ..integrator import surface
from ..scene import EMISSION, GLASS, MICROFACET, REFRACTION
from ..textures import mapped_normal, surface_albedo, surface_emission
from .layout import DX, DY, DZ, OX, OY, OZ, PRIM, T, U, V


@njit(cache=True, _nrt=False, forceinline=True)
def hit_features(shapes, materials, ox, oy, oz, dx, dy, dz, t, prim, u, v):
    """(albedo r, g, b, normal x, y, z, distance, hit) of a camera ray's hit (t, prim, u, v),
    o + t d: the surface's albedo at the hit as a denoiser wants it (diffuse: its albedo;
    mirror: its reflectance; glass and refraction: their transmittance; a conductor: its
    reflectance at normal incidence; an emitter: its emission clamped to 1), the shading normal
    turned toward the camera, world space (bent by a normal texture), and the distance along the
    ray; zeros and hit 0 on a miss."""
    m, px, py, pz, gx, gy, gz, nx, ny, nz, offset = surface(shapes, materials.kind, ox, oy, oz,
                                                            dx, dy, dz, t, prim, u, v)
    if m < 0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    nx, ny, nz = mapped_normal(shapes, materials, m, prim, u, v, nx, ny, nz)
    kind = materials.kind[m]
    ar, ag, ab, alpha, _ = surface_albedo(shapes, materials, m, prim, u, v)
    if kind == EMISSION:
        er, eg, eb = surface_emission(shapes, materials, m, prim, u, v)
        ar, ag, ab = min(er, 1.0), min(eg, 1.0), min(eb, 1.0)
    elif kind == GLASS or kind == REFRACTION:
        tr = materials.transmittance
        ar, ag, ab = tr[m, 0], tr[m, 1], tr[m, 2]
    elif kind == MICROFACET:
        eta, k, specular = materials.eta, materials.k, materials.specular
        ar = conductor_fresnel(eta[m, 0], k[m, 0], 1.0) * specular[m, 0]
        ag = conductor_fresnel(eta[m, 1], k[m, 1], 1.0) * specular[m, 1]
        ab = conductor_fresnel(eta[m, 2], k[m, 2], 1.0) * specular[m, 2]
    if nx * dx + ny * dy + nz * dz > 0.0:    # glass keeps its outward normal: face the camera
        nx, ny, nz = -nx, -ny, -nz
    return ar, ag, ab, nx, ny, nz, t * math.sqrt(dx * dx + dy * dy + dz * dz), 1.0


@njit(cache=True, nogil=True, _nrt=False)
def features_stage(shapes, materials, floats, ints, n, features):
    """The AOVs (albedo, normal, distance, hit: hit_features) of each of
    the first n paths' camera hit, into the rows of features (8, wave size). materials: the
    full record (ptrace.integrator.MaterialArrays)."""
    for i in range(n):
        a0, a1, a2, a3, a4, a5, a6, a7 = hit_features(
            shapes, materials, floats[OX, i], floats[OY, i], floats[OZ, i], floats[DX, i],
            floats[DY, i], floats[DZ, i], floats[T, i], ints[PRIM, i], floats[U, i],
            floats[V, i])
        features[0, i], features[1, i], features[2, i], features[3, i] = a0, a1, a2, a3
        features[4, i], features[5, i], features[6, i], features[7, i] = a4, a5, a6, a7
