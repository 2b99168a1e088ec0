"""The price of distribution, and a model of how render time falls with more machines.

    python -m benchmarks.distributed [--quick]

On this machine's cores, the same render (CBspheres_lambertian, path, -m 5 -l 4) runs
in-process and on local Dask clusters of 1, 2 and 4 worker processes (all bit-identical, which
the script checks). From those runs: cluster start-up, the first job's extra cost on fresh
workers (import, numba cache, scene scatter, BVH build), the overhead per task (wall time x
busy cores minus the seconds spent inside tasks, per task), and the client's merge time per
task. An "empty" job of tiny tiles measures the bare cost of a task.

The model: a frame of P pixels at S samples, split as ptrace splits it (16-sample passes, tiles
of about TASK_RAYS rays), on M machines of C cores each running C one-thread workers, takes
    T(M) = start + tasks x (task + overhead) / (M x C) + one task (the tail)
where `task` is the seconds per pixel-sample measured inside the tasks of the C-worker local
cluster (every core busy) times the pixels and samples of a tile, bounded below by the client's
serial merge, tasks x merge. It is checked against the
local clusters here (busy cores = min(workers, cores)), then evaluated for an 800x600 frame at
1024 spp on 2, 8 and 32 machines like this one. Writes benchmarks/results/distributed.md.
"""
import argparse
import math
import os
import statistics
import time

import numpy as np

from . import report
from .rays import scenes_dir

SCENE = "sky/CBspheres_lambertian.dae"
OPTIONS = {"light_samples": 4, "max_depth": 5, "seed": 1}


