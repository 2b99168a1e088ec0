"""BSDFs in a local shading frame (normal = +z), as numba functions of one material index.

Conventions: wo and wi are unit vectors pointing away from the surface; f excludes the cosine term;
pdf is per unit solid angle. Delta BSDFs (mirror, glass, refraction; `is_delta(kind)`) return from
bsdf_sample() an f that carries the whole weight divided by |cos theta_i| and as pdf the discrete
probability of the branch taken; bsdf_eval() and bsdf_pdf() of a delta BSDF are 0. A kind with
a delta lobe beside a non-delta one (MIXED: PLASTIC, Mitsuba's smooth plastic) returns from a
delta lobe's sample the negated probability of that lobe; its eval and pdf are its non-delta
lobe's. Semantics follow
docs/course.md#bsdfs, with the textbook Smith Lambda for Beckmann (sqrt(pi), where the course's
starter has pi). GLTF_PBR is glTF's metallic-roughness BRDF (ptrace.gltf_brdf), the only kind the
metallic argument matters to.
"""
import math

from numba import njit

from .gltf_brdf import INV_PI, gltf_eval, gltf_pdf, gltf_sample, half_vector
from .scene import (
    DIFFUSE,
    GLASS,
    GLOSSY,
    GLTF_PBR,
    MICROFACET,
    MIRROR,
    PLASTIC,
    REFRACTION,
    ROUGH_PLASTIC,
)
from .trig import sincos_2pi

SQRT_PI = math.sqrt(math.pi)


@njit(cache=True, inline="always")
def is_delta(kind):
    return kind == MIRROR or kind == GLASS or kind == REFRACTION


@njit(cache=True, inline="always")
def cosine_hemisphere(u1, u2):
    """Cosine-weighted direction about +z (docs/course.md#bsdfs): r = sqrt(u1), z = sqrt(1 - u1)."""
    r = math.sqrt(u1)
    c, s = sincos_2pi(u2)     # (cos, sin) of phi = 2 pi u2, inline (ptrace.trig)
    return r * c, r * s, math.sqrt(max(0.0, 1.0 - u1))


@njit(cache=True, inline="always")
def uniform_hemisphere(u1, u2):
    """Uniform direction about +z: z = u1, pdf 1 / (2 pi)."""
    z = u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    c, s = sincos_2pi(u2)
    return r * c, r * s, z


# -- microfacet (Beckmann, Smith G, conductor Fresnel) --------------------------------------------

@njit(cache=True, inline="always")
def beckmann_d(alpha, cos_h):
    if cos_h <= 0.0:
        return 0.0
    cos2 = cos_h * cos_h
    tan2 = (1.0 - cos2) / cos2
    return math.exp(-tan2 / (alpha * alpha)) / (math.pi * alpha * alpha * cos2 * cos2)


@njit(cache=True, inline="always")
def smith_lambda(alpha, cos_w):
    """Beckmann Lambda, textbook form: (erf(a) - 1)/2 + exp(-a^2) / (2 a sqrt(pi)),
    a = 1/(alpha tan)."""
    cos_w = abs(cos_w)
    if cos_w >= 1.0:
        return 0.0
    tan_w = math.sqrt(max(0.0, 1.0 - cos_w * cos_w)) / cos_w
    a = 1.0 / (alpha * tan_w)
    return 0.5 * (math.erf(a) - 1.0) + math.exp(-a * a) / (2.0 * a * SQRT_PI)


@njit(cache=True, inline="always")
def conductor_fresnel(eta, k, cos_i):
    """Unpolarised conductor Fresnel for one channel (docs/course.md#bsdfs)."""
    c2 = cos_i * cos_i
    ek = eta * eta + k * k
    rs = (ek - 2.0 * eta * cos_i + c2) / (ek + 2.0 * eta * cos_i + c2)
    rp = (ek * c2 - 2.0 * eta * cos_i + 1.0) / (ek * c2 + 2.0 * eta * cos_i + 1.0)
    return 0.5 * (rs + rp)


