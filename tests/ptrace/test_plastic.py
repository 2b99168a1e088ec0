"""Mitsuba's smooth plastic (material kind PLASTIC, ptrace.bsdf's plastic_*): its energy, its
values against Mitsuba's own BSDF, what the reader packs, and a scene of it rendered by both
renderers, compared pixel by pixel. (Its sampling against its pdf is in test_bsdf.py.)"""
import math

import numpy as np
import pytest

import ptrace
from ptrace.bsdf import TABLE, plastic_eval, plastic_pdf, plastic_sample
from ptrace.io.mitsuba_materials import fresnel_diffuse_reflectance
from ptrace.scene import PLASTIC, ROUGH_PLASTIC, Materials


def fresnel(cos_i, eta):
    """The textbook unpolarised Fresnel reflectance (numpy, for the tests' own integrals)."""
    sin2_t = (1.0 - cos_i ** 2) / eta ** 2
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    rs = ((cos_i - eta * cos_t) / (cos_i + eta * cos_t)) ** 2
    rp = ((eta * cos_i - cos_t) / (eta * cos_i + cos_t)) ** 2
    return np.where(sin2_t >= 1.0, 1.0, 0.5 * (rs + rp))


def diffuse_fresnel(eta, n=200000):
    """The cosine-weighted hemispherical mean of fresnel(., eta): 2 int F mu dmu (midpoint)."""
    mu = (np.arange(n) + 0.5) / n
    return float(np.mean(2.0 * mu * fresnel(mu, eta)))


def plastic(albedo, specular=(1.0, 1.0, 1.0), eta=1.5, nonlinear=False, fdr=None, weight=None):
    """A one-material record of Mitsuba's plastic, packed as the reader packs it (its fdr_int
    from the exact integral unless given)."""
    fdr = diffuse_fresnel(1.0 / eta) if fdr is None else fdr
    if weight is None:
        weight = np.mean(specular) / (np.mean(specular) + np.mean(albedo))
    return Materials.from_records([dict(kind=PLASTIC, albedo=albedo, specular=specular, ior=eta,
                                        eta=(eta, fdr, weight),
                                        k=(float(nonlinear), 0.0, 0.0))])


def sample(M, wo, u):
    return plastic_sample(*M.albedo[0], M.transmittance, M.ior, 0.0, 0.0, M.eta, M.k,
                          M.specular, 0, *wo, *u)


def direction(theta_degrees, phi=0.3):
    t = math.radians(theta_degrees)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


@pytest.mark.parametrize("eta", [0.5, 0.75, 1.0 / 1.49, 1.33, 1.49, 2.0])
def test_the_diffuse_fresnel_fits_are_close_to_the_integral(eta):
    assert fresnel_diffuse_reflectance(eta) == pytest.approx(diffuse_fresnel(eta), rel=7e-3)


@pytest.mark.parametrize("eta", [1.3, 1.5, 2.2])
@pytest.mark.parametrize("nonlinear", [False, True])
def test_a_white_plastic_reflects_all_and_a_coloured_one_less(eta, nonlinear):
    """White furnace: a white base under a clear coat (exact fdr_int) loses nothing: the mean
    sampled weight f cos / pdf, delta lobe included, is 1 at every angle (the coat passes
    1 - fdr_ext = eta^2 (1 - fdr_int) of the base's light out); a base of albedo 0.5 returns
    less, and more with `nonlinear` (its inter-reflections then coloured by the base)."""
    rng = np.random.default_rng(7)
    white = plastic((1.0, 1.0, 1.0), eta=eta, nonlinear=nonlinear)
    grey = plastic((0.5, 0.5, 0.5), eta=eta, nonlinear=nonlinear)
    for theta in (0, 40, 75, 88):
        wo = direction(theta)
        for M, low, high in ((white, 0.995, 1.005), (grey, 0.2, 0.99)):
            weights = []
            for u in rng.random((20000, 3)):
                x, y, z, fr, fg, fb, pdf = sample(M, wo, u)
                weights.append(fr * abs(z) / abs(pdf) if pdf != 0 else 0.0)
            mean = np.mean(weights)
            assert low <= mean <= high, (theta, mean)
    # analytic grey: F_o + (1 - F_o)(1 - fdr_ext) / eta^2 d / (1 - fdr_int [d])
    d, f0 = 0.5, fresnel(1.0, eta)
    fdr_int, fdr_ext = diffuse_fresnel(1.0 / eta), diffuse_fresnel(eta)
    expected = f0 + (1 - f0) * (1 - fdr_ext) / eta ** 2 * d / (1 - fdr_int * (d if nonlinear
                                                                                else 1.0))
    weights = [sample(grey, direction(0), u) for u in rng.random((40000, 3))]
    mean = np.mean([w[3] * abs(w[2]) / abs(w[6]) for w in weights if w[6] != 0])
    assert mean == pytest.approx(expected, rel=0.01)


