"""Choosing lights in a room of many: every light at every vertex against -l lights chosen by
power or by the light BVH (--light-sampler), by relative MSE at equal samples and relative MSE
x seconds.

    python -m benchmarks.many_lights [--quick] [--spp 4 16] [--reference-spp 1024]
        [--resolution 160 120] [--threads 2] [--output many_lights.md]

The scene is scenes/make_many_lights.py's room (64 area lights of radiance 1 to 64 and 1,024
emissive ceiling tiles), written to a temporary folder, seen from inside it (--eye 0,1.6,7.5
--look-at 0,1.2,0 --fov 60), `-m 5 -l 1`. The reference is a --reference-spp render by the light BVH
(seed 99; every estimator is unbiased, and the table shows each against it; the image means
say so too). Each estimator
renders every spp in turns, seeds 0..repeats-1; its error is the median relative MSE (benchmarks'
error_vs_time.relative_mse: pixels whose reference is at most 1) and its seconds the median wall
seconds of the render call. Beside them, the paths per second of the same room lit by its
brightest area light alone, the yardstick for the cost of having many lights.
"""
import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import ptrace

from . import report
from .error_vs_time import relative_mse
from .templating import blocks, fill

ROOT = Path(__file__).resolve().parents[1]
VIEW = dict(eye=(0.0, 1.6, 7.5), target=(0.0, 1.2, 0.0), fov=60.0)
SAMPLERS = ("all", "power", "bvh")
TEMPLATE = "many_lights.md"      # the prose, in benchmarks/templates/


def room(folder, *flags):
    path = Path(folder) / ("brightest.dae" if flags else "many_lights.dae")
    subprocess.run([sys.executable, str(ROOT / "scenes" / "make_many_lights.py"), "-o",
                    str(path), *flags], check=True, capture_output=True)
    return ptrace.load(path)


def render(scene, width, height, spp, seed, sampler, threads):
    camera = ptrace.look_at(scene, VIEW["eye"], VIEW["target"], fov=VIEW["fov"], width=width,
                            height=height)
    stats = {}
    start = time.perf_counter()
    image = ptrace.render(scene, camera=camera, resolution=(width, height), spp=spp, seed=seed,
                          light_samples=1, max_depth=5, light_sampler=sampler, threads=threads,
                          stats=stats)
    return image, time.perf_counter() - start, stats["rays"]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--spp", type=int, nargs="+", default=None)
    parser.add_argument("--reference-spp", type=int, default=None)
    parser.add_argument("--resolution", type=int, nargs=2, default=None)
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--output", default="many_lights.md")
    args = report.quick_defaults(parser.parse_args(argv), spp=([2], [4, 16]),
                                 reference_spp=(64, 1024), resolution=((64, 48), (160, 120)),
                                 repeats=(1, 3))
    width, height = args.resolution
    with tempfile.TemporaryDirectory() as folder:
        scene, brightest = room(folder), room(folder, "--brightest-only")
    for sampler in SAMPLERS:          # compile and warm each
        render(scene, 8, 6, 1, 0, sampler, args.threads)
    render(brightest, 8, 6, 1, 0, "all", args.threads)
    reference, reference_seconds, _ = render(scene, width, height, args.reference_spp, 99,
                                             "bvh", args.threads)
    rows, yard = {}, []
    for spp in args.spp:
        for repeat in range(args.repeats):
            for sampler in SAMPLERS:
                image, seconds, rays = render(scene, width, height, spp, repeat, sampler,
                                              args.threads)
                rows.setdefault((sampler, spp), []).append(
                    (relative_mse(image, reference), seconds, rays, float(image.mean())))
            if spp == args.spp[-1]:     # the yardstick, in the same turns
                yard.append(render(brightest, width, height, spp, repeat, "all",
                                   args.threads)[1])
    text = blocks(TEMPLATE)
    lines = [report.header("Many lights: every light at every vertex, or -l chosen by power "
                           "or by the light BVH"),
             fill(text["intro"], width=width, height=height, threads=args.threads,
                  reference_spp=args.reference_spp, reference_seconds=reference_seconds,
                  reference_mean=float(reference.mean()), repeats=args.repeats)]
    paths = width * height
    summary = {}
    for (sampler, spp), runs in sorted(rows.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        mse = statistics.median(r[0] for r in runs)
        seconds = statistics.median(r[1] for r in runs)
        rays = statistics.median(r[2] for r in runs)
        summary[(sampler, spp)] = (mse, seconds)
        lines.append(fill(text["row"], sampler=sampler, spp=spp, mse=mse, seconds=seconds,
                          cost=mse * seconds, rays_per_path=rays / (paths * spp),
                          paths_per_second=paths * spp / seconds,
                          mean=statistics.median(r[3] for r in runs)))
    compare = [text["compare"]]
    yard_rate = paths * args.spp[-1] / statistics.median(yard)
    for spp in args.spp:
        mse_all, s_all = summary[("all", spp)]
        for sampler in SAMPLERS[1:]:
            mse, seconds = summary[(sampler, spp)]
            compare.append(fill(text["compare_row"], spp=spp, sampler=sampler,
                                gain=mse_all * s_all / (mse * seconds),
                                rate_ratio=paths * spp / seconds / yard_rate,
                                yard_rate=yard_rate, yard_spp=args.spp[-1]))
    path = report.write(args.output, "\n".join(lines + compare) + "\n")
    print("\n".join(compare))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
