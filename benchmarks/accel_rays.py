"""Rays per second of naive, bvh (mean and SAH splits) and embree, plus BVH build figures.

    python -m benchmarks.accel_rays [--quick] [--rays 1000000] [--threads 1 2] [--repeats 3]
        [--meshes meshedit/cow.dae ...] [--synthetic 1024 4096 ...] [--output accel_rays.md]

Meshes: six course meshes (teapot, cow, CBbunny, building, peter, maxplanck, loaded through
`ptrace.load`; their triangles, plus spheres if any, go to the backends as the loaded
accel.Geometry) and a synthetic series of displaced tori with 1k to 1M triangles
(benchmarks.synthetic). For each mesh: build seconds of bvh mean, bvh sah and embree (numba
compile measured apart, on a one-triangle mesh first: cold in a fresh process with an empty
cache, and loading the cache), BVH nodes, leaves, depth and bytes; then every backend traces the
same three batches of rays, at each thread count (numba.set_num_threads; the embree backend
splits a batch over numba's thread count too):
- random: accel.raygen.sphere_rays(geometry, n, seed=0), from a sphere around the mesh toward
  random points in its bounds;
- camera: accel.raygen.camera_rays(geometry, w, h, seed=0), one pinhole ray per pixel, w*h ~ n;
- secondary: accel.raygen.surface_rays(geometry, n, seed=0), from points on the triangles in
  random directions.
Rates are closest-hit (intersect) rays per second, the median of --repeats runs after a warm-up
call. naive tests every triangle, so it runs on the first min(n, --naive-budget / triangles)
rays of the same batch (the table gives the count). The traversal table gives, per ray, the
bvh's nodes visited and ray-triangle tests. Writes benchmarks/results/accel_rays.md (or
--output; a relative path is taken inside benchmarks/results/) and a log-log chart beside it.
"""
import argparse
import math
import os
import statistics
import time

import numba

import accel
from accel import raygen
from accel.types import Rays

from . import report, synthetic

MESHES = ["meshedit/teapot.dae", "meshedit/cow.dae", "sky/CBbunny.dae", "keenan/building.dae",
          "meshedit/peter.dae", "meshedit/maxplanck.dae"]
RAY_KINDS = ("random", "camera", "secondary")
BACKENDS = ("naive", "bvh mean", "bvh sah", "embree")
# the targets: closest-hit rays/s of a bvh split over embree's, on random rays
TARGETS = [("sky/CBbunny.dae", "bvh sah", 0.5), ("meshedit/maxplanck.dae", "bvh sah", 0.5),
           ("sky/CBbunny.dae", "bvh mean", 0.25), ("meshedit/maxplanck.dae", "bvh mean", 0.25)]


def scenes_dir():
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return os.environ.get("PTRACE_SCENES", os.path.join(here, "..", "shared", "scenes", "cs184"))


def timed(function, *args):
    start = time.perf_counter()
    result = function(*args)
    return time.perf_counter() - start, result


