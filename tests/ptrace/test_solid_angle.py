"""Solid-angle samplers (ptrace.solid_angle): sampled directions against their pdf (chi-square),
the pdf's integral over the sphere of directions, sampler and pdf agreeing, a floor point's
irradiance under a rectangle light against the closed form, and the area fallbacks."""
import math

import numpy as np
import pytest
from scipy import stats

from accel.interpreted import interpreted
from ptrace.solid_angle import (
    RECTANGLE_MAX_GRAZING,
    RECTANGLE_MIN_SOLID_ANGLE,
    TRIANGLE_MIN_SOLID_ANGLE,
    rectangle_axes_table,
    rectangle_pdf,
    rectangle_sample,
    rectangle_sample_row,
    rectangle_solid_angle,
    triangle_pdf,
    triangle_sample,
    triangle_solid_angle,
)
from ptrace.solid_angle_sphere import sphere_pdf, sphere_sample

# a Cornell-box-like light: 0.8 x 0.6, centre at height 1.49, facing down
CENTRE = np.array([0.0, 1.49, 0.0])
EX, EY = np.array([0.8, 0.0, 0.0]), np.array([0.0, 0.0, 0.6])
RECTANGLE, TRIANGLE, SPHERE = range(3)


SAMPLERS = {RECTANGLE: rectangle_sample, TRIANGLE: triangle_sample, SPHERE: sphere_sample}
PDFS = {RECTANGLE: rectangle_pdf, TRIANGLE: triangle_pdf, SPHERE: sphere_pdf}
# (Called from Python, not from a compiled loop here: numba's cache of a test's loop would keep
# an inlined copy of the samplers that it does not recompile when ptrace/solid_angle.py changes.)


def draw(kind, args, us):
    """Samples of a shape (args: p then the shape's parameters) for each row of us: points
    (n, 3), pdfs (n,), and for triangles the barycentrics (n, 2)."""
    sampler, args = SAMPLERS[kind], tuple(float(a) for a in args)
    out = np.array([sampler(*args, u1, u2) for u1, u2 in us.tolist()])
    bary = out[:, 3:5] if kind == TRIANGLE else np.zeros((len(us), 2))
    return out[:, :3], out[:, -1], bary


def densities(kind, args, w):
    """The pdf function's density for each unit direction (row of w) from p."""
    pdf, args = PDFS[kind], tuple(float(a) for a in args)
    return np.array([pdf(*args, *d) for d in w.tolist()])


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rotated(seed, *vectors):
    """The vectors under one random rotation: no configuration lies along the axes."""
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return [q @ v for v in vectors]


class Shape:
    """A shape seen from p, with (s, t) coordinates over the unit square for the part of it
    that the sampler reaches: point(s, t), coordinates(points) (and each point's distance off
    the shape's surface), jacobian (area per unit s t) and normals(points)."""

    def sample(self, us):
        points, pdfs, bary = draw(self.kind, self.args, np.atleast_2d(us))
        return points, pdfs

    def pdf(self, w):
        return densities(self.kind, self.args, np.atleast_2d(w))


class Rectangle(Shape):
    kind = RECTANGLE

    def __init__(self, p, centre, ex, ey):
        self.p, self.centre, self.ex, self.ey = (np.asarray(v, float) for v in (p, centre, ex, ey))
        self.args = np.array([*self.p, *self.centre, *self.ex, *self.ey])
        self.corner = self.centre - 0.5 * (self.ex + self.ey)
        # the dual basis of (ex, ey) in their plane: coordinates of a point on the parallelogram
        gram = np.array([[self.ex @ self.ex, self.ex @ self.ey],
                         [self.ex @ self.ey, self.ey @ self.ey]])
        self.dual = np.linalg.solve(gram, np.array([self.ex, self.ey]))
        self.area = np.linalg.norm(np.cross(self.ex, self.ey))
        self.normal = np.cross(self.ex, self.ey) / self.area
        self.jacobian = self.area

    def coordinates(self, q):
        d = q - self.corner
        return d @ self.dual.T, np.abs(d @ self.normal)

    def point(self, s, t):
        return self.corner + s[:, None] * self.ex + t[:, None] * self.ey

    def normals(self, q):
        return np.broadcast_to(self.normal, q.shape)


