"""ptrace against Mitsuba 3 on the project's own Mitsuba XML scenes (scenes/mitsuba/): every
file read by both renderers, its mean ratio, a per-pixel z-test and the wall times side by side.

    python -m benchmarks.mitsuba_scenes [--quick] [--scenes cbox lights ...]
        [--resolution 96 72] [--spp 64] [--z-resolution 32 24] [--z-spp 256] [--batches 8]
        [--threads 2] [--variant llvm_ad_rgb] [--load-triangles 1000000] [--load-repeats 3]
        [--output mitsuba_scenes.md]

Both renderers read the same file with the same $width, $height and $spp (ptrace through
ptrace.load's defines, so the file's film, sampler and max_depth set the render as on the
command line; Mitsuba through mi.load_file's keyword arguments). The timing run renders each
scene twice with each renderer and keeps the second (the first compiles); the z-test renders
--batches batches of --z-spp / --batches samples with seeds 1, 2, ... with each and compares
every pixel channel by Welch's t (`z_test`). Last, both load a scene of one torus of
--load-triangles triangles as a PLY and as a serialized file (`loading`; 0 skips it). Mitsuba
is needed only here, never by ptrace. --quick: two scenes (cbox, lights) at 24x18, 8 spp,
z-test 12x9 at 32 spp in 4 batches, Mitsuba's scalar_rgb variant (no LLVM compile), a torus of
10,000 triangles loaded once.
"""
import argparse
import math
import os
import time
from pathlib import Path

import numpy as np

import ptrace

from . import report
from .templating import blocks, fill

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes" / "mitsuba"
TEMPLATE = "mitsuba_scenes.md"
# each scene and the plugins it is there to cover (the files' own comments say the same)
COVERS = {
    "cbox": "rectangle, cube, sphere, twosided, diffuse, area, include, path, independent",
    "meshes": "obj, ply (face_normals), serialized, disk (flip_normals), point, moment, "
              "stratified",
    "lights": "point, spot, directional, constant, direct, multijitter",
    "envmap": "envmap (scale, to_world), conductor, roughconductor (eta, k), thinlens, "
              "volpath, ldsampler",
    "textures": "bitmap (nearest, mirror, raw, to_uv), checkerboard, mask, conductor (Au)",
    "glass_plastic": "dielectric, roughdielectric, thindielectric, plastic, roughplastic, "
                     "principled",
    "ptracer": "ptracer",
}
QUICK_SCENES = ("cbox", "lights")
P_VALUE, BINOMIAL = 0.01, 0.001
ROUNDING = 1e-5       # z_test's least standard error, relative to the mean


def defines(width, height, spp):
    return {"width": str(width), "height": str(height), "spp": str(spp)}


def ptrace_render(path, width, height, spp, seed, threads):
    """(image, load seconds, render seconds) of ptrace on the file at this size."""
    start = time.perf_counter()
    scene = ptrace.load(path, defines=defines(width, height, spp))
    loaded = time.perf_counter()
    image = ptrace.render(scene, seed=seed, threads=threads)     # the file's lens too
    return np.asarray(image, np.float64), loaded - start, time.perf_counter() - loaded


def mitsuba_render(mi, path, width, height, spp, seed):
    """(image, load seconds, render seconds) of Mitsuba on the file at this size."""
    start = time.perf_counter()
    scene = mi.load_file(str(path), **defines(width, height, spp))
    loaded = time.perf_counter()
    image = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)[:, :, :3]
    return image, loaded - start, time.perf_counter() - loaded