def test_the_mirror_lobe_is_flagged_delta_and_chosen_with_mitsubas_probability():
    """Its sample is the mirror direction with the negated probability F w / (F w + (1 - F)
    (1 - w)), its weight F times the specular reflectance over that probability; the other
    samples are the diffuse lobe's, with eval's f and pdf's density."""
    M = plastic((0.2, 0.3, 0.6), specular=(0.5, 0.6, 0.7), eta=1.49)
    wo = direction(60)
    f = float(fresnel(wo[2], 1.49))
    w = M.eta[0, 2]
    p = f * w / (f * w + (1 - f) * (1 - w))
    x, y, z, fr, fg, fb, pdf = sample(M, wo, (0.3, 0.4, p * 0.999))
    assert pdf == pytest.approx(-p) and (x, y, z) == pytest.approx((-wo[0], -wo[1], wo[2]))
    assert np.array([fr, fg, fb]) * z / p == pytest.approx(f * M.specular[0] / p)
    x, y, z, fr, fg, fb, pdf = sample(M, wo, (0.3, 0.4, p * 1.001))
    assert pdf > 0 and pdf == pytest.approx(plastic_pdf(*M.albedo[0], 0.0, 0.0, M.eta, M.k,
                                                        M.specular, 0, *wo, x, y, z))
    assert pdf == pytest.approx((1 - p) * z / math.pi)


@pytest.mark.parametrize("nonlinear", [False, True])
@pytest.mark.parametrize("int_ior, ext_ior", [(1.49, 1.0), (1.9, 1.2)])
def test_plastic_evaluates_and_samples_as_mitsubas(tmp_path, nonlinear, int_ior, ext_ior):
    """The reader's record of a <bsdf type="plastic"> against Mitsuba's own BSDF of the same
    parameters, on 200 pairs of directions: eval's f cos (Mitsuba's eval includes the cosine),
    pdf, and the delta lobe's weight and probability (Mitsuba's sample with sample1 near 0)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    params = {"type": "plastic", "int_ior": int_ior, "ext_ior": ext_ior,
              "nonlinear": nonlinear,
              "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.1]},
              "specular_reflectance": {"type": "rgb", "value": [0.9, 0.8, 0.5]}}
    theirs = mi.load_dict(params)
    flag = "true" if nonlinear else "false"
    (tmp_path / "p.xml").write_text(
        f'<scene version="3.0.0"><shape type="sphere"><bsdf type="plastic"><float '
        f'name="int_ior" value="{int_ior}"/><float name="ext_ior" value="{ext_ior}"/><boolean '
        f'name="nonlinear" value="{flag}"/><rgb name="diffuse_reflectance" value="0.7 0.3 '
        f'0.1"/><rgb name="specular_reflectance" value="0.9 0.8 0.5"/></bsdf></shape></scene>')
    scene = ptrace.load(tmp_path / "p.xml")
    M, m = scene.materials, int(scene.material_index[0])
    assert M.kind[m] == PLASTIC
    rng = np.random.default_rng(5)
    for _ in range(200):
        a, b = rng.normal(size=3), rng.normal(size=3)
        a[2], b[2] = abs(a[2]), abs(b[2])
        wo, wi = a / np.linalg.norm(a), b / np.linalg.norm(b)
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wo)      # Mitsuba's wi is ptrace's wo
        si.n = mi.Normal3f(0, 0, 1)
        si.sh_frame = mi.Frame3f(si.n)
        value = np.array(theirs.eval(mi.BSDFContext(), si, mi.Vector3f(*wi)))
        ours = np.array(plastic_eval(*M.albedo[m], 0.0, 0.0, M.eta, M.k, M.specular, m, *wo,
                                     *wi))
        np.testing.assert_allclose(ours * wi[2], value, rtol=1e-5, atol=1e-7)
        pdf = plastic_pdf(*M.albedo[m], 0.0, 0.0, M.eta, M.k, M.specular, m, *wo, *wi)
        assert pdf == pytest.approx(float(theirs.pdf(mi.BSDFContext(), si, mi.Vector3f(*wi))),
                                    rel=1e-5, abs=1e-7)
        sampled, weight = theirs.sample(mi.BSDFContext(), si, 1e-7, mi.Point2f(0.5, 0.5))
        x, y, z, fr, fg, fb, p = plastic_sample(*M.albedo[m], M.transmittance, M.ior, 0.0, 0.0,
                                                M.eta, M.k, M.specular, m, *wo, 0.5, 0.5, 1e-7)
        assert -p == pytest.approx(float(sampled.pdf), rel=1e-5)
        np.testing.assert_allclose(np.array([fr, fg, fb]) * z / -p, np.array(weight),
                                   rtol=1e-5)


PLASTIC_BOX = """<scene version="3.0.0">
<default name="spp" value="16"/><default name="width" value="16"/>
<default name="height" value="12"/>
<integrator type="path"><integer name="max_depth" value="4"/></integrator>
<sensor type="perspective"><float name="fov" value="45"/>
  <transform name="to_world"><lookat origin="0, 1.2, 3" target="0, 0, 0" up="0, 1, 0"/>
  </transform>
  <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
  <film type="hdrfilm"><integer name="width" value="$width"/><integer name="height"
    value="$height"/><rfilter type="box"/></film></sensor>
