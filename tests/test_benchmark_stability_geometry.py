"""Pins the claims of the geometry sections of benchmarks/results/stability.md
(`python -m studies.stability`): where the BVH, Möller–Trumbore and Embree's float32 fail, and
what ptrace does there. The measurements are the report's own helpers, at the --quick sizes.

A test here that starts failing because a method got *better* (the BVH gains on overlapping
boxes, the float64 kernel becomes watertight) is asking for the report to be rerun and updated.

The report is written from the measured data alone (stability.write_report): the last tests run
the writer on made-up data and check that the text follows the numbers and that every test it
names (stability.PINS) is defined, here or in the other test files it quotes.
"""
import copy
import math

import numpy as np
import pytest

import accel
from accel import raygen
from accel.bvh import STACK_SIZE
from benchmarks import report, templating
from studies import stability

import study_checks as check

N = 4000            # triangles per distribution (the report's --quick size)
RAYS = 1000
MAX_LEAF = stability.MAX_LEAF_SIZE   # the BVH's default max_leaf_size


@pytest.fixture(scope="module", autouse=True)
def compiled_kernels():
    stability.warm_up()


# -- 1. distributions that defeat a BVH ------------------------------------------------------------
@pytest.mark.parametrize("split", ["mean", "sah"])
@pytest.mark.parametrize("name", list(stability.DISTRIBUTIONS))
def test_bvh_build_is_bounded_and_exact(name, split):
    geometry, rays = stability.study_rays(name, N, RAYS)
    bvh, seconds, python_peak = stability.measured_build(geometry, split)
    stats = bvh.stats()
    P = geometry.primitive_count
    # time: measured 0.003-0.03 s at this size; 2 s means the build went superlinear
    assert seconds < 2.0, seconds
    # the depth accel/bvh.py documents: mean/SAH splits to MEAN_SPLIT_DEPTH, then count splits
    assert stats["max_depth"] <= stability.depth_bound(P) < STACK_SIZE - 1
    assert stats["largest_leaf"] <= MAX_LEAF
    assert stats["nodes"] <= 2 * P - 1
    # memory: the traversal's arrays within their layout's bound, numpy temporaries linear
    assert stats["bytes"] <= stability.allocated_node_bytes(P)
    # measured about 365 bytes per triangle, most of it the traversal's own arrays (a leaf's
    # triangles take a 288-byte block of four)
    assert python_peak <= 500 * P, python_peak
    # answers never depend on the tree
    reference = accel.build("naive", geometry).intersect(rays)
    assert stability.same_hits(bvh.intersect(rays), reference)


@pytest.mark.parametrize("name", ["identical", "concentric"])
def test_coincident_centroids_give_a_balanced_count_split_tree(name):
    geometry, _ = stability.distribution(name, N)
    for split in ("mean", "sah"):
        bvh = accel.build("bvh", geometry, split=split)
        assert bvh.max_depth <= math.ceil(math.log2(N / MAX_LEAF)), (split, bvh.max_depth)


def test_bvh_gains_nothing_when_all_boxes_overlap():
    """The report's failure claim: identical triangles make every ray visit every node;
    concentric triangles and slivers make rays visit a large share of the tree (visits count
    the traversal's 8-wide nodes)."""
    visits = {}
    for name in ("identical", "concentric", "slivers"):
        geometry, rays = stability.study_rays(name, N, RAYS)
        bvh = accel.build("bvh", geometry)
        visits[name] = bvh.traversal_work(rays)[0] / bvh.stats()["wide_nodes"]
    assert visits["identical"] == 1.0
    assert visits["concentric"] > 0.25 and visits["slivers"] > 0.25, visits


@pytest.mark.parametrize("split", ["mean", "sah"])
def test_bvh_visits_few_nodes_where_the_split_still_works(split):
    """uniform, cluster+outliers and huge+small: measured 9-51 nodes per ray (of 2,000-2,700)."""
    for name in ("uniform", "cluster+outliers", "huge+small"):
        geometry, rays = stability.study_rays(name, N, RAYS)
        bvh = accel.build("bvh", geometry, split=split)
        visits = bvh.traversal_work(rays)[0]
        assert visits <= 100, (name, visits)


