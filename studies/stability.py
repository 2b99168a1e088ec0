"""Where methods fail: the inputs that defeat each method, measured, and what ptrace does there.

    python -m studies.stability [--quick] [--threads 2] [--output stability.md]

Writes benchmarks/results/stability.md (or --output, relative to benchmarks/results/), its PNG
charts beside it and the measured data as stability.json beside it; a --quick run without
--output goes to a new temporary directory (printed), never over the full report. The report
has the geometry sections below, the light-transport sections of studies/stability_light.py
and the failure regimes studied in the tests themselves.

Measuring and writing are apart. measure(quick) runs every study of SECTIONS and returns plain
data (dicts, lists, numbers, strings: what stability.json holds); write_report(data) writes the
report from that data alone, filling the named blocks of benchmarks/templates/stability.md (the
prose, with str.format fields) from the fields that each write_* function computes. A new study
is one more (name, measure, write) entry of SECTIONS. The tests a section quotes are PINS
entries, checked to exist in their files when the report is written. The geometry sections:

1. BVH-defeating primitive distributions: build figures, nodes visited and rays per second of
   bvh (mean split), bvh (split="sah"), embree and naive on the same rays.
2. Möller–Trumbore cracks: rays aimed exactly at the shared edges and vertices of closed meshes,
   scaled by s and moved by d; the fraction that leaks through.
3. Embree's float32 far from the origin: how often it disagrees with bvh as the cow moves away,
   with and without the re-centring that accel/embree.py does.

tests/test_benchmark_stability_geometry.py pins the claims of the report with the helpers below.
"""
import inspect
import math
import os
import time
import tracemalloc
from pathlib import Path

import numba
import numpy as np

import accel
from accel import raygen
from accel.bvh import MEAN_SPLIT_DEPTH, STACK_SIZE, BVHAccelerator
from accel.embree import EmbreeAccelerator
from benchmarks import templating
from benchmarks.rays import scenes_dir
from benchmarks.templating import blocks, fill, join, pinned_ids, pins_by_file, plain
from ptrace.integrator import OFFSET

REPRODUCE = "python -m studies.stability"
AXIS = np.array([1.0, 0.7, 0.3]) / np.linalg.norm([1.0, 0.7, 0.3])   # direction of every offset
RAY_SEED = 1        # section 1's rays
COW_SEED = 3        # section 3's rays
TEMPLATE = "stability.md"
GEOMETRY_TESTS = "tests/test_benchmark_stability_geometry.py"
STABILITY_TESTS = "tests/ptrace/test_stability.py"
# claim -> (test file, test function), written file by file: the tests the report quotes, by
# the field names of the template (`{test[claim]}` prints file::function, `{short[claim]}`
# ::function)
PINS = pins_by_file({
    GEOMETRY_TESTS: {
        "bounded": "test_bvh_build_is_bounded_and_exact",
        "coincident": "test_coincident_centroids_give_a_balanced_count_split_tree",
        "few_visits": "test_bvh_visits_few_nodes_where_the_split_still_works",
        "overlap": "test_bvh_gains_nothing_when_all_boxes_overlap",
        "watertight": "test_the_watertight_test_never_leaks_on_closed_meshes",
        "crack_bound": "test_moller_trumbore_leaks_stay_bounded",
        "embree_closed": "test_embree_never_leaks_on_closed_meshes",
        "random": "test_random_rays_do_not_leak",
        "not_watertight": "test_moller_trumbore_is_not_watertight",
        "far": "test_embree_agrees_with_bvh_far_from_origin",
        "outliers": "test_embree_recentring_survives_far_outliers"},
    "tests/accel/test_embree_far_camera.py": {
        "far_camera": "test_a_far_camera_agrees_with_bvh_on_the_cow",
        "far_camera_teeth": "test_without_the_clipping_a_far_camera_disagrees"},
    STABILITY_TESTS: {
        "self_hit": "test_spawned_rays_never_rehit_their_own_triangle",
        "spheres": "test_spawned_rays_leave_spheres",
        "non_finite": "test_no_non_finite_pixel_in_any_course_scene"},
    "tests/ptrace/test_light_transport.py": {
        "quad_shadow": "test_the_quad_on_the_area_light_does_not_shadow_it"},
    "tests/test_benchmark_stability_light.py": {
        "wide_floor": "test_emitter_on_the_light_does_not_shadow_a_wide_floor"},
    "tests/ptrace/test_malformed_corpus.py": {
        "malformed": "test_every_malformed_file_fails_cleanly"},
})


