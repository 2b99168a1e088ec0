"""Rays per second of naive, bvh and embree on the same random rays, plus BVH build figures.

    python -m benchmarks.accel_rays [--rays 1000000] [--threads 2] [--repeats 3]

For each mesh: the BVH's build seconds (numba compile measured apart, on a tiny mesh first),
nodes, leaves, depth and bytes; then each backend traces the same batch of rays from a sphere
around the mesh toward random points inside its bounds (accel.raygen.sphere_rays, seed 0).
bvh and embree report the median of --repeats runs; naive runs once (it is slow) and may use
fewer rays (--naive-rays). Writes benchmarks/results/accel_rays.md.
"""
import argparse
import os
import statistics
import time

import numba

import accel
from accel import raygen

from . import report

MESHES = ["meshedit/cow.dae", "meshedit/maxplanck.dae"]


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


def main(argv=None):
    import ptrace
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--naive-rays", type=int, default=None,
                        help="rays for naive (default: the same as --rays)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--meshes", nargs="*", default=MESHES)
    parser.add_argument("--output", default="accel_rays.md")
    args = parser.parse_args(argv)
    numba.set_num_threads(args.threads)
    cold_seconds = cold_compile_seconds()
    compile_seconds = warm_up()
    lines = [report.header("Intersection: naive vs bvh vs embree"),
             f"{args.rays:,} rays per mesh from `accel.raygen.sphere_rays(geometry, n, seed=0)`; "
             f"{args.threads} threads; bvh and embree: median of {args.repeats} runs; naive: one "
             f"run on {(args.naive_rays or args.rays):,} rays.", "",
             "First-call cost per backend on a one-triangle mesh: numba compile with an empty "
             "cache (fresh process): " + ", ".join(f"{k} {v:.1f} s" for k, v in cold_seconds.items())
             + "; loading numba's cache: "
             + ", ".join(f"{k} {v:.2f} s" for k, v in compile_seconds.items()) + ".",
             "", "| mesh | triangles | bvh build s | nodes | leaves | depth | bytes | embree build s "
             "| naive rays/s | bvh rays/s | embree rays/s | bvh/naive | embree/bvh | mean nodes visited |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for relpath in args.meshes:
        geometry = ptrace.load(os.path.join(scenes_dir(), relpath)).geometry
        rays = raygen.sphere_rays(geometry, args.rays, seed=0)
        naive_rays = raygen.sphere_rays(geometry, args.naive_rays or args.rays, seed=0)
        bvh = accel.build("bvh", geometry)
        embree = accel.build("embree", geometry)
        naive = accel.build("naive", geometry)
        stats = bvh.stats()
        rates = {}
        for name, backend, batch, repeats in [("bvh", bvh, rays, args.repeats),
                                              ("embree", embree, rays, args.repeats),
                                              ("naive", naive, naive_rays, 1)]:
            times = [timed(backend.intersect, batch)[0] for _ in range(repeats)]
            rates[name] = len(batch) / statistics.median(times)
            print(f"{relpath} {name}: {rates[name]:,.0f} rays/s", flush=True)
        bvh.intersect(rays)
        lines.append(
            f"| {relpath} | {geometry.triangle_count} | {stats['build_seconds']:.3f} | "
            f"{stats['nodes']} | {stats['leaves']} | {stats['max_depth']} | {stats['bytes']:,} | "
            f"{embree.stats()['build_seconds']:.3f} | {rates['naive']:,.0f} | {rates['bvh']:,.0f} | "
            f"{rates['embree']:,.0f} | {rates['bvh'] / rates['naive']:.0f}x | "
            f"{rates['embree'] / rates['bvh']:.2f}x | {bvh.last_mean_visits:.1f} |")
    path = report.write(args.output, "\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
