"""Wall time and rays per second of the seed's command lines, per backend.

    python -m benchmarks.seed_commands [--backends bvh embree naive] [--spp-scale 1]
        [--only NAME ...]

Each command is the seed's flags run through `ptrace.render` (the CLI's code path) on 2
threads. --spp-scale divides every -s (a quick look at the same commands); naive, which tests
every primitive, runs at -s divided by --naive-scale on meshes above 1,000 triangles and its time
is multiplied back per sample (the table says so). Kernels are compiled before timing.

naive and bvh trace the same paths bit for bit, so on meshes above 1,000 triangles naive is run
on a reduced render (resolution divided by --naive-shrink per axis, -s 1) to measure its rays
per second, and its full wall time is
estimated as the bvh run's exact ray count divided by that rate, plus its build time; those rows
are marked "est.".
Writes benchmarks/results/seed_commands.md.
"""
import argparse
import os
import time

import numba

from . import report
from .accel_rays import scenes_dir

# name: (scene, spp, light samples, max depth, resolution, extra options)
COMMANDS = {
    "CBspheres_lambertian -s 64 -l 16 -m 6": ("sky/CBspheres_lambertian.dae", 64, 16, 6,
                                              (480, 360), {}),
    "CBbunny -s 64 -l 16 -m 6": ("sky/CBbunny.dae", 64, 16, 6, (480, 360), {}),
    "cow -s 64 -l 16 -m 6": ("meshedit/cow.dae", 64, 16, 6, (480, 360), {}),
    "CBbunny -s 16 -l 8 -m 6 -H": ("sky/CBbunny.dae", 16, 8, 6, (480, 360), {"hemisphere": True}),
    "CBbunny -s 16 -l 8 -m 6": ("sky/CBbunny.dae", 16, 8, 6, (480, 360), {}),
    "CBbunny -s 64 -l 4 -m 0": ("sky/CBbunny.dae", 64, 4, 0, (480, 360), {}),
    "CBbunny -s 64 -l 4 -m 1": ("sky/CBbunny.dae", 64, 4, 1, (480, 360), {}),
    "CBbunny -s 64 -l 4 -m 2": ("sky/CBbunny.dae", 64, 4, 2, (480, 360), {}),
    "CBbunny -s 64 -l 4 -m 3": ("sky/CBbunny.dae", 64, 4, 3, (480, 360), {}),
    "CBbunny -s 64 -l 4 -m 100": ("sky/CBbunny.dae", 64, 4, 100, (480, 360), {}),
    "CBbunny -s 2048 -a 64 0.05 -l 1 -m 5": ("sky/CBbunny.dae", 2048, 1, 5, (480, 360),
                                             {"adaptive": (64, 0.05)}),
    "CBspheres -s 64 -l 16 -m 6": ("sky/CBspheres.dae", 64, 16, 6, (480, 360), {}),
    "CBspheres_microfacet_al_ag -s 64 -l 16 -m 6": ("sky/CBspheres_microfacet_al_ag.dae", 64, 16,
                                                    6, (480, 360), {}),
    "CBbunny_microfacet_cu -s 64 -l 16 -m 6": ("sky/CBbunny_microfacet_cu.dae", 64, 16, 6,
                                               (480, 360), {}),
    "bunny -s 64 -l 16 -m 6": ("sky/bunny.dae", 64, 16, 6, (480, 360), {}),
    "CBgems -s 64 -l 16 -m 6": ("sky/CBgems.dae", 64, 16, 6, (480, 360), {}),
    "maxplanck -s 64 -l 16 -m 6": ("meshedit/maxplanck.dae", 64, 16, 6, (480, 360), {}),
}

# what the seed quotes for the course's own solution (8 threads, -t 8 -s 64 -l 16 -m 6)
COURSE = {
    "cow -s 64 -l 16 -m 6": "BVH 18 s, naive 2088 s (116x)",
    "CBspheres -s 64 -l 16 -m 6": "4 s",
    "CBgems -s 64 -l 16 -m 6": "30 s",
    "maxplanck -s 64 -l 16 -m 6": "21-22 s (Lucy / Max Planck)",
}


NAIVE_RUN_TRIANGLES = 1000   # naive runs a command for real up to this many triangles