# -- 2. cracks: the watertight test against Möller–Trumbore ---------------------------------------
@pytest.mark.parametrize("mesh", ["icosphere", "cube"])
def test_the_watertight_test_never_leaks_on_closed_meshes(mesh):
    """The default triangle test: no ray aimed at an edge or a vertex of a closed mesh passes
    through it, in any (scale, offset) cell of the report's grid (1e-3..1e6, up to 1e6), with
    naive and bvh, which agree ray for ray."""
    vertices, faces = stability.closed_meshes()[mesh]
    for kind in ("naive", "bvh"):
        grid, _ = stability.leak_grid(kind, vertices, faces)
        assert grid.sum() == 0, (kind, grid)
    for scale in stability.SCALES[::3]:
        for offset in stability.OFFSETS[::3]:
            geometry, rays, _ = stability.crack_rays(vertices, faces, scale, offset)
            assert stability.same_hits(accel.build("bvh", geometry).intersect(rays),
                                       accel.build("naive", geometry).intersect(rays))


# largest measured leak rate in one (s, |d|) cell with Möller–Trumbore: icosphere 4.8%, cube 3.8%
CRACK_BOUND = {"icosphere": 0.06, "cube": 0.05}


@pytest.mark.parametrize("mesh", ["icosphere", "cube"])
def test_moller_trumbore_leaks_stay_bounded(mesh):
    vertices, faces = stability.closed_meshes()[mesh]
    grid, per_cell = stability.leak_grid("naive-mt", vertices, faces)
    assert grid.max() <= CRACK_BOUND[mesh] * per_cell, grid.max() / per_cell
    for scale in stability.SCALES[::3]:           # bvh answers exactly like naive, ray for ray
        for offset in stability.OFFSETS[::3]:
            geometry, rays, _ = stability.crack_rays(vertices, faces, scale, offset)
            assert stability.same_hits(stability.build("bvh-mt", geometry).intersect(rays),
                                       stability.build("naive-mt", geometry).intersect(rays))


def test_moller_trumbore_is_not_watertight():
    """The option the report compares against still leaks where the watertight test does not:
    rays aimed exactly at the icosphere's shared edges pass through Möller–Trumbore."""
    vertices, faces = stability.closed_meshes()["icosphere"]
    geometry, rays, _ = stability.crack_rays(vertices, faces, 1.0, 0.0)
    leaked = (accel.build("naive", geometry, triangle="moller-trumbore").intersect(rays).prim
              < 0).sum()
    assert leaked > 0
    assert (accel.build("naive", geometry).intersect(rays).prim < 0).sum() == 0


@pytest.mark.parametrize("mesh", ["icosphere", "cube"])
def test_embree_never_leaks_on_closed_meshes(mesh):
    vertices, faces = stability.closed_meshes()[mesh]
    grid, _ = stability.leak_grid("embree", vertices, faces)
    assert grid.sum() == 0, grid
    # without re-centring the float32 mesh collapses where |d|/s >= 1e7, and only there
    before, per_cell = stability.leak_grid("embree-not-recentred", vertices, faces)
    relative = np.array([[d / s for d in stability.OFFSETS] for s in stability.SCALES])
    assert before[relative < 1e7].sum() == 0
    assert before[relative >= 1e9].min() > 0.9 * per_cell     # measured: every ray


def test_random_rays_do_not_leak():
    """The report's control: rays not aimed at edges do not find the cracks."""
    for vertices, faces in stability.closed_meshes().values():
        for kind in ("naive", "naive-mt", "embree"):
            for scale, offset in ((1.0, 0.0), (1e-3, 1e6)):
                assert stability.random_leaks(kind, vertices, faces, scale, offset, 20000) == 0


# -- 3. embree far from the origin -----------------------------------------------------------------
def test_embree_agrees_with_bvh_far_from_origin(course_scene):
    import ptrace
    geometry = ptrace.load(course_scene("meshedit/cow.dae")).geometry
    rays = raygen.sphere_rays(geometry, 5000, seed=3)
    rates = stability.far_disagreement(geometry, rays,
                                       kinds=("embree", "embree-not-recentred"))
    after = [r["any"] for r in rates["embree"]]
    assert max(after) <= 0.001, after              # measured 0 of 5,000 at every m = 1..1e7
    before = dict(zip(stability.FAR_MAGNITUDES, (r["any"] for r in rates["embree-not-recentred"])))
    assert before[1e5] > 0.10, before              # measured 60%: the test has teeth