class Triangle(Shape):
    """(s, t) -> A + sqrt(s) (1 - t) (B - A) + sqrt(s) t (C - A) maps the unit square onto the
    triangle keeping area."""
    kind = TRIANGLE

    def __init__(self, p, a, b, c):
        self.p, self.a, self.b, self.c = (np.asarray(v, float) for v in (p, a, b, c))
        self.args = np.array([*self.p, *self.a, *self.b, *self.c])
        n = np.cross(self.b - self.a, self.c - self.a)
        self.area, self.normal = 0.5 * np.linalg.norm(n), unit(n)
        self.jacobian = self.area

    def sample(self, us):
        points, pdfs, bary = draw(self.kind, self.args, np.atleast_2d(us))
        # the returned barycentrics say where the point is
        again = self.a + bary[:, :1] * (self.b - self.a) + bary[:, 1:] * (self.c - self.a)
        assert np.abs(again - points).max() <= 1e-12 * max(np.abs(points).max(), 1.0)
        return points, pdfs

    def coordinates(self, q):
        e1, e2 = self.b - self.a, self.c - self.a
        gram = np.array([[e1 @ e1, e1 @ e2], [e1 @ e2, e2 @ e2]])
        d = q - self.a
        wb, wc = np.linalg.solve(gram, np.array([d @ e1, d @ e2]))
        total = wb + wc
        t = np.divide(wc, total, out=np.zeros_like(wc), where=total > 0)
        return np.stack([total * total, t], axis=1), np.abs(d @ self.normal)

    def point(self, s, t):
        r = np.sqrt(s)[:, None]
        return (self.a + r * (1 - t[:, None]) * (self.b - self.a)
                + r * t[:, None] * (self.c - self.a))

    def normals(self, q):
        return np.broadcast_to(self.normal, q.shape)


class Sphere(Shape):
    """(s, t) over the part of the sphere the sampler reaches (the cap facing p, or all of it
    from inside): cos alpha (about the axis from the centre toward p) and phi, both linear."""
    kind = SPHERE

    def __init__(self, p, centre, radius):
        self.p, self.centre, self.radius = np.asarray(p, float), np.asarray(centre, float), radius
        self.args = np.array([*self.p, *self.centre, radius])
        d = self.p - self.centre
        self.axis = unit(d)
        self.low = radius / np.linalg.norm(d) if np.linalg.norm(d) > radius else -1.0
        helper = np.array([1.0, 0, 0]) if abs(self.axis[0]) < 0.9 else np.array([0, 1.0, 0])
        self.t1 = unit(np.cross(self.axis, helper))
        self.t2 = np.cross(self.axis, self.t1)
        self.jacobian = radius ** 2 * (1 - self.low) * 2 * math.pi

    def coordinates(self, q):
        n = (q - self.centre) / self.radius
        phi = np.arctan2(n @ self.t2, n @ self.t1) % (2 * math.pi)
        s = (n @ self.axis - self.low) / (1 - self.low)
        return (np.stack([s, phi / (2 * math.pi)], axis=1),
                np.abs(np.linalg.norm(q - self.centre, axis=1) - self.radius))

    def point(self, s, t):
        cos_a = (self.low + s * (1 - self.low))[:, None]
        sin_a = np.sqrt(np.maximum(0.0, 1 - cos_a * cos_a))
        phi = (2 * math.pi * t)[:, None]
        return self.centre + self.radius * (cos_a * self.axis + sin_a * (
            np.cos(phi) * self.t1 + np.sin(phi) * self.t2))

    def normals(self, q):
        return (q - self.centre) / self.radius


