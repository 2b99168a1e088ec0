"""Normal-shading render time per backend (the course's part 2 comparison) and CLI start-up.

    python -m benchmarks.first_images [--threads 2] [--repeats 3]

The README's render command (`ptrace -s 16 -l 4 -m 5 -f cornell.png scenes/cornell.dae`) in a
fresh process, cold (an empty numba cache: NUMBA_CACHE_DIR set to a new directory, so every
kernel compiles) and warm (the same cache again): wall seconds, the build and render seconds
from its summary line, and the rest (interpreter start, imports, loading, compiling or loading
kernels) before the first pass.

For cow and maxplanck: `ptrace.render(scene, integrator="normals", resolution=(480, 360))` with
naive, bvh and embree (BVH/Embree build time reported apart; bvh and embree the median of
--repeats runs, naive one run). Start-up: wall time of `ptrace --info cow.dae` in a fresh process,
cold (an empty bytecode cache for every module, PYTHONPYCACHEPREFIX) and warm (median of 5).
Writes benchmarks/results/first_images.md.
"""
import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numba

from . import report
from .rays import scenes_dir
from .templating import blocks, fill

MESHES = ["meshedit/cow.dae", "meshedit/maxplanck.dae"]
TEMPLATE = "first_images.md"      # the prose, in benchmarks/templates/


def info_seconds(scene, env):
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "ptrace", "--info", scene], env=env, check=True,
                   capture_output=True)
    return time.perf_counter() - start


README_COMMAND = ["-s", "16", "-l", "4", "-m", "5"]
SHIPPED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes",
                       "cornell.dae")


def readme_render(env, output_dir):
    """(wall, build, render, stderr) of the README's render command in a fresh process."""
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-m", "ptrace", *README_COMMAND, "-f",
                             os.path.join(output_dir, "cornell.png"), SHIPPED], env=env,
                            check=True, capture_output=True, text=True)
    wall = time.perf_counter() - start
    words = result.stdout.split()
    build = float(words[words.index("build") + 1])
    render = float(words[words.index("render") + 1])
    return wall, build, render, result.stderr


def start_up_lines():
    """Cold and warm runs of the README's render command, as report lines."""
    text = blocks(TEMPLATE)
    rows = []
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold (empty numba cache)", "warm", "warm"):
            wall, build, render, stderr = readme_render(env, out)
            said = "yes" if "compiling kernels" in stderr else "no"
            rows.append(fill(text["readme_row"], run=label, wall=wall, build=build,
                             render=render, before=wall - build - render, notice=said))
            print(label, f"{wall:.2f} s", flush=True)
    return [fill(text["readme"], command=" ".join(README_COMMAND)), *rows]


def main(argv=None):
    import ptrace
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--output", default="first_images.md")
    args = parser.parse_args(argv)
    numba.set_num_threads(args.threads)
    text = blocks(TEMPLATE)
    lines = [report.header("First images: normal shading per backend, and start-up"),
             fill(text["intro"], threads=args.threads, repeats=args.repeats)]
    for relpath in MESHES:
        scene = ptrace.load(os.path.join(scenes_dir(), relpath))
        ptrace.render(scene, integrator="normals", resolution=(16, 12))   # compile / load cache
        results = {}
        for kind, repeats in (("bvh", args.repeats), ("embree", args.repeats), ("naive", 1)):
            runs = []
            for _ in range(repeats):
                stats = {}
                ptrace.render(scene, integrator="normals", resolution=(480, 360), accel=kind,
                              stats=stats)
                runs.append(stats)
            seconds = statistics.median(r["render_seconds"] for r in runs)
            build = statistics.median(r["build_seconds"] for r in runs)
            results[kind] = (build, seconds, runs[0]["rays"] / seconds)
            print(relpath, kind, f"{seconds:.3f} s", flush=True)
        for kind in ("naive", "bvh", "embree"):
            build, seconds, rate = results[kind]
            lines.append(fill(text["row"], scene=relpath, backend=kind, build=build,
                              seconds=seconds, rate=rate, speedup=results["naive"][1] / seconds))
    cow = os.path.join(scenes_dir(), MESHES[0])
    with tempfile.TemporaryDirectory() as prefix:
        cold = info_seconds(cow, dict(os.environ, PYTHONPYCACHEPREFIX=prefix))
    warm = statistics.median(info_seconds(cow, dict(os.environ)) for _ in range(5))
    lines.append(fill(text["info"], cold=cold, warm=warm))
    lines += start_up_lines()
    path = report.write(args.output, "\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
