"""Path guiding: relative MSE against wall time (training included) for unguided ptrace, guided
ptrace (--guiding on), --guiding auto and Mitsuba 3's `path` (llvm_ad_rgb, its multijitter
sampler, a box filter of one pixel) on the project's indirectly lit scenes
(scenes/guiding_*.xml), with one chart per scene, and unguided against auto on two course
Cornell boxes (where next-event estimation does the work, so auto must not lose: at most 1.05x
the unguided relative MSE x time).

    python -m benchmarks.guiding [--quick] [--size N] [--spp 16,32,64] [--reference-spp N]
                                 [--repeats R] [--pairs SPP] [--pairs-size N]

The reference is ptrace's unguided render at --reference-spp (Mitsuba and ptrace agree on these
scenes' means: their lamps reflect nothing). Each point is rendered R times on 2 threads after
warm-up renders (compiled kernels), the modes in turns within each repeat, and its seconds are
the median (the machine may be shared: the relative MSE at equal samples is the firmer figure;
the images do not change between repeats); relative MSE is the mean over pixels of the squared
error over (reference^2 + 1e-3), averaged over R, G, B. With --pairs SPP, each scene is also
rendered unguided and guided at SPP under R seeds, the modes in turns, and the error of each is
half the mean squared difference of its seed 1 and seed 2 images (over the reference^2 + 1e-3):
no reference noise in it, so it holds where SPP is past the reference's reach; Mitsuba's the
same way. --pairs-size renders those at N x N (the issue's targets name 256x256 and 60-120 s),
over the level of the pairs' own mean image. Writes
benchmarks/results/guiding.md and guiding_<scene>.png.
"""
import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

from . import report

SCENES = Path(__file__).resolve().parents[1] / "scenes"
# (file, ptrace's -m; Mitsuba's max_depth is one more)
CASES = (("guiding_ceiling.xml", 5), ("guiding_door.xml", 7))
# course boxes: (path under PTRACE_SCENES, -m, resolution)
COURSE = (("sky/CBspheres_lambertian.dae", 5, (100, 75)), ("sky/CBbunny.dae", 5, (100, 75)))
MODES = ("off", "on", "auto")


def relative_mse(image, reference):
    return float(np.mean((image - reference) ** 2 / (reference ** 2 + 1e-3)))


def ptrace_point(scene, spp, depth, resolution, guiding, reference):
    import ptrace
    stats = {}
    start = time.perf_counter()
    image = ptrace.render(scene, spp=spp, max_depth=depth, resolution=resolution, threads=2,
                          guiding=guiding, stats=stats, seed=1)
    seconds = time.perf_counter() - start
    return seconds, relative_mse(image, reference), stats.get("guiding", {})


def mitsuba_sensor(mi, scene, size, spp):
    """The file's camera with a box filter of one pixel (Mitsuba's default is a Gaussian of 2
    pixels' radius, whose image ptrace's per-pixel reference does not converge to) and the
    multijitter sampler the issue's target names."""
    p = mi.traverse(scene.sensors()[0])
    matrix = np.array(p["to_world"].matrix).reshape(4, 4, -1)[..., 0]
    return mi.load_dict({
        "type": "perspective", "to_world": mi.ScalarTransform4f(matrix),
        "fov": float(p["x_fov"][0]), "fov_axis": "x",
        "near_clip": float(p["near_clip"]), "far_clip": float(p["far_clip"]),
        "film": {"type": "hdrfilm", "width": size, "height": size, "pixel_format": "rgb",
                 "rfilter": {"type": "box"}},
        "sampler": {"type": "multijitter", "sample_count": spp}})