def chi_square(shape, n=40000, bins=10, sub=8, seed=0, check=4000):
    """p-value of the samples' histogram over a bins x bins grid of the shape's (s, t)
    coordinates (each cell a set of directions from p) against the probabilities the pdf
    function gives the cells (midpoint rule, sub x sub points a cell: pdf(w) |cos| / distance^2
    dA). Along the way: every sample lies on the shape, and (for the first `check`) its pdf is
    the pdf function's for its direction."""
    points, pdfs = shape.sample(np.random.default_rng(seed).random((n, 2)))
    assert (pdfs > 0).all() and np.isfinite(pdfs).all()
    np.testing.assert_allclose(shape.pdf(unit(points[:check] - shape.p)), pdfs[:check], rtol=1e-9)
    st, off_surface = shape.coordinates(points)
    assert (off_surface <= 1e-9 * max(np.abs(shape.args).max(), 1.0)).all()
    assert ((st >= -1e-9) & (st <= 1 + 1e-9)).all()
    cells = np.minimum((st * bins).astype(int), bins - 1)
    counts = np.bincount(cells[:, 0] * bins + cells[:, 1], minlength=bins * bins)
    grid = (np.arange(bins * sub) + 0.5) / (bins * sub)
    s, t = (a.ravel() for a in np.meshgrid(grid, grid, indexing="ij"))
    q = shape.point(s, t)
    d = q - shape.p
    dist = np.linalg.norm(d, axis=1)
    w = d / dist[:, None]
    density = shape.pdf(w) * np.abs(np.sum(w * shape.normals(q), axis=1)) / dist ** 2
    expected = (density * shape.jacobian).reshape(bins, sub, bins, sub).sum(axis=(1, 3))
    expected /= (bins * sub) ** 2
    total = expected.sum()
    assert total == pytest.approx(1.0, rel=2e-3)     # the pdf integrates to 1 over the shape
    expected = expected.ravel() * n / total
    observed = counts.astype(float)
    small = expected < 5
    if small.any():
        observed = np.append(observed[~small], observed[small].sum())
        expected = np.append(expected[~small], expected[small].sum())
    return stats.chisquare(observed, expected).pvalue


RECTANGLES = {
    # (point, centre, edge x, edge y)
    "floor below": (np.array([0.3, 0.0, -0.2]), CENTRE, EX, EY),
    "just below": (np.array([0.2, 1.44, 0.1]), CENTRE, EX, EY),   # solid angle near 2 pi
    "beside, grazing": (np.array([0.9, 1.45, 0.0]), CENTRE, EX, EY),
    "rotated": (*rotated(1, np.array([0.1, 0.2, 0.3]), np.array([0.5, 1.0, 0.9]),
                         np.array([1.2, 0.0, 0.0]), np.array([0.0, 0.3, 0.0])),),
}


@pytest.mark.parametrize("name", list(RECTANGLES))
def test_rectangle_sampler_matches_its_pdf(name):
    p, centre, ex, ey = RECTANGLES[name]
    value = chi_square(Rectangle(p, centre, ex, ey))
    print(f"{name}: p = {value:.3g}")
    assert value > 1e-3


TRIANGLES = {
    "ordinary": (np.zeros(3), np.array([-0.4, 1.0, -0.3]), np.array([0.5, 1.2, -0.2]),
                 np.array([0.1, 0.9, 0.6])),
    "close, large": (np.array([0.05, 0.02, 0.0]), np.array([-1.0, -1.0, 0.2]),
                     np.array([2.0, -0.5, 0.2]), np.array([-0.5, 2.0, 0.2])),
    "obtuse, grazing": (np.zeros(3), np.array([1.0, 0.0, 0.05]), np.array([3.0, 0.2, 0.05]),
                        np.array([1.2, 0.1, 0.08])),
    "small, far": (np.zeros(3), np.array([3.0, 4.0, 5.0]), np.array([3.01, 4.0, 5.0]),
                   np.array([3.0, 4.02, 5.005])),
}


@pytest.mark.parametrize("name", list(TRIANGLES))
def test_triangle_sampler_matches_its_pdf(name):
    value = chi_square(Triangle(*TRIANGLES[name]))
    print(f"{name}: p = {value:.3g}")
    assert value > 1e-3


SPHERES = {
    "outside": (np.zeros(3), np.array([0.3, 0.5, 2.0]), 0.7),
    "close outside": (np.zeros(3), np.array([0.0, 0.0, 1.3]), 1.0),
    "inside": (np.array([0.4, 0.3, 0.5]), np.array([0.0, 0.0, 0.0]), 1.7),
}


@pytest.mark.parametrize("name", list(SPHERES))
def test_sphere_sampler_matches_its_pdf(name):
    value = chi_square(Sphere(*SPHERES[name]))
    print(f"{name}: p = {value:.3g}")
    assert value > 1e-3


