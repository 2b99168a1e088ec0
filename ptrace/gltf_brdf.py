"""The glTF 2.0 metallic-roughness BRDF (the glTF specification, Appendix B), as numba functions.

Same conventions as ptrace.bsdf: a local shading frame with the normal +z; wo and wi are unit
vectors pointing away from the surface; f excludes the cosine term; pdf is per unit solid angle.
The BRDF is one-sided: only wo.z > 0 and wi.z > 0 give a non-zero f or pdf (the caller flips the
frame for back faces, as for ptrace's other opaque kinds).

The model, as the specification writes it, with h the half vector of wo and wi:
    material        = mix(dielectric_brdf, metal_brdf, metallic)        (linear in metallic)
    metal_brdf      = specular * (base + (1 - base) (1 - |wo.h|)^5)     (conductor_fresnel)
    dielectric_brdf = mix(base / pi, specular, 0.04 + 0.96 (1 - |wo.h|)^5)
                                                        (fresnel_mix, ior 1.5, so f0 = 0.04)
    specular        = D * Vis, alpha = roughness^2
    D   = alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2)                  (Trowbridge-Reitz, GGX)
    Vis = 1 / (2 (|n.wo| sqrt(alpha^2 + (1 - alpha^2) (n.wi)^2)
                  + |n.wi| sqrt(alpha^2 + (1 - alpha^2) (n.wo)^2)))     (height-correlated Smith)
The specification itself says (its "Coupling Diffuse and Specular Reflection") that fresnel_mix
is not energy conserving: the diffuse part loses only 1 - F(wo.h), evaluated at the half vector,
so near grazing a white dielectric's directional albedo exceeds 1. It is kept as written because
the point of this module is the BRDF a glTF file means; the metal part (and any metallic = 1
material) conserves energy, and loses what single-scattering GGX loses at high roughness.

Sampling is a one-sample mixture of the specular lobe, sampled by the GGX distribution of visible
normals (E. Heitz, "Sampling the GGX Distribution of Visible Normals", JCGT 7(4), 2018), and a
cosine-weighted hemisphere for the diffuse lobe. gltf_sample returns f (gltf_eval's value, not a
weight) and the mixture's pdf (both lobes' densities, weighted by their selection probabilities),
so the path weight is f cos / pdf and multiple importance sampling with light samples uses the
same density as gltf_pdf.
"""
import math

from numba import njit

INV_PI = 1.0 / math.pi
DIELECTRIC_F0 = 0.04     # ((1 - ior) / (1 + ior))^2 for the specification's fixed ior = 1.5

# alpha = roughness^2 is clamped from below to ALPHA_MIN. At alpha = 0 (roughness 0: a perfect
# mirror in glTF) D is a delta: the formula gives 0/0 at n.h = 1, and the sampled pdf would be
# infinite. At 1e-4 the lobe is about 1e-4 radians wide (a mirror for any practical purpose),
# D peaks at 1 / (pi alpha^2) ~ 3.2e7 and the pdf at about 8e6 at normal incidence: finite, and
# well within float64. D's denominator is computed as (h.x^2 + h.y^2) + alpha^2 h.z^2 (equal to
# the specification's (n.h)^2 (alpha^2 - 1) + 1 for unit h), which has no cancellation, so it
# keeps full relative precision near n.h = 1 at any alpha >= ALPHA_MIN.
ALPHA_MIN = 1e-4

NO_SAMPLE = (0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0)


@njit(cache=True, inline="always")
def ggx_d(alpha, hx, hy, hz):
    """Trowbridge-Reitz (GGX) normal distribution D(h) for a unit h with h.z > 0, else 0."""
    if hz <= 0.0:
        return 0.0
    a2 = alpha * alpha
    t = hx * hx + hy * hy + a2 * hz * hz
    return a2 / (math.pi * t * t)


@njit(cache=True, inline="always")
def ggx_lambda_root(alpha, cos_w):
    """sqrt(alpha^2 + (1 - alpha^2) cos^2): the term of the Smith masking function of GGX."""
    a2 = alpha * alpha
    return math.sqrt(a2 + (1.0 - a2) * cos_w * cos_w)


@njit(cache=True, inline="always")
def ggx_vis(alpha, cos_o, cos_i):
    """The specification's visibility G2 / (4 |n.wo| |n.wi|), with G2 the height-correlated
    Smith masking-shadowing of GGX. Symmetric in cos_o and cos_i."""
    return 0.5 / (cos_o * ggx_lambda_root(alpha, cos_i) + cos_i * ggx_lambda_root(alpha, cos_o))


