"""The three backends against each other: naive is the oracle for bvh (exact), bvh for embree.

One module, parametrised over the backends, on real course meshes and on degenerate inputs.
"""
import numpy as np
import pytest

import accel
import ptrace
from accel import raygen
from accel.bvh import STACK_SIZE

COURSE_MESHES = ["meshedit/cow.dae", "meshedit/teapot.dae", "sky/CBbunny.dae",
                 "sky/CBspheres.dae", "meshedit/maxplanck.dae"]


@pytest.fixture(scope="module")
def course_geometry(scenes_dir):
    cache = {}

    def get(relpath):
        if relpath not in cache:
            cache[relpath] = ptrace.load(scenes_dir / relpath).geometry
        return cache[relpath]
    return get


def ray_batches(geometry, n):
    return {
        "sphere": raygen.sphere_rays(geometry, n, seed=1),
        "camera": raygen.camera_rays(geometry, int(np.sqrt(n)), int(np.sqrt(n)), seed=2),
        "surface": raygen.surface_rays(geometry, n, seed=3),
    }


def assert_same_hits(expected, actual):
    np.testing.assert_array_equal(actual.prim, expected.prim)
    np.testing.assert_array_equal(actual.t, expected.t)
    np.testing.assert_array_equal(actual.u, expected.u)
    np.testing.assert_array_equal(actual.v, expected.v)


def compare_to_float32(geometry, rays, reference, other, label, ties=False):
    """Embree (float32) against bvh (float64): hit/miss, t and prim agreement."""
    ref_hit = reference.prim >= 0
    other_hit = other.prim >= 0
    disagree = int((ref_hit != other_hit).sum())
    both = ref_hit & other_hit
    # float32 coordinates carry an absolute error of about 1e-7 of the scene's size, and a short
    # grazing hit (a surface ray meeting a nearby fold) magnifies it to about 1e-6 of that size
    # (seen on cow), so hits shorter than 5% of the scene's radius are measured against that.
    radius = 0.5 * np.linalg.norm(np.subtract(*geometry.bounds()[::-1]))
    length = np.linalg.norm(rays.directions[both], axis=1)
    floor = 0.05 * radius / length
    rel = np.abs(other.t[both] - reference.t[both]) / np.maximum(np.abs(reference.t[both]), floor)
    prim_differs = both & (other.prim != reference.prim)
    print(f"{label}: {len(rays)} rays, {int(ref_hit.sum())} hits, hit/miss disagreements "
          f"{disagree}, prim differs {int(prim_differs.sum())}, max rel t {rel.max(initial=0):.2e}")
    assert disagree <= 1e-4 * len(rays), f"{label}: {disagree} hit/miss disagreements"
    assert rel.max(initial=0.0) <= 1e-4, f"{label}: t differs by {rel.max():.3e} relative"
    # float32 can send a ray grazing a shared edge to the neighbour, whose t the check above
    # holds to 1e-4; such rays are rare (0 of 10,000 on every course mesh, 2026-12-02). With
    # coincident primitives (ties=True) Embree may return any of them.
    if not ties:
        assert int(prim_differs.sum()) <= 1e-4 * len(rays), \
            f"{label}: {int(prim_differs.sum())} rays hit another primitive"


@pytest.mark.parametrize("relpath", COURSE_MESHES)
def test_backends_agree_on_course_meshes(course_geometry, relpath):
    geometry = course_geometry(relpath)
    large = geometry.triangle_count > 20000
    n = 4000 if large else 10000
    naive = accel.build("naive", geometry)
    bvh = accel.build("bvh", geometry)
    embree = accel.build("embree", geometry)
    for label, rays in ray_batches(geometry, n).items():
        reference = naive.intersect(rays)
        ours = bvh.intersect(rays)
        assert_same_hits(reference, ours)
        assert (reference.prim >= 0).mean() > 0.05, \
            "a ray batch that misses everything tests nothing"
        compare_to_float32(geometry, rays, ours, embree.intersect(rays), f"{relpath} {label}")
        # naive's occluded (a brute force, rays x triangles) on a large mesh's first batch only
        for backend in (naive, bvh, embree) if label == "sphere" or not large else (bvh, embree):
            hits = reference if backend is naive else backend.intersect(rays)
            np.testing.assert_array_equal(backend.occluded(rays),
                                          np.isfinite(hits.t) & (hits.t <= rays.tmax))