def test_a_wrong_pdf_fails_the_chi_square():
    """The test has power: the same samples against area sampling's density fail."""
    p, centre, ex, ey = RECTANGLES["just below"]

    class AreaDensity(Rectangle):
        def pdf(self, w):
            w = np.atleast_2d(w)
            cos = np.abs(w @ self.normal)
            t = np.abs((self.corner - self.p) @ self.normal) / cos
            return t * t / (self.area * cos)

    wrong = AreaDensity(p, centre, ex, ey)
    with pytest.raises(AssertionError):      # the consistency check catches it first ...
        chi_square(wrong, n=3000)
    assert chi_square(wrong, n=3000, check=0) < 1e-6     # ... and the histogram too


def sphere_integral(shape, axis, cos_max, n=200, seed=1):
    """Integral of the shape's pdf over the cap of directions within acos(cos_max) of axis: one
    jittered direction in each of n x n cells of equal solid angle."""
    axis = unit(axis)
    helper = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    t1 = unit(np.cross(axis, helper))
    t2 = np.cross(axis, t1)
    jitter = np.random.default_rng(seed).random((n, n, 2))
    cells = np.arange(n)
    z = (1 - (cells[:, None] + jitter[..., 0]) / n * (1 - cos_max)).ravel()[:, None]
    phi = (2 * math.pi * (cells[None, :] + jitter[..., 1]) / n).ravel()[:, None]
    r = np.sqrt(np.maximum(0.0, 1 - z * z))
    w = z * axis + r * np.cos(phi) * t1 + r * np.sin(phi) * t2
    return shape.pdf(w).mean() * 2 * math.pi * (1 - cos_max)


@pytest.mark.parametrize("kind, name", [("rectangle", "floor below"), ("rectangle", "just below"),
                                        ("triangle", "ordinary"), ("triangle", "close, large"),
                                        ("sphere", "outside"), ("sphere", "inside")])
def test_pdf_integrates_to_one_over_the_sphere(kind, name):
    """Over directions (the whole sphere where the shape is close, else a cap holding it), by
    stratified quadrature, independent of any shape parametrisation."""
    if kind == "rectangle":
        shape = Rectangle(*RECTANGLES[name])
        corners = shape.point(np.array([0.0, 0, 1, 1]), np.array([0.0, 1, 0, 1]))
    elif kind == "triangle":
        shape = Triangle(*TRIANGLES[name])
        corners = np.array([shape.a, shape.b, shape.c])
    else:
        shape = Sphere(*SPHERES[name])
    if kind == "sphere":
        d = np.linalg.norm(shape.centre - shape.p)
        axis = shape.centre - shape.p
        cos_max = math.sqrt(1 - (shape.radius / d) ** 2) - 1e-3 if d > shape.radius else -1.0
    else:
        axis = corners.mean(axis=0) - shape.p
        cos_max = (unit(corners - shape.p) @ unit(axis)).min() - 1e-3
        if cos_max < 0.2:
            axis, cos_max = np.array([0, 0, 1.0]), -1.0
    integral = sphere_integral(shape, axis, cos_max)
    print(f"{kind} {name}: {integral:.5f}")
    assert integral == pytest.approx(1.0, abs=3e-3)


def test_solid_angles_against_quadrature():
    p, centre, ex, ey = RECTANGLES["rotated"]
    shape = Rectangle(p, centre, ex, ey)
    n = 600
    s = (np.arange(n) + 0.5) / n
    q = shape.corner + s[:, None, None] * ex + s[None, :, None] * ey
    d = q - p
    dist = np.linalg.norm(d, axis=-1)
    quadrature = np.sum(np.abs(d @ shape.normal) / dist ** 3) * shape.area / n / n
    assert rectangle_solid_angle(*shape.args) == pytest.approx(quadrature, rel=1e-4)
    # the two triangles of the rectangle add up to it
    a, b, c, d_ = shape.corner, shape.corner + ex, shape.corner + ex + ey, shape.corner + ey
    assert (triangle_solid_angle(*p, *a, *b, *c) + triangle_solid_angle(*p, *a, *c, *d_)
            == pytest.approx(quadrature, rel=1e-4))
    # the whole hemisphere, less about 2 pi h, from h = 1e-9 above the middle (within the
    # conditioning of the corners' coordinates there, eps size / h)
    assert rectangle_solid_angle(0, 0, 1e-9, 0, 0, 0, 1, 0, 0, 0, 1, 0) == \
        pytest.approx(2 * math.pi, rel=1e-7)


