"""BSDF and light samplers against their own pdfs (chi-square), and eval/pdf consistency."""
import functools
import math

import numpy as np
import pytest
from numba import njit
from scipy import stats

from ptrace.bsdf import BSDFS, bsdf_eval, bsdf_pdf, bsdf_sample
from ptrace.environment import environment_arrays
from ptrace.integrator import LightArrays
from ptrace.io.mitsuba_materials import rough_coat_tables
from ptrace.lights import sample_light
from ptrace.scene import (
    AREA,
    COURSE,
    DIFFUSE,
    GLASS,
    GLOSSY,
    GLTF_PBR,
    MICROFACET,
    MIRROR,
    PLASTIC,
    REFRACTION,
    ROUGH_PLASTIC,
    Materials,
)

MATERIALS = Materials.from_records([
    dict(kind=DIFFUSE, albedo=(0.8, 0.5, 0.2)),
    dict(kind=MICROFACET, alpha=0.25, eta=(0.059193, 0.059881, 0.047366),
         k=(4.1283, 3.5892, 2.8132)),
    dict(kind=MICROFACET, alpha=0.5, eta=(1.3352, 1.0109, 0.68955), k=(7.3398, 6.6157, 5.6471)),
    dict(kind=MIRROR, albedo=(1.0, 0.8, 0.4)),
    dict(kind=GLASS, albedo=(1, 1, 1), transmittance=(1, 1, 1), ior=1.45),
    dict(kind=REFRACTION, transmittance=(1, 1, 1), ior=1.45),
    dict(kind=GLOSSY, albedo=(0.8, 0.3, 0.1), specular=(0.04, 0.04, 0.04), alpha=0.2),
    dict(kind=GLOSSY, albedo=(1.0, 1.0, 1.0), specular=(1.0, 1.0, 1.0), alpha=0.6),
    dict(kind=GLOSSY, albedo=(1.0, 1.0, 1.0), specular=(0.0, 0.0, 0.0), alpha=0.05),
    # glTF's material through the dispatch (ptrace.gltf_brdf has its own, finer tests)
    dict(kind=GLTF_PBR, albedo=(1.0, 1.0, 1.0), metallic=1.0, alpha=0.49),
    dict(kind=GLTF_PBR, albedo=(0.8, 0.5, 0.2), metallic=0.4, alpha=0.25),
    # Mitsuba's smooth plastic (11-13): eta row (eta, fdr_int, specular weight), k[0] nonlinear
    dict(kind=PLASTIC, albedo=(0.2, 0.3, 0.6), specular=(1.0, 1.0, 1.0), ior=1.49,
         eta=(1.49, 0.5904, 1.0 / 1.3667), k=(0.0, 0.0, 0.0)),
    dict(kind=PLASTIC, albedo=(0.9, 0.5, 0.1), specular=(0.5, 0.6, 0.7), ior=1.9,
         eta=(1.9, 0.7216, 0.6 / 1.1), k=(1.0, 0.0, 0.0)),
    dict(kind=PLASTIC, albedo=(1.0, 1.0, 1.0), specular=(1.0, 1.0, 1.0), ior=1.5,
         eta=(1.5, 0.5956, 0.5), k=(0.0, 0.0, 0.0)),
    # Mitsuba's roughplastic (14: Beckmann, 15: GGX), its tables after the specular colour
    dict(kind=ROUGH_PLASTIC, albedo=(0.2, 0.3, 0.6), specular=(1.0, 1.0, 1.0), ior=1.49,
         alpha=0.2, eta=(1.49, 0.5552, 1.0 / 1.3667), k=(0.0, 0.0, 0.0),
         table=rough_coat_tables(0.2, 1.49, False)[0]),
    dict(kind=ROUGH_PLASTIC, albedo=(0.9, 0.5, 0.1), specular=(0.5, 0.6, 0.7), ior=1.6,
         alpha=0.4, eta=(1.6, 0.45, 0.6 / 1.1), k=(1.0, 1.0, 0.0),
         table=rough_coat_tables(0.4, 1.6, True)[0]),
])
M = MATERIALS