@njit(cache=True, inline="always")
def ggx_g1_over_cos(alpha, cos_w):
    """Smith's G1(w) / cos(w) for GGX: 2 / (cos + sqrt(alpha^2 + (1 - alpha^2) cos^2)), finite
    as cos -> 0 (so a grazing wo keeps a finite pdf)."""
    return 2.0 / (cos_w + ggx_lambda_root(alpha, cos_w))


@njit(cache=True, inline="always")
def fresnel_weight(cos):
    """Schlick's (1 - cos)^5, the weight of (1 - f0) in F = f0 + (1 - f0) (1 - cos)^5."""
    c = 1.0 - min(1.0, max(0.0, cos))
    c2 = c * c
    return c2 * c2 * c


@njit(cache=True, inline="always")
def half_vector(wox, woy, woz, wix, wiy, wiz):
    """The unit half vector h of wo and wi, wo.h (= wi.h = |wo + wi| / 2: symmetric in wo and
    wi in floating point too), and whether the pair reflects: both above the surface (z > 0;
    then wo + wi has z > 0 and is never zero)."""
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, False
    hx, hy, hz = wox + wix, woy + wiy, woz + wiz
    norm = math.sqrt(hx * hx + hy * hy + hz * hz)
    return hx / norm, hy / norm, hz / norm, 0.5 * norm, True


@njit(cache=True, _nrt=False, forceinline=True)
def gltf_eval(br, bg, bb, metallic, alpha, wox, woy, woz, wix, wiy, wiz):
    """f(wo, wi) of the glTF metallic-roughness material: base colour (br, bg, bb), linear;
    metallic in [0, 1], blended linearly; alpha = roughness^2 (clamped to ALPHA_MIN).
    Zero unless wo.z > 0 and wi.z > 0. Reciprocal: f(wo, wi) = f(wi, wo)."""
    hx, hy, hz, cos_d, reflects = half_vector(wox, woy, woz, wix, wiy, wiz)
    if not reflects:
        return 0.0, 0.0, 0.0
    a = max(alpha, ALPHA_MIN)
    specular = ggx_d(a, hx, hy, hz) * ggx_vis(a, woz, wiz)
    w = fresnel_weight(cos_d)
    f_dielectric = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * w
    diffuse = (1.0 - metallic) * (1.0 - f_dielectric) * INV_PI
    dielectric_specular = (1.0 - metallic) * f_dielectric * specular
    metal = metallic * specular
    return (diffuse * br + dielectric_specular + metal * (br + (1.0 - br) * w),
            diffuse * bg + dielectric_specular + metal * (bg + (1.0 - bg) * w),
            diffuse * bb + dielectric_specular + metal * (bb + (1.0 - bb) * w))


@njit(cache=True, inline="always")
def specular_probability(metallic, br, bg, bb, woz):
    """The probability of sampling the specular lobe: its estimated share s / (s + d) of the
    reflected energy, from the Fresnel term at wo (the half vector is not known before
    sampling). s is the mean over RGB of Schlick's F(wo.z) for the blended f0 = (1 - metallic)
    0.04 + metallic * base; d = (1 - metallic) (1 - F_dielectric(wo.z)) mean(base), the diffuse
    lobe's albedo under that Fresnel. 1 when both are 0 (a black metal seen head-on: nothing
    is reflected except what the specular lobe carries)."""
    w = fresnel_weight(woz)
    base = (br + bg + bb) / 3.0
    f0 = (1.0 - metallic) * DIELECTRIC_F0 + metallic * base
    s = f0 + (1.0 - f0) * w
    d = (1.0 - metallic) * (1.0 - (DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * w)) * base
    if s + d <= 0.0:
        return 1.0
    return s / (s + d)


@njit(cache=True, inline="always")
def _specular_pdf(a, wox, woy, woz, wix, wiy, wiz):
    """Density of wi when h is drawn from the visible normals of wo and wo is reflected about
    it: D_wo(h) / (4 wo.h) = G1(wo) D(h) / (4 wo.z). Zero unless both are above the surface."""
    hx, hy, hz, _, reflects = half_vector(wox, woy, woz, wix, wiy, wiz)
    if not reflects:
        return 0.0
    return 0.25 * ggx_g1_over_cos(a, woz) * ggx_d(a, hx, hy, hz)


