"""Rays per second of naive, bvh (mean and SAH splits; watertight and Möller–Trumbore triangle
tests) and embree, for closest-hit and shadow (any-hit) rays, plus BVH build figures.

    python -m benchmarks.accel_rays [--quick] [--rays 1000000] [--threads 2] [--repeats 3]
        [--meshes meshedit/cow.dae ...] [--synthetic 1024 4096 ...] [--no-mt-synthetic]
        [--output accel_rays.md]

Meshes: six course meshes (teapot, cow, CBbunny, building, peter, maxplanck, loaded through
`ptrace.load`; their triangles, plus spheres if any, go to the backends as the loaded
accel.Geometry) and a synthetic series of displaced tori with 1k to 1M triangles
(benchmarks.synthetic). Backends: naive (watertight, the default test), bvh mean and bvh sah
(watertight), bvh mean mt and bvh sah mt (triangle="moller-trumbore", the seed's test; the same
trees, only the triangle test differs) and embree. For each mesh: build seconds of bvh mean, bvh
sah and embree (numba compile measured apart, on a one-triangle mesh first: cold in a fresh
process with an empty cache, and loading the cache), BVH nodes, leaves, depth and bytes; then
every backend traces the same four batches of rays at each thread count (numba.set_num_threads;
the embree backend splits a batch over numba's thread count too):
- random: accel.raygen.sphere_rays(geometry, n, seed=0), from a sphere around the mesh toward
  random points in its bounds;
- camera: accel.raygen.camera_rays(geometry, w, h, seed=0), one pinhole ray per pixel, w*h ~ n;
- secondary: accel.raygen.surface_rays(geometry, n, seed=0), from points on the triangles in
  random directions;
- shadow: accel.raygen.shadow_rays(geometry, n, seed=0, light=...), segments from the same
  points as secondary's to random points on a light, ending 1e-4 short of it: the scene's first
  area light when the scene has one (of the default meshes only CBbunny, whose light is the
  issue's target), otherwise accel.raygen.light_square(geometry), a small square above the
  bounds (a synthetic light above CBbunny's closed box would be hidden by its ceiling).
Rates are rays per second, the median of --repeats runs after a warm-up call, the backends taking
turns (each traces the batch once per round, so a slow spell of the machine touches all): closest
hit (intersect) for random, camera and secondary rays; any hit (occluded) for shadow rays. naive
tests every triangle, so it runs on the first min(n, --naive-budget / triangles) rays of the same
batch (the tables give the count). The traversal table gives, per ray, the bvh's nodes visited
and ray-triangle tests (closest hit; mean and sah splits with the watertight test), counted by
an untimed trace of the whole batch (BVHAccelerator.traversal_work). Writes
benchmarks/results/accel_rays.md (or --output; a relative path is taken inside
benchmarks/results/) and a log-log chart beside it.

Run time (estimated from quick-size rates on a 2-core machine): 6 backends x 4 kinds of 1M rays
x 3 repeats on 12 meshes is about 10 minutes at 2 threads (of which the Möller–Trumbore variants
on the tori take 2; --no-mt-synthetic skips them) plus about a minute of cold compile. One
thread halves the rates, so --threads 1 2 would take about 30 minutes: --threads defaults to 2
only.
"""
import argparse
import itertools
import os
import statistics
import time

import numba
import numpy as np

import accel
from accel import raygen
from accel.types import Rays

from . import report, synthetic
from .rays import RAY_KINDS, make_rays, scene_light, scenes_dir

MESHES = ["meshedit/teapot.dae", "meshedit/cow.dae", "sky/CBbunny.dae", "keenan/building.dae",
          "meshedit/peter.dae", "meshedit/maxplanck.dae"]
ANY_HIT = ("shadow",)        # kinds timed with occluded(); the others with intersect()
BACKENDS = ("naive", "bvh mean", "bvh sah", "bvh mean mt", "bvh sah mt", "embree")
BUILD = {"naive": ("naive", {}),
         "bvh mean": ("bvh", {"split": "mean"}),
         "bvh sah": ("bvh", {"split": "sah"}),
         "bvh mean mt": ("bvh", {"split": "mean", "triangle": "moller-trumbore"}),
         "bvh sah mt": ("bvh", {"split": "sah", "triangle": "moller-trumbore"}),
         "embree": ("embree", {})}