def sample(m, wo, u):
    return bsdf_sample(int(M.kind[m]), *M.albedo[m], M.transmittance, M.ior, M.alpha[m],
                       M.metallic[m], M.eta, M.k, M.specular, m, wo[0], wo[1], wo[2], u[0], u[1],
                       u[2])


def pdf_of(m, wo, x, y, z):
    return bsdf_pdf(int(M.kind[m]), *M.albedo[m], M.alpha[m], M.metallic[m], M.eta, M.k,
                    M.specular, m, *wo, x, y, z)


def eval_of(m, wo, x, y, z):
    return bsdf_eval(int(M.kind[m]), *M.albedo[m], M.alpha[m], M.metallic[m], M.eta, M.k,
                     M.specular, m, *wo, x, y, z)


@functools.lru_cache(maxsize=None)
def batched(kind):
    """Kind `kind`'s (sample, eval and pdf) of ptrace.bsdf.BSDFS, each called in a compiled loop
    over many directions: (samples, pdfs_and_evals)."""
    SAMPLE, EVAL, PDF = BSDFS[kind]

    @njit(cache=True)
    def samples_(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular, m, wo, u):
        out = np.empty((u.shape[0], 7))
        for i in range(u.shape[0]):
            out[i, :] = SAMPLE(ar, ag, ab, transmittance, ior, alpha, metallic, eta, k, specular,
                               m, wo[0], wo[1], wo[2], u[i, 0], u[i, 1], u[i, 2])
        return out

    @njit(cache=True)
    def pdfs_and_evals_(ar, ag, ab, alpha, metallic, eta, k, specular, m, wo, wi):
        out = np.empty((wi.shape[0], 4))
        for i in range(wi.shape[0]):
            out[i, 0] = PDF(ar, ag, ab, alpha, metallic, eta, k, specular, m, wo[0], wo[1],
                            wo[2], wi[i, 0], wi[i, 1], wi[i, 2])
            out[i, 1:] = EVAL(ar, ag, ab, alpha, metallic, eta, k, specular, m, wo[0], wo[1],
                              wo[2], wi[i, 0], wi[i, 1], wi[i, 2])
        return out
    return samples_, pdfs_and_evals_


def samples(m, wo, u):
    """sample(m, wo, u) for each row of u, compiled in one loop: rows (x, y, z, fr, fg, fb,
    pdf)."""
    return batched(int(M.kind[m]))[0](*M.albedo[m], M.transmittance, M.ior, M.alpha[m],
                                      M.metallic[m], M.eta, M.k, M.specular, m,
                                      np.asarray(wo, np.float64),
                                      np.ascontiguousarray(u, np.float64))


def pdfs_and_evals(m, wo, wi):
    """(pdf_of, *eval_of) at each row of wi, compiled in one loop: rows (pdf, fr, fg, fb)."""
    return batched(int(M.kind[m]))[1](*M.albedo[m], M.alpha[m], M.metallic[m], M.eta, M.k,
                                      M.specular, m, np.asarray(wo, np.float64),
                                      np.ascontiguousarray(wi, np.float64))


def direction(theta_degrees, phi=0.3):
    t = math.radians(theta_degrees)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


