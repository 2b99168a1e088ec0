"""The environment light (the course's -e): the white furnace, the sampler against its pdf,
importance sampling of a small sun, the unlit course bunnies lit, and the shipped sky map."""
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

import ptrace
from ptrace.camera import Camera
from ptrace.environment import (
    Environment,
    environment_arrays,
    environment_density,
    environment_pdf,
    environment_radiance,
    environment_sample,
    load_environment,
)
from ptrace.scene import DIFFUSE, EXACT, GLASS, SCHLICK

from scenes_by_hand import make_scene

ROOT = pathlib.Path(__file__).resolve().parents[2]
SKY = ROOT / "scenes" / "sky.exr"


def sphere_scene(albedo):
    return make_scene(centers=[[0.0, 0.0, 0.0]], radii=[1.0],
                      materials=[dict(kind=DIFFUSE, albedo=(albedo,) * 3)], material_index=[0])


def front_camera(size=24):
    return Camera(np.array([0.0, 0.0, 4.0]), np.zeros(3), np.eye(3), size * 1.2, size, size,
                  1e-3, 1e3)


@pytest.mark.parametrize("options", [dict(), dict(direct="light"), dict(hemisphere=True),
                                     dict(max_depth=5), dict(max_depth=5, direct="light")],
                         ids=["mis", "light", "hemisphere", "mis depth 5", "light depth 5"])
def test_white_furnace_a_convex_diffuse_object_shows_its_albedo(options):
    """Under a uniform environment of radiance 1 a convex diffuse sphere (it sees only the sky)
    has radiance exactly its albedo at every depth, and the background is 1: each estimator's
    mean over the sphere's pixels is the albedo within 4 standard errors, and indirect rays
    that escape are not counted twice (MIS's weights add to one)."""
    albedo = 0.6
    scene = sphere_scene(albedo).with_environment(Environment.constant((1.0, 1.0, 1.0)))
    kwargs = dict(dict(spp=16, light_samples=4, max_depth=1), **options)
    size = 48
    camera = front_camera(size)
    image = ptrace.render(scene, camera=camera, resolution=(size, size), **kwargs)
    values = image[..., 0]
    background = values[[0, 0, -1, -1], [0, -1, 0, -1]]
    np.testing.assert_array_equal(background, 1.0)
    # pixels wholly on the sphere: 1.5 px inside its silhouette (angular radius asin(1/4))
    silhouette = camera.screen_dist * math.tan(math.asin(0.25))
    rows, cols = np.indices(values.shape)
    inside = np.hypot(rows + 0.5 - size / 2, cols + 0.5 - size / 2) < silhouette - 1.5
    on_sphere = values[inside]
    assert on_sphere.size > 100
    stderr = on_sphere.std(ddof=1) / math.sqrt(on_sphere.size)
    print(f"{options}: sphere mean {on_sphere.mean():.4f} (albedo {albedo}), stderr {stderr:.4f}")
    assert abs(on_sphere.mean() - albedo) < 4 * stderr + 1e-6
    assert stderr < 0.01


@pytest.mark.parametrize("fresnel", [SCHLICK, EXACT], ids=["schlick", "exact"])
def test_white_furnace_a_clear_glass_sphere_vanishes(fresnel):
    """Under a uniform environment of radiance 1 a sphere of clear glass (white reflectance and
    transmittance, no absorption) sends back exactly the radiance it receives whatever its
    Fresnel weights: each path enters and leaves the glass any number of times, the radiance
    it carries scaled by 1/eta^2 on the way in and eta^2 on the way out, and finds the sky.
    So every pixel is 1 (the sphere does not show), with no roulette and depth enough that no
    path inside is cut off."""
    scene = make_scene(centers=[[0.0, 0.0, 0.0]], radii=[1.0],
                       materials=[dict(kind=GLASS, albedo=(1.0,) * 3, transmittance=(1.0,) * 3,
                                       ior=1.5, fresnel=fresnel)],
                       material_index=[0])
    scene = scene.with_environment(Environment.constant((1.0, 1.0, 1.0)))
    size = 32
    image = ptrace.render(scene, camera=front_camera(size), resolution=(size, size), spp=8,
                          max_depth=64, roulette=False)
    np.testing.assert_allclose(image, 1.0, rtol=1e-12)


