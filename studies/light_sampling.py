"""Study: area lights sampled by solid angle against by area, side by side with Mitsuba 3.

    python studies/light_sampling.py --before [LABEL=]CHECKOUT [--before ...] [--label LABEL]
        [--scenes CBspheres_lambertian CBbunny CBsphere_light]
        [--spp 16 64] [--seeds 3] [--depth 5] [--output light_sampling.md] [--title TITLE]

Each CHECKOUT is a checkout of ptrace before a change (a git worktree of an earlier commit);
this tree is the last. Each ptrace render runs in a fresh process of its tree (so every tree's
kernels are its own), at 480x360, -m 5 -l 1, 2 threads, the default estimator (MIS, Sobol'),
on the course scene without its emissive quad (benchmarks.error_vs_time.test_scene, as
error_vs_time measures) or CBsphere_light (sphere_lit); Mitsuba 3 llvm_ad_rgb renders the same
scene with its multijitter sampler. Error: benchmarks.error_vs_time.relative_mse against its
cached 1024-spp Mitsuba reference. For every spp and seed the renderers run in turns; a cell is
the mean
relative MSE over the seeds and the median seconds of the render call (kernels compiled
before; a ptrace process times only its render call). Writes benchmarks/results/OUTPUT.
"""
import argparse
import inspect
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import error_vs_time as evt  # noqa: E402
from benchmarks import report  # noqa: E402

SPHERE_LIT = "CBsphere_light"     # CBspheres_lambertian lit by one emissive sphere alone
SPHERE_LIGHT = ((0.0, 1.15, 0.0), 0.2, 10.0)     # centre, radius, radiance (the quad's)


def sphere_lit(scene, centre, radius, radiance):
    """The scene without its lights, with one more sphere that emits `radiance`: a material
    row appended to every per-material array (a copy of material 0's, then made EMISSION)."""
    import dataclasses

    import numpy as np

    from accel import Geometry
    from ptrace.scene import EMISSION, Lights
    materials, rows = scene.materials, len(scene.materials.kind)
    grown = {}
    for field in dataclasses.fields(materials):
        value = getattr(materials, field.name)
        if isinstance(value, np.ndarray) and len(value) == rows:
            grown[field.name] = np.concatenate([value, value[:1]])
        elif isinstance(value, tuple) and len(value) == rows:
            grown[field.name] = (*value, "sphere light")
    grown["kind"][-1] = EMISSION
    grown["emission"][-1] = radiance
    g = scene.geometry
    geometry = Geometry(g.vertices, g.faces, np.concatenate([g.centers, [centre]]),
                        np.concatenate([g.radii, [radius]]))
    return dataclasses.replace(
        scene, geometry=geometry, materials=dataclasses.replace(materials, **grown),
        material_index=np.concatenate([scene.material_index, [rows]]).astype(
            scene.material_index.dtype),
        lights=Lights.from_records([]))


def study_scene(name):
    """The scene `name` as both renderers see it (evt.test_scene, or the sphere-lit box)."""
    from benchmarks.error_vs_time import test_scene
    if name == SPHERE_LIT:
        return sphere_lit(test_scene("CBspheres_lambertian"), *SPHERE_LIGHT)
    return test_scene(name)


WORKER = """
import json, sys, time, numpy as np
sys.path.insert(0, {root!r})
import ptrace
from benchmarks.error_vs_time import FULL, THREADS
DEPTH = {depth}
{functions}
SPHERE_LIT, SPHERE_LIGHT = {sphere_lit!r}, {sphere_light!r}
scene = study_scene({name!r})
ptrace.render(scene, spp=1, resolution=(8, 6), max_depth=DEPTH)           # compile
start = time.perf_counter()
image = ptrace.render(scene, spp={spp}, resolution=FULL, max_depth=DEPTH, threads=THREADS,
                      seed={seed}, light_samples=1)
seconds = time.perf_counter() - start
np.save({out!r}, image)
print(json.dumps(dict(seconds=seconds, file=ptrace.__file__)))
"""