def time_command(scene, kind, spp, light_samples, depth, resolution, extra, naive_shrink=4,
                 bvh_rays=None):
    """One timed `ptrace.render` of a command on a loaded scene with backend `kind`.

    Wall time includes the acceleration build (compile the kernels first). naive on a scene of
    more than NAIVE_RUN_TRIANGLES triangles instead renders resolution // naive_shrink per axis
    at -s 1 to measure its rays per second, and its wall time is estimated as `bvh_rays` (the
    bvh run's exact ray count: naive traces the same paths) divided by that rate, plus its build
    time. Returns a dict: wall, rays_per_second, estimated, spp and resolution (as run), stats
    (ptrace.render's) and image.
    """
    import ptrace
    run_spp, run_resolution = spp, resolution
    estimated = kind == "naive" and scene.triangle_count > NAIVE_RUN_TRIANGLES
    if estimated:
        if bvh_rays is None:
            raise SystemExit("naive estimates need bvh in --backends before naive")
        run_spp = 1
        run_resolution = (resolution[0] // naive_shrink, resolution[1] // naive_shrink)
    stats = {}
    start = time.perf_counter()
    image = ptrace.render(scene, spp=run_spp, light_samples=light_samples, max_depth=depth,
                          resolution=run_resolution, accel=kind, stats=stats, **extra)
    wall = time.perf_counter() - start
    rays_per_second = stats["rays"] / stats["render_seconds"]
    if estimated:
        wall = stats["build_seconds"] + bvh_rays / rays_per_second
    return {"wall": wall, "rays_per_second": rays_per_second, "estimated": estimated,
            "spp": run_spp, "resolution": run_resolution, "stats": stats, "image": image}


def main(argv=None):
    import ptrace
    from ptrace.image import write_image
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", nargs="*", default=["bvh", "embree", "naive"])
    parser.add_argument("--spp-scale", type=int, default=1)
    parser.add_argument("--naive-shrink", type=int, default=4)
    parser.add_argument("--only", nargs="*", default=None, help="command names to run")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--images", default=None, help="directory for the bvh images")
    parser.add_argument("--output", default="seed_commands.md")
    args = parser.parse_args(argv)
    numba.set_num_threads(args.threads)
    names = args.only or list(COMMANDS)
    rows = []
    for name in names:
        relpath, spp, light_samples, depth, resolution, extra = COMMANDS[name]
        scene = ptrace.load(os.path.join(scenes_dir(), relpath))
        ptrace.render(scene, spp=1, light_samples=1, max_depth=2, resolution=(8, 6), **extra)
        bvh_rays = None
        for kind in args.backends:
            run = time_command(scene, kind, max(1, spp // args.spp_scale), light_samples, depth,
                               resolution, extra, naive_shrink=args.naive_shrink,
                               bvh_rays=bvh_rays)
            stats, image, wall = run["stats"], run["image"], run["wall"]
            rays_per_second = run["rays_per_second"]
            if kind == "bvh":
                bvh_rays = stats["rays"]
            if run["estimated"]:
                run_resolution, run_spp = run["resolution"], run["spp"]
                rows.append(f"| {name} | naive | est. from {stats['rays']:,} rays "
                            f"({run_resolution[0]}x{run_resolution[1]}, -s {run_spp}) | "
                            f"{wall:.0f} | {bvh_rays:,} | {rays_per_second:,.0f} | |")
            else:
                rows.append(f"| {name} | {kind} | {run['spp']} | {wall:.1f} | "
                            f"{stats['rays']:,} | {rays_per_second:,.0f} | "
                            f"{stats['samples'].mean():.1f} |")
            rows[-1] += f" {COURSE.get(name, '') if kind == args.backends[0] else ''} |"
            print(rows[-1], flush=True)
            if args.images and kind == "bvh":
                os.makedirs(args.images, exist_ok=True)
                write_image(os.path.join(args.images, name.replace(" ", "_") + ".png"), image)
    lines = [report.header("The seed's command lines: wall time and rays per second per backend"),
             f"{args.threads} threads; -s divided by {args.spp_scale}. Wall time includes the "
             "acceleration build and excludes loading and compiling. Rows marked est.: naive's "
             "rays per second measured on the reduced render named there, and its wall time "
             "estimated as the bvh run's exact ray count (naive traces the same paths) divided "
             "by that rate, plus naive's build time.", "",
             "| command | backend | -s run | wall s | rays | rays/s | mean samples per pixel | "
             "the course's figure (8 threads) |",
             "|---|---|---:|---:|---:|---:|---:|---|"] + rows
    path = report.write(args.output, "\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
