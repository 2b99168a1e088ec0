"""Path guiding: relative MSE against wall time (training included) for unguided ptrace, guided
ptrace (--guiding on) and Mitsuba 3's `path` (llvm_ad_rgb, its independent sampler) on the
project's indirectly lit scenes (scenes/guiding_*.xml), with one chart per scene.

    python -m benchmarks.guiding [--quick] [--size N] [--spp 16,32,64] [--reference-spp N]

The reference is ptrace's unguided render at --reference-spp (Mitsuba and ptrace agree on these
scenes' means: their lamps reflect nothing). Each point is one render on 2 threads after a
warm-up render (compiled kernels); relative MSE is the mean over pixels of the squared error
over (reference^2 + 1e-3), averaged over R, G, B. Writes benchmarks/results/guiding.md and
guiding_<scene>.png.
"""
import argparse
import time
from pathlib import Path

import numpy as np

from . import report

SCENES = Path(__file__).resolve().parents[1] / "scenes"
# (file, ptrace's -m; Mitsuba's max_depth is one more)
CASES = (("guiding_ceiling.xml", 5), ("guiding_door.xml", 7))


def relative_mse(image, reference):
    return float(np.mean((image - reference) ** 2 / (reference ** 2 + 1e-3)))


def ptrace_point(scene, spp, depth, size, guiding, reference):
    import ptrace
    stats = {}
    start = time.perf_counter()
    image = ptrace.render(scene, spp=spp, max_depth=depth, resolution=(size, size), threads=2,
                          guiding=guiding, stats=stats, seed=1)
    seconds = time.perf_counter() - start
    train = stats.get("guiding", {}).get("training_seconds", 0.0)
    return seconds, relative_mse(image, reference), train


def mitsuba_point(path, spp, size, reference):
    import mitsuba as mi
    scene = mi.load_file(str(path), res=size)
    start = time.perf_counter()
    image = np.array(mi.render(scene, spp=spp, seed=1))
    return time.perf_counter() - start, relative_mse(image, reference)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.guiding")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--size", type=int, default=None)
    parser.add_argument("--spp", default=None)
    parser.add_argument("--reference-spp", type=int, default=None)
    args = parser.parse_args(argv)
    size = args.size or (32 if args.quick else 128)
    spps = [int(s) for s in (args.spp or ("4,8" if args.quick else "16,32,64,128")).split(",")]
    reference_spp = args.reference_spp or (32 if args.quick else 1024)
    import ptrace
    try:
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
    except (ImportError, AttributeError):
        mi = None
    lines = [report.header("Path guiding: relative MSE against wall time"),
             f"{size}x{size}, reference: ptrace unguided at {reference_spp} spp; 2 threads; "
             "seconds include training (guided) and exclude compiling (a warm-up render runs "
             "first). Mitsuba: `path`, llvm_ad_rgb, max_depth one more than ptrace's -m.", ""]
    for name, depth in CASES:
        path = SCENES / name
        scene = ptrace.load(str(path), defines={"res": str(size)})   # the whole view
        reference = ptrace.render(scene, spp=reference_spp, max_depth=depth,
                                  resolution=(size, size), seed=99)
        for guiding in ("off", "on"):   # warm-up: compile
            ptrace.render(scene, spp=4, max_depth=depth, resolution=(size, size),
                          guiding=guiding)
        rows = {"unguided": [], "guided": [], "mitsuba": []}
        lines += [f"## {name} (-m {depth})", "",
                  "| spp | unguided s | unguided relMSE | guided s (training s) | guided relMSE "
                  "| guided/unguided relMSE x time | mitsuba s | mitsuba relMSE |",
                  "|---|---|---|---|---|---|---|---|"]
        for spp in spps:
            off = ptrace_point(scene, spp, depth, size, "off", reference)
            on = ptrace_point(scene, spp, depth, size, "on", reference)
            rows["unguided"].append(off[:2])
            rows["guided"].append(on[:2])
            mit = ("-", "-")
            if mi is not None:
                mit = mitsuba_point(path, spp, size, reference)
                rows["mitsuba"].append(mit)
            ratio = (on[0] * on[1]) / (off[0] * off[1])
            mit_text = f"{mit[0]:.2f} | {mit[1]:.4f}" if mi is not None else "- | -"
            lines.append(f"| {spp} | {off[0]:.2f} | {off[1]:.4f} | {on[0]:.2f} ({on[2]:.2f}) "
                         f"| {on[1]:.4f} | {ratio:.2f} | {mit_text} |")
            print(lines[-1], flush=True)
        lines.append("")
        chart(rows, report.destination(f"guiding_{path.stem}.png"), name)
        lines += [f"![{name}](guiding_{path.stem}.png)", ""]
    out = report.destination("guiding.md")
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