@njit(cache=True, _nrt=False, forceinline=True)
def _microfacet_f(alpha, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz):
    """The microfacet conductor's f: Beckmann D and Smith G, the conductor's Fresnel times
    specular[m] (Mitsuba's specular_reflectance; 1 for every other file's)."""
    hx, hy, hz, _, defined = half_vector(wox, woy, woz, wix, wiy, wiz)
    if not defined:
        return 0.0, 0.0, 0.0
    d = beckmann_d(alpha, hz)
    g = 1.0 / (1.0 + smith_lambda(alpha, wiz) + smith_lambda(alpha, woz))
    scale = d * g / (4.0 * woz * wiz)
    return (conductor_fresnel(eta[m, 0], k[m, 0], wiz) * scale * specular[m, 0],
            conductor_fresnel(eta[m, 1], k[m, 1], wiz) * scale * specular[m, 1],
            conductor_fresnel(eta[m, 2], k[m, 2], wiz) * scale * specular[m, 2])


@njit(cache=True, _nrt=False, forceinline=True)
def _microfacet_pdf(alpha, wox, woy, woz, wix, wiy, wiz):
    hx, hy, hz, _, defined = half_vector(wox, woy, woz, wix, wiy, wiz)
    if not defined:
        return 0.0
    # p(h) = D(h) cos(theta_h): the Beckmann distribution of normals, then the reflection Jacobian
    p_h = beckmann_d(alpha, hz) * hz
    return p_h / (4.0 * (wix * hx + wiy * hy + wiz * hz))


# -- glossy: a diffuse base under a glossy dielectric coat -----------------------------------------

GLOSSY_DIFFUSE = 28.0 / (23.0 * math.pi)


@njit(cache=True, inline="always")
def schlick(r0, cos):
    return r0 + (1.0 - r0) * (1.0 - cos) ** 5


@njit(cache=True, _nrt=False, forceinline=True)
def _glossy_f(ar, ag, ab, alpha, specular, m, wox, woy, woz, wix, wiy, wiz):
    """Ashikhmin and Shirley's coupled diffuse + glossy model (2000), as pbrt's FresnelBlend:
    a Beckmann coat of normal reflectance Rs with Schlick's Fresnel, F D / (4 |wi.h|
    max(cos_i, cos_o)), over a diffuse base of albedo Rd that gets what the coat lets through,
    28 Rd (1 - Rs) / (23 pi) (1 - (1 - cos_i / 2)^5)(1 - (1 - cos_o / 2)^5): reciprocal, and
    its directional albedo at most 1 for Rd, Rs in [0, 1] (tested)."""
    hx, hy, hz, _, defined = half_vector(wox, woy, woz, wix, wiy, wiz)
    if not defined:
        return 0.0, 0.0, 0.0
    cos_d = wix * hx + wiy * hy + wiz * hz
    coat = beckmann_d(alpha, hz) / (4.0 * cos_d * max(wiz, woz))
    base = GLOSSY_DIFFUSE * (1.0 - (1.0 - 0.5 * wiz) ** 5) * (1.0 - (1.0 - 0.5 * woz) ** 5)
    r0, r1, r2 = specular[m, 0], specular[m, 1], specular[m, 2]
    return (base * ar * (1.0 - r0) + coat * schlick(r0, cos_d),
            base * ag * (1.0 - r1) + coat * schlick(r1, cos_d),
            base * ab * (1.0 - r2) + coat * schlick(r2, cos_d))


@njit(cache=True, _nrt=False, forceinline=True)
def _glossy_pdf(alpha, wox, woy, woz, wix, wiy, wiz):
    """Half cosine-weighted, half the coat's Beckmann half-vector density."""
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0
    return 0.5 * wiz * INV_PI + 0.5 * _microfacet_pdf(alpha, wox, woy, woz, wix, wiy, wiz)


@njit(cache=True, inline="always")
def beckmann_half_vector(alpha, u1, u2):
    tan2 = -alpha * alpha * math.log(max(1.0 - u1, 1e-300))
    cos_h = 1.0 / math.sqrt(1.0 + tan2)
    sin_h = math.sqrt(max(0.0, 1.0 - cos_h * cos_h))
    c, s = sincos_2pi(u2)
    return sin_h * c, sin_h * s, cos_h


