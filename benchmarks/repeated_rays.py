"""What a ray's second trace finds free, for bvh and Embree side by side: every ray of a batch
traced k times in a row (k = 1, 4, 64; the batch always holds the same number of traces), so
that the k - 1 repeats find the branch outcomes and the cache lines that the first one left.

    python -m benchmarks.repeated_rays [--quick] [--rays 262144] [--repeats 5] [--threads 2]
        [--meshes keenan/building.dae ...] [--output repeated_rays.md]

Why: on distinct random rays bvh runs below Embree's rays per second (accel_rays), with a
per-visit cost that removing work from the ray set-up, prefetching and branch-free variants did
not move (issue 14's notes). If bvh's time per trace falls further than Embree's once a ray
repeats, the gap is in what a repeat makes free (mispredicted branches, cache misses), not in
the arithmetic both do on every trace. Rays are accel_rays' (random and secondary); closest hit
through each backend's batch face, the backends taking turns in every repeat, the median
kept. Writes benchmarks/results/repeated_rays.md (or --output, relative to it); --quick: one
small mesh, a small batch, one repeat, into a new temporary directory unless --output is given.
"""
import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

import accel
import ptrace
from accel.types import Rays

from . import report
from .accel_rays import make_rays, scenes_dir

MESHES = ["keenan/building.dae", "sky/CBbunny.dae", "meshedit/cow.dae", "meshedit/maxplanck.dae"]
KINDS = ("random", "secondary")
TIMES = (1, 4, 64)
BACKENDS = (("bvh mean", "bvh", {}), ("bvh sah", "bvh", {"split": "sah"}), ("embree", "embree", {}))


def repeated(rays, times):
    """The first len(rays) // times rays, each `times` times in a row."""
    index = np.repeat(np.arange(len(rays) // times), times)
    return Rays(rays.origins[index], rays.directions[index], rays.tmin[index].copy(),
                rays.tmax[index].copy())


def measure(meshes, n, repeats):
    """{(mesh, kind, times, label): nanoseconds per trace}."""
    results = {}
    for mesh in meshes:
        geometry = ptrace.load(str(Path(scenes_dir()) / mesh)).geometry
        built = {label: accel.build(kind, geometry, **options)
                 for label, kind, options in BACKENDS}
        for kind in KINDS:
            rays = make_rays(kind, geometry, n)
            for times in TIMES:
                batch = repeated(rays, times)
                seconds = {label: [] for label in built}
                for backend in built.values():   # compile or load, and touch the batch once
                    backend.intersect(batch)
                for _ in range(repeats):
                    for label, backend in built.items():
                        start = time.perf_counter()
                        backend.intersect(batch)
                        seconds[label].append(time.perf_counter() - start)
                for label, values in seconds.items():
                    results[mesh, kind, times, label] = statistics.median(values) / len(batch) * 1e9
                print(mesh, kind, f"x{times}", ", ".join(
                    f"{label} {results[mesh, kind, times, label]:.1f} ns" for label in built),
                    flush=True)
    return results


def table(results, meshes):
    labels = [label for label, _, _ in BACKENDS]
    lines = ["| mesh | rays | traced in a row | "
             + " | ".join(f"{label} ns per trace" for label in labels)
             + " | " + " | ".join(f"{label} / embree (rate)" for label in labels[:-1]) + " |",
             "|---|---|---:|" + "---:|" * (2 * len(labels) - 1)]
    for mesh in meshes:
        for kind in KINDS:
            for times in TIMES:
                ns = [results[mesh, kind, times, label] for label in labels]
                lines.append(f"| {mesh} | {kind} | {times} | "
                             + " | ".join(f"{value:.1f}" for value in ns) + " | "
                             + " | ".join(f"{ns[-1] / value:.2f}" for value in ns[:-1]) + " |")
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--rays", type=int, default=262144)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--meshes", nargs="+", default=None)
    parser.add_argument("--output", default=None)
    args = parser.parse_args(argv)
    meshes = args.meshes or (["meshedit/cow.dae"] if args.quick else MESHES)
    n = 4096 if args.quick else args.rays
    repeats = 1 if args.quick else args.repeats
    numba.set_num_threads(args.threads)
    results = measure(meshes, n, repeats)
    text = "\n".join([
        report.header("Repeated rays: what a ray's second trace finds free"), "",
        f"{n:,} traces per batch, closest hit, {args.threads} threads; each ray traced 1, 4 or "
        f"64 times in a row (so {n:,}, {n // 4:,} or {n // 64:,} distinct rays); each cell the "
        f"median of {repeats} runs, the backends taking turns. bvh with the default mean split "
        "and with the SAH split; the rate ratio is Embree's time per trace over bvh's.", "",
        *table(results, meshes), ""])
    if args.output is None and args.quick:
        path = Path(tempfile.mkdtemp(prefix="ptrace-repeated-")) / "repeated_rays.md"
        path.write_text(text)
    else:
        path = report.write(args.output or "repeated_rays.md", text)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