def warm_up():
    """Compile (or load from numba's cache) every kernel on a tiny mesh; return the seconds."""
    tiny = accel.Geometry([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    rays = raygen.sphere_rays(tiny, 8)
    seconds = {}
    for kind in accel.KINDS:
        start = time.perf_counter()
        backend = accel.build(kind, tiny)
        backend.intersect(rays)
        backend.occluded(rays)
        if kind == "bvh":
            accel.build(kind, tiny, split="sah").intersect(rays)
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
        code = "import json; from benchmarks.accel_rays import warm_up; print(json.dumps(warm_up()))"
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        output = subprocess.run([sys.executable, "-c", code], env=env, cwd=root, check=True,
                                capture_output=True, text=True).stdout
    return json.loads(output.strip().splitlines()[-1])


def head(rays, k):
    """The first k rays of a batch (naive traces a prefix of the same rays)."""
    return Rays(rays.origins[:k], rays.directions[:k], rays.tmin[:k], rays.tmax[:k])


def make_rays(kind, geometry, n):
    if kind == "random":
        return raygen.sphere_rays(geometry, n, seed=0)
    if kind == "camera":
        width = max(1, round(math.sqrt(n * 4 / 3)))
        return raygen.camera_rays(geometry, width, max(1, n // width), seed=0)
    return raygen.surface_rays(geometry, n, seed=0)


def load_meshes(args):
    """[(label, geometry)]: the course meshes, then the synthetic series."""
    import ptrace
    meshes = [(relpath, ptrace.load(os.path.join(scenes_dir(), relpath)).geometry)
              for relpath in args.meshes]
    for triangles in args.synthetic:
        vertices, faces = synthetic.displaced_torus(triangles)
        meshes.append((synthetic.name(triangles), accel.Geometry(vertices, faces)))
    return meshes


def measure(label, geometry, args):
    """Build figures, rates and traversal work of one mesh: a dict of plain values."""
    numba.set_num_threads(max(args.threads))
    backends = {"naive": accel.build("naive", geometry)}
    builds = {}
    for name, kind, options in (("bvh mean", "bvh", {"split": "mean"}),
                                ("bvh sah", "bvh", {"split": "sah"}), ("embree", "embree", {})):
        backends[name] = accel.build(kind, geometry, **options)
        builds[name] = backends[name].stats()
    triangles = geometry.triangle_count
    naive_n = min(args.rays, max(args.naive_min, int(args.naive_budget // max(1, triangles))))
    rates, work, counts, mismatches = {}, {}, {}, {}
    for ray_kind in RAY_KINDS:
        rays = make_rays(ray_kind, geometry, args.rays)
        batches = {name: rays for name in BACKENDS}
        batches["naive"] = head(rays, min(naive_n, len(rays)))
        counts[ray_kind] = (len(rays), len(batches["naive"]))
        for threads in args.threads:
            numba.set_num_threads(threads)
            for name in BACKENDS:
                backend, batch = backends[name], batches[name]
                backend.intersect(head(batch, 64 if name == "naive" else 4096))   # warm-up
                times = [timed(backend.intersect, batch)[0] for _ in range(args.repeats)]
                rates[ray_kind, threads, name] = len(batch) / statistics.median(times)
            print(f"{label} {ray_kind} {threads}T: " + ", ".join(
                f"{name} {rates[ray_kind, threads, name]:,.0f}" for name in BACKENDS) + " rays/s",
                flush=True)
        reference = backends["naive"].intersect(batches["naive"]).prim
        hits = None
        for name in ("bvh mean", "bvh sah"):
            bvh = backends[name]
            result = bvh.intersect(rays)
            work[ray_kind, name] = (bvh.last_mean_visits, bvh.last_mean_triangle_tests)
            mismatches[ray_kind, name] = int((result.prim[:len(reference)] != reference).sum())
            hits = float((result.prim >= 0).mean())
        work[ray_kind, "hit fraction"] = hits
    numba.set_num_threads(max(args.threads))
    return {"label": label, "triangles": triangles, "builds": builds, "rates": rates,
            "work": work, "counts": counts, "mismatches": mismatches,
            "load": os.getloadavg()[0]}


def fmt_rate(value):
    return f"{value:,.0f}"


def tables(results, args):
    threads = args.threads
    builds = ["## Builds", "",
              ("*load*: the 1-minute load average when the mesh's measurements ended; above "
               f"{max(threads)} (this run's threads) another process shared the CPU."), "",
              "| mesh | triangles | backend | build s | nodes | leaves | depth | bytes | load |",
              "|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        for name in ("bvh mean", "bvh sah", "embree"):
            s = r["builds"][name]
            if name == "embree":
                tail = "– | – | – | –"   # embreex exposes no tree
            else:
                tail = f"{s['nodes']:,} | {s['leaves']:,} | {s['max_depth']} | {s['bytes']:,}"
            builds.append(f"| {r['label']} | {r['triangles']:,} | {name} | "
                          f"{s['build_seconds']:.3f} | {tail} | {r['load']:.1f} |")
    lines = ["## Closest-hit rays per second", "",
             ("naive traces the first *naive rays* of the batch; ratios are rays/s over "
              "embree's on the same rays and thread count."), "",
             ("| mesh | triangles | rays | kind | threads | naive rays | naive | bvh mean | "
              "bvh sah | embree | mean/embree | sah/embree |"),
             "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        for kind in RAY_KINDS:
            n, naive_n = r["counts"][kind]
            for t in threads:
                rate = {name: r["rates"][kind, t, name] for name in BACKENDS}
                lines.append(
                    f"| {r['label']} | {r['triangles']:,} | {n:,} | {kind} | {t} | {naive_n:,} | "
                    + " | ".join(fmt_rate(rate[name]) for name in BACKENDS)
                    + f" | {rate['bvh mean'] / rate['embree']:.2f} | "
                    f"{rate['bvh sah'] / rate['embree']:.2f} |")
    t = max(threads)
    ratios = [f"## bvh / embree rays/s ratio ({t} threads)", "",
              "| mesh | triangles | " + " | ".join(f"{k} mean | {k} sah" for k in RAY_KINDS) + " |",
              "|---|---:|" + "---:|" * (2 * len(RAY_KINDS))]
    for r in results:
        cells = []
        for kind in RAY_KINDS:
            embree = r["rates"][kind, t, "embree"]
            cells += [f"{r['rates'][kind, t, 'bvh mean'] / embree:.2f}",
                      f"{r['rates'][kind, t, 'bvh sah'] / embree:.2f}"]
        ratios.append(f"| {r['label']} | {r['triangles']:,} | " + " | ".join(cells) + " |")
    work = ["## Traversal work per ray (bvh, whole batch)", "",
            ("Nodes visited and ray-triangle tests per ray (thread-independent); "
             "*mismatches*: rays on which the bvh's hit primitive differs from naive's "
             "(naive's prefix)."), "",
            ("| mesh | kind | hit fraction | mean: nodes | mean: triangles | sah: nodes | "
             "sah: triangles | mismatches mean/sah |"),
            "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        for kind in RAY_KINDS:
            (mv, mt), (sv, st) = r["work"][kind, "bvh mean"], r["work"][kind, "bvh sah"]
            work.append(f"| {r['label']} | {kind} | {r['work'][kind, 'hit fraction']:.3f} | "
                        f"{mv:.1f} | {mt:.1f} | {sv:.1f} | {st:.1f} | "
                        f"{r['mismatches'][kind, 'bvh mean']}/{r['mismatches'][kind, 'bvh sah']} |")
    by_label = {r["label"]: r for r in results}
    targets = ["## Targets (issue 5): bvh closest-hit rays/s over embree's, random rays", "",
               "| mesh | split | threads | target | measured | result |",
               "|---|---|---:|---:|---:|---|"]
    for mesh, name, target in TARGETS:
        for t in threads:
            r = by_label.get(mesh)
            if r is None:
                targets.append(f"| {mesh} | {name.split()[1]} | {t} | >= {target:.2f}x | – | "
                               "not run |")
                continue
            ratio = r["rates"]["random", t, name] / r["rates"]["random", t, "embree"]
            verdict = "pass" if ratio >= target else "FAIL"
            targets.append(f"| {mesh} | {name.split()[1]} | {t} | >= {target:.2f}x | "
                           f"{ratio:.2f}x | {verdict} |")
    return targets + [""] + ratios + [""] + lines + [""] + builds + [""] + work


def chart(results, args, path):
    """Log-log rays/s against triangles: rows are thread counts, columns ray kinds."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    colours = {"naive": "tab:gray", "bvh mean": "tab:blue", "bvh sah": "tab:green",
               "embree": "tab:red"}
    series = [r for r in results if not r["label"].endswith(".dae")]
    course = [r for r in results if r["label"].endswith(".dae")]
    figure, axes = plt.subplots(len(args.threads), len(RAY_KINDS), squeeze=False,
                                figsize=(4.2 * len(RAY_KINDS), 3.6 * len(args.threads)),
                                sharex=True, sharey=True)
    for row, t in enumerate(args.threads):
        for col, kind in enumerate(RAY_KINDS):
            ax = axes[row][col]
            for name in BACKENDS:
                if series:
                    ax.plot([r["triangles"] for r in series],
                            [r["rates"][kind, t, name] for r in series], "-o", markersize=3,
                            color=colours[name], label=f"{name} (tori)")
                if course:
                    ax.plot([r["triangles"] for r in course],
                            [r["rates"][kind, t, name] for r in course], "s", markersize=5,
                            markerfacecolor="none", color=colours[name],
                            label=f"{name} (course)")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, which="both", alpha=0.3)
            ax.set_title(f"{kind} rays, {t} thread{'s' if t > 1 else ''}", fontsize=10)
            if row == len(args.threads) - 1:
                ax.set_xlabel("triangles")
            if col == 0:
                ax.set_ylabel("closest-hit rays/s")
    handles, labels = axes[0][0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncol=4, fontsize=8)
    figure.suptitle("Closest-hit rays per second against triangle count (displaced tori: "
                    "lines; course meshes: squares)", fontsize=11)
    figure.tight_layout(rect=(0, 0.08 if len(args.threads) > 1 else 0.14, 1, 1))
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
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=None, help="timed runs per rate (3)")
    parser.add_argument("--meshes", nargs="*", default=MESHES, help="course scenes")
    parser.add_argument("--synthetic", type=int, nargs="*", default=None,
                        help="triangle counts of displaced tori, each 4 * rows**2 "
                             f"(default {' '.join(map(str, synthetic.SERIES))})")
    parser.add_argument("--no-cold-compile", action="store_true",
                        help="skip the fresh-process compile measurement")
    parser.add_argument("--output", default="accel_rays.md",
                        help="report path (relative: inside benchmarks/results/); the chart "
                             "goes beside it with the extension .png")
    args = parser.parse_args(argv)
    quick = args.quick
    if args.rays is None:
        args.rays = 20_000 if quick else 1_000_000
    if args.naive_budget is None:
        args.naive_budget = 1e7 if quick else 1e8
    if args.repeats is None:
        args.repeats = 1 if quick else 3
    if args.synthetic is None:
        args.synthetic = list(synthetic.QUICK_SERIES if quick else synthetic.SERIES)
    args.threads = sorted(set(args.threads))
    numba.set_num_threads(max(args.threads))
    load_before = os.getloadavg()[0]
    cold_seconds = None if (quick or args.no_cold_compile) else cold_compile_seconds()
    compile_seconds = warm_up()
    results = []
    for label, geometry in load_meshes(args):
        results.append(measure(label, geometry, args))

    load_after = os.getloadavg()[0]
    report_path = report.RESULTS / args.output      # an absolute --output stays as it is
    report_path.parent.mkdir(parents=True, exist_ok=True)
    chart_path = chart(results, args, report_path.with_suffix(".png"))
    cold = ("numba compile with an empty cache (fresh process): "
            + ", ".join(f"{k} {v:.1f} s" for k, v in cold_seconds.items()) + "; "
            if cold_seconds else "cold compile not measured in this run; ")
    lines = [report.header("Intersection: naive vs bvh (mean, sah) vs embree"),
             (f"{'Quick run (--quick): ' if quick else ''}"
             f"{args.rays:,} rays per batch (camera: the nearest 4:3 image); threads "
             f"{', '.join(map(str, args.threads))}; every rate is the median of {args.repeats} "
             f"run{'s' if args.repeats > 1 else ''} after a warm-up call; naive traces at most "
             f"{args.naive_budget:,.0f} ray-triangle tests (at least {args.naive_min} rays). "
             "Synthetic meshes: `benchmarks.synthetic.displaced_torus` (4 * rows^2 triangles). "
             "Build seconds are single runs on "
             f"{max(args.threads)} threads (the BVH build is serial; Embree's uses its own "
             "thread pool); embree traces a batch split over numba's thread count. "
             f"Load average (1 min) before the run {load_before:.1f}, after it "
             f"{load_after:.1f}, on {os.cpu_count()} cores: well above this run's own threads "
             "means another process shared the CPU and the rates are low and noisy."), "",
             "First-call cost per backend on a one-triangle mesh (bvh: both splits): " + cold
             + "loading numba's cache: "
             + ", ".join(f"{k} {v:.2f} s" for k, v in compile_seconds.items()) + ".", "",
             f"![rays per second against triangles]({chart_path.name})", ""]
    lines += tables(results, args)
    path = report.write(report_path, "\n".join(lines) + "\n")
    print(f"wrote {path} and {chart_path}")
    return path


if __name__ == "__main__":
    main()