@pytest.mark.parametrize("relpath", ["meshedit/cow.dae", "sky/CBbunny.dae"])
def test_the_two_triangle_tests_agree_off_the_edges(course_geometry, relpath):
    """Möller–Trumbore (the option) and the watertight test (the default) are the same
    intersection computed differently: the same primitive for all but rays through an edge
    (where either neighbour is right), t and barycentrics to float64 rounding. bvh equals naive
    bit for bit with either test."""
    geometry = course_geometry(relpath)
    n = 4000 if geometry.triangle_count > 20000 else 10000   # naive is n x triangles tests
    bvh = accel.build("bvh", geometry)
    bvh_mt = accel.build("bvh", geometry, triangle="moller-trumbore")
    naive_mt = accel.build("naive", geometry, triangle="moller-trumbore")
    for label, rays in ray_batches(geometry, n).items():
        watertight = bvh.intersect(rays)
        mt = bvh_mt.intersect(rays)
        assert_same_hits(naive_mt.intersect(rays), mt)
        same = (watertight.prim == mt.prim) & (mt.prim >= 0)
        assert (watertight.prim != mt.prim).mean() <= 1e-3, label
        assert same.sum() > 0.05 * len(rays), label
        scale = np.maximum(np.abs(mt.t[same]), 1e-3)
        np.testing.assert_allclose(watertight.t[same] / scale, mt.t[same] / scale, atol=1e-9)
        np.testing.assert_allclose(watertight.u[same], mt.u[same], atol=1e-7)
        np.testing.assert_allclose(watertight.v[same], mt.v[same], atol=1e-7)


def test_unknown_triangle_test_names_the_tests():
    for kind in ("naive", "bvh"):
        with pytest.raises(ValueError, match="watertight, moller-trumbore"):
            accel.build(kind, ONE_TRIANGLE, triangle="plucker")


def test_course_spheres_are_analytic(course_geometry):
    geometry = course_geometry("sky/CBspheres.dae")
    assert geometry.sphere_count == 2
    # rays straight down onto each sphere's top hit the sphere at centre.y + r exactly-ish
    origins = geometry.centers + [0.0, 0.5, 0.0]
    rays = accel.Rays(origins, np.tile([0.0, -1.0, 0.0], (2, 1)))
    for kind in accel.KINDS:
        hits = accel.build(kind, geometry).intersect(rays)
        np.testing.assert_array_equal(hits.prim, geometry.triangle_count + np.arange(2))
        np.testing.assert_allclose(hits.t, 0.5 - geometry.radii, rtol=1e-12)


# -- contract details on small geometry ---------------------------------------------------------

ONE_TRIANGLE = accel.Geometry([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])


BACKENDS = [("naive", {}), ("bvh", {}), ("embree", {}),
            ("naive", {"triangle": "moller-trumbore"}), ("bvh", {"triangle": "moller-trumbore"})]
BACKEND_IDS = ["naive", "bvh", "embree", "naive-mt", "bvh-mt"]


@pytest.mark.parametrize("kind, options", BACKENDS, ids=BACKEND_IDS)
def test_tmin_tmax_and_barycentrics(kind, options):
    backend = accel.build(kind, ONE_TRIANGLE, **options)
    origins = np.array([[0.25, 0.5, 1.0]] * 5)
    directions = np.array([[0, 0, -1.0], [0, 0, -2.0], [0, 0, -1.0], [0, 0, -1.0], [0, 0, -1.0]])
    tmin = np.array([0.0, 0.0, 1.5, 0.0, 1.0])     # ray 2 starts past the triangle
    # ray 3 stops short; ray 4: t == tmin == tmax
    tmax = np.array([np.inf, np.inf, np.inf, 0.5, 1.0])
    hits = backend.intersect(accel.Rays(origins, directions, tmin, tmax))
    np.testing.assert_array_equal(hits.prim, [0, 0, -1, -1, 0])
    np.testing.assert_allclose(hits.t[[0, 1, 4]], [1.0, 0.5, 1.0], rtol=1e-6)
    assert np.isinf(hits.t[2]) and np.isinf(hits.t[3])
    np.testing.assert_allclose(hits.u[0], 0.25, rtol=1e-6)
    np.testing.assert_allclose(hits.v[0], 0.5, rtol=1e-6)
    np.testing.assert_array_equal(backend.occluded(accel.Rays(origins, directions, tmin, tmax)),
                                  [True, True, False, False, True])