def bright_sun(rows=32, columns=64):
    image = np.full((rows, columns, 3), 0.05)
    image[8, 40] = 5000.0     # one pixel 22.5 degrees below the zenith
    return Environment(image, name="sun")


def reference_table(image):
    """The density the module docstring defines, written out cell by cell: the luminance of
    the pixels blurred by [1/8, 3/4, 1/8] along each axis (wrapping around in phi, clamped at
    the poles), times sin theta, plus 1e-3 of its mean, scaled to mean 1."""
    rows, columns = image.shape[:2]
    lum = image.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    blurred = np.zeros((rows, columns))
    for j in range(rows):
        for i in range(columns):
            for dj, wj in ((-1, 0.125), (0, 0.75), (1, 0.125)):
                for di, wi in ((-1, 0.125), (0, 0.75), (1, 0.125)):
                    blurred[j, i] += wj * wi * lum[min(max(j + dj, 0), rows - 1),
                                                   (i + di) % columns]
    table = blurred * np.sin((np.arange(rows) + 0.5) / rows * np.pi)[:, None]
    table += 1e-3 * table.mean()
    return table / table.mean()


def test_the_sampler_draws_directions_by_its_pdf():
    """Chi-square of sampled image cells against the table's probabilities (computed here, on
    their own: reference_table), the density the sampler keeps (its cdfs' steps) is that table,
    and the pdf the sampler reports is environment_pdf of the direction it returns."""
    environment = Environment(np.random.default_rng(1).random((8, 16, 3)) ** 3 * 4, name="r")
    image, marginal, conditional, table = environment_arrays(environment)
    reference = reference_table(environment.image)
    np.testing.assert_allclose(environment_density(table), reference, rtol=1e-5)
    rows, columns = reference.shape
    rng = np.random.default_rng(2)
    counts = np.zeros((rows, columns))
    for u1, u2 in rng.random((40000, 2)):
        x, y, z, pdf = environment_sample(marginal, conditional, table, u1, u2)
        assert pdf == pytest.approx(environment_pdf(table, x, y, z), rel=1e-9)
        theta, phi = math.acos(y), math.atan2(-z, x) + math.pi
        j = min(int(theta / math.pi * rows), rows - 1)
        i = min(int(phi / (2 * math.pi) * columns), columns - 1)
        assert pdf == pytest.approx(reference[j, i] / (2 * math.pi ** 2 * math.sin(theta)),
                                    rel=1e-5)
        counts[j, i] += 1
    expected = reference / reference.sum() * counts.sum()
    p = stats.chisquare(counts.ravel(), expected.ravel()).pvalue
    print(f"chi-square p = {p:.3g}")
    assert p > 1e-3


def test_the_pdf_integrates_to_one_over_the_sphere():
    _, _, _, table = environment_arrays(bright_sun())
    n_t, n_p = 320, 640     # a midpoint rule, 10 x 10 points per table cell
    total = 0.0
    for i in range(n_t):
        t = (i + 0.5) / n_t * math.pi
        for j in range(n_p):
            p = (j + 0.5) / n_p * 2 * math.pi - math.pi
            total += environment_pdf(table, math.sin(t) * math.cos(p), math.cos(t),
                                     -math.sin(t) * math.sin(p)) * math.sin(t)
    total *= (math.pi / n_t) * (2 * math.pi / n_p)
    assert total == pytest.approx(1.0, rel=0.01)


