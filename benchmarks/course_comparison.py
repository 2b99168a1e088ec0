"""The course's headline comparisons in one report: normal shading, the seed's full commands, and
how the naive-to-BVH speedup grows with triangle count.

    python -m benchmarks.course_comparison [--quick] [--threads 2] [--repeats 3]
        [--commands NAME ...] [--torus 1024 4096 ...] [--output course_comparison.md]

1. Normal shading (`integrator="normals"`, 1 spp, 480x360) of cow and maxplanck with naive, bvh
   and embree: wall seconds of the `ptrace.render` call, acceleration build included, kernels
   compiled beforehand by a tiny render per backend; bvh and embree the median of --repeats
   runs, naive one run; speedups naive/bvh and naive/embree beside the course's figures.
2. The seed's full commands (cow, maxplanck, CBspheres, CBgems at -s 64 -l 16 -m 6, CBbunny
   -s 16 -l 8 -m 6 with and without -H, plus the commands the Sp19 staff solution was timed on
   here: cow -s 16 -l 1 -m 1, CBbunny -s 64 -l 32 -m 1 with and without -H), 480x360, one run
   per backend through `benchmarks.seed_commands.time_command` (the seed_commands code path:
   wall of the render call including the build, naive estimated from a reduced render above
   1,000 triangles); the cow command also end to end through the CLI in a fresh process
   (`python -m ptrace -t 2 ...`, start-up included, numba's cache warm), for the 6 s target.
3. Growth: on the displaced tori of benchmarks.synthetic, closest-hit rays/s of naive and bvh on
   the same camera rays (accel_rays.make_rays "camera"; naive on an evenly spaced subset of
   them), S(n) = rate_bvh / rate_naive, fitted by S = c * n / log2(n) (one constant, least
   squares in log space) and by a free power law S = a * n^b, with a log-log chart beside the
   report.
--quick: 120x90, -s divided by 16, only cow and CBspheres among the commands, tori 1k/4k/16k,
--repeats 1. Writes benchmarks/results/course_comparison.md (or --output; a relative path is
taken inside benchmarks/results/) and the chart beside it with the extension .png.
"""
import argparse
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numba
import numpy as np

from . import report, synthetic
from .accel_rays import make_rays, scenes_dir, warm_up
from .seed_commands import COMMANDS, COURSE, NAIVE_RUN_TRIANGLES, time_command

BACKENDS = ("naive", "bvh", "embree")
RESOLUTION = (480, 360)
QUICK_RESOLUTION = (120, 90)
QUICK_SPP_SCALE = 16

# the course's normal-shading figures (docs/course.md#course-scenes: student logs, thread counts
# unknown)
NORMALS = {
    "meshedit/cow.dae": "students: naive 43.8 s, BVH 0.116 s (378x); the seed's full cow "
                        "render: 116x",
    "meshedit/maxplanck.dae": "students: naive 606 s, BVH 0.172 s (3,523x)",
}

# the commands the Sp19 staff solution was rendered with on this 2-core machine (2 threads;
# /work/shared/scenes/cs184/reference_sp19_staff/README.md), in seed_commands.COMMANDS' format
STAFF_COMMANDS = {
    "cow -s 16 -l 1 -m 1": ("meshedit/cow.dae", 16, 1, 1, (480, 360), {}),
    "CBbunny -s 64 -l 32 -m 1 -H": ("sky/CBbunny.dae", 64, 32, 1, (480, 360),
                                    {"hemisphere": True}),
    "CBbunny -s 64 -l 32 -m 1": ("sky/CBbunny.dae", 64, 32, 1, (480, 360), {}),
}
ALL_COMMANDS = {**COMMANDS, **STAFF_COMMANDS}
FULL = ["cow -s 64 -l 16 -m 6", "maxplanck -s 64 -l 16 -m 6", "CBspheres -s 64 -l 16 -m 6",
        "CBgems -s 64 -l 16 -m 6", "CBbunny -s 16 -l 8 -m 6 -H", "CBbunny -s 16 -l 8 -m 6",
        *STAFF_COMMANDS]