# -- one kind's sample, eval and pdf ---------------------------------------------------------------
# Every kind has the same three signatures, so a shading kernel takes one kind's functions as the
# constants of its code (BSDFS) and compiles nothing of the other kinds. `sample` returns (wix,
# wiy, wiz, fr, fg, fb, pdf), pdf 0 meaning no sample; for a delta kind f carries the whole
# weight divided by |cos theta_i| and pdf is the discrete probability of the branch taken (1 for
# mirror and refraction, R or 1-R for glass), so f * |cos| / pdf is the path weight in every case.

@njit(cache=True, _nrt=False, forceinline=True)
def diffuse_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wox,
                   woy, woz, u1, u2, u3):
    if woz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    x, y, z = cosine_hemisphere(u1, u2)
    if z <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    return x, y, z, ar * INV_PI, ag * INV_PI, ab * INV_PI, z * INV_PI


@njit(cache=True, _nrt=False, forceinline=True)
def diffuse_eval(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz):
    if woz > 0.0 and wiz > 0.0:
        return ar * INV_PI, ag * INV_PI, ab * INV_PI
    return 0.0, 0.0, 0.0


@njit(cache=True, _nrt=False, forceinline=True)
def diffuse_pdf(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy,
                wiz):
    return wiz * INV_PI if (woz > 0.0 and wiz > 0.0) else 0.0


@njit(cache=True, _nrt=False, forceinline=True)
def delta_eval(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz):
    """A delta kind's f, and an emitter's: 0 (its direction is never sampled by another)."""
    return 0.0, 0.0, 0.0


@njit(cache=True, _nrt=False, forceinline=True)
def delta_pdf(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy,
              wiz):
    return 0.0


@njit(cache=True, _nrt=False, forceinline=True)
def mirror_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wox,
                  woy, woz, u1, u2, u3):
    if woz == 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    c = abs(woz)
    return -wox, -woy, woz, ar / c, ag / c, ab / c, 1.0


@njit(cache=True, _nrt=False, forceinline=True)
def microfacet_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wox,
                      woy, woz, u1, u2, u3):
    if woz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    a = alpha
    hx, hy, hz = beckmann_half_vector(a, u1, u2)
    d = wox * hx + woy * hy + woz * hz
    wix, wiy, wiz = 2.0 * d * hx - wox, 2.0 * d * hy - woy, 2.0 * d * hz - woz
    if wiz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    pdf = _microfacet_pdf(a, wox, woy, woz, wix, wiy, wiz)
    fr, fg, fb = _microfacet_f(alpha, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz)
    return wix, wiy, wiz, fr, fg, fb, pdf


@njit(cache=True, _nrt=False, forceinline=True)
def microfacet_eval(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy,
                    wiz):
    return _microfacet_f(alpha, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz)


@njit(cache=True, _nrt=False, forceinline=True)
def microfacet_pdf(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy,
                   wiz):
    return _microfacet_pdf(alpha, wox, woy, woz, wix, wiy, wiz)


@njit(cache=True, _nrt=False, forceinline=True)
def glossy_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wox,
                  woy, woz, u1, u2, u3):
    if woz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    if u3 < 0.5:     # the base's cosine lobe
        wix, wiy, wiz = cosine_hemisphere(u1, u2)
    else:            # the coat's: reflect wo about a Beckmann half vector
        hx, hy, hz = beckmann_half_vector(alpha, u1, u2)
        d = wox * hx + woy * hy + woz * hz
        wix, wiy, wiz = 2.0 * d * hx - wox, 2.0 * d * hy - woy, 2.0 * d * hz - woz
    if wiz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    fr, fg, fb = _glossy_f(ar, ag, ab, alpha, specular, m, wox, woy, woz, wix, wiy, wiz)
    return wix, wiy, wiz, fr, fg, fb, _glossy_pdf(alpha, wox, woy, woz, wix, wiy, wiz)


@njit(cache=True, _nrt=False, forceinline=True)
def glossy_eval(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz):
    return _glossy_f(ar, ag, ab, alpha, specular, m, wox, woy, woz, wix, wiy, wiz)


