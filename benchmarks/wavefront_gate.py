"""The wavefront's gate: the diffuse Cornell boxes rendered by the megakernel and by the wavefront
prototype (--loop), side by side, in turns.

    python -m benchmarks.wavefront_gate [--turns 3] [--cold-turns 1] [--no-cold] [--no-mitsuba]

Cold: the README's render (`ptrace -s 16 -l 4 -m 5 scenes/cornell.dae`) in a fresh process with
an empty numba cache (NUMBA_CACHE_DIR a new folder), then the same with `--accel embree` on that
cache: the seconds spent in numba's compiler (the command's "compiled kernels in" line) and the
wall seconds to the image, one loop after the other in each turn. Then the README's render again
on the warm cache: its process (CPU) seconds.

Warm: camera paths per second on CBspheres_lambertian and CBbunny, 480x360, 16 spp, -m 5 -l 1,
2 threads, with bvh and embree (and naive on CBspheres_lambertian, 14 primitives), each loop
in turns in one process (seed = turn), and Mitsuba 3 llvm_ad_rgb in the same turns where it
imports; every wavefront image is checked equal, bit for bit, to the megakernel's of the same
seed. Medians. Writes benchmarks/results/wavefront_gate.md.
"""
import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from . import report
from .first_images import README_COMMAND, SHIPPED
from .rays import scenes_dir

LOOPS = ("megakernel", "wavefront")
SCENES = {"sky/CBspheres_lambertian.dae": ("naive", "bvh", "embree"),
          "sky/CBbunny.dae": ("bvh", "embree")}
SPP, RESOLUTION, DEPTH, LIGHT_SAMPLES, THREADS = 16, (480, 360), 5, 1, 2


def _run(args, env):
    """(wall seconds, compile seconds or 0, child CPU seconds) of one ptrace command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-m", "ptrace", *args], env=env, check=True,
                            capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    found = re.search(r"compiled kernels in ([0-9.]+) s", result.stderr)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, float(found.group(1)) if found else 0.0, cpu


def cold(turns):
    """{loop: {what: [seconds per turn]}} of the README's render cold, embree after it, and
    the README's render warm."""
    out = {loop: {k: [] for k in ("compile", "wall", "embree compile", "embree wall",
                                  "warm cpu", "warm wall")} for loop in LOOPS}
    with tempfile.TemporaryDirectory() as folder:
        for turn in range(turns):
            for loop in LOOPS:
                env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(folder, f"{loop}{turn}"))
                image = os.path.join(folder, "cornell.png")
                command = [*README_COMMAND, "--loop", loop, "-f", image, SHIPPED]
                wall, compiled, _ = _run(command, env)
                embree_wall, embree_compiled, _ = _run(["--accel", "embree", *command], env)
                warm_wall, _, warm_cpu = _run(command, env)
                for key, value in (("compile", compiled), ("wall", wall),
                                   ("embree compile", embree_compiled),
                                   ("embree wall", embree_wall), ("warm cpu", warm_cpu),
                                   ("warm wall", warm_wall)):
                    out[loop][key].append(value)
                print(f"cold turn {turn} {loop}: compile {compiled:.1f} s, first image "
                      f"{wall:.1f} s; embree +{embree_compiled:.1f} s; warm {warm_wall:.1f} s "
                      f"wall, {warm_cpu:.1f} s CPU", flush=True)
    return out