def corner_irradiance(x, y, h):
    """Irradiance (radiance 1) at a point from a Lambertian rectangle in the parallel plane at
    height h spanning [0, x] x [0, y] from the point's foot, signed (odd in x and in y): pi
    times the configuration factor from a differential area to a parallel rectangle with a
    corner above it (as tabulated in Howell's catalogue of configuration factors)."""
    a, b = math.hypot(x, h), math.hypot(y, h)
    return 0.5 * (x / a * math.atan(y / a) + y / b * math.atan(x / b))


def rectangle_irradiance(p, centre, ex, ey):
    """The same for an axis-aligned light (edges along x and z) above p, by inclusion-exclusion."""
    h = centre[1] - p[1]
    x0, x1 = centre[0] - abs(ex[0]) / 2 - p[0], centre[0] + abs(ex[0]) / 2 - p[0]
    z0, z1 = centre[2] - abs(ey[2]) / 2 - p[2], centre[2] + abs(ey[2]) / 2 - p[2]
    return (corner_irradiance(x1, z1, h) - corner_irradiance(x0, z1, h)
            - corner_irradiance(x1, z0, h) + corner_irradiance(x0, z0, h))


def irradiance_estimates(p, n, seed, centre=CENTRE):
    """n one-sample estimates of E = int cos dw (radiance 1, receiver facing +y) by solid-angle
    sampling and by area sampling (lights.sample_light's density), from the same numbers."""
    shape = Rectangle(p, centre, EX, EY)
    us = np.random.default_rng(seed).random((n, 2))
    points, pdfs = shape.sample(us)
    solid = unit(points - p)[:, 1] / pdfs
    d = centre + (us[:, :1] - 0.5) * EX + (us[:, 1:] - 0.5) * EY - p
    dist2 = np.sum(d * d, axis=1)
    area = d[:, 1] ** 2 / dist2 * shape.area / dist2       # cos at p, cos at q, area / d^2
    return solid, area


@pytest.mark.parametrize("p, margin", [(np.array([0.1, 0.0, 0.05]), 5.0),      # the floor
                                       (np.array([0.3, 1.39, -0.2]), 20.0),    # 0.1 below it
                                       (np.array([0.45, 1.44, 0.0]), 30.0)])   # beside, close
def test_floor_irradiance_under_a_rectangle_light(p, margin):
    """Both estimates match the closed form within 4 standard errors; near the light,
    solid-angle sampling's variance is lower than area sampling's by at least `margin` (about
    a third of what this seed measures)."""
    exact = rectangle_irradiance(p, CENTRE, EX, EY)
    solid, area = irradiance_estimates(p, 20000, seed=5)
    for name, values in (("solid angle", solid), ("area", area)):
        se = values.std() / math.sqrt(values.size)
        print(f"{name}: {values.mean():.5f} +- {se:.5f} (exact {exact:.5f}), "
              f"var {values.var():.3g}")
        assert abs(values.mean() - exact) < 4 * se + 1e-12
    ratio = area.var() / solid.var()
    print(f"variance ratio area / solid angle: {ratio:.3g}")
    assert ratio > margin


# -- fallbacks ----------------------------------------------------------------------------------

def check_consistent(shape, draws=64, by_area=None, omega=None):
    """Finite samples on the shape, with finite positive pdfs that the pdf function repeats for
    their directions; by_area (True/False) also says which technique gave them: area sampling's
    density, or exactly 1 / omega for every sample."""
    points, pdfs = shape.sample(np.random.default_rng(7).random((draws, 2)))
    assert np.isfinite(points).all() and np.isfinite(pdfs).all() and (pdfs > 0).all()
    d = points - shape.p
    w = unit(d)
    np.testing.assert_allclose(shape.pdf(w), pdfs, rtol=1e-6)
    if by_area is not None:
        area_density = np.sum(d * d, axis=1) / (shape.area * np.abs(w @ shape.normal))
        np.testing.assert_allclose(pdfs, area_density, rtol=1e-6 if by_area else 10.0)
        assert (pdfs == 1.0 / omega).all() != by_area