def chi_square_p(m, wo, n=60000, n_cos=10, n_phi=16, seed=0):
    """p-value of the sampled directions' histogram over (cos theta, phi) against the pdf."""
    rng = np.random.default_rng(seed)
    drawn = samples(m, wo, rng.random((n, 3)))
    x, y, z, pdf = drawn[:, 0], drawn[:, 1], drawn[:, 2], drawn[:, 6]
    # f and pdf returned by sample() agree with eval() and pdf() (checked on 2000 samples)
    first = drawn[:2001][(drawn[:2001, 6] > 0) & (drawn[:2001, 2] > 0)]
    again = pdfs_and_evals(m, wo, first[:, :3])
    np.testing.assert_allclose(first[:, 6], again[:, 0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(first[:, 3:6], again[:, 1:], rtol=1e-9, atol=1e-12)
    kept = (pdf > 0) & (z > 0)
    rejected = int(n - kept.sum())
    i = np.minimum((z[kept] * n_cos).astype(int), n_cos - 1)
    j = np.minimum((np.arctan2(y[kept], x[kept]) % (2 * math.pi) / (2 * math.pi) * n_phi)
                   .astype(int), n_phi - 1)
    counts = np.zeros((n_cos, n_phi))
    np.add.at(counts, (i, j), 1)
    # expected probability per bin: midpoint rule on a fine grid in (cos theta, phi)
    sub = 12
    zs = (np.arange(n_cos)[:, None] + (np.arange(sub) + 0.5) / sub).ravel() / n_cos
    phis = (np.arange(n_phi)[:, None] + (np.arange(sub) + 0.5) / sub).ravel() / n_phi * 2 * math.pi
    zz, pp = np.meshgrid(zs, phis, indexing="ij")
    rr = np.sqrt(1 - zz * zz)
    grid = np.stack([rr * np.cos(pp), rr * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    density = pdfs_and_evals(m, wo, grid)[:, 0].reshape(n_cos, sub, n_phi, sub)
    expected = density.sum(axis=(1, 3)) / sub / sub * (1.0 / n_cos) * (2 * math.pi / n_phi)
    observed = np.append(counts.ravel(), rejected)
    expected = np.append(expected.ravel(), max(0.0, 1 - expected.sum())) * n
    small = expected < 5   # pool sparse bins
    if expected[small].sum() > 0:
        observed = np.append(observed[~small], observed[small].sum())
        expected = np.append(expected[~small], expected[small].sum())
    else:   # samples where the pdf says there can be none fail the test outright
        assert observed[small].sum() == 0
        observed, expected = observed[~small], expected[~small]
    expected *= observed.sum() / expected.sum()
    return stats.chisquare(observed, expected).pvalue


@pytest.mark.parametrize("m, theta", [(0, 10), (0, 70), (1, 20), (1, 60), (2, 45), (6, 15),
                                      (6, 60), (7, 40), (9, 30), (10, 60), (11, 5), (11, 75),
                                      (12, 40), (14, 20), (14, 70), (15, 45)])
def test_sampler_matches_its_pdf(m, theta):
    p = chi_square_p(m, direction(theta))
    print(f"material {m} theta {theta}: p = {p:.3g}")
    assert p > 1e-3


def test_diffuse_pdf_integrates_to_one_and_eval_is_albedo_over_pi():
    rng = np.random.default_rng(1)
    wi = rng.normal(size=(20000, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wi[:, 2] = np.abs(wi[:, 2])
    wo = direction(30)
    pdfs = [pdf_of(0, wo, *w) for w in wi]
    assert np.mean(pdfs) * 2 * math.pi == pytest.approx(1.0, rel=0.02)
    assert eval_of(0, wo, *wi[0]) == \
        pytest.approx(tuple(M.albedo[0] / math.pi))


@pytest.mark.parametrize("m", [1, 2, 6, 7, 8, 9, 14, 15])
def test_microfacet_sampling_carries_the_energy_eval_integrates_to(m):
    """One microfacet (or glossy) bounce's directional albedo (red): the mean of the sampled
    weights f cos / pdf equals the integral of eval's f cos over the hemisphere (a midpoint rule,
    to within 4 standard errors of the mean); and it is at most 1 (a conductor cannot reflect
    more than arrives; nor can a white base under a white or a clear coat)."""
    rng = np.random.default_rng(2)
    for theta in (0, 45, 80):
        wo = direction(theta)
        drawn = samples(m, wo, rng.random((20000, 3)))
        weights = np.divide(drawn[:, 3] * drawn[:, 2], drawn[:, 6], out=np.zeros(len(drawn)),
                            where=drawn[:, 6] > 0)
        # midpoint rule in (theta, phi), 300 x 300 cells of 0.3 and 1.2 degrees
        n_t, n_p = 300, 300
        t = (np.arange(n_t) + 0.5) / n_t * math.pi / 2
        phi = (np.arange(n_p) + 0.5) / n_p * 2 * math.pi
        tt, pp = np.meshgrid(t, phi, indexing="ij")
        z, r = np.cos(tt), np.sin(tt)
        grid = np.stack([r * np.cos(pp), r * np.sin(pp), z], axis=-1).reshape(-1, 3)
        f = pdfs_and_evals(m, wo, grid)[:, 1]
        integral = float((f * (z * r).ravel()).sum())
        integral *= (math.pi / 2 / n_t) * (2 * math.pi / n_p)
        sampled = np.mean(weights)
        se = np.std(weights) / math.sqrt(len(weights))
        print(f"m {m} theta {theta}: sampled {sampled:.4f} integral {integral:.4f} se {se:.4f}")
        assert abs(sampled - integral) < 4 * se + 1e-3 * integral
        assert se < 0.01 * integral                     # the comparison has power
        assert sampled <= 1.0


@pytest.mark.parametrize("m", [0, 6, 7, 8, 9, 10, 11, 12, 14, 15])
def test_diffuse_and_glossy_are_reciprocal(m):
    """f(wo, wi) = f(wi, wo) for random pairs of directions above the surface. (Not the course's
    microfacet: its Fresnel term takes cos theta_i, docs/course.md#bsdfs, so it is not.)"""
    rng = np.random.default_rng(4)
    for _ in range(300):
        a, b = rng.normal(size=3), rng.normal(size=3)
        a[2], b[2] = abs(a[2]), abs(b[2])
        a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
        forward = eval_of(m, a, *b)
        backward = eval_of(m, b, *a)
        assert forward == pytest.approx(backward, rel=1e-9, abs=1e-300)


def test_mirror_reflects_exactly():
    wo = direction(40, 1.1)
    x, y, z, fr, fg, fb, pdf = sample(3, wo, (0.3, 0.6, 0.9))
    np.testing.assert_allclose([x, y, z], [-wo[0], -wo[1], wo[2]])
    assert pdf == 1.0 and fr * z / pdf == pytest.approx(1.0) and fb * z == pytest.approx(0.4)


def test_glass_reflects_with_schlick_probability_and_refracts_by_snell():
    wo = direction(50)
    r0 = ((1 - 1.45) / (1 + 1.45)) ** 2
    schlick = r0 + (1 - r0) * (1 - wo[2]) ** 5
    reflected = 0
    n = 20000
    for u3 in (np.arange(n) + 0.5) / n:
        x, y, z, fr, fg, fb, pdf = sample(4, wo, (0.5, 0.5, u3))
        if z > 0:
            reflected += 1
            continue
        sin_t = math.hypot(x, y)
        assert math.sin(math.radians(50)) == pytest.approx(1.45 * sin_t, rel=1e-9)   # Snell
        # weight f |cos| / pdf is the radiance scale (1/1.45)^2 entering
        assert fr * abs(z) / pdf == pytest.approx(1 / 1.45 ** 2, rel=1e-9)
    assert reflected / n == pytest.approx(schlick, abs=1e-3)


@pytest.mark.parametrize("m", [4, 5], ids=["glass", "refraction"])
def test_leaving_the_medium_refracts_by_snell_with_the_leaving_radiance_scale(m):
    """From inside (wo below the surface, 30 degrees: under the critical angle of 43.6) the
    ray leaves at arcsin(1.45 sin 30) on the other side, and its weight f |cos| / pdf is the
    leaving radiance scale 1.45^2 (radiance compresses into the denser medium and expands out
    of it); glass reflects back inside with Schlick's probability of the inside angle."""
    inside = -direction(30)
    inside[0], inside[1] = -inside[0], -inside[1]    # incoming from outside the normal's side
    r0 = ((1 - 1.45) / (1 + 1.45)) ** 2
    schlick = r0 + (1 - r0) * (1 - abs(inside[2])) ** 5
    n = 20000
    reflected = 0
    for u3 in (np.arange(n) + 0.5) / n:
        x, y, z, fr, fg, fb, pdf = sample(m, inside, (0.5, 0.5, u3))
        assert pdf > 0
        if z < 0:
            reflected += 1
            np.testing.assert_allclose([x, y, z], [-inside[0], -inside[1], inside[2]])
            continue
        sin_t = math.hypot(x, y)
        assert sin_t == pytest.approx(1.45 * math.sin(math.radians(30)), rel=1e-9)   # Snell
        assert math.hypot(sin_t, z) == pytest.approx(1.0, rel=1e-12)
        assert x * inside[0] < 0 or inside[0] == 0      # on the far side of the normal
        assert fr * abs(z) / pdf == pytest.approx(1.45 ** 2, rel=1e-9)
    expected = schlick if M.kind[m] == GLASS else 0.0
    assert reflected / n == pytest.approx(expected, abs=1e-3)


def test_total_internal_reflection():
    inside = -direction(60)          # leaving glass at 60 degrees: past the critical angle
    inside[0], inside[1] = -inside[0], -inside[1]
    x, y, z, fr, fg, fb, pdf = sample(4, inside, (0.5, 0.5, 0.99))
    assert z < 0 and pdf == 1.0                      # reflected back inside
    assert sample(5, inside, (0.5, 0.5, 0.5))[6] == 0.0   # refraction only: nothing


def light_record(kind, radiance, position, direction, edge_x, edge_y, area, model=COURSE,
                 cos_inner=1.0, cos_outer=1.0):
    """One light as the integrator's LightArrays (the fields sample_light reads; the rest
    empty). The record type is ptrace's own: numba's cache index of sample_light keeps the
    types it was compiled for, and a type defined in a test module could not be unpickled by a
    later render."""
    empty = np.zeros(0)
    return LightArrays(np.array([kind]), radiance, position, direction, edge_x, edge_y, area,
                       np.array([model]), np.array([cos_inner]), np.array([cos_outer]),
                       np.zeros(1, np.int64), np.zeros(0, np.int64), empty, empty, False,
                       *environment_arrays(None), empty, empty)


def test_area_light_pdf_integrates_its_solid_angle():
    """E[1 / pdf] over light samples is the light's solid angle, computed here on a fine grid."""
    position = np.array([[0.0, 1.49, 0.0]])
    facing = np.array([[0.0, -1.0, 0.0]])
    edge_x, edge_y = np.array([[0.6, 0, 0]]), np.array([[0, 0, 0.8]])
    radiance, area = np.ones((1, 3)), np.array([0.48])
    area_light = light_record(AREA, radiance, position, facing, edge_x, edge_y, area)
    p = np.array([0.3, 0.2, -0.4])
    rng = np.random.default_rng(3)
    inverse = [1.0 / sample_light(area_light, 0,
                                  *p, *u)[7] for u in rng.random((40000, 2))]
    s = (np.arange(400) + 0.5) / 400 - 0.5
    sx, sy = np.meshgrid(s, s)
    q = position[0] + sx[..., None] * edge_x[0] + sy[..., None] * edge_y[0]
    d = q - p
    dist = np.linalg.norm(d, axis=-1)
    solid_angle = np.sum(np.abs(d @ facing[0]) / dist ** 3) * area[0] / s.size ** 2
    assert np.mean(inverse) == pytest.approx(solid_angle, rel=0.01)
    # and the point behind the light gets nothing
    behind = sample_light(area_light, 0,
                          0.0, 2.0, 0.0, 0.5, 0.5)
    assert behind[7] == 0.0