@njit(cache=True, _nrt=False, forceinline=True)
def glossy_pdf(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy,
               wiz):
    return _glossy_pdf(alpha, wox, woy, woz, wix, wiy, wiz)


@njit(cache=True, _nrt=False, forceinline=True)
def pbr_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wox, woy,
               woz, u1, u2, u3):
    return gltf_sample(ar, ag, ab, metallic, alpha, wox, woy, woz, u1, u2, u3)


@njit(cache=True, _nrt=False, forceinline=True)
def pbr_eval(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz):
    return gltf_eval(ar, ag, ab, metallic, alpha, wox, woy, woz, wix, wiy, wiz)


@njit(cache=True, _nrt=False, forceinline=True)
def pbr_pdf(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy,
            wiz):
    return gltf_pdf(metallic, alpha, ar, ag, ab, wox, woy, woz, wix, wiy, wiz)


@njit(cache=True, _nrt=False, inline="always")
def _refracted(ior_m, wox, woy, woz):
    """wo refracted through a dielectric of index ior_m (below the surface, above it air):
    (cos_o, its sin^2 theta_t (>= 1: total internal reflection), cos_t, t's x y z, the
    radiance scale eta^2)."""
    entering = woz > 0.0
    eta_ratio = 1.0 / ior_m if entering else ior_m    # n_incident / n_transmitted
    cos_o = abs(woz)
    sin2_t = eta_ratio * eta_ratio * max(0.0, 1.0 - cos_o * cos_o)
    if sin2_t >= 1.0:
        return cos_o, sin2_t, 0.0, 0.0, 0.0, 0.0, 0.0
    cos_t = math.sqrt(1.0 - sin2_t)
    tz = -cos_t if entering else cos_t
    return cos_o, sin2_t, cos_t, -eta_ratio * wox, -eta_ratio * woy, tz, eta_ratio * eta_ratio


@njit(cache=True, _nrt=False, inline="always")
def dielectric_reflectance(cos_i, cos_t, eta_it):
    """The unpolarised Fresnel reflectance of a smooth dielectric boundary, from the cosines of
    the incident and the transmitted direction and eta_it, the index ratio transmitted over
    incident (the mean of the s and p amplitudes squared)."""
    a_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t)
    a_p = (cos_t - eta_it * cos_i) / (cos_t + eta_it * cos_i)
    return 0.5 * (a_s * a_s + a_p * a_p)


@njit(cache=True, _nrt=False, inline="always")
def _smooth_glass(ar, ag, ab, transmittance, ior, m, wox, woy, woz, u3, exact):
    """Reflection with probability R (the exact Fresnel reflectance if `exact`, else Schlick's),
    else refraction: glass_sample's and dielectric_sample's values."""
    if woz == 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    cos_o, sin2_t, cos_t, tx, ty, tz, radiance_scale = _refracted(ior[m], wox, woy, woz)
    if sin2_t >= 1.0:   # total internal reflection
        return -wox, -woy, woz, ar / cos_o, ag / cos_o, ab / cos_o, 1.0
    if exact:
        reflect = dielectric_reflectance(cos_o, cos_t, ior[m] if woz > 0.0 else 1.0 / ior[m])
    else:
        r0 = (1.0 - ior[m]) / (1.0 + ior[m])
        r0 = r0 * r0
        reflect = schlick(r0, cos_o)
    if u3 < reflect:
        s = reflect / cos_o
        return -wox, -woy, woz, ar * s, ag * s, ab * s, reflect
    s = (1.0 - reflect) * radiance_scale / cos_t
    return tx, ty, tz, transmittance[m, 0] * s, transmittance[m, 1] * s, \
        transmittance[m, 2] * s, 1.0 - reflect


@njit(cache=True, _nrt=False, forceinline=True)
def glass_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wox, woy,
                 woz, u1, u2, u3):
    """Reflection with Schlick's Fresnel R, else refraction (the course's glass)."""
    return _smooth_glass(ar, ag, ab, transmittance, ior, m, wox, woy, woz, u3, False)


