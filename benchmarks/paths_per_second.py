"""Camera paths per second: ptrace (naive, bvh, embree) and Mitsuba 3 (llvm_ad_rgb, scalar_rgb)
side by side on the same scenes, at the same resolution, spp, depth and thread count.

    python -m benchmarks.paths_per_second [--quick] [--spp 16] [--resolution 480 360]
        [--threads 2] [--repeats 3] [--no-mitsuba] [--output paths_per_second.md]

Scenes sky/CBspheres_lambertian.dae (12 triangles, 2 spheres: naive, bvh and embree) and
sky/CBbunny.dae (28,588 triangles: bvh and embree), ptrace's `-m 5 -l 1`:
ptrace.render(scene, spp=S, light_samples=1, max_depth=5, resolution=(W, H), threads=2,
accel=...), seed r for repeat r. Paths = W x H x S camera paths; a rate is paths over the median
wall seconds of --repeats render calls, with the scene loaded and the kernels compiled
beforehand (a tiny render per backend). ptrace's call includes its acceleration build (figures
in the JSON); Mitsuba's scene, its BVH included, is loaded before the clock starts.

Mitsuba 3 (where `import mitsuba` works; it is not a ptrace dependency: pip install mitsuba)
renders the scene mapped by benchmarks.mitsuba_reference.mitsuba_scene: its `path` integrator at
max_depth 6 (= ptrace's -m 5, Mitsuba counts segments), independent sampler at the same spp,
box filter, seed r for repeat r. The course's sky/ files also carry an emissive quad on the area
light, which mitsuba_scene refuses (diffuse materials only), so this module maps emissive
materials itself, as what they are to ptrace's light-sampling estimator: black (they reflect
nothing, and rays that hit them end) and not emitters (the area light is the light); only camera
rays that see them directly get their emission in ptrace, so the report compares mean image
values over the pixels that do not see the lamp (from a ptrace -m 0 render), as well as over the
whole image. Variants:
- llvm_ad_rgb, the anchor of the ratio column: needs libLLVM, found by find_libllvm()
  (DRJIT_LIBLLVM_PATH if set, else the newest libLLVM in the usual system, LLVM and conda
  directories, exported as DRJIT_LIBLLVM_PATH before Mitsuba is imported). Its first render
  JIT-compiles the megakernel (or loads it from Dr.Jit's kernel cache): it is run once untimed,
  reported apart, and the --repeats timed renders follow;
- scalar_rgb, for reference (nothing to compile: every render is timed).
Threads: drjit.set_thread_count(threads) (Dr.Jit's nanothread pool, which runs both the LLVM
backend's kernels and the scalar variant's render blocks; the calling thread counts as one), and
numba's thread count through render(threads=...) for ptrace. The CPU/wall column (process CPU
seconds over wall seconds of the timed renders) shows how many cores each renderer kept busy.

A missing mitsuba or libLLVM skips the Mitsuba rows with a one-line note. --quick: 4 spp,
160x120. Writes benchmarks/results/paths_per_second.md (or --output; a relative path is taken
inside benchmarks/results/) and the raw numbers beside it as paths_per_second.json.
"""
import argparse
import dataclasses
import datetime
import glob
import json
import os
import platform
import re
import statistics
import sys
import tempfile
import time

import numpy as np

from ptrace.codes import RR_DEPTH

from . import report
from .rays import scenes_dir

SCENES = {"sky/CBspheres_lambertian.dae": ("naive", "bvh", "embree"),
          "sky/CBbunny.dae": ("bvh", "embree")}
VARIANTS = ("llvm_ad_rgb", "scalar_rgb")
ANCHOR = "llvm_ad_rgb"
DEPTH = 5            # ptrace's -m; Mitsuba's max_depth is DEPTH + 1
LIGHT_SAMPLES = 1
FULL = dict(spp=16, resolution=(480, 360))
QUICK = dict(spp=4, resolution=(160, 120))
LIBLLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*", "/usr/lib64/libLLVM*.so*", "/usr/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*", "/usr/local/opt/llvm/lib/libLLVM*.dylib",
    "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib", os.path.join(sys.prefix, "lib", "libLLVM*.so*"))