# -- shared helpers ----------------------------------------------------------------------------
def warm_up():
    """Load every kernel from numba's cache (or compile it) so no timing includes the JIT."""
    tiny = accel.Geometry([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    rays = raygen.sphere_rays(tiny, 8)
    for kind in accel.KINDS:
        accel.build(kind, tiny).intersect(rays)
    accel.build("bvh", tiny, split="sah").intersect(rays)


def rays_per_second(backend, rays, min_seconds=0.2, max_repeats=20):
    """(hits, rays/s): the best of repeated intersect() calls lasting at least min_seconds."""
    best = math.inf
    total = 0.0
    hits = None
    for _ in range(max_repeats):
        start = time.perf_counter()
        hits = backend.intersect(rays)
        seconds = time.perf_counter() - start
        best = min(best, seconds)
        total += seconds
        if total >= min_seconds:
            break
    return hits, len(rays) / max(best, 1e-9)


def same_hits(a, b):
    """Exactly the same answer: t, primitive and barycentrics, bit for bit."""
    return all(np.array_equal(x, y) for x, y in ((a.t, b.t), (a.prim, b.prim), (a.u, b.u),
                                                  (a.v, b.v)))


def triangle_soup(corners):
    """Geometry of independent triangles from corners of shape (n, 3, 3)."""
    n = corners.shape[0]
    return accel.Geometry(corners.reshape(-1, 3), np.arange(3 * n).reshape(n, 3))


def pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save_chart(plt, figure, chart_dir, name):
    """Lay out, save into chart_dir and close a chart; return its file name for the report."""
    figure.tight_layout()
    figure.savefig(Path(chart_dir) / name, dpi=100)
    plt.close(figure)
    return name


def rate_axis(axis, xlabel, ylabel):
    """A chart of rates against sizes: log x, y from 0 to 1.5 on a symlog scale (linear below
    1e-3, so a rate of 0 shows)."""
    axis.set_xscale("log")
    axis.set_yscale("symlog", linthresh=1e-3)
    axis.set_ylim(0, 1.5)
    axis.set_xlabel(xlabel)
    axis.set_ylabel(ylabel)


def exponent(x):
    """The power of ten x is (1e-3 -> -3)."""
    return int(round(math.log10(x)))


# -- 1. distributions that defeat a BVH ----------------------------------------------------------
def uniform(n, seed=0):
    """Baseline: small random triangles (edge about 0.02) spread through the unit cube."""
    rng = np.random.default_rng(seed)
    return triangle_soup(rng.random((n, 1, 3)) + 0.01 * rng.normal(size=(n, 3, 3)))


def identical(n):
    """n copies of one triangle: every centroid equal, every box equal."""
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.5], [0.0, 1.0, -0.5]])
    return accel.Geometry(vertices, np.tile([0, 1, 2], (n, 1)))


def concentric(n, seed=0):
    """n different triangles, random sizes and orientations, all with box centre exactly 0.

    Integer corners where each axis takes -a, +a and one value between: the box on that axis is
    [-a, a], so every centroid (box centre) is exactly the origin in floating point.
    """
    rng = np.random.default_rng(seed)
    half = rng.integers(1, 1000, size=(n, 3)).astype(float)
    middle = np.clip(rng.integers(-999, 1000, size=(n, 3)).astype(float), -half, half)
    corners = np.stack([-half, half, middle], axis=1)            # (n, corner, axis)
    order = np.argsort(rng.random((n, 3, 3)), axis=1)            # shuffle corners per axis
    return triangle_soup(np.take_along_axis(corners, order, axis=1))


def cluster_with_outliers(n, outliers=8, seed=0):
    """n - outliers small triangles in the unit cube and `outliers` ones 1e6 away."""
    rng = np.random.default_rng(seed)
    far = rng.normal(size=(outliers, 1, 3))
    far = 1e6 * far / np.linalg.norm(far, axis=2, keepdims=True)
    centres = np.concatenate([rng.random((n - outliers, 1, 3)), far])
    return triangle_soup(centres + 0.01 * rng.normal(size=(n, 3, 3)))


def slivers(n, seed=0):
    """Long thin triangles (length 4, width about 1e-3) through random points of a cube of side 2:
    every one spans the scene, so every box is about as large as the scene."""
    rng = np.random.default_rng(seed)
    middle = 2 * rng.random((n, 3)) - 1
    along = rng.normal(size=(n, 3))
    along /= np.linalg.norm(along, axis=1, keepdims=True)
    corners = np.stack([middle - 2 * along, middle + 2 * along,
                        middle + 1e-3 * rng.normal(size=(n, 3))], axis=1)
    return triangle_soup(corners)