# k[m, 0] of an EXACT glass (ptrace.scene's Materials, whose glass reads no k otherwise): 0 for
# a smooth dielectric boundary, THIN_GLASS for a thin slab of that glass (Mitsuba's
# thindielectric, _thin_glass)
THIN_GLASS = -1.0    # (no k of a conductor: those are >= 0)


@njit(cache=True, _nrt=False, inline="always")
def _thin_glass(ar, ag, ab, transmittance, ior, m, wox, woy, woz, u3):
    """A thin slab of glass, as Mitsuba's thindielectric: the slab's reflectance
    R' = R + T^2 R / (1 - R^2) = 2 R / (1 + R) (R the exact Fresnel reflectance of one face at
    |cos theta_o|, light bouncing between the two faces), reflected with probability R' (weight
    the albedo), else passed straight through, -wo, with the transmittance: no refraction."""
    if woz == 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    cos_o = abs(woz)
    reflect = fresnel_dielectric(cos_o, ior[m])
    reflect *= 2.0 / (1.0 + reflect)
    if u3 <= reflect:
        s = reflect / cos_o
        return -wox, -woy, woz, ar * s, ag * s, ab * s, reflect
    s = (1.0 - reflect) / cos_o
    return -wox, -woy, -woz, transmittance[m, 0] * s, transmittance[m, 1] * s, \
        transmittance[m, 2] * s, 1.0 - reflect


@njit(cache=True, _nrt=False, forceinline=True)
def dielectric_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m,
                      wox, woy, woz, u1, u2, u3):
    """glass_sample with the exact Fresnel reflectance (dielectric_reflectance) in place of
    Schlick's: Mitsuba's smooth dielectric; with k[m, 0] == THIN_GLASS, a thin slab of it
    (_thin_glass: Mitsuba's thindielectric). The glass kernel of a scene whose glass is EXACT
    (ptrace.scene) calls it."""
    if k[m, 0] == THIN_GLASS:
        return _thin_glass(ar, ag, ab, transmittance, ior, m, wox, woy, woz, u3)
    return _smooth_glass(ar, ag, ab, transmittance, ior, m, wox, woy, woz, u3, True)


@njit(cache=True, _nrt=False, forceinline=True)
def refraction_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wox,
                      woy, woz, u1, u2, u3):
    """Refraction alone (none past total internal reflection)."""
    if woz == 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    cos_o, sin2_t, cos_t, tx, ty, tz, radiance_scale = _refracted(ior[m], wox, woy, woz)
    if sin2_t >= 1.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    s = radiance_scale / cos_t
    return tx, ty, tz, transmittance[m, 0] * s, transmittance[m, 1] * s, \
        transmittance[m, 2] * s, 1.0


# -- plastic: Mitsuba's smooth plastic, a smooth dielectric coat over a diffuse base -------------
# Material m's eta row holds (eta, fdr_int, specular weight) and k[m, 0] its `nonlinear`
# (ptrace.scene.Materials; ptrace.io.mitsuba_materials computes them). Light reaching the base
# passes the coat twice, (1 - F(cos_i)) (1 - F(cos_o)) / eta^2, and the light the coat
# reflects back down, a fraction fdr_int of what leaves the base, scatters again: the base's
# albedo d becomes d / (1 - fdr_int), or with `nonlinear` d / (1 - d fdr_int) (the series of
# bounces between base and coat, each coloured by d). The coat's mirror lobe is delta and
# is sampled with probability F(cos_o) w / (F(cos_o) w + (1 - F(cos_o))(1 - w)), w the
# specular weight (the mean specular reflectance over its sum with the mean diffuse one).

@njit(cache=True, _nrt=False, inline="always")
def fresnel_dielectric(cos_i, eta):
    """The exact unpolarised reflectance of a smooth boundary met at cos_i > 0 from the side
    whose index is 1 / eta times the other's; 1 past total internal reflection."""
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0
    return dielectric_reflectance(cos_i, math.sqrt(1.0 - sin2_t), eta)