def libllvm_version(path):
    """LLVM major version in a library path (libLLVM-19.so, libLLVM.so.19.1, llvm-19/lib/...),
    0 when it names none."""
    numbers = re.findall(r"(?:llvm|LLVM)(?:-|\.so\.)(\d+)", path)
    return int(numbers[-1]) if numbers else 0


def find_libllvm(patterns=LIBLLVM_GLOBS, environ=os.environ):
    """The libLLVM shared library Dr.Jit should load: DRJIT_LIBLLVM_PATH if set (returned as
    given, even if missing: the user asked for it), else the newest one found by `patterns`,
    or None."""
    if environ.get("DRJIT_LIBLLVM_PATH"):
        return environ["DRJIT_LIBLLVM_PATH"]
    found = {}
    for pattern in patterns:
        for path in glob.glob(pattern):
            if os.path.isfile(path) and not path.endswith(".a"):
                found.setdefault(os.path.realpath(path), path)
    if not found:
        return None
    return max(found.values(), key=lambda p: (libllvm_version(p), -len(p), p))


def lamp_mask(scene, resolution, spp):
    """Pixels whose camera rays see emissive geometry, from a ptrace -m 0 render (only the
    emission seen directly): (H, W) bool, top row first like the images."""
    import ptrace
    image = ptrace.render(scene, spp=spp, max_depth=0, resolution=resolution)
    return (image > 0).any(axis=-1)


def image_means(image, mask):
    """(mean over every pixel and channel, the same over the pixels outside `mask`)."""
    image = np.asarray(image, dtype=np.float64)
    outside = image[~mask] if mask is not None and mask.any() else image.reshape(-1, 3)
    return float(image.mean()), float(outside.mean())


def summarise(scene_name, renderer, resolution, spp, seconds, cpu, images, mask, **extra):
    """One row of the report: the rate from the median wall seconds, the image means."""
    paths = resolution[0] * resolution[1] * spp
    median = statistics.median(seconds)
    means = [image_means(image, mask) for image in images]
    whole, off = [m[0] for m in means], [m[1] for m in means]
    sd = lambda values: statistics.stdev(values) if len(values) > 1 else 0.0
    return dict(scene=scene_name, renderer=renderer, paths=paths, seconds=seconds,
                median_seconds=median, paths_per_second=paths / median,
                cpu_per_wall=statistics.median(c / s for c, s in zip(cpu, seconds)),
                mean=statistics.fmean(whole), mean_sd=sd(whole),
                mean_off_lamp=statistics.fmean(off), mean_off_lamp_sd=sd(off),
                mean_rgb=np.mean([np.asarray(i, np.float64).reshape(-1, 3).mean(axis=0)
                                  for i in images], axis=0).tolist(), **extra)


def warm_up(scene, kinds):
    """Compile (or load from numba's cache) the path kernel of every backend in `kinds`."""
    import ptrace
    for kind in kinds:
        ptrace.render(scene, spp=1, resolution=(8, 6), max_depth=2,
                      light_samples=LIGHT_SAMPLES, accel=kind)


def measure_ptrace(scene, scene_name, kind, spp, resolution, threads, repeats, mask=None):
    """Time `repeats` ptrace renders (seed r for repeat r); kernels must be warm already."""
    import ptrace
    seconds, cpu, images, builds, rays = [], [], [], [], []
    for r in range(repeats):
        stats = {}
        start, start_cpu = time.perf_counter(), time.process_time()
        image = ptrace.render(scene, spp=spp, light_samples=LIGHT_SAMPLES, max_depth=DEPTH,
                              resolution=resolution, threads=threads, accel=kind, seed=r,
                              stats=stats)
        seconds.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
        images.append(image)
        builds.append(stats["build_seconds"])
        rays.append(stats["rays"])
    paths = resolution[0] * resolution[1] * spp
    row = summarise(scene_name, f"ptrace {kind}", resolution, spp, seconds, cpu, images, mask,
                    build_seconds=builds, rays_per_path=statistics.fmean(rays) / paths)
    print(f"{scene_name} ptrace {kind}: {row['paths_per_second']:,.0f} paths/s "
          f"({row['median_seconds']:.2f} s)", flush=True)
    return row