def z_test(ours, theirs):
    """(share of pixel channels whose Welch p < P_VALUE, whether that count is within what
    agreeing images give by a binomial test at BINOMIAL) of two stacks of batch images
    (batches, H, W, 3). Each mean's standard error is at least ROUNDING of its magnitude:
    Mitsuba sums a pixel's samples in float32, so a pixel that sees one constant radiance
    (an environment's ground, an emitter) comes out a few float32 ulps (5e-7 of the value)
    from ptrace's with no spread in either, which is not a difference any sample count
    could measure."""
    from scipy import stats
    n_a, n_b = len(ours), len(theirs)
    mean_a, mean_b = ours.mean(axis=0), theirs.mean(axis=0)
    var_a, var_b = ours.var(axis=0, ddof=1) / n_a, theirs.var(axis=0, ddof=1) / n_b
    spread = var_a + var_b + (ROUNDING * np.maximum(np.abs(mean_a), np.abs(mean_b))) ** 2
    flat = spread <= 0      # both means 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (mean_a - mean_b) / np.sqrt(spread)
        dof = spread ** 2 / (var_a ** 2 / (n_a - 1) + var_b ** 2 / (n_b - 1))
    dof = np.where(np.isfinite(dof), dof, 1e9)      # no spread: the floor's normal law
    p = np.where(flat, 1.0, 2 * stats.t.sf(np.abs(np.where(flat, 0.0, t)), dof))
    count = int((p < P_VALUE).sum())
    binomial = stats.binomtest(count, p.size, P_VALUE, alternative="greater").pvalue
    return count / p.size, binomial > BINOMIAL


def notes_of(path, width, height, spp):
    from ptrace.app.cli import grouped_notes
    return grouped_notes(ptrace.load(path, defines=defines(width, height, spp)).notes)


def measure(mi, name, args):
    path = SCENES / f"{name}.xml"
    width, height = args.resolution
    runs = {}
    for renderer in ("ptrace", "mitsuba"):
        for _ in range(2):      # the second is timed: the first compiles
            if renderer == "ptrace":
                runs[renderer] = ptrace_render(path, width, height, args.spp, 0, args.threads)
            else:
                runs[renderer] = mitsuba_render(mi, path, width, height, args.spp, 0)
    z_width, z_height = args.z_resolution
    batch = args.z_spp // args.batches
    ours = np.stack([ptrace_render(path, z_width, z_height, batch, 1 + seed, args.threads)[0]
                     for seed in range(args.batches)])
    theirs = np.stack([mitsuba_render(mi, path, z_width, z_height, batch, 1 + seed)[0]
                       for seed in range(args.batches)])
    share, agrees = z_test(ours, theirs)
    return {"name": name, "plugins": COVERS[name],
            "ptrace_load": runs["ptrace"][1], "mitsuba_load": runs["mitsuba"][1],
            "ptrace_seconds": runs["ptrace"][2], "mitsuba_seconds": runs["mitsuba"][2],
            "ratio": float(runs["ptrace"][0].mean() / runs["mitsuba"][0].mean()),
            "z_ratio": float(ours.mean() / theirs.mean()), "share": share,
            "verdict": "agrees" if agrees else "differs",
            "notes": notes_of(path, width, height, args.spp)}