@njit(cache=True, _nrt=False, inline="always")
def _plastic_diffuse_probability(eta, m, fresnel_o):
    """The probability that plastic m samples its diffuse lobe, Fresnel reflectance fresnel_o
    at wo."""
    weight = eta[m, 2]
    specular = fresnel_o * weight
    diffuse = (1.0 - fresnel_o) * (1.0 - weight)
    if not specular + diffuse > 0.0:
        return 0.5
    return diffuse / (specular + diffuse)


@njit(cache=True, _nrt=False, inline="always")
def _plastic_base(d, fdr, nonlinear):
    """The base's albedo d with the coat's internal reflections (the header above)."""
    return d / (1.0 - (d * fdr if nonlinear else fdr))


@njit(cache=True, _nrt=False, forceinline=True)
def _plastic_f(ar, ag, ab, eta, k, m, fresnel_o, woz, wiz):
    """The diffuse lobe's f (the mirror lobe is delta), fresnel_o the coat's reflectance at wo."""
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0, 0.0, 0.0
    e, fdr, nonlinear = eta[m, 0], eta[m, 1], k[m, 0] != 0.0
    scale = (1.0 - fresnel_o) * (1.0 - fresnel_dielectric(wiz, e)) / (e * e) * INV_PI
    return (_plastic_base(ar, fdr, nonlinear) * scale, _plastic_base(ag, fdr, nonlinear) * scale,
            _plastic_base(ab, fdr, nonlinear) * scale)


@njit(cache=True, _nrt=False, forceinline=True)
def plastic_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wox,
                   woy, woz, u1, u2, u3):
    """The coat's mirror reflection with its probability (its pdf negated: a delta lobe of a
    MIXED kind), else the base's cosine-weighted lobe."""
    if woz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    fresnel_o = fresnel_dielectric(woz, eta[m, 0])
    diffuse = _plastic_diffuse_probability(eta, m, fresnel_o)
    if u3 < 1.0 - diffuse:
        s = fresnel_o / woz
        return -wox, -woy, woz, specular[m, 0] * s, specular[m, 1] * s, specular[m, 2] * s, \
            -(1.0 - diffuse)
    x, y, z = cosine_hemisphere(u1, u2)
    if z <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    fr, fg, fb = _plastic_f(ar, ag, ab, eta, k, m, fresnel_o, woz, z)
    return x, y, z, fr, fg, fb, diffuse * z * INV_PI


@njit(cache=True, _nrt=False, forceinline=True)
def plastic_eval(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz):
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0, 0.0, 0.0
    return _plastic_f(ar, ag, ab, eta, k, m, fresnel_dielectric(woz, eta[m, 0]), woz, wiz)


@njit(cache=True, _nrt=False, forceinline=True)
def plastic_pdf(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy,
                wiz):
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0
    fresnel_o = fresnel_dielectric(woz, eta[m, 0])
    return _plastic_diffuse_probability(eta, m, fresnel_o) * wiz * INV_PI


# -- roughplastic: Mitsuba's, a microfacet dielectric coat over a diffuse base -----------------
# As plastic, with the coat rough: its lobe is Beckmann's or GGX's (k[m, 1]: 0 or 1) of alpha,
# with Smith's separable shadowing (for Beckmann, Walter et al.'s rational G1, as Mitsuba), and
# the base's light passes it with the coat's transmittance t(cos) from outside (a table of TABLE
# values in specular[m, 3:], linear in cos; ptrace.io.mitsuba_materials computes it at load
# time), d / (1 - eta[m, 1] [d]) t(cos_i) t(cos_o) / (pi eta^2). The lobes are chosen with
# probability (1 - t(cos_o)) w against t(cos_o)(1 - w), the coat's half vectors drawn from
# D(h) cos theta_h.

TABLE = 64      # the coat's transmittance table: cos theta = j / (TABLE - 1), j = 0 .. TABLE-1


@njit(cache=True, _nrt=False, inline="always")
def _table(specular, m, cos):
    """Material m's coat transmittance at cos, linear between the table's values."""
    x = min(max(cos, 0.0), 1.0) * (TABLE - 1)
    j = min(int(x), TABLE - 2)
    t = x - j
    return specular[m, 3 + j] * (1.0 - t) + specular[m, 4 + j] * t