def without_emission(scene):
    """The scene with every emissive material made black diffuse, and what was changed."""
    from ptrace.scene import DIFFUSE, EMISSION
    materials = scene.materials
    used = np.unique(scene.material_index)
    emissive = [int(m) for m in used if materials.kind[m] == EMISSION]
    kind, albedo = materials.kind.copy(), materials.albedo.copy()
    kind[emissive] = DIFFUSE
    albedo[emissive] = 0.0
    notes = [f"material {m} (emission {materials.emission[m].tolist()}, "
             f"{int((scene.material_index == m).sum())} primitives) -> black twosided diffuse, "
             "no emitter" for m in emissive]
    proxy = dataclasses.replace(scene, materials=dataclasses.replace(materials, kind=kind,
                                                                     albedo=albedo))
    return proxy, notes


def mitsuba_description(scene, camera, spp, seed, workdir):
    """(Mitsuba scene dict, mapping note): benchmarks.mitsuba_reference's mapping, applied to
    the scene without emission when that mapping refuses the emissive materials."""
    from .mitsuba_reference import mitsuba_scene
    try:
        return mitsuba_scene(scene, camera, DEPTH, spp, seed, workdir), "mitsuba_reference"
    except SystemExit as refusal:
        proxy, notes = without_emission(scene)
        if not notes:
            raise
        return (mitsuba_scene(proxy, camera, DEPTH, spp, seed, workdir),
                f"mitsuba_reference refuses it ({refusal}); mapped here: " + "; ".join(notes))


def import_mitsuba():
    """(mitsuba module or None, libLLVM path or None, note or None). Exports
    DRJIT_LIBLLVM_PATH first, so the llvm variant can find libLLVM."""
    libllvm = find_libllvm()
    if libllvm is not None:
        os.environ["DRJIT_LIBLLVM_PATH"] = libllvm
    try:
        import mitsuba as mi
    except ImportError as error:
        return None, libllvm, (f"Mitsuba rows skipped: mitsuba is not importable ({error}; "
                               "pip install mitsuba).")
    return mi, libllvm, None


def set_variant(mi, variant, threads, libllvm):
    """Switch Mitsuba to `variant` on `threads` threads; a note instead when it cannot run."""
    try:
        mi.set_variant(variant)
    except (ImportError, AttributeError, RuntimeError, ValueError) as error:
        hint = (f"libLLVM {libllvm!r} did not load" if libllvm else
                "no libLLVM found (install libllvm, or set DRJIT_LIBLLVM_PATH to libLLVM.so)")
        if not variant.startswith("llvm"):
            hint = "variant not available"
        return f"Mitsuba {variant} rows skipped: {hint}: {str(error).splitlines()[0]}"
    import drjit as dr
    if variant.startswith("llvm") and not dr.has_backend(dr.JitBackend.LLVM):
        return f"Mitsuba {variant} rows skipped: Dr.Jit's LLVM backend is inactive"
    dr.set_thread_count(threads)
    mi.set_log_level(mi.LogLevel.Warn)
    return None


def measure_mitsuba(mi, variant, scene, scene_name, spp, resolution, repeats, mask=None):
    """Time `repeats` Mitsuba renders of the mapped scene (seed r for repeat r) in the current
    variant; on llvm variants one untimed render first (JIT compilation)."""
    import drjit as dr

    from ptrace.camera import course_camera
    camera = course_camera(scene, *resolution)
    with tempfile.TemporaryDirectory() as workdir:
        description, mapping = mitsuba_description(scene, camera, spp, 0, workdir)
        loaded = mi.load_dict(description)
    jit = variant.startswith(("llvm", "cuda"))

    def render(seed):
        image = mi.render(loaded, seed=seed)
        if jit:
            dr.eval(image)
            dr.sync_thread()
        return image

    first = None
    if jit:
        start = time.perf_counter()
        render(0)
        first = time.perf_counter() - start
    seconds, cpu, images = [], [], []
    for r in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        image = render(r)
        seconds.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
        images.append(np.array(image, dtype=np.float32))
    row = summarise(scene_name, f"Mitsuba {variant}", resolution, spp, seconds, cpu, images,
                    mask, mapping=mapping, first_render_seconds=first,
                    thread_count=dr.thread_count())
    print(f"{scene_name} Mitsuba {variant}: {row['paths_per_second']:,.0f} paths/s "
          f"({row['median_seconds']:.2f} s)", flush=True)
    return row