def test_rectangle_fallbacks():
    p, centre, ex, ey = RECTANGLES["floor below"]
    # ordinary: by solid angle (the pdf is not the area density)
    ordinary = Rectangle(p, centre, ex, ey)
    check_consistent(ordinary, by_area=False, omega=rectangle_solid_angle(*ordinary.args))
    # tiny, on both sides of the threshold, and far
    for scale in (1e-3, 1e-5, 1e-9):
        tiny = Rectangle(p, centre, scale * ex, scale * ey)
        omega = rectangle_solid_angle(*tiny.args)
        check_consistent(tiny, by_area=omega < RECTANGLE_MIN_SOLID_ANGLE, omega=omega)
    check_consistent(Rectangle(p, centre, 1e-30 * ex, 1e-30 * ey))
    assert rectangle_solid_angle(*Rectangle(p, centre, 1e-3 * ex, 1e-3 * ey).args) > \
        RECTANGLE_MIN_SOLID_ANGLE > \
        rectangle_solid_angle(*Rectangle(p, centre, 1e-5 * ex, 1e-5 * ey).args)
    far = Rectangle(p, p + 1e7 * np.array([0.1, 1.0, 0.3]), ex, ey)
    check_consistent(far, by_area=True, omega=rectangle_solid_angle(*far.args))
    # grazing: p 1e-5 below the plane, 0.5 beside the rectangle ((0.5 / 1e-5)^2 > the limit)
    assert (0.5 / 1e-5) ** 2 > RECTANGLE_MAX_GRAZING
    for beside in (np.array([0.9, -1e-5, 0.0]), np.array([0.0, -1e-5, 0.8])):   # along x, y
        grazing = Rectangle(centre + beside, centre, ex, ey)
        assert rectangle_solid_angle(*grazing.args) > RECTANGLE_MIN_SOLID_ANGLE
        check_consistent(grazing, by_area=True, omega=rectangle_solid_angle(*grazing.args))
    # a parallelogram without a right angle: by area, and its samples follow that density
    sheared = (p, centre, ex, np.array([0.2, 0.0, 0.6]))
    check_consistent(Rectangle(*sheared), by_area=True,
                     omega=rectangle_solid_angle(*Rectangle(*sheared).args))
    assert chi_square(Rectangle(*sheared), n=20000) > 1e-3
    # p in the plane: seen edge-on, no sample and no density; no rectangle at all: the same
    beside = centre + np.array([1.0, 0, 0])
    assert rectangle_sample(*beside, *centre, *ex, *ey, 0.5, 0.5)[3] == 0
    assert rectangle_pdf(*beside, *centre, *ex, *ey, -1.0, 0, 0) == 0
    assert rectangle_sample(*p, *centre, *ex, *(0 * ey), 0.5, 0.5)[3] == 0
    assert rectangle_pdf(*p, *centre, *ex, *(0 * ey), *unit(centre - p)) == 0
    # directions that miss it, or point away, have density 0
    assert rectangle_pdf(*p, *centre, *ex, *ey, *unit(centre + 0.6 * ex - p)) == 0
    assert rectangle_pdf(*p, *centre, *ex, *ey, *-unit(centre - p)) == 0