def warm(turns, mitsuba=True):
    """{(scene, renderer): [paths/s per turn]} and the count of wavefront images that differ
    from the megakernel's."""
    import ptrace
    mi = None
    if mitsuba:
        from . import paths_per_second as pps
        mi, libllvm, note = pps.import_mitsuba()
        if mi is not None and pps.set_variant(mi, "llvm_ad_rgb", THREADS, libllvm):
            mi = None
    rates, unequal = {}, 0
    paths = RESOLUTION[0] * RESOLUTION[1] * SPP
    for name, kinds in SCENES.items():
        scene = ptrace.load(os.path.join(scenes_dir(), name))
        for kind in kinds:
            for loop in LOOPS:   # compile or load, outside the turns
                ptrace.render(scene, spp=1, resolution=(8, 6), max_depth=DEPTH, accel=kind,
                              loop=loop)
        if mi is not None:
            mask = pps.lamp_mask(scene, RESOLUTION, SPP)
            pps.measure_mitsuba(mi, "llvm_ad_rgb", scene, name, SPP, RESOLUTION, 1, mask)
        for turn in range(turns):
            for kind in kinds:
                images = {}
                for loop in LOOPS:
                    start = time.perf_counter()
                    images[loop] = ptrace.render(
                        scene, spp=SPP, resolution=RESOLUTION, max_depth=DEPTH,
                        light_samples=LIGHT_SAMPLES, accel=kind, threads=THREADS, seed=turn,
                        loop=loop)
                    rates.setdefault((name, f"{kind} {loop}"), []).append(
                        paths / (time.perf_counter() - start))
                unequal += not np.array_equal(images["megakernel"], images["wavefront"])
            if mi is not None:
                row = pps.measure_mitsuba(mi, "llvm_ad_rgb", scene, name, SPP, RESOLUTION, 1,
                                          mask)
                rates.setdefault((name, "Mitsuba llvm_ad_rgb"), []).append(
                    row["paths_per_second"])
            print(f"{name} turn {turn}: " + ", ".join(
                f"{who} {values[-1]:,.0f}" for (scene_name, who), values in rates.items()
                if scene_name == name), flush=True)
    return rates, unequal


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--turns", type=int, default=3)
    parser.add_argument("--cold-turns", type=int, default=1)
    parser.add_argument("--no-cold", action="store_true")
    parser.add_argument("--no-mitsuba", action="store_true")
    args = parser.parse_args(argv)
    lines = [report.header("The wavefront's gate: megakernel and wavefront, in turns")]
    median = statistics.median
    if not args.no_cold:
        result = cold(args.cold_turns)
        lines += ["## Cold start: the README's render with an empty numba cache", "",
                  f"Medians of {args.cold_turns} turn(s), each loop in its own process and "
                  "cache. Compile: seconds inside numba's compiler.", "",
                  "| loop | compile s | first image s | then embree: compile s | warm wall s "
                  "| warm CPU s |", "|---|---:|---:|---:|---:|---:|"]
        for loop in LOOPS:
            r = result[loop]
            lines.append(f"| {loop} | {median(r['compile']):.1f} | {median(r['wall']):.1f} | "
                         f"{median(r['embree compile']):.1f} | {median(r['warm wall']):.1f} | "
                         f"{median(r['warm cpu']):.1f} |")
        ratio = median(result["wavefront"]["compile"]) / median(result["megakernel"]["compile"])
        embree = (median(result["wavefront"]["embree compile"])
                  / median(result["megakernel"]["embree compile"]))
        lines += ["", f"Wavefront / megakernel compile seconds: {ratio:.2f} (the gate: at most "
                  f"0.5, {'met' if ratio <= 0.5 else 'missed'}); for embree after bvh: "
                  f"{embree:.2f}.", ""]
    rates, unequal = warm(args.turns, not args.no_mitsuba)
    lines += ["## Camera paths per second, warm", "",
              f"{RESOLUTION[0]}x{RESOLUTION[1]}, {SPP} spp, -m {DEPTH} -l {LIGHT_SAMPLES}, "
              f"{THREADS} threads; median of {args.turns} turns; wavefront images unequal to "
              f"the megakernel's: {unequal}.", "",
              "| scene | renderer | paths/s | wavefront / megakernel |", "|---|---|---:|---:|"]
    ratios = []
    for (name, who), values in rates.items():
        ratio = ""
        if who.endswith("wavefront"):
            mega = rates[(name, who.replace("wavefront", "megakernel"))]
            ratios.append(median(values) / median(mega))
            ratio = f"{ratios[-1]:.2f}"
        lines.append(f"| {name} | {who} | {median(values):,.0f} | {ratio} |")
    if ratios:
        lines += ["", f"Wavefront / megakernel paths/s: {min(ratios):.2f} to {max(ratios):.2f} "
                  f"(the gate: at least 1.3, {'met' if min(ratios) >= 1.3 else 'missed'})."]
    path = report.destination("wavefront_gate.md")
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")
    return 0 if unequal == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