QUICK = ["cow -s 64 -l 16 -m 6", "CBspheres -s 64 -l 16 -m 6"]
TARGET_COMMAND = "cow -s 64 -l 16 -m 6"
HEMISPHERE_PAIRS = [("CBbunny -s 16 -l 8 -m 6 -H", "CBbunny -s 16 -l 8 -m 6"),
                    ("CBbunny -s 64 -l 32 -m 1 -H", "CBbunny -s 64 -l 32 -m 1")]

# the course's figure per command: the seed's quotes (seed_commands.COURSE, 8 threads) and the
# Sp19 staff solution's times on this 2-core machine (2 threads; adaptive sampling always on in
# that program, 32 / 0.05, so it stopped early on converged pixels)
STAFF = {
    "cow -s 64 -l 16 -m 6": "Sp19 staff solution here, 2 threads: 20 s (issue 5)",
    "CBbunny -s 16 -l 8 -m 6 -H": "spec part 3 image at 480x480 (XJuFCwn), no time quoted; "
                                  "staff -H vs light sampling: rows below",
    "CBbunny -s 16 -l 8 -m 6": "no course time for this command; staff -H vs light sampling: "
                               "rows below",
    "cow -s 16 -l 1 -m 1": "Sp19 staff solution here, 2 threads: 9 s",
    "CBbunny -s 64 -l 32 -m 1 -H": "Sp19 staff solution here, 2 threads: 541 s (hemisphere)",
    "CBbunny -s 64 -l 32 -m 1": "Sp19 staff solution here, 2 threads: 240 s (light sampling)",
}
STAFF_SECONDS = {"CBbunny -s 64 -l 32 -m 1 -H": 541.0, "CBbunny -s 64 -l 32 -m 1": 240.0}

NORMALS_TARGET = 300.0     # cow normal shading, naive wall over bvh wall
COMMAND_TARGET = 6.0       # seconds, cow command with bvh, CLI start-up included
GROWTH_TARGET = 1.5        # the n / log2 n fit within this factor at every point


def course_figure(name):
    parts = []
    if name in COURSE:
        parts.append(f"seed, 8 threads: {COURSE[name]}")
    if name in STAFF:
        parts.append(STAFF[name])
    return "; ".join(parts)


def set_threads(threads):
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))


def speedup(x):
    """A speedup with two significant digits below 10 (0.31x, 2.4x), whole numbers above."""
    return f"{x:.2g}x" if x < 10 else f"{x:,.0f}x"


def children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def cpu_share(cpu_seconds, wall_seconds):
    """This process's CPU seconds over wall seconds times its threads: near 1 when it had its
    cores to itself, well below when other processes took them (or part of it was serial)."""
    return cpu_seconds / max(wall_seconds * numba.get_num_threads(), 1e-9)


# ---------------------------------------------------------------------------------------------
# 1. normal shading


def normals_runs(scene, kind, resolution, repeats):
    """(wall, build, render, rays, cpu share) medians of `repeats` normal-shading renders."""
    import ptrace
    runs = []
    for _ in range(repeats):
        stats = {}
        cpu, start = time.process_time(), time.perf_counter()
        ptrace.render(scene, integrator="normals", resolution=resolution, accel=kind,
                      stats=stats)
        wall = time.perf_counter() - start
        runs.append((wall, stats["build_seconds"], stats["render_seconds"], stats["rays"],
                     cpu_share(time.process_time() - cpu, wall)))
    return tuple(statistics.median(r[i] for r in runs) for i in range(5))