def test_triangle_fallbacks():
    p, a, b, c = TRIANGLES["ordinary"]
    check_consistent(Triangle(p, a, b, c), by_area=False,
                     omega=triangle_solid_angle(*p, *a, *b, *c))
    for scale in (1e-4, 1e-8, 1e-12):
        tiny = Triangle(p, a, a + scale * (b - a), a + scale * (c - a))
        omega = triangle_solid_angle(*tiny.args)
        check_consistent(tiny, by_area=omega < TRIANGLE_MIN_SOLID_ANGLE, omega=omega)
    assert triangle_solid_angle(*Triangle(p, a, a + 1e-8 * (b - a), a + 1e-8 * (c - a)).args) > \
        TRIANGLE_MIN_SOLID_ANGLE > \
        triangle_solid_angle(*Triangle(p, a, a + 1e-12 * (b - a), a + 1e-12 * (c - a)).args)
    check_consistent(Triangle(p, *(v + 1e8 * np.array([0.3, 1.0, 0.2]) for v in (a, b, c))))
    # by area, the barycentrics are uniform over the triangle: (s, t) uniform over the square
    tiny = Triangle(p, a, a + 1e-12 * (b - a), a + 1e-12 * (c - a))
    points, pdfs, bary = draw(TRIANGLE, tiny.args, np.random.default_rng(9).random((20000, 2)))
    total = bary.sum(axis=1)
    cells = np.minimum((np.stack([total * total, bary[:, 1] / total], axis=1) * 10).astype(int), 9)
    counts = np.bincount(cells[:, 0] * 10 + cells[:, 1], minlength=100)
    assert stats.chisquare(counts).pvalue > 1e-3
    # edge-on: p in the triangle's plane
    flat = (np.array([2.0, 0.5, 0.0]), np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    assert triangle_sample(*(v for point in flat for v in point), 0.3, 0.3)[5] == 0
    assert triangle_pdf(*(v for point in flat for v in point), -1.0, 0.0, 0.0) == 0
    # a degenerate triangle, and directions that miss
    assert triangle_sample(*p, *a, *b, *b, 0.3, 0.3)[5] == 0
    assert triangle_pdf(*p, *a, *b, *b, *unit(b - p)) == 0
    assert triangle_pdf(*p, *a, *b, *c, *-unit(a - p)) == 0
    assert triangle_pdf(*p, *a, *b, *c, *unit(2 * b - a - p)) == 0


def test_sphere_fallbacks():
    # tiny and far: finite, and on the sphere
    for centre, radius in ((np.array([0.0, 0.0, 1.0]), 1e-9), (np.array([1e6, 2e6, 0.0]), 0.5),
                           (np.array([0.0, 1.0, 0.0]), 1e-120)):
        shape = Sphere(np.zeros(3), centre, radius)
        points, pdfs = shape.sample(np.random.default_rng(8).random((32, 2)))
        assert np.isfinite(points).all() and np.isfinite(pdfs).all() and (pdfs > 0).all()
        off = np.abs(np.linalg.norm(points - centre, axis=1) - radius)
        assert (off <= 1e-9 * radius + 1e-15 * np.abs(centre).max()).all()
        assert (shape.pdf(unit(centre - shape.p)) == pdfs).all()
    # inside: area sampling, consistent; on the surface: finite
    check_consistent(Sphere(*SPHERES["inside"]))
    for u in ((0.3, 0.7), (0.0, 0.0), (0.999, 0.5)):
        assert np.isfinite(sphere_sample(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, *u)).all()
    # a sphere of radius 0, and directions that miss
    assert sphere_sample(0, 0, 0, 1.0, 0, 0, 0.0, 0.5, 0.5)[3] == 0
    assert sphere_pdf(0, 0, 0, 0, 0, 2.0, 0.5, 0, 1.0, 0) == 0
    assert sphere_pdf(0, 0, 0, 0, 0, 2.0, 0.5, 0, 0, -1.0) == 0


def test_rectangle_sampler_from_a_table_of_axes_is_the_same_bit_for_bit():
    """rectangle_sample_row (the shading kernel's, with the light's axes computed once per render
    by rectangle_axes_table, compiled or run as Python) gives rectangle_sample's numbers exactly:
    near, far, grazing, behind and on the plane, a parallelogram without a right angle and a
    degenerate one."""
    rng = np.random.default_rng(5)
    shapes = [(CENTRE, EX, EY), (CENTRE, EX, EY + 0.3 * EX), (CENTRE, EX, 2.0 * EX),
              (np.array([3.0, -2.0, 1.0]), np.array([0.0, 1e-4, 0.0]), np.array([0.0, 0.0, 2e-4]))]
    points = np.concatenate([rng.uniform(-2.0, 2.0, (40, 3)), [[0.0, 1.49, 0.0], [5.0, 1.49, 0.1],
                                                                [0.1, 1.49 - 1e-9, 0.05],
                                                                [1e4, 1.4899, 0.0]]])
    for centre, ex, ey in shapes:
        axes = rectangle_axes_table(centre[None], ex[None], ey[None])
        # a render's few lights get the table from its function run as Python: the same bits
        assert np.array_equal(interpreted(rectangle_axes_table)(centre[None], ex[None], ey[None]),
                              axes)
        shape = tuple(float(a) for a in (*centre, *ex, *ey))
        for p in points.tolist():
            for u1, u2 in rng.uniform(0.0, 1.0, (4, 2)).tolist():
                expected = rectangle_sample(*p, *shape, u1, u2)
                got = rectangle_sample_row(*p, *shape, axes, 0, u1, u2)
                assert got == expected, (centre, ex, ey, p, u1, u2)