def ptrace_render(tree, name, spp, seed, folder, depth=evt.DEPTH):
    out = os.path.join(folder, f"{abs(hash((tree, name, spp, seed, depth)))}.npy")
    env = dict(os.environ, PYTHONPATH=str(tree))
    functions = inspect.getsource(sphere_lit) + "\n" + inspect.getsource(study_scene)
    code = WORKER.format(root=str(tree), name=name, spp=spp, seed=seed, out=out,
                         functions=functions, sphere_lit=SPHERE_LIT, sphere_light=SPHERE_LIGHT,
                         depth=depth)
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                            text=True, check=True, cwd=folder)
    answer = json.loads(result.stdout.strip().splitlines()[-1])
    assert answer["file"].startswith(str(tree)), answer   # the tree asked for
    return np.load(out), answer["seconds"]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True,
                        help="LABEL=CHECKOUT (or CHECKOUT: labelled 'before'), repeatable: "
                             "earlier trees rendered in turns with this one", action="append")
    parser.add_argument("--label", default="after", help="this tree's label")
    parser.add_argument("--scenes", nargs="+",
                        default=["CBspheres_lambertian", "CBbunny", SPHERE_LIT])
    parser.add_argument("--depth", type=int, default=evt.DEPTH,
                        help="-m: 1 is direct light alone, where the light sampler is all")
    parser.add_argument("--spp", type=int, nargs="+", default=[16, 64])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--output", default="light_sampling.md")
    parser.add_argument("--title", default="Area lights by solid angle against by area, beside "
                                           "Mitsuba 3", help="the report's title")
    args = parser.parse_args(argv)
    evt.DEPTH = args.depth      # the references' and Mitsuba's depth (read at call time)
    trees = {}
    for entry in args.before:
        label, _, path = entry.rpartition("=")
        trees[label or "before"] = Path(path).resolve()
    trees[args.label] = ROOT
    mitsuba = evt.Mitsuba()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for name in args.scenes:
            scene = study_scene(name)
            # the sphere is seen: Mitsuba shows it (its pixels pass 1 and leave the error)
            mapping = (dict(emissive=True, hide_emitters=False) if name == SPHERE_LIT else {})
            ref, _ = evt.reference(name, mitsuba, evt.REFERENCE_SPP, scene=scene, **mapping)
            for spp in args.spp:
                cells = {label: [] for label in [*trees, "Mitsuba multijitter"]}
                for seed in range(args.seeds):
                    for label, tree in trees.items():
                        image, seconds = ptrace_render(tree, name, spp, seed, folder, args.depth)
                        cells[label].append((evt.relative_mse(image, ref), seconds))
                    image, seconds, _ = mitsuba.render(scene, spp, sampler="multijitter",
                                                       seed=seed, **mapping)
                    cells["Mitsuba multijitter"].append((evt.relative_mse(image, ref), seconds))
                for label, runs in cells.items():
                    mse = statistics.fmean(r[0] for r in runs)
                    seconds = statistics.median(r[1] for r in runs)
                    rows.append((name, spp, label, mse, seconds))
                    print(name, spp, label, f"{mse:.5f}", f"{seconds:.2f}", flush=True)
    lines = [report.header(args.title),
             f"480x360, `-m {args.depth} -l 1`, 2 threads; trees: "
             + ", ".join(f"{label} `{tree}`" for label, tree in trees.items()) + "; mean "
             f"relative MSE over {args.seeds} seeds against the cached {evt.REFERENCE_SPP}-spp "
             "Mitsuba reference, median seconds of the render call.", "",
             "| scene | spp | renderer | rel. MSE | seconds | rel. MSE x s | rel. MSE / "
             "Mitsuba's | rel. MSE x s / Mitsuba's |", "|---|---:|---|---:|---:|---:|---:|---:|"]
    for name, spp, label, mse, seconds in rows:
        m_mse, m_s = next((r[3], r[4]) for r in rows
                          if r[0] == name and r[1] == spp and r[2] == "Mitsuba multijitter")
        lines.append(f"| {name} | {spp} | {label} | {mse:.5f} | {seconds:.2f} | "
                     f"{mse * seconds:.5f} | {mse / m_mse:.2f}x | "
                     f"{mse * seconds / (m_mse * m_s):.2f}x |")
    path = report.write(args.output, "\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