def huge_among_small(n, seed=0):
    """A height-field grid of n - 1 small triangles over the unit square and, in the middle of
    the face list, one triangle 1e3 times the grid's size standing across it (plane x = 0.5)."""
    rng = np.random.default_rng(seed)
    k = max(1, int(math.sqrt((n - 1) / 2)))
    xs = np.linspace(0.0, 1.0, k + 1)
    gx, gy = np.meshgrid(xs, xs)
    vertices = np.stack([gx.ravel(), gy.ravel(), 0.01 * rng.random(gx.size)], axis=1)
    i = (np.arange(k)[:, None] * (k + 1) + np.arange(k)[None, :]).ravel()
    faces = np.concatenate([np.stack([i, i + 1, i + k + 1], 1),
                            np.stack([i + 1, i + k + 2, i + k + 1], 1)])
    big = np.array([[0.5, -1e3, -1e3], [0.5, 1e3, -1e3], [0.5, 0.0, 1e3]])
    first = len(vertices)
    faces = np.concatenate([faces[:len(faces) // 2], [[first, first + 1, first + 2]],
                            faces[len(faces) // 2:]])
    return accel.Geometry(np.concatenate([vertices, big]), faces)


# name -> (builder, what it is, what the rays aim at)
DISTRIBUTIONS = {
    "uniform": (uniform, "baseline: small triangles spread through a cube", "the whole scene"),
    "identical": (identical, "all triangles the same triangle", "the whole scene"),
    "concentric": (concentric, "different triangles, all box centres exactly equal",
                   "the whole scene"),
    "cluster+outliers": (cluster_with_outliers, "a dense cluster and 8 triangles 1e6 away",
                         "the cluster"),
    "slivers": (slivers, "long thin triangles each spanning the scene", "the whole scene"),
    "huge+small": (huge_among_small, "a grid of small triangles and one 1e3 times larger",
                   "the grid"),
}


def distribution(name, n):
    """(geometry, rays target geometry) for a DISTRIBUTIONS entry with n triangles."""
    geometry = DISTRIBUTIONS[name][0](n)
    if name == "cluster+outliers":   # rays at the cluster, not at the empty box the outliers span
        target = accel.Geometry(geometry.vertices[:3 * (n - 8)], geometry.faces[:n - 8])
    elif name == "huge+small":   # rays at the grid; the huge triangle is in the middle
        middle = (geometry.triangle_count - 1) // 2
        big = geometry.faces[middle]
        keep = np.ones(geometry.triangle_count, dtype=bool)
        keep[middle] = False
        assert (geometry.vertices[big][:, 1] == [-1e3, 1e3, 0.0]).all()
        target = accel.Geometry(geometry.vertices, geometry.faces[keep])
    else:
        target = geometry
    return geometry, target


def study_rays(name, n, rays, seed=RAY_SEED):
    geometry, target = distribution(name, n)
    return geometry, raygen.sphere_rays(target, rays, seed=seed)


def allocated_node_bytes(primitives):
    """The bound accel/bvh.py's layout puts on what its traversal keeps (stats()['bytes']): a
    wide row (256 bytes) per interior node folded into it and a block of four triangles (288
    bytes of coordinates, 32 of primitive ids) per leaf block, and there are at most P of each
    (every wide row holds at least one interior binary node, every block at least one
    primitive)."""
    return primitives * (256 + 288 + 32)


def measured_build(geometry, split):
    """(bvh, build seconds, tracemalloc's peak bytes of another identical build), both after a
    first build that compiles what the split's build needs (each split compiles its own)."""
    accel.build("bvh", geometry, split=split)
    start = time.perf_counter()
    bvh = accel.build("bvh", geometry, split=split)
    seconds = time.perf_counter() - start
    tracemalloc.start()
    accel.build("bvh", geometry, split=split)
    python_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return bvh, seconds, python_peak


def measure_distribution(name, n, rays_count, min_seconds=0.2):
    """Every figure of section 1 for one distribution: a dict per method."""
    geometry, rays = study_rays(name, n, rays_count)
    naive = accel.build("naive", geometry)
    reference, naive_rate = rays_per_second(naive, rays, min_seconds, max_repeats=3)
    rows = {"naive": {"rays_per_second": naive_rate}}
    for split in ("mean", "sah"):
        bvh, build_seconds, python_peak = measured_build(geometry, split)
        stats = bvh.stats()
        leaves = bvh.count[bvh.count > 0]
        hits, rate = rays_per_second(bvh, rays, min_seconds)
        visits, tests = bvh.traversal_work(rays)
        rows[f"bvh-{split}"] = {
            "build_seconds": build_seconds, "nodes": stats["nodes"],
            "wide_nodes": stats["wide_nodes"], "depth": stats["max_depth"],
            "largest_leaf": stats["largest_leaf"],
            "mean_leaf": float(leaves.mean()), "bytes": stats["bytes"],
            "allocated_bytes": allocated_node_bytes(geometry.primitive_count),
            "python_peak_bytes": python_peak, "rays_per_second": rate,
            "mean_visits": visits, "mean_tests": tests,
            "exact": same_hits(hits, reference)}
    embree = accel.build("embree", geometry)
    hits, rate = rays_per_second(embree, rays, min_seconds)
    rows["embree"] = {"build_seconds": embree.stats()["build_seconds"], "rays_per_second": rate,
                      "same_prim": float(np.mean(hits.prim == reference.prim))}
    rows["hit_fraction"] = float(np.mean(reference.prim >= 0))
    return rows


def depth_bound(primitives):
    """The depth accel/bvh.py documents: mean (or SAH) splits down to MEAN_SPLIT_DEPTH, then
    count splits, which halve: at most MEAN_SPLIT_DEPTH + log2(P), below the stack's size."""
    return MEAN_SPLIT_DEPTH + math.ceil(math.log2(max(primitives, 2)))


MAX_LEAF_SIZE = inspect.signature(BVHAccelerator).parameters["max_leaf_size"].default
BVH_METHODS = ("bvh-mean", "bvh-sah")


def measure_distributions(quick):
    """Section 1's data: every distribution's figures (measure_distribution) at the report's
    size, and the bounds the build promises at that size."""
    n, rays_count = (4000, 1000) if quick else (20000, 4000)
    results = {}
    for name in DISTRIBUTIONS:
        results[name] = measure_distribution(name, n, rays_count, 0.05 if quick else 0.3)
        print(f"distribution {name}: done", flush=True)
    return plain(dict(triangles=n, rays=rays_count, ray_seed=RAY_SEED,
                      depth_bound=depth_bound(n), mean_split_depth=MEAN_SPLIT_DEPTH,
                      stack_size=STACK_SIZE, max_leaf_size=MAX_LEAF_SIZE,
                      allocated_bytes=allocated_node_bytes(n), results=results))


def distribution_rows(data):
    """The table rows of section 1, as fields of the row blocks."""
    rows = []
    for name, r in data["results"].items():
        naive = r["naive"]["rays_per_second"]
        common = dict(name=name, target=DISTRIBUTIONS[name][2], naive=naive)
        for method in BVH_METHODS:
            m = r[method]
            rows.append(("distributions_row_bvh", {
                **common, **m, "method": method, "hit": r["hit_fraction"],
                "mb": m["bytes"] / 1e6, "allocated_mb": m["allocated_bytes"] / 1e6,
                "peak_mb": m["python_peak_bytes"] / 1e6,
                "tests": "" if m["mean_tests"] is None else format(m["mean_tests"], ",.0f"),
                "speedup": m["rays_per_second"] / naive, "exact": "yes" if m["exact"] else "NO"}))
        e = r["embree"]
        rows.append(("distributions_row_embree",
                     {**common, **e, "speedup": e["rays_per_second"] / naive}))
        rows.append(("distributions_row_naive", {**common, "tests": data["triangles"]}))
    return rows


def write_distributions(data, chart_dir):
    text = blocks(TEMPLATE)
    results = data["results"]
    bvh = [r[m] for r in results.values() for m in BVH_METHODS]
    ratio = {name: {m: r[m]["rays_per_second"] / r["naive"]["rays_per_second"]
                    for m in (*BVH_METHODS, "embree")} for name, r in results.items()}
    return fill(
        text["distributions"], data, pinned_ids(PINS),
        rows="\n".join(fill(text[block], row) for block, row in distribution_rows(data)),
        chart=chart_distributions(chart_dir, data), ratio=ratio,
        visits={name: r["bvh-mean"]["mean_visits"] for name, r in results.items()},
        worst_depth=max(r["depth"] for r in bvh), worst_leaf=max(r["largest_leaf"] for r in bvh),
        worst_build=max(r["build_seconds"] for r in bvh),
        allocated_mb=data["allocated_bytes"] / 1e6,
        exact="all exact" if all(r["exact"] for r in bvh) else "NOT all exact")


def chart_distributions(chart_dir, data):
    plt = pyplot()
    results = data["results"]
    names = list(results)
    methods = ["naive", *BVH_METHODS, "embree"]
    figure, axes = plt.subplots(figsize=(9, 4))
    width = 0.2
    for i, method in enumerate(methods):
        rates = [results[name][method]["rays_per_second"] for name in names]
        axes.bar(np.arange(len(names)) + (i - 1.5) * width, rates, width, label=method)
    axes.set_xticks(np.arange(len(names)), names)
    axes.set_yscale("log")
    axes.set_ylabel("rays per second")
    axes.set_title("Rays per second on BVH-defeating distributions")
    axes.legend()
    return save_chart(plt, figure, chart_dir, "stability_distributions.png")


# -- 2. Möller–Trumbore cracks ----------------------------------------------------------------
SCALES = [10.0 ** k for k in range(-3, 7)]
OFFSETS = [0.0] + [10.0 ** k for k in range(-3, 7)]


class NotRecentredEmbree(EmbreeAccelerator):
    """The embree backend as it was before this study: float32 of the raw coordinates. For
    measuring what re-centring buys; never used by ptrace."""

    def centre(self, geometry):
        return np.zeros(3)


class BoxCentredEmbree(EmbreeAccelerator):
    """Re-centred on the centre of the triangles' bounding box instead of ptrace's median of the
    vertices."""

    def centre(self, geometry):
        if geometry.triangle_count == 0:
            return np.zeros(3)
        corners = geometry.vertices[geometry.faces.reshape(-1)]
        return 0.5 * (corners.min(axis=0) + corners.max(axis=0))


EMBREE_VARIANTS = {"embree-not-recentred": NotRecentredEmbree,
                   "embree-box-centre": BoxCentredEmbree}


MT = "-mt"   # suffix of a kind built with the Möller–Trumbore triangle test (naive-mt, bvh-mt)


def build(kind, geometry):
    """accel.build, plus the measurement-only embree variants of EMBREE_VARIANTS and naive or bvh
    with triangle="moller-trumbore" (kind + MT)."""
    if kind == "embree-not-recentred":   # before this study: no re-centring, no clipping
        return NotRecentredEmbree(geometry, clip_to_bounds=False)
    if kind in EMBREE_VARIANTS:
        return EMBREE_VARIANTS[kind](geometry)
    if kind.endswith(MT):
        return accel.build(kind[:-len(MT)], geometry, triangle="moller-trumbore")
    return accel.build(kind, geometry)


def closed_meshes():
    """Closed (watertight, vertex-sharing) meshes centred on the origin: name -> (V, F)."""
    import trimesh
    sphere = trimesh.creation.icosphere(subdivisions=2)
    box = trimesh.creation.box()
    vertices, faces = trimesh.remesh.subdivide(box.vertices, box.faces)
    vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    return {"icosphere": (np.asarray(sphere.vertices), np.asarray(sphere.faces)),
            "cube": (np.asarray(vertices), np.asarray(faces))}


def unique_edges(faces):
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(edges, axis=0)


def crack_rays(vertices, faces, scale, offset):
    """The mesh scaled by `scale` and moved by offset * AXIS, and rays that must hit it.

    Targets: every edge's midpoint and every vertex, computed from the moved vertices. Rays
    from outside (twice as far from the centre as the target) through the target toward the
    centre, then rays from the centre out through each target. Returns (geometry, rays, labels)
    with labels[i] in {"outside edge", "outside vertex", "inside edge", "inside vertex"}.
    """
    moved = scale * vertices + offset * AXIS
    centre = offset * AXIS
    edges = unique_edges(faces)
    targets = np.concatenate([0.5 * (moved[edges[:, 0]] + moved[edges[:, 1]]), moved])
    kind = np.array(["edge"] * len(edges) + ["vertex"] * len(moved))
    outside = centre + 2.0 * (targets - centre)
    origins = np.concatenate([outside, np.broadcast_to(centre, targets.shape)])
    directions = np.concatenate([centre - outside, targets - centre])
    labels = np.concatenate([np.char.add("outside ", kind), np.char.add("inside ", kind)])
    return accel.Geometry(moved, faces), accel.Rays(origins, directions), labels


def leak_grid(kind, vertices, faces, scales=SCALES, offsets=OFFSETS):
    """Missed rays (a closed mesh they must hit) per (scale, offset); also the ray count."""
    grid = np.zeros((len(scales), len(offsets)), dtype=np.int64)
    total = 0
    for i, scale in enumerate(scales):
        for j, offset in enumerate(offsets):
            geometry, rays, _ = crack_rays(vertices, faces, scale, offset)
            grid[i, j] = int(np.sum(build(kind, geometry).intersect(rays).prim < 0))
            total = len(rays)
    return grid, total


def random_leaks(kind, vertices, faces, scale, offset, n, seed=0):
    """Misses among n random rays that must hit: from outside toward random points near the
    centre, and from the centre in random directions."""
    rng = np.random.default_rng(seed)
    geometry = accel.Geometry(scale * vertices + offset * AXIS, faces)
    centre = offset * AXIS
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    outside = centre + 3.0 * scale * directions
    inner = centre + 0.4 * scale * (2 * rng.random((n, 3)) - 1)   # inside both meshes
    backend = build(kind, geometry)
    misses = backend.intersect(accel.Rays(outside, inner - outside)).prim < 0
    misses_in = backend.intersect(accel.Rays(np.broadcast_to(centre, (n, 3)), directions)).prim < 0
    return int(misses.sum() + misses_in.sum())


CRACK_KINDS = ["naive", "bvh", "naive-mt", "bvh-mt", "embree", "embree-not-recentred"]
RANDOM_CASES = [(1.0, 0.0), (1e-3, 1e3), (1e3, 1e6), (1e-3, 1e6)]   # (s, |d|) of the control
LABELS = ("outside edge", "outside vertex", "inside edge", "inside vertex")


def measure_cracks(quick):
    """Section 2's data: leaked rays per (s, |d|) cell of every mesh and method, the random-ray
    control and the kinds of leaked rays at s = 1, d = 0."""
    meshes = closed_meshes()
    # quick: every third power of ten of the grid (a fifth of its cells)
    scales = SCALES[::3] if quick else SCALES
    offsets = OFFSETS[:1] + OFFSETS[1::3] if quick else OFFSETS
    grids = {}
    for mesh, (vertices, faces) in meshes.items():
        grids[mesh] = {}
        for kind in CRACK_KINDS:
            grid, per_cell = leak_grid(kind, vertices, faces, scales, offsets)
            grids[mesh][kind] = dict(leaked=grid, rays_per_cell=per_cell)
    print("cracks: grid done", flush=True)
    random_n = 50_000 if quick else 200_000
    randoms = {mesh: {kind: sum(random_leaks(kind, v, f, s, d, random_n) for s, d in RANDOM_CASES)
                      for kind in ("naive", "naive-mt", "embree")}
               for mesh, (v, f) in meshes.items()}
    breakdown = {}
    for mesh, (vertices, faces) in meshes.items():
        geometry, rays, labels = crack_rays(vertices, faces, 1.0, 0.0)
        missed = build("naive-mt", geometry).intersect(rays).prim < 0
        breakdown[mesh] = {label: dict(missed=int(missed[labels == label].sum()),
                                       rays=int((labels == label).sum())) for label in LABELS}
    return plain(dict(scales=scales, offsets=offsets,
                      triangles={mesh: len(f) for mesh, (_, f) in meshes.items()},
                      grids=grids, random_rays=random_n, random_cases=RANDOM_CASES,
                      random_leaks=randoms, breakdown=breakdown))


def crack_summary(data, mesh, kind):
    """Leak figures of one grid: leaked, rate, worst cell's rate and where, cells with a leak."""
    g = data["grids"][mesh][kind]
    grid, per_cell = np.array(g["leaked"]), g["rays_per_cell"]
    worst = np.unravel_index(np.argmax(grid), grid.shape)
    return dict(mesh=mesh, kind=kind, per_cell=per_cell, leaked=int(grid.sum()),
                rate=grid.sum() / (per_cell * grid.size), worst=grid.max() / per_cell,
                worst_scale=data["scales"][worst[0]], worst_offset=data["offsets"][worst[1]],
                leaky_cells=int((grid > 0).sum()), cells=grid.size)


def write_cracks(data, chart_dir):
    text = blocks(TEMPLATE)
    meshes = list(data["grids"])
    grids = {(m, k): np.array(g["leaked"]) for m in meshes for k, g in data["grids"][m].items()}
    rows = []
    for mesh in meshes:
        for kind in data["grids"][mesh]:
            s = crack_summary(data, mesh, kind)
            worst = fill(text["cracks_worst"], s) if s["leaked"] else "0"
            rows.append(fill(text["cracks_row"], s, worst=worst))
    before = sum(grids[m, "embree-not-recentred"] for m in meshes)
    ratios = [data["offsets"][j] / data["scales"][i] for i, j in zip(*np.nonzero(before))]
    before_text = (fill(text["cracks_before_leaked"], leaked=int(before.sum()), ratio=min(ratios))
                   if ratios else text["cracks_before_clean"])
    same = all(np.array_equal(grids[m, "naive"], grids[m, "bvh"]) and
               np.array_equal(grids[m, "naive-mt"], grids[m, "bvh-mt"]) for m in meshes)
    lo, hi = data["scales"][0], data["scales"][-1]
    positive = [d for d in data["offsets"] if d > 0]
    return fill(
        text["cracks"], data, pinned_ids(PINS), rows="\n".join(rows),
        chart=chart_cracks(chart_dir, data), cells=before.size,
        scale_range=[exponent(lo), exponent(hi)],
        offset_range=[exponent(min(positive)), exponent(max(positive))],
        breakdown={mesh: join(text["breakdown_item"], [dict(label=label, **counts) for label,
                                                         counts in kinds.items()], ", ")
                   for mesh, kinds in data["breakdown"].items()},
        random_cases=join(text["random_case"], [dict(scale=s, offset=d)
                                                for s, d in data["random_cases"]], ", "),
        random_leaks=join(text["random_leak"], [dict(mesh=mesh, kind=kind, leaked=count)
                                                for mesh, kinds in data["random_leaks"].items()
                                                for kind, count in kinds.items()], ", "),
        same_grids=text["cracks_same_grids"] if same else "",
        ico=crack_summary(data, "icosphere", "naive-mt"),
        cube=crack_summary(data, "cube", "naive-mt"),
        watertight_leaked=sum(int(grids[m, k].sum()) for m in meshes for k in ("naive", "bvh")),
        embree_leaked=sum(int(grids[m, "embree"].sum()) for m in meshes), before=before_text)


def chart_cracks(chart_dir, data):
    plt = pyplot()
    scales, offsets = data["scales"], data["offsets"]
    figure, (by_scale, by_ratio) = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    styles = {"naive-mt": ("naive = bvh, Möller–Trumbore (float64)", "-o"),
              "naive": ("naive = bvh, watertight (float64)", "-x"),
              "embree": ("embree (float32)", "-s"),
              "embree-not-recentred": ("embree, not re-centred", "--^")}
    meshes = sorted(data["grids"])
    ratios = sorted({d / s for s in scales for d in offsets if d > 0})
    for kind, (label, style) in styles.items():
        grid = sum(np.array(data["grids"][mesh][kind]["leaked"]) for mesh in meshes)
        per_cell = sum(data["grids"][mesh][kind]["rays_per_cell"] for mesh in meshes)
        rate = grid / per_cell
        by_scale.plot(scales, rate.mean(axis=1), style, label=label)
        xs, ys = [], []
        for ratio in ratios:
            cells = [rate[i, j] for i, s in enumerate(scales) for j, d in enumerate(offsets)
                     if d > 0 and math.isclose(d / s, ratio)]
            xs.append(ratio)
            ys.append(np.mean(cells))
        by_ratio.plot(xs, ys, style, label=label)
    rate_axis(by_scale, "scale s (mean over |d|)", "leak rate (icosphere + cube)")
    by_ratio.set_xscale("log")
    by_ratio.set_xlabel("offset / scale, |d|/s (mean over cells)")
    by_ratio.legend()
    figure.suptitle("Rays aimed at shared edges and vertices that miss a closed mesh")
    return save_chart(plt, figure, chart_dir, "stability_cracks.png")


# -- 3. embree far from the origin -------------------------------------------------------------
FAR_MAGNITUDES = [10.0 ** k for k in range(8)]
T_TOLERANCE = 1e-4


def disagreement(reference, hits):
    """Fractions of rays where hits differ from reference (accel.Hits.disagreement at
    T_TOLERANCE): hit vs miss, another primitive, t off by more than T_TOLERANCE relative, and
    any of the three."""
    return hits.disagreement(reference, T_TOLERANCE)


def moved_geometry_rays(geometry, rays, magnitude):
    offset = magnitude * AXIS
    return (accel.Geometry(geometry.vertices + offset, geometry.faces),
            accel.Rays(rays.origins + offset, rays.directions, rays.tmin, rays.tmax))


FAR_KINDS = ("embree-not-recentred", "embree-box-centre", "embree")
FAR_LABELS = {"embree-not-recentred": "not re-centred (before)",
              "embree-box-centre": "box centre", "embree": "median (ptrace)"}


def far_disagreement(geometry, rays, magnitudes=FAR_MAGNITUDES, kinds=FAR_KINDS):
    """{kind: [disagreement with bvh at each magnitude]} with geometry and rays moved together."""
    out = {kind: [] for kind in kinds}
    for magnitude in magnitudes:
        moved, moved_rays = moved_geometry_rays(geometry, rays, magnitude)
        reference = accel.build("bvh", moved).intersect(moved_rays)
        for kind in kinds:
            out[kind].append(disagreement(reference, build(kind, moved).intersect(moved_rays)))
    return out


def outlier_disagreement(n, rays_count, kinds=FAR_KINDS):
    """{kind: disagreement with bvh} on cluster+outliers (section 1), rays at the cluster."""
    geometry, rays = study_rays("cluster+outliers", n, rays_count)
    reference = accel.build("bvh", geometry).intersect(rays)
    return {kind: disagreement(reference, build(kind, geometry).intersect(rays))
            for kind in kinds}


def distant_camera_disagreement(geometry, rays_count, distances, seed=0, clip=True):
    """Geometry left where it is, ray origins at `distance` from its centre aiming at random
    points of its box: what re-centring cannot fix (the ray origin itself is far), and what
    clipping each ray to the triangles' box does (clip=False: embree without it)."""
    rng = np.random.default_rng(seed)
    bvh = accel.build("bvh", geometry)
    embree = accel.build("embree", geometry, clip_to_bounds=clip)
    out = []
    for distance in distances:
        rays = raygen.distant_rays(geometry, rays_count, distance, rng)
        out.append(disagreement(bvh.intersect(rays), embree.intersect(rays)))
    return out


def load_cow():
    import ptrace
    return ptrace.load(str(scenes_dir() / "meshedit" / "cow.dae")).geometry


def measure_far(quick):
    """Section 3's data: embree's disagreement with bvh as the cow and the rays move away
    together (three ways to hand Embree the triangles), on cluster+outliers, and with only the
    ray origins far away."""
    geometry = load_cow()
    rays_count = 5000 if quick else 20000
    rays = raygen.sphere_rays(geometry, rays_count, seed=COW_SEED)
    distances = [10.0 ** k for k in range(1, 8)]
    outlier_n = 4000 if quick else 20000
    lower, upper = geometry.bounds()
    return plain(dict(
        triangles=geometry.triangle_count, box=np.round(upper - lower, 2), rays=rays_count,
        seed=COW_SEED, t_tolerance=T_TOLERANCE, magnitudes=FAR_MAGNITUDES,
        moved=far_disagreement(geometry, rays), distances=distances,
        camera=distant_camera_disagreement(geometry, rays_count, distances),
        camera_not_clipped=distant_camera_disagreement(geometry, rays_count, distances,
                                                       clip=False),
        outlier_triangles=outlier_n, outliers=outlier_disagreement(outlier_n, rays_count)))


def write_far(data, chart_dir):
    text = blocks(TEMPLATE)
    moved = data["moved"]
    before, after = moved["embree-not-recentred"], moved["embree"]
    rows = [dict(m=m, before=b, box=c, after=a) for m, b, c, a in
            zip(data["magnitudes"], before, moved["embree-box-centre"], after)]
    grows_from = next((m for m, r in zip(data["magnitudes"], before) if r["any"] > 0.001),
                      math.inf)
    return fill(
        text["far"], data, pinned_ids(PINS), rows=join(text["far_row"], rows),
        outlier_rows=join(text["far_outlier_row"], [dict(label=FAR_LABELS[kind], r=r)
                                                    for kind, r in data["outliers"].items()]),
        camera_rows=join(text["far_camera_row"], [
            dict(distance=d, r=r, before=b) for d, r, b in
            zip(data["distances"], data["camera"], data["camera_not_clipped"])]),
        chart=chart_far(chart_dir, data), grows_from=grows_from,
        # by the power of ten of m (or R): {before[5][any]} is the "any" rate at m = 1e5
        before={exponent(m): r for m, r in zip(data["magnitudes"], before)},
        camera={exponent(d): r for d, r in zip(data["distances"], data["camera"])},
        camera_before={exponent(d): r for d, r in zip(data["distances"],
                                                      data["camera_not_clipped"])},
        after_max=max(r["any"] for r in after))


def chart_far(chart_dir, data):
    plt = pyplot()
    figure, axes = plt.subplots(figsize=(7, 4))
    for kind, style in zip(FAR_KINDS, ("--^", ":v", "-o")):
        axes.plot(data["magnitudes"], [r["any"] for r in data["moved"][kind]], style,
                  label=f"cow moved m: {FAR_LABELS[kind]}")
    axes.plot(data["distances"], [r["any"] for r in data["camera_not_clipped"]], "-.s",
              label="cow at origin, ray origins R away (not clipped: before)")
    axes.plot(data["distances"], [r["any"] for r in data["camera"]], "-D",
              label="cow at origin, ray origins R away (clipped to the box: ptrace)")
    rate_axis(axes, "distance from the origin m (or R)", "fraction of rays disagreeing with bvh")
    axes.set_title("Embree (float32) vs bvh (float64), cow")
    axes.legend(fontsize=8)
    return save_chart(plt, figure, chart_dir, "stability_far.png")


# -- light transport; the studies in the tests -------------------------------------------------
def measure_light(quick):
    """The light-transport studies' data (studies/stability_light.py)."""
    from studies import stability_light
    return stability_light.measure(quick)


def write_light(data, chart_dir):
    """The light-transport sections, their charts saved beside the report."""
    from studies import stability_light
    return "\n\n".join(stability_light.write_sections(data, chart_dir))


def write_pinned(data, chart_dir):
    """Failure regimes whose study lives in the test suite itself (the tests measure and assert
    on every run; their figures are quoted, not measured by this script): no data."""
    return fill(blocks(TEMPLATE)["pinned"], pinned_ids(PINS), offset=OFFSET)


# -- the report --------------------------------------------------------------------------------
# (data key, measure(quick) -> plain data or None for no data, write(data, chart dir) -> Markdown)
SECTIONS = [("distributions", measure_distributions, write_distributions),
            ("cracks", measure_cracks, write_cracks),
            ("far", measure_far, write_far),
            ("light", measure_light, write_light),
            ("pinned", None, write_pinned)]


def measure(quick, threads=None):
    """Every section's data, and the run's: {"run": {...}, section name: data}."""
    load = os.getloadavg()[0]
    warm_up()
    start = time.perf_counter()
    data = {"run": dict(quick=quick, threads=threads or numba.get_num_threads(),
                        niceness=os.nice(0), load=load, cores=os.cpu_count())}
    for name, measure_section, _ in SECTIONS:
        if measure_section is not None:
            data[name] = measure_section(quick)
    data["run"]["seconds"] = time.perf_counter() - start
    return plain(data)


def report_text(data, chart_dir):
    """The Markdown report of data (what measure returns); charts are saved into chart_dir."""
    text = blocks(TEMPLATE)
    run = data["run"]
    busy = run["niceness"] > 0 or run["load"] > 0.5
    notes = ([text["intro_quick"]] if run["quick"] else []) + \
        ([fill(text["intro_busy"], run)] if busy else [])
    sections = [write(data.get(name), chart_dir) for name, _, write in SECTIONS]
    return templating.study_text(text, run, REPRODUCE, "".join(n + " " for n in notes), sections)


def write_report(data, output="stability.md"):
    """Write data's report to output (relative to report.RESULTS, or absolute), its charts
    beside it and data itself as JSON beside it (same name, .json); return the report's path."""
    return templating.write_study(data, output, report_text)


def main(argv=None):
    args = templating.study_arguments(argv, __doc__.splitlines()[0],
                                      "fewer triangles and rays", "stability.md")
    pyplot()
    path = write_report(measure(args.quick, numba.get_num_threads()), args.output)
    print(f"wrote {path} and {path.with_suffix('.json').name} beside it")
    return 0


if __name__ == "__main__":
    main()