def measure_normals(args, resolution):
    import ptrace
    results = {}
    for relpath in NORMALS:
        scene = ptrace.load(os.path.join(scenes_dir(), relpath))
        for kind in BACKENDS:        # compile (or load numba's cache) outside the timing
            ptrace.render(scene, integrator="normals", resolution=(16, 12), accel=kind)
        for kind in BACKENDS:
            repeats = 1 if kind == "naive" else args.repeats
            results[relpath, kind] = normals_runs(scene, kind, resolution, repeats)
            print(f"normals {relpath} {kind}: {results[relpath, kind][0]:.3f} s", flush=True)
        results[relpath, "triangles"] = scene.triangle_count
    return results


def normals_table(results, args, resolution):
    lines = ["## 1. Normal shading: naive, bvh, embree", "",
             (f"{resolution[0]}x{resolution[1]}, 1 spp, {args.threads} threads. *wall s*: the "
              "`ptrace.render(..., integrator=\"normals\")` call, acceleration build included, "
              f"kernels compiled beforehand; bvh and embree the median of {args.repeats} "
              f"run{'s' if args.repeats > 1 else ''}, naive one run. Speedups are naive's "
              "seconds over the backend's; *render only* leaves the build out. *CPU share*: "
              "this process's CPU seconds over wall seconds times threads (well below 100%: "
              "other processes took the cores, or the run is dominated by serial work)."), "",
             "| scene | triangles | backend | build s | render s | wall s | rays/s | "
             "speedup (wall) | speedup (render only) | CPU share | the course |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for relpath, course in NORMALS.items():
        naive_wall, _, naive_render, _, _ = results[relpath, "naive"]
        for kind in BACKENDS:
            wall, build, render_s, rays, share = results[relpath, kind]
            lines.append(f"| {relpath} | {results[relpath, 'triangles']:,} | {kind} | "
                         f"{build:.3f} | {render_s:.3f} | {wall:.3f} | {rays / render_s:,.0f} | "
                         f"{speedup(naive_wall / wall)} | {speedup(naive_render / render_s)} | "
                         f"{share:.0%} | {course if kind == 'bvh' else ''} |")
    return lines


# ---------------------------------------------------------------------------------------------
# 2. full commands


def cli_args(command, spp, resolution, threads, kind, output):
    relpath, _, light_samples, depth, _, extra = command
    argv = ["-t", str(threads), "-s", str(spp), "-l", str(light_samples), "-m", str(depth),
            "-r", str(resolution[0]), str(resolution[1]), "--accel", kind, "-q", "-f", output]
    if extra.get("hemisphere"):
        argv.append("-H")
    if extra.get("adaptive"):
        argv += ["-a", str(extra["adaptive"][0]), str(extra["adaptive"][1])]
    return argv + [os.path.join(scenes_dir(), relpath)]


def cli_seconds(command, spp, resolution, threads, kind="bvh"):
    """(wall seconds, CPU share) of `python -m ptrace ...` in a fresh process (after one
    untimed tiny run of the CLI, so numba's cache is warm): what a user waits for, start-up
    included."""
    with tempfile.TemporaryDirectory() as directory:
        output = os.path.join(directory, "out.png")
        subprocess.run([sys.executable, "-m", "ptrace",
                        *cli_args(command, 1, (8, 6), threads, kind, output)],
                       check=True, capture_output=True)
        cpu, start = children_cpu(), time.perf_counter()
        subprocess.run([sys.executable, "-m", "ptrace",
                        *cli_args(command, spp, resolution, threads, kind, output)],
                       check=True, capture_output=True)
        wall = time.perf_counter() - start
        return wall, (children_cpu() - cpu) / (wall * threads)


def measure_commands(args, names, resolution, spp_scale):
    import ptrace
    results = {}
    for name in names:
        relpath, spp, light_samples, depth, _, extra = ALL_COMMANDS[name]
        run_spp = max(1, spp // spp_scale)
        scene = ptrace.load(os.path.join(scenes_dir(), relpath))
        for kind in BACKENDS:        # compile (or load numba's cache) outside the timing
            ptrace.render(scene, spp=1, light_samples=1, max_depth=2, resolution=(8, 6),
                          accel=kind, **extra)
        runs = {}
        bvh_rays = None
        for kind in ("bvh", "embree", "naive"):
            cpu, start = time.process_time(), time.perf_counter()
            run = time_command(scene, kind, run_spp, light_samples, depth, resolution, extra,
                               naive_shrink=args.naive_shrink, bvh_rays=bvh_rays)
            run["cpu_share"] = cpu_share(time.process_time() - cpu, time.perf_counter() - start)
            run.pop("image")
            if kind == "bvh":
                bvh_rays = run["stats"]["rays"]
            runs[kind] = run
            print(f"{name} {kind}: {run['wall']:.1f} s"
                  f"{' (estimated)' if run['estimated'] else ''}", flush=True)
        results[name] = {"runs": runs, "spp": run_spp, "triangles": scene.triangle_count,
                         "spheres": scene.sphere_count}
        if name == TARGET_COMMAND:
            results[name]["cli"], results[name]["cli_share"] = cli_seconds(
                ALL_COMMANDS[name], run_spp, resolution, args.threads)
            print(f"{name} bvh through the CLI: {results[name]['cli']:.1f} s", flush=True)
    return results


def commands_table(results, args, resolution):
    lines = ["## 2. The seed's full commands", "",
             (f"{resolution[0]}x{resolution[1]}, {args.threads} threads (`-t {args.threads}`), "
              "one run per backend. *s*: wall seconds of the `ptrace.render` call with the "
              "acceleration build, after the kernels were compiled (numba's compile and the "
              "scene's loading are not in it). naive's seconds are *est.* (estimated, see "
              "below) on meshes above "
              f"{NAIVE_RUN_TRIANGLES:,} triangles and a full run otherwise. The course's column "
              "gives the seed's quotes for the course's own solution (8 threads) and the Sp19 "
              "staff solution's times on this 2-core machine (2 threads; that program always "
              "samples adaptively, 32 / 0.05, so it stops early on converged pixels)."), "",
             "| command | triangles | -s run | naive s | naive | bvh s | embree s | naive/bvh | "
             "naive/embree | bvh rays | bvh rays/s | CPU share bvh/embree/naive | "
             "the course's figure |",
             "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for name, result in results.items():
        runs = result["runs"]
        naive = runs["naive"]
        if naive["estimated"]:
            w, h = naive["resolution"]
            how = (f"est. from {naive['stats']['rays']:,} rays ({w}x{h}, -s {naive['spp']}): "
                   f"{naive['rays_per_second']:,.0f} rays/s")
        else:
            how = "run"
        triangles = f"{result['triangles']:,}" + (f" + {result['spheres']} spheres"
                                                 if result["spheres"] else "")
        bvh = runs["bvh"]
        lines.append(f"| {name} | {triangles} | {result['spp']} | {secs(naive['wall'])} | {how} | "
                     f"{secs(bvh['wall'])} | {secs(runs['embree']['wall'])} | "
                     f"{speedup(naive['wall'] / bvh['wall'])} | "
                     f"{speedup(naive['wall'] / runs['embree']['wall'])} | "
                     f"{bvh['stats']['rays']:,} | {bvh['rays_per_second']:,.0f} | "
                     + "/".join(f"{runs[k]['cpu_share']:.0%}" for k in ("bvh", "embree", "naive"))
                     + f" | {course_figure(name)} |")
    target = command_target(results, args)
    if target is not None:
        seconds, verdict = target
        lines.append(f"| target: {TARGET_COMMAND} with bvh through the CLI, start-up included "
                     f"(`python -m ptrace -t {args.threads} ...`, fresh process) | | "
                     f"{results[TARGET_COMMAND]['spp']} | | | {seconds:.1f} | | | | | | "
                     f"{results[TARGET_COMMAND]['cli_share']:.0%} | "
                     f"<= {COMMAND_TARGET:.0f} s: {verdict} |")
    ratios = []
    for hemisphere, light in HEMISPHERE_PAIRS:
        if hemisphere in results and light in results:
            ours = (results[hemisphere]["runs"]["bvh"]["wall"]
                    / results[light]["runs"]["bvh"]["wall"])
            text = f"{light.replace('CBbunny ', '')}: ours (bvh) {ours:.2f}x"
            if light in STAFF_SECONDS:
                staff = STAFF_SECONDS[hemisphere] / STAFF_SECONDS[light]
                text += (f", the Sp19 staff solution {staff:.2f}x ({STAFF_SECONDS[hemisphere]:.0f}"
                         f" s / {STAFF_SECONDS[light]:.0f} s, 2 threads, this machine)")
            ratios.append(text)
    if ratios:
        lines += ["", "CBbunny, hemisphere sampling (-H) over light sampling, wall time: "
                  + "; ".join(ratios) + "."]
    lines += ["", ("How naive's rows were estimated: naive and bvh trace the same paths bit for "
                   "bit, so the bvh run's exact ray count is the full command's. On a mesh above "
                   f"{NAIVE_RUN_TRIANGLES:,} triangles naive renders the same command at "
                   + (f"the resolution divided by {args.naive_shrink} per axis"
                      if args.naive_shrink > 1 else "the same resolution")
                   + " with -s 1 "
                   "(`seed_commands.time_command`, as `python -m benchmarks.seed_commands` "
                   "does); its rays per second there (the *naive* column) give its wall time as "
                   "the bvh run's ray count divided by that rate, plus naive's build time. This "
                   "is the seed's 'run at a lower -s and scale per sample', with the scaling done "
                   "per ray, which also holds when paths differ in length. Scenes of at most "
                   f"{NAIVE_RUN_TRIANGLES:,} triangles (the sphere scenes, CBgems) ran naive in "
                   "full.")]
    return lines


def command_target(results, args):
    """(seconds, verdict) of the cow command through the CLI, or None if it was not run."""
    if TARGET_COMMAND not in results or "cli" not in results[TARGET_COMMAND]:
        return None
    seconds = results[TARGET_COMMAND]["cli"]
    if seconds <= COMMAND_TARGET:
        verdict = f"PASS ({COMMAND_TARGET - seconds:.1f} s to spare)"
    else:
        verdict = (f"FAIL: misses by {seconds - COMMAND_TARGET:.1f} s "
                   f"({seconds / COMMAND_TARGET:.2f}x the target)")
    return seconds, verdict


# ---------------------------------------------------------------------------------------------
# 3. growth of the speedup with triangle count


def rate(backend, rays, repeats):
    """Closest-hit rays per second: median of `repeats` runs after a warm-up call."""
    from accel.types import Rays
    k = min(len(rays), 64)
    backend.intersect(Rays(rays.origins[:k], rays.directions[:k], rays.tmin[:k], rays.tmax[:k]))
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        backend.intersect(rays)
        times.append(time.perf_counter() - start)
    return len(rays) / statistics.median(times)


def measure_growth(args):
    import accel
    from accel.types import Rays
    warm_up()
    rows = []
    for n in args.torus:
        vertices, faces = synthetic.displaced_torus(n)
        geometry = accel.Geometry(vertices, faces)
        rays = make_rays("camera", geometry, args.rays)
        bvh = accel.build("bvh", geometry)
        naive = accel.build("naive", geometry)
        k = min(len(rays), max(args.naive_min, int(args.naive_budget // n)))
        step = len(rays) // k        # an evenly spaced subset, not the image's first rows
        subset = Rays(rays.origins[::step][:k], rays.directions[::step][:k],
                      rays.tmin[::step][:k], rays.tmax[::step][:k])
        rate_bvh = rate(bvh, rays, args.repeats)
        rate_naive = rate(naive, subset, args.repeats)
        mismatches = int((bvh.intersect(subset).prim != naive.intersect(subset).prim).sum())
        hits = float((bvh.intersect(rays).prim >= 0).mean())
        rows.append({"n": n, "rays": len(rays), "naive_rays": k, "bvh": rate_bvh,
                     "naive": rate_naive, "speedup": rate_bvh / rate_naive,
                     "mismatches": mismatches, "hits": hits})
        print(f"{synthetic.name(n)}: bvh {rate_bvh:,.0f}, naive {rate_naive:,.0f} rays/s, "
              f"speedup {rate_bvh / rate_naive:,.0f}", flush=True)
    return rows


def n_log_n(n):
    n = np.asarray(n, dtype=float)
    return n / np.log2(n)


def fit(rows):
    """Least squares in log space: S = c * n / log2 n (c only) and S = a * n^b (a, b)."""
    n = np.array([r["n"] for r in rows], dtype=float)
    s = np.array([r["speedup"] for r in rows])
    c = float(np.exp(np.mean(np.log(s) - np.log(n_log_n(n)))))
    if len(rows) >= 2:
        b, log_a = np.polyfit(np.log(n), np.log(s), 1)
        a, b = float(np.exp(log_a)), float(b)
    else:
        a, b = float("nan"), float("nan")
    return {"c": c, "a": a, "b": b,
            "nlogn": c * n_log_n(n), "power": a * n ** b, "n": n, "s": s}


def factor(measured, fitted):
    """How far apart two positive numbers are, as a factor >= 1."""
    return float(max(measured / fitted, fitted / measured))


def growth_verdict(f):
    worst_nlogn = max(factor(s, p) for s, p in zip(f["s"], f["nlogn"]))
    worst_power = max(factor(s, p) for s, p in zip(f["s"], f["power"]))
    where = synthetic.name(int(f["n"][int(np.argmax([factor(s, p) for s, p in
                                                      zip(f["s"], f["nlogn"])]))]))
    passed = worst_nlogn <= GROWTH_TARGET
    lo, hi = f["n"].min(), f["n"].max()
    sentence = (f"S(n) = c * n / log2(n) with c = {f['c']:.3g} is within a factor "
                f"{worst_nlogn:.2f} of every measured point (worst at {where}; the limit is "
                f"{GROWTH_TARGET}): "
                + ("the naive-to-bvh speedup grows like n / log n over "
                   if passed else "the speedup does not follow n / log n closely enough over ")
                + f"{lo:,.0f} to {hi:,.0f} triangles. The free power law S = a * n^b gives "
                f"b = {f['b']:.2f} (worst factor {worst_power:.2f}); n / log2(n) has the local "
                f"exponent 1 - 1/ln(n) = {1 - 1 / math.log(lo):.2f} to {1 - 1 / math.log(hi):.2f} "
                "over this range (1 would be a constant bvh cost per ray, and naive's cost per "
                "ray is proportional to n).")
    return passed, worst_nlogn, sentence


def growth_table(rows, f, args, chart_path):
    lines = ["## 3. Growth of the speedup with triangle count", "",
             f"![speedup against triangles]({chart_path.name})", "",
             (f"Displaced tori (`benchmarks.synthetic.displaced_torus`), {args.threads} threads, "
              f"camera rays (`accel_rays.make_rays(\"camera\", geometry, {args.rays:,})`, one "
              "pinhole ray per pixel); bvh traces them all, naive an evenly spaced subset of "
              f"them (at most {args.naive_budget:,.0f} ray-triangle tests, at least "
              f"{args.naive_min} rays); closest-hit rays/s, median of {args.repeats} "
              f"run{'s' if args.repeats > 1 else ''} after a warm-up call. S = bvh rays/s over "
              "naive rays/s. *fit ratio*: measured S over the fit. *mismatches*: subset rays "
              "whose hit triangle differs between bvh and naive."), "",
             "| mesh | triangles | rays | hit fraction | naive rays | bvh rays/s | naive rays/s "
             "| S | n / log2 n | c n / log2 n | fit ratio | a n^b | fit ratio | mismatches |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r, nlogn, power in zip(rows, f["nlogn"], f["power"]):
        lines.append(f"| {synthetic.name(r['n'])} | {r['n']:,} | {r['rays']:,} | "
                     f"{r['hits']:.3f} | {r['naive_rays']:,} | {r['bvh']:,.0f} | "
                     f"{r['naive']:,.0f} | "
                     f"{r['speedup']:,.1f} | {float(n_log_n(r['n'])):,.0f} | {nlogn:,.1f} | "
                     f"{r['speedup'] / nlogn:.2f} | {power:,.1f} | {r['speedup'] / power:.2f} | "
                     f"{r['mismatches']} |")
    _, _, sentence = growth_verdict(f)
    lines += ["", f"Fits (least squares in log space): S = c * n / log2(n), c = {f['c']:.4g}; "
              f"S = a * n^b, a = {f['a']:.4g}, b = {f['b']:.3f}.", "", sentence]
    return lines


def chart(rows, f, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = f["n"]
    smooth = np.geomspace(n.min(), n.max(), 200)
    figure, ax = plt.subplots(figsize=(6.4, 4.6))
    ax.plot(n, f["s"], "o", color="black", label="measured S = bvh rays/s / naive rays/s")
    ax.plot(smooth, f["c"] * n_log_n(smooth), "-", color="tab:blue",
            label=f"c n / log2 n, c = {f['c']:.3g}")
    if np.isfinite(f["b"]):
        ax.plot(smooth, f["a"] * smooth ** f["b"], "--", color="tab:orange",
                label=f"a n^b, a = {f['a']:.3g}, b = {f['b']:.2f}")
    for r in rows:
        ax.annotate(synthetic.name(r["n"]), (r["n"], r["speedup"]), textcoords="offset points",
                    xytext=(4, -10), fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_xlabel("triangles n (displaced torus)")
    ax.set_ylabel("speedup of bvh over naive (camera rays)")
    ax.set_title("Naive-to-BVH closest-hit speedup against triangle count", fontsize=10)
    ax.legend(fontsize=8)
    figure.tight_layout()
    tmp = path.with_name(path.name + ".tmp.png")
    figure.savefig(tmp, dpi=110)
    plt.close(figure)
    tmp.replace(path)
    return path


# ---------------------------------------------------------------------------------------------


def targets_table(normals, commands, f, args, quick):
    note = (" at quick settings (not the target's resolution and -s): indicative only"
            if quick else "")
    lines = ["## Targets (issue 5)", "",
             "| target | measured | result |", "|---|---|---|"]
    cow = "meshedit/cow.dae"
    if (cow, "naive") in normals:
        ratio = normals[cow, "naive"][0] / normals[cow, "bvh"][0]
        verdict = "PASS" if ratio >= NORMALS_TARGET else "FAIL"
        lines.append(f"| cow normal shading, naive/bvh speedup (wall) >= {NORMALS_TARGET:.0f}x "
                     f"(the course's students: about 380x) | {speedup(ratio)} | "
                     f"{verdict}{note} |")
    target = command_target(commands, args)
    if target is not None:
        seconds, verdict = target
        in_process = commands[TARGET_COMMAND]["runs"]["bvh"]["wall"]
        lines.append(f"| cow `-t {args.threads} -s 64 -l 16 -m 6 -r 480 360` with bvh <= "
                     f"{COMMAND_TARGET:.0f} s, start-up included (the Sp19 staff solution: 20 s "
                     f"here; the seed: 18 s on 8 threads) | {seconds:.1f} s through the CLI "
                     f"at a CPU share of {commands[TARGET_COMMAND]['cli_share']:.0%} (the render "
                     f"call alone: {in_process:.1f} s) | {verdict}{note} |")
    if f is not None:
        passed, worst, _ = growth_verdict(f)
        lines.append(f"| naive-to-bvh speedup grows like n / log n (c n / log2 n within "
                     f"{GROWTH_TARGET}x of every point) | worst factor {worst:.2f}, "
                     f"c = {f['c']:.3g} | {'PASS' if passed else 'FAIL'}{note} |")
    return lines


def secs(value):
    """Seconds with three significant digits under 10 s (quick runs take a few ms), else 0.1."""
    return f"{value:.3g}" if value < 10 else f"{value:.1f}"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="120x90, -s divided by 16, cow and CBspheres only, tori 1k/4k/16k, "
                             "one repeat")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=None, help="timed runs (3; quick 1)")
    parser.add_argument("--commands", nargs="*", default=None,
                        help=f"full commands to run (default {', '.join(FULL)})")
    parser.add_argument("--naive-shrink", type=int, default=None,
                        help="naive's reduced render divides the resolution by this per axis "
                             "(4, giving 120x90; quick 1, the same 120x90)")
    parser.add_argument("--torus", type=int, nargs="*", default=None,
                        help="triangle counts of the tori (default 1k to 1M; quick 1k 4k 16k)")
    parser.add_argument("--rays", type=int, default=None,
                        help="camera rays per torus (1,000,000; quick 50,000)")
    parser.add_argument("--naive-budget", type=float, default=None,
                        help="naive's ray-triangle tests per torus (1e8; quick 1e7)")
    parser.add_argument("--naive-min", type=int, default=128)
    parser.add_argument("--output", default="course_comparison.md",
                        help="report path (relative: inside benchmarks/results/); the chart "
                             "goes beside it with the extension .png")
    args = report.quick_defaults(
        parser.parse_args(argv), repeats=(1, 3), naive_shrink=(1, 4), commands=(QUICK, FULL),
        torus=([1024, 4096, 16384], list(synthetic.SERIES)), rays=(50_000, 1_000_000),
        naive_budget=(1e7, 1e8))
    quick = args.quick
    unknown = [name for name in args.commands if name not in ALL_COMMANDS]
    if unknown:
        raise SystemExit(f"unknown command(s) {unknown}; choose from {list(ALL_COMMANDS)}")
    resolution = QUICK_RESOLUTION if quick else RESOLUTION
    spp_scale = QUICK_SPP_SCALE if quick else 1

    previous_threads = numba.get_num_threads()
    set_threads(args.threads)
    load_before = os.getloadavg()[0]
    start, cpu = time.perf_counter(), time.process_time()
    try:
        normals = measure_normals(args, resolution)
        commands = measure_commands(args, args.commands, resolution, spp_scale)
        rows = measure_growth(args) if args.torus else []
    finally:
        numba.set_num_threads(previous_threads)
    f = fit(rows) if rows else None
    share = (time.process_time() - cpu) / ((time.perf_counter() - start) * args.threads)
    minutes = (time.perf_counter() - start) / 60
    load_after = os.getloadavg()[0]

    report_path = report.destination(args.output)
    chart_path = chart(rows, f, report_path.with_suffix(".png")) if f else None
    lines = [report.header("The course's comparisons: normal shading, the seed's commands, "
                           "and the speedup's growth"),
             (f"{'Quick run (--quick): ' if quick else ''}{resolution[0]}x{resolution[1]}, "
              f"-s divided by {spp_scale}, {args.threads} threads, {args.repeats} "
              f"repeat{'s' if args.repeats > 1 else ''}; the whole run took {minutes:.1f} min "
              f"at a CPU share of {share:.0%} (this process's CPU seconds over wall seconds "
              f"times {args.threads} threads). "
              f"Load average (1 min) before it {load_before:.1f}, after it {load_after:.1f}, on "
              f"{os.cpu_count()} cores: above {args.threads} means another process shared the "
              "CPU and the times are long and noisy."), ""]
    lines += targets_table(normals, commands, f, args, quick) + [""]
    lines += normals_table(normals, args, resolution) + [""]
    if commands:
        lines += commands_table(commands, args, resolution) + [""]
    if f is not None:
        lines += growth_table(rows, f, args, chart_path) + [""]
    path = report.write(report_path, "\n".join(lines))
    print(f"wrote {path}" + (f" and {chart_path}" if chart_path else ""))
    return path


if __name__ == "__main__":
    main()