<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/>
  <translate y="-0.5"/></transform><bsdf type="twosided"><bsdf type="plastic"><rgb
  name="diffuse_reflectance" value="0.6 0.5 0.2"/><boolean name="nonlinear" value="true"/>
  </bsdf></bsdf></shape>
<shape type="sphere"><float name="radius" value="0.5"/><bsdf type="plastic"><rgb
  name="diffuse_reflectance" value="0.1 0.2 0.6"/><float name="int_ior" value="1.7"/>
  </bsdf></shape>
<shape type="cube"><transform name="to_world"><scale value="0.3"/><rotate y="1" angle="30"/>
  <translate x="-0.9" y="-0.2" z="0.3"/></transform><bsdf type="roughplastic"><string
  name="distribution" value="ggx"/><float name="alpha" value="0.25"/><rgb
  name="diffuse_reflectance" value="0.7 0.2 0.2"/></bsdf></shape>
<shape type="sphere"><point name="center" x="1.2" y="1.5" z="0.5"/><float name="radius"
  value="0.3"/><emitter type="area"><rgb name="radiance" value="12"/></emitter></shape>
<emitter type="constant"><rgb name="radiance" value="0.3"/></emitter>
</scene>
"""


def test_a_plastic_scene_agrees_with_mitsuba_per_pixel(tmp_path):
    """A plastic floor (nonlinear), a plastic sphere and a GGX roughplastic cube under a
    spherical lamp and a constant sky, read by both renderers: the z-test over batches finds
    no more differing pixel channels than chance."""
    mi = pytest.importorskip("mitsuba")
    pytest.importorskip("scipy")
    mi.set_variant("scalar_rgb")
    from benchmarks.mitsuba_scenes import z_test
    path = tmp_path / "plastic.xml"
    path.write_text(PLASTIC_BOX)
    defines, batches = {"width": "16", "height": "12", "spp": "32"}, 6
    scene = mi.load_file(str(path), **defines)
    theirs = np.stack([np.array(mi.render(scene, spp=32, seed=1 + s))[:, :, :3]
                       for s in range(batches)])
    ours = ptrace.load(path, defines=defines)
    ours = np.stack([np.asarray(ptrace.render(ours, seed=1 + s)) for s in range(batches)])
    share, agrees = z_test(ours.astype(np.float64), theirs.astype(np.float64))
    assert agrees, share


@pytest.mark.parametrize("distribution, alpha, int_ior, nonlinear, tolerance", [
    ("beckmann", 0.2, 1.49, False, 1e-3), ("ggx", 0.3, 1.6, True, 5e-3),
    ("beckmann", 0.05, 1.33, False, 1e-3)])
def test_roughplastic_evaluates_as_mitsubas(tmp_path, distribution, alpha, int_ior, nonlinear,
                                            tolerance):
    """The reader's record of a <bsdf type="roughplastic"> (its tables computed here at load
    time) against Mitsuba's own BSDF of the same parameters, on 300 pairs of directions:
    eval's f cos (the coat's lobe and the base's, through the transmittance tables: their
    quadratures differ, by up to 4e-3 of GGX's heavier tails at 96 x 96 nodes)."""
    from ptrace.bsdf import rough_plastic_eval
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    theirs = mi.load_dict({"type": "roughplastic", "distribution": distribution,
                           "alpha": alpha, "int_ior": int_ior, "nonlinear": nonlinear,
                           "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.1]},
                           "specular_reflectance": {"type": "rgb", "value": [0.9, 0.8, 0.5]}})
    flag = "true" if nonlinear else "false"
    (tmp_path / "p.xml").write_text(
        f'<scene version="3.0.0"><shape type="sphere"><bsdf type="roughplastic"><string '
        f'name="distribution" value="{distribution}"/><float name="alpha" value="{alpha}"/>'
        f'<float name="int_ior" value="{int_ior}"/><boolean name="nonlinear" value="{flag}"/>'
        f'<rgb name="diffuse_reflectance" value="0.7 0.3 0.1"/><rgb name="specular_'
        f'reflectance" value="0.9 0.8 0.5"/></bsdf></shape></scene>')
    scene = ptrace.load(tmp_path / "p.xml")
    M, m = scene.materials, int(scene.material_index[0])
    assert M.kind[m] == ROUGH_PLASTIC and M.specular.shape[1] == 3 + TABLE
    rng = np.random.default_rng(6)
    worst = 0.0
    for _ in range(300):
        a, b = rng.normal(size=3), rng.normal(size=3)
        a[2], b[2] = abs(a[2]) + 0.05, abs(b[2]) + 0.05
        wo, wi = a / np.linalg.norm(a), b / np.linalg.norm(b)
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wo)
        si.n = mi.Normal3f(0, 0, 1)
        si.sh_frame = mi.Frame3f(si.n)
        value = np.array(theirs.eval(mi.BSDFContext(), si, mi.Vector3f(*wi)))
        ours = np.array(rough_plastic_eval(*M.albedo[m], M.alpha[m], 0.0, M.eta, M.k,
                                           M.specular, m, *wo, *wi)) * wi[2]
        worst = max(worst, float(np.max(np.abs(ours - value) / (value + 1e-3))))
    print(f"largest relative difference {worst:.2e}")
    assert worst < tolerance


def test_mis_and_light_sampling_agree_on_a_plastic_scene(tmp_path):
    """The plastic box (a smooth plastic's delta lobe beside its diffuse one, a roughplastic)
    rendered with MIS and with light sampling alone: both unbiased, their mean luminances over
    four seeds agree within their standard errors. A delta bounce flagged as not delta (or
    the reverse) drops or doubles the lamp's reflection in one of them."""
    path = tmp_path / "plastic.xml"
    path.write_text(PLASTIC_BOX)
    scene = ptrace.load(path, defines={"width": "32", "height": "24", "spp": "32"})
    luminance = np.array([0.2126, 0.7152, 0.0722])
    stats = {}
    for direct in ("mis", "light"):
        values = [float((ptrace.render(scene, seed=seed, direct=direct) @ luminance).mean())
                  for seed in range(4)]
        stats[direct] = (np.mean(values), np.std(values, ddof=1) / 2.0)
    difference = abs(stats["mis"][0] - stats["light"][0])
    assert difference < max(4 * np.hypot(stats["mis"][1], stats["light"][1]),
                            0.003 * stats["light"][0]), stats