def test_embree_recentring_survives_far_outliers():
    rates = stability.outlier_disagreement(N, 2000)
    assert rates["embree"]["any"] <= 0.001, rates["embree"]
    assert rates["embree-box-centre"]["any"] > 0.10, rates["embree-box-centre"]   # measured 36%


# -- the report: written from the data alone -------------------------------------------------------
def test_every_pinned_test_exists():
    """The report names the tests of stability.PINS: each is a test function of its file (this
    one's by name here, so renaming one of them fails this test until PINS follows)."""
    here = {name for name, value in globals().items() if name.startswith("test_")
            and callable(value)}
    for path, function in stability.PINS.values():
        assert function in (here if path == stability.GEOMETRY_TESTS
                            else templating.defined_tests(path)), (path, function)


def disagreement(rate):
    return dict(hit_miss=rate, prim=rate / 2, t=rate / 4, any=rate)


def synthetic_data():
    """Made-up measurements with the shape of stability.measure's (no light sections)."""
    def bvh(rate, visits):
        return dict(build_seconds=0.0126, nodes=1999, wide_nodes=700, depth=12, largest_leaf=4,
                    mean_leaf=2.5, bytes=128_000, allocated_bytes=130_000,
                    python_peak_bytes=900_000, rays_per_second=rate, mean_visits=visits,
                    mean_tests=12.0, exact=True)

    results = {name: {"naive": dict(rays_per_second=1000.0), "bvh-mean": bvh(50_000.0, 40.0),
                      "bvh-sah": bvh(60_000.0, 30.0), "hit_fraction": 0.5,
                      "embree": dict(build_seconds=0.002, rays_per_second=200_000.0,
                                     same_prim=1.0)}
               for name in stability.DISTRIBUTIONS}
    results["identical"]["bvh-mean"]["rays_per_second"] = 2000.0
    cells = [[0] * len(stability.OFFSETS) for _ in stability.SCALES]
    grids = {mesh: {kind: dict(leaked=copy.deepcopy(cells), rays_per_cell=1000)
                    for kind in stability.CRACK_KINDS} for mesh in ("icosphere", "cube")}
    for mesh in grids:
        for kind in ("naive-mt", "bvh-mt"):
            grids[mesh][kind]["leaked"][2][3] = 30          # s = 0.1, |d| = 0.01: 3.0%
    grids["cube"]["bvh"]["leaked"][0][0] = 2                 # the watertight default leaked 2
    grids["cube"]["embree-not-recentred"]["leaked"][0][-1] = 1000     # |d|/s = 1e9
    labels = ("outside edge", "outside vertex", "inside edge", "inside vertex")
    magnitudes, distances = stability.FAR_MAGNITUDES, [10.0 ** k for k in range(1, 8)]
    return {
        "run": dict(quick=True, threads=2, niceness=0, load=0.0, cores=2, seconds=12.0),
        "distributions": dict(triangles=4000, rays=1000, ray_seed=1, depth_bound=24,
                              mean_split_depth=12, stack_size=64, max_leaf_size=4,
                              allocated_bytes=600_000, results=results),
        "cracks": dict(scales=stability.SCALES, offsets=stability.OFFSETS,
                       triangles=dict(icosphere=320, cube=192), grids=grids, random_rays=500,
                       random_cases=[[1.0, 0.0]],
                       random_leaks={m: {"naive": 0, "naive-mt": 0, "embree": 0}
                                     for m in grids},
                       breakdown={m: {label: dict(missed=1, rays=10) for label in labels}
                                  for m in grids}),
        "far": dict(triangles=5856, box=[0.81, 1.46, 1.48], rays=5000, seed=3,
                    t_tolerance=1e-4, magnitudes=magnitudes,
                    moved={"embree-not-recentred": [disagreement(m / 1e7) for m in magnitudes],
                           "embree-box-centre": [disagreement(0.0) for m in magnitudes],
                           "embree": [disagreement(0.0) for m in magnitudes]},
                    distances=distances, camera=[disagreement(0.0) for d in distances],
                    camera_not_clipped=[disagreement(d / 1e8) for d in distances],
                    outlier_triangles=4000,
                    outliers={kind: disagreement(0.36 if kind == "embree-box-centre" else 0.0)
                              for kind in stability.FAR_KINDS})}