class MitsubaRenderer:
    """Mitsuba's renders of one file at spp and size x size through mitsuba_sensor, compiled
    by a first render; a call renders under one seed: (image, seconds). taken: the samples it
    takes (multijitter rounds some counts up: 32 to 35, 512 to 528)."""

    def __init__(self, path, spp, size):
        import mitsuba as mi
        self.mi, self.spp = mi, spp
        self.scene = mi.load_file(str(path), res=size)
        self.sensor = mitsuba_sensor(mi, self.scene, size, spp)
        self.taken = self.sensor.sampler().sample_count()
        self(0)

    def __call__(self, seed):
        start = time.perf_counter()
        image = np.array(self.mi.render(self.scene, sensor=self.sensor, spp=self.spp,
                                        seed=seed))
        return image, time.perf_counter() - start


def measure(scene, spps, depth, resolution, reference, modes, repeats, mitsuba=None):
    """{(mode, spp): (median seconds, relMSE, guiding figures, median training seconds)}, the
    modes in turns within each repeat; with mitsuba (a file's path), its renders in turn after
    them under mode "mitsuba" (figures: the samples it took)."""
    for guiding in modes:   # warm-up: compile
        ptrace_point(scene, 16, depth, resolution, guiding, reference)
    renderers = {spp: MitsubaRenderer(mitsuba, spp, resolution[0]) for spp in spps} \
        if mitsuba else {}
    runs = {}
    for _ in range(repeats):
        for spp in spps:
            for guiding in modes:
                runs.setdefault((guiding, spp), []).append(
                    ptrace_point(scene, spp, depth, resolution, guiding, reference))
            if spp in renderers:
                image, seconds = renderers[spp](1)
                runs.setdefault(("mitsuba", spp), []).append(
                    (seconds, relative_mse(image, reference), renderers[spp].taken))
    return {key: (statistics.median(r[0] for r in points), points[-1][1], points[-1][2],
                  statistics.median(r[2].get("training_seconds", 0.0) if isinstance(r[2], dict)
                                    else 0.0 for r in points))
            for key, points in runs.items()}


def pairs(scene, spp, depth, resolution, repeats, mitsuba=None):
    """{mode: (median seconds, the images of seeds 1 and 2, median training seconds)} for
    unguided and guided, and Mitsuba's (mitsuba: a file's path) with its sample count in place
    of training seconds, the three in turns within each repeat (seed = repeat + 1)."""
    import ptrace
    for guiding in ("off", "on"):   # warm-up: compile
        ptrace.render(scene, spp=4, max_depth=depth, resolution=resolution, threads=2,
                      guiding=guiding)
    renderer = MitsubaRenderer(mitsuba, spp, resolution[0]) if mitsuba else None
    images, seconds, training = {}, {}, {}
    for r in range(max(repeats, 2)):
        for guiding in ("off", "on"):
            stats = {}
            start = time.perf_counter()
            image = ptrace.render(scene, spp=spp, max_depth=depth, resolution=resolution,
                                  threads=2, guiding=guiding, stats=stats, seed=r + 1)
            seconds.setdefault(guiding, []).append(time.perf_counter() - start)
            training.setdefault(guiding, []).append(
                stats.get("guiding", {}).get("training_seconds", 0.0))
            images.setdefault(guiding, []).append(image)
        if renderer:
            image, took = renderer(r + 1)
            seconds.setdefault("mitsuba", []).append(took)
            training.setdefault("mitsuba", []).append(renderer.taken)
            images.setdefault("mitsuba", []).append(image)
    return {mode: (statistics.median(seconds[mode]), images[mode][:2],
                   statistics.median(training[mode])) for mode in images}


def pair_error(a, b, level):
    """Half the mean squared difference of two seeds' images over (level^2 + 1e-3): the
    relative MSE of either, without a reference's noise."""
    return float(np.mean((a - b) ** 2 / (level ** 2 + 1e-3))) / 2.0