@pytest.mark.parametrize("kind, options", BACKENDS, ids=BACKEND_IDS)
def test_axis_aligned_and_parallel_rays(kind, options):
    backend = accel.build(kind, ONE_TRIANGLE, **options)
    # directions with zero components, exactly along axes, and parallel to the triangle's plane
    origins = np.array([[0.2, 0.2, 5.0], [-1.0, 0.2, 0.0], [0.2, -1.0, 0.5], [0.3, 0.3, -2.0]])
    directions = np.array([[0, 0, -3.0], [1.0, 0, 0], [0, 1.0, 0], [0, 0, 0.5]])
    hits = backend.intersect(accel.Rays(origins, directions))
    np.testing.assert_array_equal(hits.prim, [0, -1, -1, 0])
    np.testing.assert_allclose(hits.t[[0, 3]], [5 / 3, 4.0], rtol=1e-6)


@pytest.mark.parametrize("kind", accel.KINDS)
def test_no_primitives_every_ray_misses(kind):
    empty = accel.Geometry(np.zeros((0, 3)), np.zeros((0, 3), dtype=int))
    rays = raygen.sphere_rays(ONE_TRIANGLE, 100)
    backend = accel.build(kind, empty)
    hits = backend.intersect(rays)
    assert (hits.prim == -1).all() and np.isinf(hits.t).all()
    assert not backend.occluded(rays).any()
    assert backend.stats()["primitives"] == 0


def degenerate_geometries():
    rng = np.random.default_rng(7)
    one = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    copies = accel.Geometry(np.tile(one, (1000, 1)), np.arange(3000).reshape(1000, 3))
    # 10,000 triangles sharing one centroid: rotated copies about the same centre
    angles = rng.random(10000) * 2 * np.pi
    tilt = rng.random(10000) - 0.5
    pts = np.stack([np.stack([np.cos(angles + k * 2.1), np.sin(angles + k * 2.1),
                              tilt * (k - 1)], axis=1) for k in range(3)], axis=1)
    pts -= pts.mean(axis=1, keepdims=True)
    shared = accel.Geometry(pts.reshape(-1, 3), np.arange(30000).reshape(10000, 3))
    # one huge triangle among 10,000 tiny ones
    tiny = rng.random((10000, 1, 3)) + 1e-4 * rng.random((10000, 3, 3))
    huge = np.array([[[-1e4, -1e4, 0.5], [1e4, -1e4, 0.5], [0, 1e4, 0.5]]])
    mixed_pts = np.concatenate([tiny, huge]).reshape(-1, 3)
    mixed = accel.Geometry(mixed_pts, np.arange(len(mixed_pts)).reshape(-1, 3))
    # zero-area triangles (collinear and coincident corners) beside a normal one
    zero = accel.Geometry([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 0], [0, 1, 0]],
                          [[0, 1, 2], [0, 0, 0], [0, 1, 4]])
    return {"single": ONE_TRIANGLE, "1000 copies": copies, "shared centroid": shared,
            "huge among tiny": mixed, "zero area": zero}


DEGENERATE = degenerate_geometries()


@pytest.mark.parametrize("name", list(DEGENERATE))
def test_degenerate_inputs_build_and_answer(name):
    geometry = DEGENERATE[name]
    rays = raygen.sphere_rays(geometry, 3000, seed=5)
    reference = accel.build("naive", geometry).intersect(rays)
    bvh = accel.build("bvh", geometry)
    assert_same_hits(reference, bvh.intersect(rays))
    stats = bvh.stats()
    assert stats["largest_leaf"] <= stats["max_leaf_size"]
    assert stats["max_depth"] < STACK_SIZE - 1
    compare_to_float32(geometry, rays, reference, accel.build("embree", geometry).intersect(rays),
                       name, ties=name in ("1000 copies", "shared centroid"))