MT = ("bvh mean mt", "bvh sah mt")
# the targets: (what, ray kind, meshes, numerator, denominator, at least); "{split}" is
# "mean" (the default split, which decides pass/FAIL) and "sah" (shown beside it)
TARGET_MESHES = ("meshedit/cow.dae", "sky/CBbunny.dae", "keenan/building.dae",
                 "meshedit/maxplanck.dae")
TARGETS = [
    ("bvh / embree, closest hit", "random", TARGET_MESHES, "bvh {split}", "embree", 0.8),
    ("bvh / embree, closest hit", "secondary", TARGET_MESHES, "bvh {split}", "embree", 0.6),
    ("bvh / embree, any hit", "shadow", ("sky/CBbunny.dae",), "bvh {split}", "embree", 0.8),
    ("watertight / Möller–Trumbore", "random", TARGET_MESHES, "bvh {split}", "bvh {split} mt",
     0.9),
    ("watertight / Möller–Trumbore", "secondary", TARGET_MESHES, "bvh {split}",
     "bvh {split} mt", 0.9),
]


def timed(function, *args):
    start = time.perf_counter()
    result = function(*args)
    return time.perf_counter() - start, result


def warm_up():
    """Compile (or load from numba's cache) every kernel on tiny meshes; return the seconds. Two
    meshes: the BVH keeps float32 blocks for coordinates that are all float32 values and float64
    ones otherwise, and each is a kernel of its own (accel.bvh.BVHRecord)."""
    tinies = [accel.Geometry([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]),
              accel.Geometry([[0, 0, 0], [1, 0, 0], [0, 1, 0.1]], [[0, 1, 2]])]
    seconds = {}
    for kind in accel.KINDS:
        start = time.perf_counter()
        variants = [{}]
        if kind != "embree":
            variants.append({"triangle": "moller-trumbore"})
        if kind == "bvh":
            variants += [{"split": "sah"}, {"split": "sah", "triangle": "moller-trumbore"}]
        for tiny, options in itertools.product(tinies, variants):
            backend = accel.build(kind, tiny, **options)
            rays = raygen.sphere_rays(tiny, 8)
            backend.intersect(rays)
            backend.occluded(rays)
        seconds[kind] = time.perf_counter() - start
    return seconds


def cold_compile_seconds():
    """warm_up() in a fresh process with an empty numba cache: the first-run JIT cost."""
    import json
    import subprocess
    import sys
    import tempfile
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        code = ("import json; from benchmarks.accel_rays import warm_up; "
                "print(json.dumps(warm_up()))")
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        output = subprocess.run([sys.executable, "-c", code], env=env, cwd=root, check=True,
                                capture_output=True, text=True).stdout
    return json.loads(output.strip().splitlines()[-1])


def head(rays, k):
    """The first k rays of a batch (naive traces a prefix of the same rays)."""
    return Rays(rays.origins[:k], rays.directions[:k], rays.tmin[:k], rays.tmax[:k])


def load_meshes(args):
    """[(label, geometry, light)]: the course meshes, then the synthetic series; light is the
    scene's first area light or None (shadow_rays' synthetic square)."""
    import ptrace
    meshes = []
    for relpath in args.meshes:
        scene = ptrace.load(os.path.join(scenes_dir(), relpath))
        meshes.append((relpath, scene.geometry, scene_light(scene)))
    for triangles in args.synthetic:
        vertices, faces = synthetic.displaced_torus(triangles)
        meshes.append((synthetic.name(triangles), accel.Geometry(vertices, faces), None))
    return meshes


def is_synthetic(label):
    return not label.endswith(".dae")


def backend_names(label, args):
    return tuple(name for name in BACKENDS
                 if name not in MT or not args.no_mt_synthetic or not is_synthetic(label))