def table(rows):
    """The Markdown table: scene x renderer, with the ratio to Mitsuba llvm_ad_rgb."""
    anchor = {r["scene"]: r["paths_per_second"] for r in rows
              if r["renderer"] == f"Mitsuba {ANCHOR}"}
    lines = ["| scene | renderer | median s | paths/s | / llvm_ad_rgb | CPU/wall | "
             "rays/path | mean | mean off-lamp (s.d. over seeds) |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        ratio = (f"{r['paths_per_second'] / anchor[r['scene']]:.2f}x"
                 if r["scene"] in anchor else "n/a")
        rays = f"{r['rays_per_path']:.2f}" if "rays_per_path" in r else "-"
        lines.append(f"| {r['scene']} | {r['renderer']} | {r['median_seconds']:.2f} | "
                     f"{r['paths_per_second']:,.0f} | {ratio} | {r['cpu_per_wall']:.2f} | "
                     f"{rays} | {r['mean']:.4f} | {r['mean_off_lamp']:.4f} "
                     f"({r['mean_off_lamp_sd']:.4f}) |")
    return lines


def agreement(rows):
    """One sentence per scene: the spread of the off-lamp means against their seed noise."""
    out = []
    for scene_name in dict.fromkeys(r["scene"] for r in rows):
        here = [r for r in rows if r["scene"] == scene_name]
        if len(here) < 2:
            continue
        means = [r["mean_off_lamp"] for r in here]
        noise = max(r["mean_off_lamp_sd"] for r in here)
        spread = max(means) - min(means)
        out.append(f"- {scene_name}: off-lamp means span {spread:.4f} "
                   f"({100 * spread / statistics.fmean(means):.2f}%) across {len(here)} "
                   f"renderers; the largest s.d. over seeds of one renderer is {noise:.4f}.")
    return out