@njit(cache=True, _nrt=False, forceinline=True)
def gltf_pdf(metallic, alpha, br, bg, bb, wox, woy, woz, wix, wiy, wiz):
    """The solid-angle density of gltf_sample's wi given wo (the mixture's: both lobes,
    weighted by specular_probability). Zero unless wo.z > 0 and wi.z > 0; finite for any alpha
    (clamped to ALPHA_MIN) and any wo.z > 0."""
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0
    a = max(alpha, ALPHA_MIN)
    p = specular_probability(metallic, br, bg, bb, woz)
    return p * _specular_pdf(a, wox, woy, woz, wix, wiy, wiz) + (1.0 - p) * wiz * INV_PI


@njit(cache=True, inline="always")
def ggx_visible_normal(a, wox, woy, woz, u1, u2):
    """A microfacet normal drawn from GGX's distribution of normals visible from wo (wo.z > 0),
    D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z: Heitz (2018), listing 1, isotropic alpha."""
    # wo stretched to the hemisphere configuration (alpha = 1)
    vx, vy, vz = a * wox, a * woy, woz
    norm = math.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx / norm, vy / norm, vz / norm
    # an orthonormal basis (t1, t2, v); t1 = (1, 0, 0) when v is the normal
    lensq = vx * vx + vy * vy
    if lensq > 0.0:
        inv = 1.0 / math.sqrt(lensq)
        t1x, t1y, t1z = -vy * inv, vx * inv, 0.0
    else:
        t1x, t1y, t1z = 1.0, 0.0, 0.0
    t2x, t2y, t2z = vy * t1z - vz * t1y, vz * t1x - vx * t1z, vx * t1y - vy * t1x
    # a point on the projected disk, its upper half squeezed by the visible hemisphere's shadow
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    p1 = r * math.cos(phi)
    p2 = r * math.sin(phi)
    s = 0.5 * (1.0 + vz)
    p2 = (1.0 - s) * math.sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2
    p3 = math.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    nx = p1 * t1x + p2 * t2x + p3 * vx
    ny = p1 * t1y + p2 * t2y + p3 * vy
    nz = p1 * t1z + p2 * t2z + p3 * vz
    # back to the ellipsoid configuration
    hx, hy, hz = a * nx, a * ny, max(0.0, nz)
    norm = math.sqrt(hx * hx + hy * hy + hz * hz)
    return hx / norm, hy / norm, hz / norm


@njit(cache=True, _nrt=False, forceinline=True)
def gltf_sample(br, bg, bb, metallic, alpha, wox, woy, woz, u1, u2, u3):
    """Sample wi given wo with three uniform numbers in [0, 1). Returns (wix, wiy, wiz, fr, fg,
    fb, pdf): f = gltf_eval(wo, wi) and pdf = gltf_pdf(wo, wi); pdf 0 means no sample (wo
    below the surface, or a specular sample reflected below it, which the pdf accounts for as
    missing mass). u3 < specular_probability picks the specular lobe (a visible normal from
    u1, u2, wo reflected about it), else the diffuse lobe (cosine-weighted from u1, u2)."""
    if woz <= 0.0:
        return NO_SAMPLE
    a = max(alpha, ALPHA_MIN)
    if u3 < specular_probability(metallic, br, bg, bb, woz):
        hx, hy, hz = ggx_visible_normal(a, wox, woy, woz, u1, u2)
        d = wox * hx + woy * hy + woz * hz
        wix, wiy, wiz = 2.0 * d * hx - wox, 2.0 * d * hy - woy, 2.0 * d * hz - woz
    else:
        r = math.sqrt(u1)
        phi = 2.0 * math.pi * u2
        wix, wiy, wiz = r * math.cos(phi), r * math.sin(phi), math.sqrt(max(0.0, 1.0 - u1))
    if wiz <= 0.0:
        return NO_SAMPLE
    fr, fg, fb = gltf_eval(br, bg, bb, metallic, a, wox, woy, woz, wix, wiy, wiz)
    pdf = gltf_pdf(metallic, a, br, bg, bb, wox, woy, woz, wix, wiy, wiz)
    if not pdf > 0.0:
        return NO_SAMPLE
    return wix, wiy, wiz, fr, fg, fb, pdf