def measure(label, geometry, light, args):
    """Build figures, rates and traversal work of one mesh: a dict of plain values."""
    numba.set_num_threads(max(args.threads))
    names = backend_names(label, args)
    backends, builds = {}, {}
    for name in names:
        kind, options = BUILD[name]
        backends[name] = accel.build(kind, geometry, **options)
        if name in ("bvh mean", "bvh sah", "embree"):
            builds[name] = backends[name].stats()
    triangles = geometry.triangle_count
    naive_n = min(args.rays, max(args.naive_min, int(args.naive_budget // max(1, triangles))))
    rates, work, counts, mismatches, fractions = {}, {}, {}, {}, {}
    for ray_kind in RAY_KINDS:
        rays = make_rays(ray_kind, geometry, args.rays, light)
        batches = {name: rays for name in names}
        batches["naive"] = head(rays, min(naive_n, len(rays)))
        counts[ray_kind] = (len(rays), len(batches["naive"]))
        query = "occluded" if ray_kind in ANY_HIT else "intersect"
        answers = {}
        for threads in args.threads:
            numba.set_num_threads(threads)
            for name in names:
                getattr(backends[name], query)(head(batches[name], 64 if name == "naive"
                                                    else 4096))   # warm-up
            times = {name: [] for name in names}
            for _ in range(args.repeats):   # in turns, so a slow spell touches every backend
                for name in names:
                    seconds, answers[name] = timed(getattr(backends[name], query), batches[name])
                    times[name].append(seconds)
            for name in names:
                rates[ray_kind, threads, name] = len(batches[name]) / statistics.median(times[name])
                if query == "intersect" and name in ("bvh mean", "bvh sah"):
                    # untimed: a trace of the whole batch that counts its work
                    work[ray_kind, name] = backends[name].traversal_work(batches[name])
            print(f"{label} {ray_kind} {threads}T: " + ", ".join(
                f"{name} {rates[ray_kind, threads, name]:,.0f}" for name in names) + " rays/s",
                flush=True)
        reference = answers["naive"] if query == "occluded" else answers["naive"].prim
        for name in ("bvh mean", "bvh sah"):
            answer = answers[name] if query == "occluded" else answers[name].prim
            mismatches[ray_kind, name] = int((answer[:len(reference)] != reference).sum())
        mean = answers["bvh mean"]
        fractions[ray_kind] = float(np.mean(mean if query == "occluded" else mean.prim >= 0))
        answers.clear()
    numba.set_num_threads(max(args.threads))
    return {"label": label, "triangles": triangles, "builds": builds, "rates": rates,
            "work": work, "counts": counts, "mismatches": mismatches, "fractions": fractions,
            "light": "synthetic square" if light is None else "scene's area light",
            "backends": names, "load": os.getloadavg()[0]}


def fmt_rate(value):
    return "–" if value is None else f"{value:,.0f}"


def ratio(r, kind, threads, numerator, denominator):
    top = r["rates"].get((kind, threads, numerator))
    bottom = r["rates"].get((kind, threads, denominator))
    return None if top is None or bottom is None else top / bottom


def fmt_ratio(value, suffix=""):
    return "–" if value is None else f"{value:.2f}{suffix}"


RATIOS = (("mean/embree", "bvh mean", "embree"), ("sah/embree", "bvh sah", "embree"),
          ("wt/MT mean", "bvh mean", "bvh mean mt"))


def rate_cells(r, kind, t):
    rates = [fmt_rate(r["rates"].get((kind, t, name))) for name in BACKENDS]
    ratios = [fmt_ratio(ratio(r, kind, t, a, b)) for _, a, b in RATIOS]
    return rates + ratios


def rate_tables(results, args):
    """Per mesh at the largest thread count, then one table of the other thread counts."""
    t = max(args.threads)
    columns = " | ".join(BACKENDS) + " | " + " | ".join(label for label, _, _ in RATIOS)
    lines = [f"## Rays per second ({t} threads)", "",
             ("Closest hit (intersect) for random, camera and secondary rays; any hit "
              "(occluded) for shadow rays. naive traces the first *naive rays* of each batch. "
              "*mean/embree*, *sah/embree*: bvh (watertight) rays/s over embree's on the same "
              "rays; *wt/MT mean*: bvh mean with the watertight test over bvh mean with "
              "Möller–Trumbore (above 1: watertight is faster). – : not measured."), ""]
    for r in results:
        lines += [f"### {r['label']}", "",
                  f"{r['triangles']:,} triangles; shadow rays go to the {r['light']}.", "",
                  f"| kind | query | rays | naive rays | {columns} |",
                  "|---|---|---:|---:|" + "---:|" * (len(BACKENDS) + len(RATIOS))]
        for kind in RAY_KINDS:
            n, naive_n = r["counts"][kind]
            query = "any hit" if kind in ANY_HIT else "closest"
            lines.append(f"| {kind} | {query} | {n:,} | {naive_n:,} | "
                         + " | ".join(rate_cells(r, kind, t)) + " |")
        lines.append("")
    others = [u for u in args.threads if u != t]
    if others:
        lines += [f"## Rays per second at {', '.join(map(str, others))} "
                  f"thread{'s' if others != [1] else ''}", "",
                  "The same measurements as above at the other thread counts.", "",
                  f"| mesh | kind | threads | {columns} |",
                  "|---|---|---:|" + "---:|" * (len(BACKENDS) + len(RATIOS))]
        for r in results:
            for kind in RAY_KINDS:
                for u in others:
                    lines.append(f"| {r['label']} | {kind} | {u} | "
                                 + " | ".join(rate_cells(r, kind, u)) + " |")
        lines.append("")
    return lines


def summary_table(results, args):
    t = max(args.threads)
    lines = [f"## bvh / embree rays/s ratio and watertight / Möller–Trumbore ({t} threads)", "",
             ("bvh (watertight) rays/s over embree's, each split; the last two columns: bvh mean "
              "watertight over bvh mean Möller–Trumbore. Shadow: any hit."), "",
             "| mesh | triangles | " + " | ".join(f"{k} mean | {k} sah" for k in RAY_KINDS)
             + " | wt/MT random | wt/MT secondary |",
             "|---|---:|" + "---:|" * (2 * len(RAY_KINDS) + 2)]
    for r in results:
        cells = []
        for kind in RAY_KINDS:
            cells += [fmt_ratio(ratio(r, kind, t, "bvh mean", "embree")),
                      fmt_ratio(ratio(r, kind, t, "bvh sah", "embree"))]
        cells += [fmt_ratio(ratio(r, kind, t, "bvh mean", "bvh mean mt"))
                  for kind in ("random", "secondary")]
        lines.append(f"| {r['label']} | {r['triangles']:,} | " + " | ".join(cells) + " |")
    return lines


def targets_table(results, args):
    t = max(args.threads)
    by_label = {r["label"]: r for r in results}
    lines = [f"## Targets, {t} threads", "",
             ("Pass/FAIL is decided on the default split (mean); the sah split is shown beside "
              "it. bvh and naive use the watertight test unless the row says Möller–Trumbore. "
              "The CBbunny shadow rays go to its own area light."), "",
             "| target | kind | mesh | at least | mean | result | sah | sah result |",
             "|---|---|---|---:|---:|---|---:|---|"]
    for what, kind, meshes, numerator, denominator, needed in TARGETS:
        for mesh in meshes:
            r = by_label.get(mesh)
            start = f"| {what} | {kind} | {mesh} | {needed:.2f}x |"
            if r is None:
                lines.append(f"{start} – | not run | – | not run |")
                continue
            cells = []
            for split in ("mean", "sah"):
                value = ratio(r, kind, t, numerator.format(split=split),
                              denominator.format(split=split))
                verdict = ("not run" if value is None else
                           "pass" if value >= needed else "FAIL")
                cells += [fmt_ratio(value, "x"), verdict]
            lines.append(f"{start} " + " | ".join(cells) + " |")
    return lines


def builds_table(results, args):
    lines = ["## Builds", "",
             ("*load*: the 1-minute load average when the mesh's measurements ended; above "
              f"{max(args.threads)} (this run's threads) another process shared the CPU. The "
              "Möller–Trumbore bvh variants build the same trees (the triangle test is not part "
              "of the build)."), "",
             "| mesh | triangles | backend | build s | nodes | leaves | depth | bytes | load |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        for name in ("bvh mean", "bvh sah", "embree"):
            s = r["builds"][name]
            if name == "embree":
                tail = "– | – | – | –"   # embreex exposes no tree
            else:
                tail = f"{s['nodes']:,} | {s['leaves']:,} | {s['max_depth']} | {s['bytes']:,}"
            lines.append(f"| {r['label']} | {r['triangles']:,} | {name} | "
                         f"{s['build_seconds']:.3f} | {tail} | {r['load']:.1f} |")
    return lines


def work_table(results):
    lines = ["## Traversal work per ray (bvh, whole batch)", "",
             ("Wide nodes visited and ray-triangle tests per ray of closest-hit queries "
              "(thread-independent; watertight test; the Möller–Trumbore variants walk the same "
              "trees). *hit fraction*: rays that hit (shadow: rays occluded), bvh mean; "
              "*mismatches*: rays on which the bvh's hit primitive (shadow: occluded flag) "
              "differs from naive's (naive's prefix)."), "",
             ("| mesh | kind | hit fraction | mean: nodes | mean: triangles | sah: nodes | "
              "sah: triangles | mismatches mean/sah |"),
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        for kind in RAY_KINDS:
            if kind in ANY_HIT:
                cells = "– | – | – | –"
            else:
                (mv, mt), (sv, st) = r["work"][kind, "bvh mean"], r["work"][kind, "bvh sah"]
                cells = f"{mv:.1f} | {mt:.1f} | {sv:.1f} | {st:.1f}"
            lines.append(f"| {r['label']} | {kind} | {r['fractions'][kind]:.3f} | {cells} | "
                         f"{r['mismatches'][kind, 'bvh mean']}/"
                         f"{r['mismatches'][kind, 'bvh sah']} |")
    return lines


def tables(results, args):
    return (targets_table(results, args) + [""] + summary_table(results, args) + [""]
            + rate_tables(results, args) + builds_table(results, args) + [""]
            + work_table(results))


CHART = {"naive": ("tab:gray", "-"), "bvh mean": ("tab:blue", "-"),
         "bvh sah": ("tab:green", "-"), "bvh mean mt": ("tab:blue", ":"),
         "bvh sah mt": ("tab:green", ":"), "embree": ("tab:red", "-")}


def chart(results, args, path):
    """Log-log rays/s against triangles: rows are thread counts, columns ray kinds. Tori are
    lines (Möller–Trumbore variants dotted, when measured); course meshes squares (watertight
    backends and embree only, to stay legible)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    series = [r for r in results if is_synthetic(r["label"])]
    course = [r for r in results if not is_synthetic(r["label"])]
    figure, axes = plt.subplots(len(args.threads), len(RAY_KINDS), squeeze=False,
                                figsize=(4.0 * len(RAY_KINDS), 3.6 * len(args.threads)),
                                sharex=True, sharey=True)
    for row, t in enumerate(args.threads):
        for col, kind in enumerate(RAY_KINDS):
            ax = axes[row][col]
            for name in BACKENDS:
                colour, style = CHART[name]
                points = [(r["triangles"], r["rates"][kind, t, name]) for r in series
                          if (kind, t, name) in r["rates"]]
                if points:
                    ax.plot(*zip(*points), style, marker="o", markersize=3, color=colour,
                            label=f"{name} (tori)")
                points = [(r["triangles"], r["rates"][kind, t, name]) for r in course
                          if (kind, t, name) in r["rates"]]
                if points and name not in MT:
                    ax.plot(*zip(*points), "s", markersize=5, markerfacecolor="none",
                            color=colour, label=f"{name} (course)")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, which="both", alpha=0.3)
            query = "any hit" if kind in ANY_HIT else "closest hit"
            ax.set_title(f"{kind} rays ({query}), {t} thread{'s' if t > 1 else ''}",
                         fontsize=10)
            if row == len(args.threads) - 1:
                ax.set_xlabel("triangles")
            if col == 0:
                ax.set_ylabel("rays/s")
    handles, labels = axes[0][0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncol=5, fontsize=8)
    figure.suptitle("Rays per second against triangle count (displaced tori: lines, "
                    "Möller–Trumbore dotted; course meshes: squares)", fontsize=11)
    figure.tight_layout(rect=(0, 0.1 if len(args.threads) > 1 else 0.17, 1, 1))
    tmp = path.with_name(path.name + ".tmp.png")
    figure.savefig(tmp, dpi=110)
    plt.close(figure)
    tmp.replace(path)
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="a few minutes at most: fewer rays, one repeat, tori up to 64k, "
                             "no cold-compile measurement (defaults below are for the full run)")
    parser.add_argument("--rays", type=int, default=None, help="rays per batch (1,000,000)")
    parser.add_argument("--naive-budget", type=float, default=None,
                        help="naive traces at most this many ray-triangle tests per batch (1e8)")
    parser.add_argument("--naive-min", type=int, default=128,
                        help="naive traces at least this many rays (or the whole batch)")
    parser.add_argument("--threads", type=int, nargs="+", default=[2],
                        help="thread counts (default 2; --threads 1 2 takes twice as long)")
    parser.add_argument("--repeats", type=int, default=None, help="timed runs per rate (5)")
    parser.add_argument("--meshes", nargs="*", default=MESHES, help="course scenes")
    parser.add_argument("--synthetic", type=int, nargs="*", default=None,
                        help="triangle counts of displaced tori, each 4 * rows**2 "
                             f"(default {' '.join(map(str, synthetic.SERIES))})")
    parser.add_argument("--no-mt-synthetic", action="store_true",
                        help="time the Möller–Trumbore bvh variants on the course meshes only, "
                             "not on the tori (saves about 2 minutes per thread count)")
    parser.add_argument("--no-cold-compile", action="store_true",
                        help="skip the fresh-process compile measurement")
    parser.add_argument("--output", default="accel_rays.md",
                        help="report path (relative: inside benchmarks/results/); the chart "
                             "goes beside it with the extension .png")
    args = report.quick_defaults(
        parser.parse_args(argv), rays=(20_000, 1_000_000), naive_budget=(1e7, 1e8),
        repeats=(1, 5), synthetic=(list(synthetic.QUICK_SERIES), list(synthetic.SERIES)))
    quick = args.quick
    args.threads = sorted(set(args.threads))
    numba.set_num_threads(max(args.threads))
    started = time.perf_counter()
    load_before = os.getloadavg()[0]
    cold_seconds = None if (quick or args.no_cold_compile) else cold_compile_seconds()
    compile_seconds = warm_up()
    results = []
    for label, geometry, light in load_meshes(args):
        results.append(measure(label, geometry, light, args))

    load_after = os.getloadavg()[0]
    report_path = report.destination(args.output)
    chart_path = chart(results, args, report_path.with_suffix(".png"))
    cold = ("numba compile with an empty cache (fresh process): "
            + ", ".join(f"{k} {v:.1f} s" for k, v in cold_seconds.items()) + "; "
            if cold_seconds else "cold compile not measured in this run; ")
    mt_where = ("the course meshes only (--no-mt-synthetic)" if args.no_mt_synthetic
                else "every mesh")
    lines = [report.header("Intersection: naive vs bvh (mean, sah; watertight, Möller–Trumbore)"
                           " vs embree"),
             (f"{'Quick run (--quick): ' if quick else ''}"
              f"{args.rays:,} rays per batch (camera: the nearest 4:3 image); threads "
              f"{', '.join(map(str, args.threads))}; every rate is the median of {args.repeats} "
              f"run{'s' if args.repeats > 1 else ''} after a warm-up call, the backends taking "
              "turns (one batch each per round); naive traces at most "
              f"{args.naive_budget:,.0f} ray-triangle tests (at least {args.naive_min} rays). "
              "Backends: naive and bvh mean/sah with the watertight triangle test (the "
              "default), bvh mean mt/sah mt with Möller–Trumbore "
              f"(triangle=\"moller-trumbore\"), measured on {mt_where}, and embree. "
              "Ray kinds: random (from a sphere around the mesh into its bounds), camera (a "
              "pinhole image), secondary (from points on the triangles in random directions), "
              "all closest hit; shadow: any hit (occluded) on segments from secondary's origins "
              "to random points on a light (`accel.raygen.shadow_rays`), ending 1e-4 of the "
              "segment short of it. The light is the scene's first area light when it has one "
              "(CBbunny), otherwise `accel.raygen.light_square`: a square of side a quarter of "
              "the bounds' diagonal, facing down, centred 1.5 box heights (at least 1.5 "
              "quarter-diagonals) above the box centre. "
              "Synthetic meshes: `benchmarks.synthetic.displaced_torus` (4 * rows^2 triangles). "
              "Build seconds are single runs on "
              f"{max(args.threads)} threads (the BVH build is serial; Embree's uses its own "
              "thread pool); embree traces a batch split over numba's thread count. "
              f"Load average (1 min) before the run {load_before:.1f}, after it "
              f"{load_after:.1f}, on {os.cpu_count()} cores: well above this run's own threads "
              "means another process shared the CPU and the rates are low and noisy. "
              f"The run took {(time.perf_counter() - started) / 60:.1f} minutes."), "",
             "First-call cost per backend on a one-triangle mesh (naive and bvh: each triangle "
             "test; bvh: both splits): " + cold
             + "loading numba's cache: "
             + ", ".join(f"{k} {v:.2f} s" for k, v in compile_seconds.items()) + ".", "",
             f"![rays per second against triangles]({chart_path.name})", ""]
    lines += tables(results, args)
    path = report.write(report_path, "\n".join(lines) + "\n")
    print(f"wrote {path} and {chart_path}")
    return path


if __name__ == "__main__":
    main()