def auto_text(figures):
    if not figures.get("decision"):
        return "off (too few samples)"
    d = figures["decision"]
    trained = len(figures.get("iterations", [])) > 1
    after = " after training" if trained and not figures["guided"] else ""
    return f"{'on' if figures['guided'] else 'off'}{after} (headroom {d['headroom']:.1f})"


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.guiding")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--size", type=int, default=None)
    parser.add_argument("--spp", default=None)
    parser.add_argument("--reference-spp", type=int, default=None)
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--pairs", type=int, default=0)
    parser.add_argument("--pairs-size", type=int, default=None)
    parser.add_argument("--scene", action="append", default=None)
    parser.add_argument("--output", default="guiding.md")
    args = parser.parse_args(argv)
    size = args.size or (32 if args.quick else 128)
    spp_text = args.spp or ("16,32" if args.quick else "16,32,64,128")
    spps = [] if spp_text == "none" else [int(s) for s in spp_text.split(",")]
    cases = [c for c in CASES if args.scene is None or c[0] in args.scene]
    reference_spp = args.reference_spp or (64 if args.quick else 1024)
    repeats = args.repeats or (1 if args.quick else 3)
    import ptrace
    try:
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
        mi.set_log_level(mi.LogLevel.Error)   # (not multijitter's rounding of 32 up to 35)
    except (ImportError, AttributeError):
        mi = None
    lines = [report.header("Path guiding: relative MSE against wall time"),
             f"{size}x{size}, reference: ptrace unguided at {reference_spp} spp; 2 threads; "
             "seconds include training (guided, auto) and exclude compiling (warm-up renders "
             f"run first); medians of {repeats} runs, the modes in turns. Mitsuba: `path`, "
             "llvm_ad_rgb, max_depth one more than ptrace's -m, the file's camera with a box "
             "filter of one pixel (as ptrace's pixels) and the multijitter sampler, rendered in "
             "turn after ptrace's modes, after one render that compiles. Ratios are to "
             "unguided ptrace at the same spp: relMSE at equal samples, and relMSE x seconds "
             "(equal time). auto: its choice and its probe's headroom (trains above 32; then "
             "off after training if the guided variance per sample is not below the probe's).",
             ""]
    for name, depth in cases:
        path = SCENES / name
        scene = ptrace.load(str(path), defines={"res": str(size)})   # the whole view
        resolution = (size, size)
        lines += [f"## {name} (-m {depth})", ""]
        reference, points = None, {}
        if spps:
            reference = ptrace.render(scene, spp=reference_spp, max_depth=depth,
                                      resolution=resolution, seed=99)
            points = measure(scene, spps, depth, resolution, reference, MODES, repeats,
                             path if mi is not None else None)
        rows = {"unguided": [], "guided": [], "auto": [], "mitsuba": []}
        lines += [] if not spps else [
                  "| spp | unguided s | unguided relMSE | guided s (training s) | guided relMSE "
                  "| guided/unguided relMSE | guided/unguided relMSE x s | auto s | auto "
                  "relMSE x s / unguided | auto | mitsuba s | mitsuba relMSE | guided/mitsuba "
                  "relMSE x s |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for spp in spps:
            off, on, auto = (points[(m, spp)] for m in MODES)
            for label, p in (("unguided", off), ("guided", on), ("auto", auto)):
                rows[label].append(p[:2])
            mit_text = "- | - | -"
            if ("mitsuba", spp) in points:
                mit = points[("mitsuba", spp)]
                rows["mitsuba"].append(mit[:2])
                taken = "" if mit[2] == spp else f" ({mit[2]} spp)"
                mit_text = (f"{mit[0]:.2f}{taken} | {mit[1]:.4f} | "
                            f"{on[0] * on[1] / (mit[0] * mit[1]):.2f}")
            lines.append(
                f"| {spp} | {off[0]:.2f} | {off[1]:.4f} | {on[0]:.2f} ({on[3]:.2f}) "
                f"| {on[1]:.4f} | {on[1] / off[1]:.2f} | {on[0] * on[1] / (off[0] * off[1]):.2f} "
                f"| {auto[0]:.2f} | {auto[0] * auto[1] / (off[0] * off[1]):.2f} "
                f"| {auto_text(auto[2])} | {mit_text} |")
            print(lines[-1], flush=True)
        if spps:
            lines.append("")
        if args.pairs:
            pair_size = args.pairs_size or size
            runs = pairs(scene, args.pairs, depth, (pair_size, pair_size), repeats,
                         path if mi is not None else None)
            (off_s, off_images, _), (on_s, on_images, on_training) = runs["off"], runs["on"]
            # the level: the reference where it has the pairs' size, else the mean of all the
            # pairs' images (a firefly of one renderer's over a level without it would weigh
            # as much as the rest of the image)
            level = reference if reference is not None and pair_size == size else np.mean(
                [i for run in runs.values() for i in run[1]], axis=0)
            off_error, on_error = pair_error(*off_images, level), pair_error(*on_images, level)
            mit_text = "- | - | -"
            if "mitsuba" in runs:
                seconds, images, taken = runs["mitsuba"]
                error = pair_error(*images, level)
                taken = "" if taken == args.pairs else f" ({taken:.0f} spp)"
                mit_text = (f"{seconds:.2f}{taken} | {error:.4f} | "
                            f"{on_s * on_error / (seconds * error):.3f}")
            lines += [f"At {args.pairs} spp and {pair_size}x{pair_size}, error from two seeds "
                      f"(no reference noise), seconds medians of {max(repeats, 2)}, the three "
                      "in turns:", "",
                      "| spp | unguided s | unguided error | guided s (training s) | guided "
                      "error | guided/unguided error | guided/unguided error x s | mitsuba s "
                      "| mitsuba error | guided/mitsuba error x s |",
                      "|---|---|---|---|---|---|---|---|---|---|",
                      f"| {args.pairs} | {off_s:.2f} | {off_error:.4f} | {on_s:.2f} "
                      f"({on_training:.2f}) | {on_error:.4f} | {on_error / off_error:.3f} | "
                      f"{on_s * on_error / (off_s * off_error):.3f} | {mit_text} |", ""]
            print(lines[-2], flush=True)
        if spps:
            chart(rows, report.destination(f"guiding_{path.stem}.png"), name)
            lines += [f"![{name}](guiding_{path.stem}.png)", ""]
    root = Path(os.environ.get("PTRACE_SCENES", report.RESULTS.parents[2] / "shared" / "scenes"
                               / "cs184"))
    course = [c for c in COURSE if (root / c[0]).exists() and args.scene is None]
    if course:
        spp = max(spps) if args.quick else 64
        lines += [f"## Course boxes under --guiding auto ({spp} spp, reference unguided at "
                  f"{reference_spp // 2} spp)", "",
                  "| scene | unguided s | unguided relMSE | auto s (training s) | auto relMSE "
                  "| auto/unguided relMSE x s | auto | guided/unguided relMSE |",
                  "|---|---|---|---|---|---|---|---|"]
        for relpath, depth, resolution in course:
            scene = ptrace.load(str(root / relpath))
            reference = ptrace.render(scene, spp=reference_spp // 2, max_depth=depth,
                                      resolution=resolution, seed=99)
            points = measure(scene, [spp], depth, resolution, reference, MODES,
                             max(repeats, 5) if not args.quick else 1)
            off, on, auto = (points[(m, spp)] for m in MODES)
            lines.append(f"| {Path(relpath).stem} {resolution[0]}x{resolution[1]} -m {depth} "
                         f"| {off[0]:.2f} | {off[1]:.5f} | {auto[0]:.2f} ({auto[3]:.2f}) "
                         f"| {auto[1]:.5f} | {auto[0] * auto[1] / (off[0] * off[1]):.3f} "
                         f"| {auto_text(auto[2])} | {on[1] / off[1]:.2f} |")
            print(lines[-1], flush=True)
        lines.append("")
    out = report.destination(args.output)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(out)


def chart(rows, path, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figure, axes = plt.subplots(figsize=(5, 4))
    for label, points in rows.items():
        if points:
            seconds, errors = zip(*points)
            axes.loglog(seconds, errors, "o-", label=label)
    axes.set_xlabel("wall seconds")
    axes.set_ylabel("relative MSE")
    axes.set_title(title)
    axes.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


if __name__ == "__main__":
    main()