def main(argv=None):
    import ptrace
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--spp", type=int, default=None)
    parser.add_argument("--resolution", type=int, nargs=2, default=None)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--no-mitsuba", action="store_true", help="ptrace rows only")
    parser.add_argument("--output", default="paths_per_second.md")
    args = parser.parse_args(argv)
    preset = QUICK if args.quick else FULL
    spp = args.spp or preset["spp"]
    resolution = tuple(args.resolution or preset["resolution"])

    scenes, masks = {}, {}
    for name in args.scenes:
        scenes[name] = ptrace.load(os.path.join(scenes_dir(), name))
        warm_up(scenes[name], SCENES[name])
        masks[name] = lamp_mask(scenes[name], resolution, spp)
    rows = []
    for name in args.scenes:
        for kind in SCENES[name]:
            rows.append(measure_ptrace(scenes[name], name, kind, spp, resolution, args.threads,
                                       args.repeats, masks[name]))

    notes, mitsuba = [], dict(version=None, libllvm=None, drjit=None)
    if args.no_mitsuba:
        notes.append("Mitsuba rows skipped: --no-mitsuba.")
    else:
        mi, mitsuba["libllvm"], note = import_mitsuba()
        if note:
            notes.append(note)
        else:
            import drjit as dr
            mitsuba.update(version=mi.__version__, drjit=dr.__version__)
            for variant in VARIANTS:
                note = set_variant(mi, variant, args.threads, mitsuba["libllvm"])
                if note:
                    notes.append(note)
                    continue
                for name in args.scenes:
                    try:
                        rows.append(measure_mitsuba(mi, variant, scenes[name], name, spp,
                                                    resolution, args.repeats, masks[name]))
                    except SystemExit as refusal:
                        notes.append(f"Mitsuba {variant} on {name} skipped: {refusal}")
    for note in notes:
        print(note, flush=True)
    order = ([f"ptrace {k}" for k in ("naive", "bvh", "embree")]
             + [f"Mitsuba {v}" for v in VARIANTS])
    rows.sort(key=lambda r: (args.scenes.index(r["scene"]), order.index(r["renderer"])))

    lamp = {name: int(mask.sum()) for name, mask in masks.items()}
    jit = [r for r in rows if r.get("first_render_seconds") is not None]
    mappings = dict.fromkeys(f"{r['scene']}: {r['mapping']}" for r in rows if "mapping" in r)
    builds = [f"{r['scene']} {r['renderer'].split()[1]} "
              f"{statistics.median(r['build_seconds']):.3f}" for r in rows if "build_seconds" in r]
    w, h = resolution
    lines = [report.header("Camera paths per second: ptrace against Mitsuba 3"),
             f"{w}x{h}, {spp} spp ({w * h * spp:,} camera paths per render), ptrace `-m {DEPTH} "
             f"-l {LIGHT_SAMPLES}` = Mitsuba `path` max_depth {DEPTH + 1}, {args.threads} threads, "
             f"median wall seconds of {args.repeats} renders (seeds 0..{args.repeats - 1}), scene "
             "loaded and kernels compiled beforehand. Mitsuba "
             + (f"{mitsuba['version']} (Dr.Jit {mitsuba['drjit']}, libLLVM "
                f"{mitsuba['libllvm']})" if mitsuba["version"] else "not run") + ".", "",
             *table(rows), "",
             *(f"- {note}" for note in notes), *([""] if notes else []),
             "Notes:", "",
             "- paths/s = camera paths (pixels x spp) / median wall seconds of the render call; "
             "'/ llvm_ad_rgb' divides by Mitsuba llvm_ad_rgb's rate on the same scene.",
             f"- Threads: ptrace through render(threads={args.threads}) (numba); Mitsuba through "
             f"drjit.set_thread_count({args.threads}) (the nanothread pool that runs both "
             "variants; the calling thread counts as one). CPU/wall is the process's CPU seconds "
             "over wall seconds during the timed renders: about the number of busy cores.",
             "- llvm_ad_rgb: the first render of each scene (JIT compilation, or a load from "
             "Dr.Jit's kernel cache) is not timed: " + (", ".join(
                 f"{r['scene']} {r['first_render_seconds']:.2f} s" for r in jit) or "not run")
             + ". scalar_rgb has nothing to compile: every render is timed.",
             "- ptrace's time includes its acceleration build (median seconds: " + ", ".join(builds)
             + "); Mitsuba builds its BVH when the scene is loaded, before the clock.",
             "- rays/path (ptrace's own count of camera, bounce and shadow rays) measures the "
             "work per path. Mitsuba's Russian roulette starts at its default rr_depth 5, "
             f"ptrace's at vertex {RR_DEPTH} (ptrace.codes.RR_DEPTH), so where these "
             "differ the paths differ in length: the rates compare camera paths, not rays.",
             "- Mapping: " + (" | ".join(mappings) or "not run") + ". The lamp is therefore "
             "black in Mitsuba's images, which ptrace shows at its emission: 'mean' is over "
             "every pixel and channel, 'mean off-lamp' over the pixels that do not see the lamp "
             "(" + ", ".join(f"{n}: {k} of {w * h} pixels masked" for n, k in lamp.items())
             + ", from a ptrace -m 0 render); its s.d. is over the seeds of the repeats.", "",
             "Agreement of the off-lamp means (within noise when the span is a few s.d.):", "",
             *agreement(rows), ""]
    path = report.write(args.output, "\n".join(lines))
    raw = dict(date=datetime.datetime.now().isoformat(timespec="seconds"),
               command=next(line for line in report.header("").splitlines()
                            if line.startswith("- command:"))[len("- command: "):].strip("`"),
               machine=dict(cores=os.cpu_count(), cpu=report.cpu_model(),
                            system=f"{platform.system()} {platform.machine()}",
                            python=platform.python_version()),
               settings=dict(resolution=list(resolution), spp=spp, max_depth=DEPTH,
                             mitsuba_max_depth=DEPTH + 1, light_samples=LIGHT_SAMPLES,
                             threads=args.threads, repeats=args.repeats, quick=args.quick),
               mitsuba=mitsuba, lamp_pixels=lamp, notes=notes, rows=rows)
    json_path = report.write(os.path.splitext(args.output)[0] + ".json",
                             json.dumps(raw, indent=1) + "\n")
    print(f"wrote {path} and {json_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