@njit(cache=True, _nrt=False, inline="always")
def _rough_d(ggx, alpha, cos_h):
    """Beckmann's (ggx False) or GGX's distribution of normals at cos theta_h."""
    if cos_h <= 0.0:
        return 0.0
    if not ggx:
        return beckmann_d(alpha, cos_h)
    cos2 = cos_h * cos_h
    a2 = alpha * alpha
    denominator = cos2 * (a2 - 1.0) + 1.0
    return a2 / (math.pi * denominator * denominator)


@njit(cache=True, _nrt=False, inline="always")
def _rough_g1(ggx, alpha, vx, vy, vz, hx, hy, hz):
    """Smith's G1 of direction v and half vector h (0 where v sees h's back): for Beckmann
    Walter et al.'s (2007) rational approximation, for GGX the exact form."""
    if (vx * hx + vy * hy + vz * hz) * vz <= 0.0:
        return 0.0
    xy2 = alpha * alpha * (vx * vx + vy * vy)
    if xy2 == 0.0:
        return 1.0
    tan2 = xy2 / (vz * vz)
    if ggx:
        return 2.0 / (1.0 + math.sqrt(1.0 + tan2))
    a = 1.0 / math.sqrt(tan2)
    if a >= 1.6:
        return 1.0
    return (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)


@njit(cache=True, _nrt=False, inline="always")
def _rough_plastic_diffuse_probability(eta, specular, m, woz):
    t = _table(specular, m, woz)
    weight = eta[m, 2]
    coat = (1.0 - t) * weight
    base = t * (1.0 - weight)
    if not coat + base > 0.0:
        return 0.5
    return base / (coat + base)


@njit(cache=True, _nrt=False, forceinline=True)
def _rough_plastic_f(ar, ag, ab, alpha, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz):
    hx, hy, hz, _, defined = half_vector(wox, woy, woz, wix, wiy, wiz)
    if not defined:
        return 0.0, 0.0, 0.0
    ggx = k[m, 1] != 0.0
    e = eta[m, 0]
    coat = _rough_d(ggx, alpha, hz) * _rough_g1(ggx, alpha, wox, woy, woz, hx, hy, hz) * \
        _rough_g1(ggx, alpha, wix, wiy, wiz, hx, hy, hz) * \
        fresnel_dielectric(wox * hx + woy * hy + woz * hz, e) / (4.0 * woz * wiz)
    fdr, nonlinear = eta[m, 1], k[m, 0] != 0.0
    base = _table(specular, m, woz) * _table(specular, m, wiz) / (e * e) * INV_PI
    return (coat * specular[m, 0] + _plastic_base(ar, fdr, nonlinear) * base,
            coat * specular[m, 1] + _plastic_base(ag, fdr, nonlinear) * base,
            coat * specular[m, 2] + _plastic_base(ab, fdr, nonlinear) * base)


@njit(cache=True, _nrt=False, forceinline=True)
def _rough_plastic_pdf(alpha, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz):
    hx, hy, hz, _, defined = half_vector(wox, woy, woz, wix, wiy, wiz)
    if not defined:
        return 0.0
    diffuse = _rough_plastic_diffuse_probability(eta, specular, m, woz)
    coat = _rough_d(k[m, 1] != 0.0, alpha, hz) * hz / (4.0 * (wox * hx + woy * hy + woz * hz))
    return (1.0 - diffuse) * coat + diffuse * wiz * INV_PI