def test_importance_sampling_a_small_sun_beats_uniform_sampling():
    """The irradiance of an upward surface under a sky with a bright one-pixel sun, estimated
    with 64 samples 400 times: by the environment's own sampler the variance is over 50x below
    uniform sphere sampling's (measured about 700x), and both means are the integral."""
    environment = bright_sun()
    image, marginal, conditional, table = environment_arrays(environment)
    rng = np.random.default_rng(3)

    def by_importance(u):
        x, y, z, pdf = environment_sample(marginal, conditional, table, u[0], u[1])
        r = environment_radiance(image, x, y, z)[0]
        return r * max(y, 0.0) / pdf

    def by_uniform(u):
        y = 1 - 2 * u[0]
        s = math.sqrt(max(0.0, 1 - y * y))
        x, z = s * math.cos(2 * math.pi * u[1]), s * math.sin(2 * math.pi * u[1])
        return environment_radiance(image, x, y, z)[0] * max(y, 0.0) * 4 * math.pi

    estimates = {name: [np.mean([f(u) for u in rng.random((64, 2))]) for _ in range(400)]
                 for name, f in (("importance", by_importance), ("uniform", by_uniform))}
    means = {k: np.mean(v) for k, v in estimates.items()}
    variances = {k: np.var(v) for k, v in estimates.items()}
    # the irradiance by a midpoint rule over the sphere, 16 points per pixel of the map
    n_t, n_p = 128, 256
    exact = 0.0
    for i in range(n_t // 2):   # the upper hemisphere (y > 0)
        t = (i + 0.5) / n_t * math.pi
        for j in range(n_p):
            p = (j + 0.5) / n_p * 2 * math.pi - math.pi
            y = math.cos(t)
            exact += environment_radiance(image, math.sin(t) * math.cos(p), y,
                                          -math.sin(t) * math.sin(p))[0] * y * math.sin(t)
    exact *= (math.pi / n_t) * (2 * math.pi / n_p)
    print(means, variances, exact)
    assert variances["importance"] * 50 < variances["uniform"]
    # unbiased, and without a hidden heavy tail: the mean of 400 x 64 samples is the integral
    assert abs(means["importance"] - exact) < 4 * math.sqrt(variances["importance"] / 400)
    assert abs(means["uniform"] - exact) < 4 * math.sqrt(variances["uniform"] / 400)


@pytest.mark.parametrize("name", ["bunny_unlit.dae", "bunny_microfacet_cu_unlit.dae"])
def test_the_unlit_course_bunnies_render_lit_under_an_environment(course_scene, name):
    scene = ptrace.load(course_scene(f"sky/{name}"))
    kwargs = dict(resolution=(48, 36), spp=4, light_samples=2, max_depth=2)
    assert ptrace.render(scene, **kwargs).max() == 0.0
    lit = ptrace.render(scene.with_environment(load_environment(SKY)), **kwargs)
    assert lit.mean() > 0.05


def test_the_shipped_sky_is_the_scripts_output():
    """scenes/sky.exr is what scenes/make_sky.py writes (float32 round trip)."""
    sys.path.insert(0, str(ROOT / "scenes"))
    try:
        import make_sky
    finally:
        sys.path.pop(0)
    environment = load_environment(SKY)
    np.testing.assert_array_equal(environment.image, make_sky.sky().astype(np.float64))
    assert environment.image[..., 0].max() > 100   # it has its sun


def test_environment_errors_are_one_line_and_a_constant_parses(tmp_path):
    assert load_environment("0.5").image[0, 0].tolist() == [0.5, 0.5, 0.5]
    assert load_environment("1,0.5,0.25").image[3, 7].tolist() == [1.0, 0.5, 0.25]
    with pytest.raises(ptrace.PtraceError, match="missing.exr"):
        load_environment(tmp_path / "missing.exr")
    with pytest.raises(ptrace.PtraceError, match="negative"):
        Environment(np.full((2, 2, 3), -1.0))
    result = subprocess.run([sys.executable, "-m", "ptrace", "-e", str(tmp_path / "no.hdr"),
                             "-f", str(tmp_path / "x.png"), str(ROOT / "scenes" / "cornell.dae")],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert "no.hdr" in result.stderr