GEOMETRY_CHARTS = ["stability_distributions.png", "stability_cracks.png", "stability_far.png"]


@pytest.fixture
def geometry_only(monkeypatch, tmp_path):
    """stability's report without the light-transport sections, written into tmp_path."""
    monkeypatch.setattr(stability, "SECTIONS", [s for s in stability.SECTIONS if s[0] != "light"])
    monkeypatch.setattr(report, "RESULTS", tmp_path)


def test_report_follows_the_data(geometry_only, tmp_path):
    data = synthetic_data()
    _, text = check.written(stability.write_report, data, "stability.md")
    check.charts(tmp_path, GEOMETRY_CHARTS)
    check.tables(text)
    quoted = check.quoted_tests(text)
    assert set(quoted) == set(stability.PINS.values())    # every pinned test is quoted
    # the figures are the data's
    check.says(text,
               "| identical | the whole scene | 50% | bvh-mean | 0.013 | 1,999 | 700 | 12 |",
               "the mean split ran at 2.0x and 50.0x naive's speed on them",
               "leaked 0.03% of the rays aimed at the icosphere's edges",
               "at most 3.0% in one cell, 1 of 110 cells",
               "They leaked 2 rays in the whole grid",
               "all in cells where |d|/s >= 1e+09",
               "reached 0.1% at 1e4, 1.0% at 1e5 and 100.0% at 1e7",
               "a camera R = 1e5 away from the cow disagreed on 0.1% of rays, at 1e7 on 10.0%",
               "With the clipping a camera 1e5 away disagrees on 0.00% of rays",
               "Total time 12 s.", "Quick mode (--quick)")
    # ... and a changed number changes the report
    changed = copy.deepcopy(data)
    changed["distributions"]["results"]["identical"]["bvh-mean"]["rays_per_second"] = 3000.0
    changed["far"]["moved"]["embree-not-recentred"][5]["any"] = 0.6
    changed["cracks"]["grids"]["icosphere"]["naive-mt"]["leaked"][2][3] = 50
    again = stability.write_report(changed, "changed.md").read_text()
    check.says(again, "the mean split ran at 3.0x and 50.0x",
               "| identical | the whole scene | 50% | bvh-mean |",
               "reached 0.1% at 1e4, 60.0% at 1e5", "at most 5.0% in one cell")
    assert "identical grids" not in text             # the watertight naive != bvh in the data
    grids = changed["cracks"]["grids"]
    grids["cube"]["bvh"]["leaked"][0][0] = 0
    grids["icosphere"]["bvh-mt"]["leaked"][2][3] = 50
    assert "identical grids" in stability.write_report(changed, "same.md").read_text()


def test_a_renamed_test_stops_the_report(geometry_only, monkeypatch):
    check.renamed_pin_stops(monkeypatch, stability.PINS, "bounded",
                            lambda: stability.write_report(synthetic_data(), "stability.md"))


@pytest.mark.slow
def test_quick_report_writes_markdown_json_and_charts(tmp_path, monkeypatch):
    text = check.quick_run(stability.main, tmp_path / "stability.md")
    for heading in ("## 1.", "## 2.", "## 3.", "## Hemisphere", "## Adaptive",
                    "## Russian roulette", "## Fireflies", "## Studied in the tests"):
        assert heading in text
    assert "NOT all exact" not in text and "DID NOT REPRODUCE" not in text
    check.charts(tmp_path, GEOMETRY_CHARTS + [f"stability_light_{name}.png" for name in (
        "hemisphere", "adaptive", "roulette", "fireflies")])
    check.tables(text)
    check.quoted_tests(text)
    # the report is a function of the JSON beside it: written again from it, the same text
    data = check.written_again(monkeypatch, stability.write_report, tmp_path / "stability.md",
                               skip=("- date", "- command"))
    assert data["run"]["quick"] and set(data) >= {"distributions", "cracks", "far", "light"}
    assert not list(tmp_path.glob("*.tmp"))