def assets():
    """scenes/mitsuba/make_assets.py as a module (its torus and its writers)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("make_assets", SCENES / "make_assets.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def loading(mi, triangles, repeats):
    """[(form, triangles, ptrace's median load seconds, Mitsuba's)] of a scene of one torus
    of about `triangles` triangles as a binary PLY and as a serialized file, written to a
    temporary folder."""
    import statistics
    import tempfile
    make = assets()
    sides = max(int(math.sqrt(triangles / 4)), 3)
    vertices, uv, faces = make.torus(rings=max(triangles // (2 * sides), 3), sides=sides)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        make.write_ply(folder / "big.ply", vertices, faces)
        make.write_serialized(folder / "big.serialized", vertices, uv, faces)
        for form in ("ply", "serialized"):
            path = folder / f"{form}.xml"
            path.write_text(f'<scene version="3.0.0"><shape type="{form}"><string name='
                            f'"filename" value="big.{form}"/></shape></scene>')
            times = {"ptrace": [], "mitsuba": []}
            for _ in range(repeats):
                start = time.perf_counter()
                ptrace.load(path)
                times["ptrace"].append(time.perf_counter() - start)
                start = time.perf_counter()
                mi.load_file(str(path))
                times["mitsuba"].append(time.perf_counter() - start)
            rows.append((form, len(faces), statistics.median(times["ptrace"]),
                         statistics.median(times["mitsuba"])))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--scenes", nargs="+", choices=sorted(COVERS), default=None)
    parser.add_argument("--resolution", type=int, nargs=2, default=None)
    parser.add_argument("--spp", type=int, default=None)
    parser.add_argument("--z-resolution", type=int, nargs=2, default=None)
    parser.add_argument("--z-spp", type=int, default=None)
    parser.add_argument("--batches", type=int, default=None)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--variant", default=None)
    parser.add_argument("--load-triangles", type=int, default=None)
    parser.add_argument("--load-repeats", type=int, default=None)
    parser.add_argument("--output", default="mitsuba_scenes.md")
    args = report.quick_defaults(parser.parse_args(argv), scenes=(QUICK_SCENES, list(COVERS)),
                                 resolution=((24, 18), (96, 72)), spp=(8, 64),
                                 z_resolution=((12, 9), (32, 24)), z_spp=(32, 256),
                                 batches=(4, 8), variant=("scalar_rgb", "llvm_ad_rgb"),
                                 load_triangles=(10_000, 1_000_000), load_repeats=(1, 3))
    if args.batches < 2 or args.z_spp % args.batches:
        parser.error("--batches must be at least 2 and divide --z-spp")
    import drjit
    import mitsuba as mi
    mi.set_variant(args.variant)
    if args.variant.startswith("llvm"):
        drjit.set_thread_count(args.threads)
    rows = []
    for name in args.scenes:
        rows.append(measure(mi, name, args))
        row = rows[-1]
        print(f"{name}: ratio {row['ratio']:.4f}, z {row['share']:.2%} {row['verdict']}, "
              f"ptrace {row['ptrace_seconds']:.2f} s, mitsuba {row['mitsuba_seconds']:.2f} s",
              flush=True)
    loads = loading(mi, args.load_triangles, args.load_repeats) if args.load_triangles else []
    text = blocks(TEMPLATE)
    width, height = args.resolution
    z_width, z_height = args.z_resolution
    lines = [report.header("Mitsuba scenes: ptrace and Mitsuba 3 on the same files"),
             fill(text["intro"], cpu=report.cpu_model(),
                  vectors=report.vector_extensions() or "vector extensions unknown",
                  cores=os.cpu_count(), mitsuba_version=mi.__version__, variant=args.variant,
                  threads=args.threads, width=width, height=height, spp=args.spp,
                  z_width=z_width, z_height=z_height, z_spp=args.z_spp, batches=args.batches,
                  batch_spp=args.z_spp // args.batches)]
    lines += [fill(text["row"], row) for row in rows]
    lines.append(fill(text["summary"], mean_ratio=float(np.mean([r["ratio"] for r in rows])),
                      mean_z_ratio=float(np.mean([r["z_ratio"] for r in rows])),
                      agree=sum(r["verdict"] == "agrees" for r in rows), count=len(rows)))
    lines += [fill(text["notes"], name=row["name"],
                   notes="\n".join(f"- {note}" for note in row["notes"]) or "- (none)")
              for row in rows]
    if loads:
        lines.append(fill(text["loading"], repeats=args.load_repeats))
        lines += [fill(text["loading_row"], form=form, triangles=count, ptrace=ours,
                       mitsuba=theirs, ratio=ours / theirs) for form, count, ours, theirs in loads]
    lines.append(text["history"])     # (a record of earlier runs: no fields)
    path = report.write(args.output, "\n".join(lines) + "\n")
    print(f"wrote {path}")
    return 0 if all(math.isfinite(r["ratio"]) for r in rows) else 1


if __name__ == "__main__":
    main()