@pytest.mark.parametrize("kind", accel.KINDS)
def test_nan_and_inf_are_refused(kind):
    with pytest.raises(ValueError):
        accel.Geometry([[0, 0, 0], [1, np.nan, 0], [0, 1, 0]], [[0, 1, 2]])
    with pytest.raises(ValueError):
        accel.Geometry([[0, 0, 0], [1, 0, 0], [0, np.inf, 0]], [[0, 1, 2]])
    backend = accel.build(kind, ONE_TRIANGLE)
    for origins, directions in [([[np.nan, 0, 1]], [[0, 0, -1]]), ([[0, 0, 1]], [[0, np.inf, -1]])]:
        with pytest.raises(ValueError):
            backend.intersect(accel.Rays(origins, directions))
        with pytest.raises(ValueError):
            backend.occluded(accel.Rays(origins, directions))


def test_unknown_kind_names_the_kinds():
    with pytest.raises(ValueError, match="naive, bvh, embree"):
        accel.build("octree", ONE_TRIANGLE)


TIE_BACKENDS = [("naive", {}), ("naive", dict(triangle="moller-trumbore")), ("bvh", {}),
                ("bvh", dict(split="sah")), ("bvh", dict(triangle="moller-trumbore")),
                ("bvh", dict(max_leaf_size=1))]


@pytest.mark.parametrize("kind, options", TIE_BACKENDS,
                         ids=[f"{k} {o}" if o else k for k, o in TIE_BACKENDS])
@pytest.mark.parametrize("first", [0, 3], ids=["copy first", "copy last"])
def test_a_tie_goes_to_the_lowest_primitive_id(kind, options, first):
    """The README's tie rule: coincident triangles hit at exactly the same t, and the lowest id
    wins on naive and bvh (each triangle test, each split), whichever of the two copies is
    listed first and whether or not they share a leaf (a leaf of one primitive puts them in
    different leaves). Other triangles around them keep the BVH from being a single leaf.
    Embree's float32 traversal breaks such ties as it meets them: see the next test."""
    rng = np.random.default_rng(5)
    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    clutter = rng.random((12, 3)) * 4 + [3.0, 3.0, 0.0]     # 4 triangles off to the side
    vertices = np.vstack([tri, tri, clutter])
    faces = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11], [12, 13, 14], [15, 16, 17]])
    copies = [faces[0], faces[1]]
    others = list(faces[2:])
    listed = copies[:1] + others[:first] + copies[1:] + others[first:]
    listed = np.array(listed)
    ids = [i for i, f in enumerate(listed) if f[0] in (0, 3)]
    n = 500
    origins = np.column_stack([rng.random((n, 2)) * 0.3 + 0.15, np.full(n, 2.0)])
    directions = np.column_stack([rng.normal(size=(n, 2)) * 0.05, -np.ones(n)])
    backend = accel.build(kind, accel.Geometry(vertices, listed), **options)
    hits = backend.intersect(accel.Rays(origins, directions))
    hit = hits.prim >= 0
    assert hit.sum() > 0.8 * n
    assert (hits.prim[hit] == ids[0]).all(), np.unique(hits.prim[hit])
    # the same rays against the two copies alone, in both orders: the first listed wins
    for pair in (listed[ids], listed[ids][::-1]):
        alone = accel.build(kind, accel.Geometry(vertices, pair), **options)
        again = alone.intersect(accel.Rays(origins, directions))
        np.testing.assert_array_equal(again.prim[hit], 0)
        np.testing.assert_array_equal(again.t, hits.t)


def test_embree_breaks_an_exact_tie_between_the_tied_primitives():
    """Embree does not promise the tie rule (its float32 traversal keeps whichever of equal hits
    it meets first): among 50 coincident copies it returns one of them, at their t to float32
    precision."""
    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    vertices = np.tile(tri, (50, 1))
    faces = np.arange(150).reshape(50, 3)
    rng = np.random.default_rng(9)
    origins = np.column_stack([rng.random((300, 2)) * 0.3 + 0.15, np.full(300, 2.0)])
    rays = accel.Rays(origins, np.tile([0.0, 0.0, -1.0], (300, 1)))
    embree = accel.build("embree", accel.Geometry(vertices, faces)).intersect(rays)
    naive = accel.build("naive", accel.Geometry(vertices, faces)).intersect(rays)
    assert (naive.prim == 0).all()
    assert ((embree.prim >= 0) & (embree.prim < 50)).all()
    np.testing.assert_allclose(embree.t, naive.t, rtol=1e-6)