def main(argv=None):
    import ptrace
    from ptrace.rendering import distributed
    from ptrace.rendering.settings import Settings
    from ptrace.rendering.tiles import PASS_SAMPLES

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a smaller frame, one repeat")
    parser.add_argument("--output", default="distributed.md")
    args = parser.parse_args(argv)
    cores = os.cpu_count() or 1
    resolution, spp, repeats = ((80, 60), 32, 1) if args.quick else ((160, 120), 64, 3)
    scene = ptrace.load(os.path.join(scenes_dir(), SCENE))
    kw = dict(OPTIONS, spp=spp, resolution=resolution)
    ptrace.render(scene, spp=1, resolution=(8, 6), max_depth=2)   # compile / load the cache
    pixels = resolution[0] * resolution[1]

    def timed_render(**extra):
        stats = {}
        start = time.perf_counter()
        image = ptrace.render(scene, stats=stats, **kw, **extra)
        return time.perf_counter() - start, image, stats

    lines = [report.header("Distributed rendering: the price of distribution and a scaling model"),
             f"Scene {SCENE}, path integrator, -m {OPTIONS['max_depth']} -l "
             f"{OPTIONS['light_samples']}, {resolution[0]}x{resolution[1]} at -s {spp}; "
             f"{cores} cores; medians of {repeats}.", ""]
    in_process = {}
    for threads in (cores, 1):
        runs = [timed_render(threads=threads) for _ in range(repeats)]
        in_process[threads] = (statistics.median(r[0] for r in runs), runs[0][1], runs[0][2])
    reference = in_process[cores][1]
    rows = ["| run | workers | wall s | vs in-process | tasks | median task s "
            "| overhead per task ms | merge per task ms | identical |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    rows.append(f"| in-process, {cores} threads | - | {in_process[cores][0]:.2f} | 1.00 | - | - "
                f"| - | - | reference |")
    rows.append(f"| in-process, 1 thread | - | {in_process[1][0]:.2f} | "
                f"{in_process[1][0] / in_process[cores][0]:.2f} | - | - | - | - | "
                f"{np.array_equal(in_process[1][1], reference)} |")
    measured = {}
    startup = {}
    overheads, merges = [], []
    for workers in (1, 2, 4):
        start = time.perf_counter()
        client, cluster = distributed.local_client(workers)
        startup[workers] = time.perf_counter() - start
        try:
            threads = max(1, cores // workers)
            first = timed_render(client=client, threads=threads)
            runs = [timed_render(client=client, threads=threads) for _ in range(repeats)]
        finally:
            client.close()
            cluster.close()
        wall = statistics.median(r[0] for r in runs)
        stats = runs[0][2]
        busy = min(workers * threads, cores)
        # core-seconds not spent inside a task (task seconds x its numba threads), per task
        overhead = max(0.0, (wall * busy - stats["task_seconds_total"] * threads) / stats["tasks"])
        merge = stats["merge_seconds"] / stats["tasks"]
        overheads.append(overhead)
        merges.append(merge)
        identical = all(np.array_equal(r[1], reference) for r in runs + [first])
        measured[workers] = (wall, stats, first[0] - wall, threads)
        rows.append(f"| local cluster | {workers} x {threads} thread | {wall:.2f} | "
                    f"{wall / in_process[cores][0]:.2f} | {stats['tasks']} | "
                    f"{stats['median_task_seconds']:.3f} | {overhead * 1e3:.1f} | "
                    f"{merge * 1e3:.2f} | {identical} |")
    lines += rows + [""]
    lines.append("Cluster start-up (LocalCluster + Client), seconds: " + ", ".join(
        f"{w} workers {s:.2f}" for w, s in startup.items()) + ". First job's extra time on fresh "
        "workers (numba cache load, scatter, BVH build): " + ", ".join(
            f"{w} workers {m[2]:.2f} s" for w, m in measured.items()) + ".")

    # bare cost of a task: a normals render in 1-pixel-row tiles
    client, cluster = distributed.local_client(min(2, cores))
    try:
        saved = distributed.TASK_RAYS
        distributed.TASK_RAYS = resolution[0]      # one row of pixels per task
        stats = {}
        ptrace.render(scene, integrator="normals", resolution=resolution, client=client)
        start = time.perf_counter()
        ptrace.render(scene, integrator="normals", resolution=resolution, client=client,
                      stats=stats)
        empty = (time.perf_counter() - start) / stats["tasks"]
        distributed.TASK_RAYS = saved
    finally:
        client.close()
        cluster.close()
    lines += ["", f"Empty-ish tasks (normals, one {resolution[0]}-pixel row each, "
              f"{stats['tasks']} tasks on {min(2, cores)} workers): {empty * 1e3:.1f} ms of "
              f"wall time per task, of which "
              f"{stats['task_seconds_total'] / stats['tasks'] * 1e3:.2f} ms inside the task.", ""]

    overhead = statistics.median(overheads)
    merge = statistics.median(merges)
    # the per-tile cost, measured inside the tasks of the one-thread-per-core cluster (every
    # core busy, as on a worker machine), per pixel-sample
    busy_stats = measured[cores][1] if cores in measured else measured[2][1]
    per_core = busy_stats["task_seconds_total"] / (pixels * spp)
    rays_per_path = Settings(light_samples=OPTIONS["light_samples"],
                             max_depth=OPTIONS["max_depth"]).rays_per_path(scene)

    def model(width, height, samples, machines, cores_each, start_cost):
        n_pixels = width * height
        passes = math.ceil(samples / PASS_SAMPLES)
        pass_n = min(samples, PASS_SAMPLES)
        workers = machines * cores_each
        tile = distributed.tile_pixels(n_pixels, rays_per_path, pass_n, workers)
        tasks = passes * math.ceil(n_pixels / tile)
        task = per_core * tile * pass_n
        compute = tasks * (task + overhead) / workers + task
        return start_cost + max(compute, tasks * merge), tasks, task

    lines += ["## The model against local clusters", "",
              f"Measured: {per_core * 1e6:.2f} us per pixel-sample per core inside the tasks of "
              f"the {cores}-worker cluster (every core busy; in-process on 1 thread with the "
              f"other core idle: {in_process[1][0] / (pixels * spp) * 1e6:.2f} us), overhead "
              f"{overhead * 1e3:.1f} ms per task, merge {merge * 1e3:.2f} ms "
              "per task (medians over the cluster runs above).", "",
              "| workers | busy cores | measured s | model s | model / measured |",
              "|---:|---:|---:|---:|---:|"]
    for workers, (wall, stats, _, threads) in measured.items():
        busy = min(workers * threads, cores)
        predicted, _, _ = model(resolution[0], resolution[1], spp, 1, busy,
                                stats["scatter_seconds"])
        lines.append(f"| {workers} | {busy} | {wall:.2f} | {predicted:.2f} | "
                     f"{predicted / wall:.2f} |")
    lines += ["", f"## 800x600 at 1024 spp on machines like this one ({cores} cores each)", "",
              "Start-up taken as one first job on fresh workers (scatter, numba cache, build), "
              "measured above; workers assumed already running.", "",
              "| machines | workers | tasks | task s | model s | speed-up vs 1 machine |",
              "|---:|---:|---:|---:|---:|---:|"]
    start_cost = statistics.median(m[2] for m in measured.values())
    one, _, _ = model(800, 600, 1024, 1, cores, start_cost)
    for machines in (1, 2, 8, 32):
        seconds, tasks, task = model(800, 600, 1024, machines, cores, start_cost)
        lines.append(f"| {machines} | {machines * cores} | {tasks:,} | {task:.3f} | "
                     f"{seconds:,.1f} | {one / seconds:.1f} |")
    _, _, task = model(800, 600, 1024, 1, cores, start_cost)
    lines += ["", "Where the model bends: the client merges every task's sums in order on one "
              f"core ({merge * 1e3:.2f} ms per task), so beyond about "
              f"{(task + overhead) / max(merge, 1e-9):,.0f} workers the merge, not the workers, "
              "sets the pace; larger tiles (TASK_RAYS) move that limit.", ""]
    path = report.write(args.output, "\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