@njit(cache=True, _nrt=False, forceinline=True)
def rough_plastic_sample(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m,
                         wox, woy, woz, u1, u2, u3):
    if woz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    if u3 < 1.0 - _rough_plastic_diffuse_probability(eta, specular, m, woz):   # the coat's
        if k[m, 1] != 0.0:    # GGX: tan^2 theta_h = alpha^2 u1 / (1 - u1)
            tan2 = alpha * alpha * u1 / max(1.0 - u1, 1e-300)
            cos_h = 1.0 / math.sqrt(1.0 + tan2)
            sin_h = math.sqrt(max(0.0, 1.0 - cos_h * cos_h))
            c, s = sincos_2pi(u2)
            hx, hy, hz = sin_h * c, sin_h * s, cos_h
        else:
            hx, hy, hz = beckmann_half_vector(alpha, u1, u2)
        d = wox * hx + woy * hy + woz * hz
        wix, wiy, wiz = 2.0 * d * hx - wox, 2.0 * d * hy - woy, 2.0 * d * hz - woz
    else:                 # the base's
        wix, wiy, wiz = cosine_hemisphere(u1, u2)
    if wiz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0
    fr, fg, fb = _rough_plastic_f(ar, ag, ab, alpha, eta, k, specular, m, wox, woy, woz, wix,
                                  wiy, wiz)
    return wix, wiy, wiz, fr, fg, fb, _rough_plastic_pdf(alpha, eta, k, specular, m, wox, woy,
                                                         woz, wix, wiy, wiz)


@njit(cache=True, _nrt=False, forceinline=True)
def rough_plastic_eval(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix,
                       wiy, wiz):
    return _rough_plastic_f(ar, ag, ab, alpha, eta, k, specular, m, wox, woy, woz, wix, wiy,
                            wiz)


@njit(cache=True, _nrt=False, forceinline=True)
def rough_plastic_pdf(ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix,
                      wiy, wiz):
    return _rough_plastic_pdf(alpha, eta, k, specular, m, wox, woy, woz, wix, wiy, wiz)


# each kind's (sample, eval, pdf)
BSDFS = {
    DIFFUSE: (diffuse_sample, diffuse_eval, diffuse_pdf),
    MIRROR: (mirror_sample, delta_eval, delta_pdf),
    GLASS: (glass_sample, delta_eval, delta_pdf),
    REFRACTION: (refraction_sample, delta_eval, delta_pdf),
    MICROFACET: (microfacet_sample, microfacet_eval, microfacet_pdf),
    GLOSSY: (glossy_sample, glossy_eval, glossy_pdf),
    GLTF_PBR: (pbr_sample, pbr_eval, pbr_pdf),
    PLASTIC: (plastic_sample, plastic_eval, plastic_pdf),
    ROUGH_PLASTIC: (rough_plastic_sample, rough_plastic_eval, rough_plastic_pdf),
}
# the kinds with a delta lobe beside a non-delta one: their sample returns a delta lobe's
# branch probability negated, so that the caller knows the bounce was delta
MIXED = (PLASTIC,)
# the glass of a scene whose glass reflects EXACT (ptrace.scene), in place of BSDFS[GLASS]
EXACT_GLASS = (dielectric_sample, delta_eval, delta_pdf)


# -- any kind, by its code (for tests and studies: a kernel calls its own kind's from BSDFS) ------

def bsdf_eval(kind, ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy,
              wiz):
    """f(wo, wi) for non-delta BSDFs; 0 for delta BSDFs and emitters. (ar, ag, ab), alpha and
    metallic are material m's albedo, roughness and metallic at the shading point."""
    if kind not in BSDFS:
        return 0.0, 0.0, 0.0
    return BSDFS[kind][1](ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix,
                          wiy, wiz)


def bsdf_pdf(kind, ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix, wiy,
             wiz):
    """Solid-angle pdf of sample() producing wi (non-delta BSDFs); 0 otherwise. The albedo
    and metallic matter only to GLTF_PBR, whose choice of lobe depends on them."""
    if kind not in BSDFS:
        return 0.0
    return BSDFS[kind][2](ar, ag, ab, alpha, metallic, eta, k, specular, m, wox, woy, woz, wix,
                          wiy, wiz)


def bsdf_sample(kind, ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wox,
                woy, woz, u1, u2, u3):
    """Sample wi given wo: (wix, wiy, wiz, fr, fg, fb, pdf), as each kind's sample function
    (above); pdf 0 means no sample, and emitters do not scatter."""
    if kind not in BSDFS:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0   # emission and anything else: no scattering
    return BSDFS[kind][0](ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m,
                          wox, woy, woz, u1, u2, u3)
