"""`ptrace [options] SCENE`: the course's command line over ptrace.load and ptrace.render.

Anything a user can cause (a PtraceError, a bad flag) ends in one line on stderr and exit code
2, never a traceback. Anything else is a bug in ptrace: `ptrace: internal error: ...`, the
traceback, and exit code 1. Ctrl-C writes what was rendered and exits 130.
"""
import argparse
import contextlib
import json
import os
import re
import sys
import traceback

import numpy as np

EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141   # 128 + SIGPIPE, as a shell reports a writer whose reader left


class _Parser(argparse.ArgumentParser):
    def error(self, message):   # one line, not argparse's usage block
        raise _UsageError(message)


class _UsageError(Exception):
    pass


def _int_at_least(name, minimum, maximum=None):
    """A parser of integers in [minimum, maximum] (no maximum: any size) for a flag `name`."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {text!r}") from None
        if value < minimum:
            bound = "at least 1" if minimum == 1 else f"at least {minimum}" if minimum else \
                "not negative"
            raise argparse.ArgumentTypeError(f"{name} must be {bound}, got {value}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"{name} must be an integer from {minimum} to "
                                             f"{maximum}, got {value}")
        return value
    return parse


def _int_range(name, setting):
    """A parser of the integer setting `setting` in its ptrace.settings.RANGES range."""
    from .settings import RANGES
    return _int_at_least(name, *RANGES[setting])


def _range_text(setting):
    from .settings import RANGES
    low, high = RANGES[setting]
    return f"{low} to {high:,}".replace(",", "_") if high > 10 ** 6 else f"{low} to {high}"


def _positive_int(name):
    return _int_at_least(name, 1)


def _nonnegative_int(name):
    return _int_at_least(name, 0)


def _positive_float(name):
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not value > 0 or not np.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name} must be a positive number, got {text}")
        return value
    return parse


def _size(text):
    from .budget import parse_size
    from .errors import PtraceError
    try:
        return parse_size(text)
    except PtraceError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def build_parser():
    import accel

    from .cli_camera import add_camera_flags
    from .integrator import AUTO_EVERY_LIGHT, AUTO_MANY
    from .renderer import MAX_SIDE, PIXEL_BYTES
    from .settings import (
        BVH_SPLITS,
        DIRECT,
        INTEGRATORS,
        LIGHT_SAMPLER_CODES,
        LIGHT_SAMPLERS,
        SAMPLERS,
    )
    many = next(name for name, code in LIGHT_SAMPLER_CODES.items() if code == AUTO_MANY)
    parser = _Parser(prog="ptrace", description="Render a CS184 COLLADA scene (or a mesh file) "
                     "with a path tracer whose ray intersection is naive, a BVH, or Embree.")
    add = parser.add_argument
    add("scene", help="scene file: .dae (CS184 COLLADA) or .obj .ply .stl .glb .gltf")
    add("-t", "--threads", type=_positive_int("threads"), default=None,
        help="render threads (default: all cores; with --workers or --scheduler, threads per "
             "task on each worker, default its share of its machine's cores)")
    add("-s", "--spp", type=_int_range("samples per pixel (-s)", "spp"), default=1,
        help=f"camera rays per pixel, {_range_text('spp')} (default 1)")
    add("-l", "--light-samples", type=_int_range("light samples (-l)", "light_samples"),
        default=1, help=f"samples per area light per shading point, "
                        f"{_range_text('light_samples')} (default 1)")
    add("-m", "--max-depth", type=_int_range("max depth (-m)", "max_depth"), default=1,
        help=f"maximum ray depth, {_range_text('max_depth')} (default 1)")
    add("-a", "--adaptive", nargs=2, metavar=("BATCH", "TOL"), default=None,
        help="adaptive sampling: samples per batch and tolerance")
    add("-H", "--hemisphere", action="store_true",
        help="direct light by uniform hemisphere sampling instead of light sampling")
    add("--direct", choices=DIRECT, default="mis",
        help="direct light: mis (light samples and BSDF samples combined by multiple importance "
             "sampling; default) or light (the course's light sampling alone)")
    add("--sampler", choices=SAMPLERS, default="sobol",
        help="random numbers: sobol (Owen-scrambled Sobol', stratified; default) or "
             "independent (uniform, like the course)")
    add("--light-sampler", choices=LIGHT_SAMPLERS, default="auto",
        help="which lights a vertex samples: all (-l samples of every light, one of each point "
             "or directional light: the course's), power (-l samples in all, each of one light "
             "chosen by its estimated power), bvh (-l samples in all, each of one light or "
             "emissive primitive chosen by a light BVH for the shading point) or auto (all for "
             f"a scene of at most {AUTO_EVERY_LIGHT} lights, the emissive primitives counting "
             f"as one; else {many}; the default)")
    add("-r", "--resolution", nargs=2, type=_int_at_least("resolution (-r)", 1, MAX_SIDE),
        metavar=("W", "H"), default=(800, 600),
        help=f"image size, 1 to {MAX_SIDE} per side and the image buffers (about "
             f"{PIXEL_BYTES} bytes a pixel) within --max-memory; a course scene's "
             f"camera (and -c's) keeps the focal length, so it crops; a mesh file's default "
             f"camera and --eye's frame the view at any size (default 800 600)")
    add("-f", "--output", default=None, metavar="FILE",
        help="output image, .png (the course's 8-bit curve) or .exr (linear float); "
             "default SCENE_NAME.png in the current directory")
    add("-p", "--crop", nargs=4, type=_nonnegative_int("crop"), metavar=("X", "Y", "DX", "DY"),
        default=None, help="render only this cell (y counted from the bottom) and save just it")
    add("-c", "--camera", default=None, metavar="FILE",
        help="the course's camera settings file (its focalDistance and lensRadius included)")
    add_camera_flags(parser)
    add("-e", "--environment", default=None, metavar="FILE|R,G,B",
        help="an environment light (the course's -e): an image OpenImageIO reads (.exr, .hdr, "
             "...), lat-long with +Y up, or a constant colour such as 0.5,0.5,0.5; on a mesh "
             "file it replaces the default light")
    add("--no-default-light", action="store_true",
        help="never give a mesh file without lights the default ambient light (by default it "
             "gets one unless its emissive surfaces light it)")
    add("-b", "--lens-radius", type=float, default=None, metavar="R",
        help="thin-lens aperture radius (the course's 3-2 -b; default 0: a pinhole, or the -c "
             "file's lensRadius)")
    add("-d", "--focal-distance", type=float, default=None, metavar="D",
        help="thin-lens focal distance along the view axis (the course's -d; default 4.7, or "
             "the -c file's focalDistance, or for --eye and a mesh file's default camera the "
             "distance to the point looked at)")
    add("--accel", choices=accel.KINDS, default="bvh", help="ray intersection backend (default bvh)")
    add("--bvh-split", choices=BVH_SPLITS, default="mean",
        help="with --accel bvh: mean (split at the mean centroid, the seed's; default) or sah "
             "(binned surface area heuristic)")
    add("--seed", type=_int_range("seed (--seed)", "seed"), default=0,
        help=f"random seed, {_range_text('seed')} (default 0)")
    add("--integrator", choices=INTEGRATORS, default="path",
        help="path (light transport) or normals (the course's normal shading)")
    add("--aov", default=None, metavar="LIST",
        help="feature buffers to add to an .exr output as extra channels, any of albedo, normal, "
             "depth (first hit, averaged per pixel like the radiance; one more ray per sample)")
    add("--denoise", action="store_true",
        help="also write FILE_denoised (Intel Open Image Denoise guided by the albedo and "
             "normal AOVs; biased, so the noisy image is kept; needs pip install "
             "\"ptrace[denoise]\")")
    add("--max-memory", type=_size, default=None, metavar="SIZE",
        help="memory budget, e.g. 4G or 512M: a scene whose triangles after instancing, "
             "textures, environment map and image buffers are estimated to need more is "
             "refused before they are allocated (default: half the machine's memory, or 3/4 of "
             "what a ulimit -v leaves)")
    add("--info", action="store_true", help="print a JSON summary of the scene and exit")
    add("-q", "--quiet", action="store_true",
        help="no progress bar, compile notice or notes of what the loader ignored or assumed")
    dist = parser.add_argument_group("distributed rendering (needs: pip install \"ptrace[dist]\")")
    where = dist.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_positive_int("workers"), default=None, metavar="N",
                       help="render on a local Dask cluster of N worker processes (127.0.0.1)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="render on an existing Dask cluster, e.g. tcp://host:8786 or tls://")
    dist.add_argument("--dashboard", action="store_true",
                      help="with --workers: serve Dask's dashboard on 127.0.0.1:8787")
    return parser


def scene_info(scene, camera=None):
    """--info's summary of the scene; its camera is `camera`, default the scene's default
    camera at 800x600."""
    from .pointing import default_camera
    from .scene import KIND_NAMES, PHYSICAL
    lights = scene.lights
    entries = []
    for i in range(len(lights)):
        kind = KIND_NAMES[lights.kind[i]]
        entry = {"type": kind, "radiance": lights.radiance[i].tolist()}
        if kind in ("point", "spot"):
            physical = lights.model[i] == PHYSICAL
            entry["model"] = ("physical: radiance / distance^2" + (
                ", a cone" if kind == "spot" else "")) if physical else (
                "course: no falloff" if kind == "point" else "course: contributes nothing")
            if kind == "spot" and physical:
                entry["cone_degrees"] = [
                    float(np.degrees(np.arccos(np.clip(lights.cos_inner[i], -1, 1)))),
                    float(np.degrees(np.arccos(np.clip(lights.cos_outer[i], -1, 1))))]
        if kind in ("point", "spot", "area"):
            entry["position"] = lights.position[i].tolist()
        if kind in ("directional", "spot", "area"):
            entry["direction"] = lights.direction[i].tolist()
        if kind == "area":
            entry.update(edge_x=lights.edge_x[i].tolist(), edge_y=lights.edge_y[i].tolist(),
                         area=float(lights.area[i]))
        entries.append(entry)
    camera = default_camera(scene) if camera is None else camera
    bounds = scene.bounds()
    return {
        "file": os.path.abspath(scene.path),
        "triangles": int(scene.triangle_count),
        "spheres": int(scene.sphere_count),
        "lights": entries,
        "bsdfs": scene.bsdf_kinds(),
        "textures": [f"{name} ({w}x{h})" for name, w, h in zip(
            scene.textures.names, scene.textures.width.tolist(), scene.textures.height.tolist())],
        "camera": {"position": camera.position.tolist(), "target": camera.target.tolist(),
                   "hfov": camera.hfov, "vfov": camera.vfov, "screen_dist": camera.screen_dist,
                   "znear": camera.znear, "zfar": camera.zfar},
        "bounds": None if bounds is None else [bounds[0].tolist(), bounds[1].tolist()],
        "notes": grouped_notes(scene.notes),
    }


def grouped_notes(notes):
    """The loader's notes, one line per kind: a note '<element ...>: what' names where, and notes
    that say the same `what` in several places, or the same up to its numbers (fan-triangulated
    1 polygon here, 6 there), become one line with the count of places and the first; where
    one of their numbers differs from place to place, the line gives its sum."""
    kinds = {}
    for note in notes:
        where, _, what = note.partition(": ") if note.startswith("<") else ("", "", note)
        kinds.setdefault(re.sub(r"\d+", "#", what), []).append((where, what))
    lines = []
    for kind, places in kinds.items():
        where, what = places[0]
        if len(places) == 1:
            lines.append(f"{where}: {what}" if where else what)
            continue
        columns = list(zip(*[re.findall(r"\d+", text) for _, text in places]))
        varying = [k for k, column in enumerate(columns) if len(set(column)) > 1]
        if len(varying) == 1:   # one count that differs from place to place: their sum
            values = iter([str(sum(map(int, column))) if k in varying else column[0]
                           for k, column in enumerate(columns)])
            what = re.sub(r"#", lambda _: next(values), kind)
        first = f", the first {where}" if where else ""
        lines.append(f"{what} ({len(places)} places{first})")
    return lines


def _one_line_warnings():
    import warnings
    seen = set()

    def show(message, category, filename, lineno, file=None, line=None):
        text = str(message)
        if text not in seen:
            seen.add(text)
            print(f"ptrace: warning: {text}", file=sys.stderr)
    warnings.showwarning = show


def _notice(text):
    print(f"ptrace: {text}", file=sys.stderr, flush=True)


def run(argv):
    from . import load, render
    from .budget import Budget
    from .cli_camera import attach_negative_vectors, camera_from_flags, check_pointing
    from .errors import PtraceError
    from .features import denoise, denoised_path, require_denoiser
    from .image import FORMATS, check_output_path, rate_colours, rate_path, write_images
    from .renderer import check_frame
    from .settings import Settings
    args = build_parser().parse_args(attach_negative_vectors(argv))
    budget = Budget.of(args.max_memory)     # one budget: the scene, -e and the render
    _one_line_warnings()
    if args.adaptive is not None:
        batch = _int_range("adaptive batch (-a)", "spp")(args.adaptive[0])
        tolerance = _positive_float("adaptive tolerance")(args.adaptive[1])
        args.adaptive = (batch, tolerance)
    output = args.output
    if output is None:
        output = os.path.splitext(os.path.basename(args.scene))[0] + ".png"
    if os.path.splitext(output)[1].lower() not in FORMATS:
        raise PtraceError(f"{output}: output must end in {' or '.join(FORMATS)}")
    aov_names = ()
    if args.aov is not None:
        from .features import parse_aovs
        try:
            aov_names = parse_aovs(args.aov)
        except ValueError as error:
            raise _UsageError(str(error)) from None
        if not output.lower().endswith(".exr"):
            raise PtraceError(f"{output}: --aov adds channels to an .exr output; use -f "
                              f"NAME.exr")
    if args.denoise:
        require_denoiser()
    aovs = {} if (aov_names or args.denoise) else None
    if not args.info:   # every file this run writes, checked before anything is rendered
        for path in [output, rate_path(output)] + ([denoised_path(output)] if args.denoise
                                                   else []):
            check_output_path(path)
        # the numbers, before the scene is read (Settings and the frame check again in render)
        Settings(spp=args.spp, light_samples=args.light_samples, max_depth=args.max_depth,
                 seed=args.seed, adaptive=args.adaptive)
        check_frame(*args.resolution, args.crop, features=aovs is not None, max_memory=budget)
    check_pointing(args)
    scene = load(args.scene, default_light=not args.no_default_light, max_memory=budget)
    if args.environment is not None:
        from .environment import load_environment
        scene = scene.with_environment(load_environment(args.environment, max_memory=budget))
    width, height = args.resolution
    camera = camera_from_flags(scene, args, width, height)
    if args.info:
        print(json.dumps(scene_info(scene, camera), indent=2))
        return 0
    if args.dashboard and args.workers is None:
        raise PtraceError("--dashboard needs --workers (a local cluster)")
    stats = {}
    client = cluster = None
    with contextlib.ExitStack() as scope:   # left after the client's shutdown
        try:
            if args.workers is not None or args.scheduler is not None:
                from . import distributed
                # the CLI owns the process: keep Dask's Ctrl-C race out of the user's terminal
                # from here until the client is closed (a library render scopes it to itself)
                scope.enter_context(distributed.dropping_the_sync_cancel_race())
                if args.workers is not None:
                    client, cluster = distributed.local_client(args.workers, args.dashboard)
                else:
                    client = distributed.connect(args.scheduler)
                workers = len(client.scheduler_info()["workers"])
                dashboard = f", dashboard {client.dashboard_link}" if args.dashboard else ""
                print(f"ptrace: rendering on {workers} Dask workers at "
                      f"{client.scheduler.address}{dashboard}", file=sys.stderr, flush=True)
            image = render(scene, spp=args.spp, accel=args.accel, integrator=args.integrator,
                           resolution=(width, height), seed=args.seed, threads=args.threads,
                           crop=args.crop, camera=camera,
                           progress=not args.quiet and sys.stderr.isatty(), stats=stats,
                           client=client, light_samples=args.light_samples,
                           max_depth=args.max_depth, adaptive=args.adaptive,
                           hemisphere=args.hemisphere, direct=args.direct, sampler=args.sampler,
                           light_sampler=args.light_sampler,
                           bvh_split=args.bvh_split, notice=None if args.quiet else _notice,
                           aovs=aovs, max_memory=budget)
            images = [dict(path=output, radiance=image,
                           extra=[(name, aovs[name]) for name in aov_names]),
                      dict(path=rate_path(output),
                           eight_bit=rate_colours(stats["samples"] / args.spp))]
            if args.denoise:
                images.append(dict(path=denoised_path(output),
                                   radiance=denoise(image, aovs["albedo"], aovs["normal"])))
            write_images(images)   # all of them or none
        finally:
            if client is not None:
                distributed.shutdown(client, cluster)
    seconds, build_seconds = stats["render_seconds"], stats["build_seconds"]
    phases = stats.get("phases", {})
    if "compile" in phases:   # in-process: the summary's seconds leave numba's compiler out
        seconds = phases["records"] + phases["render"]
        build_seconds = phases["build"]
        if stats["counts"].get("compiled", 0) and not args.quiet:
            print(f"ptrace: compiled kernels in {phases['compile']:.1f} s (cached for the next "
                  f"runs)", file=sys.stderr)
    mean_spp = stats["samples"].mean()
    where = f"workers {stats['workers']} " if "workers" in stats else ""
    split = f" split {args.bvh_split}" if args.bvh_split != "mean" else ""
    print(f"{image.shape[1]}x{image.shape[0]} spp {args.spp} (mean {mean_spp:.1f}) "
          f"{where}accel {args.accel}{split} build {build_seconds:.3f} s render {seconds:.3f} s "
          f"rays {stats['rays']} ({stats['rays'] / max(seconds, 1e-9):,.0f} rays/s) "
          f"non-finite samples dropped {stats['nonfinite']} -> {os.path.abspath(output)}")
    if args.denoise:
        print(f"denoised by Open Image Denoise (biased) -> "
              f"{os.path.abspath(denoised_path(output))}")
    if not args.quiet:   # what the loader ignored, changed or assumed (after the render, so that
        # an error stays the one line it promises to be)
        for line in grouped_notes(scene.notes):
            print(f"ptrace: note: {line}", file=sys.stderr)
    if stats["interrupted"]:
        print("ptrace: interrupted: wrote the samples rendered so far", file=sys.stderr)
        return EXIT_INTERRUPTED
    return 0


def main(argv=None):
    from .errors import PtraceError
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "view":   # `ptrace view SCENE [render flags]`: the browser preview
        from . import view
        return view.main(argv[1:])
    try:
        return run(argv)
    except (_UsageError, argparse.ArgumentTypeError) as error:
        print(f"ptrace: error: {error}", file=sys.stderr)
    except PtraceError as error:
        print(f"ptrace: error: {error}", file=sys.stderr)
    except KeyboardInterrupt:
        print("ptrace: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:   # `ptrace --info X | head`: the reader has gone, as with any tool
        try:
            sys.stdout = open(os.devnull, "w")   # so Python's exit flush does not fail again
        except OSError:
            pass
        return EXIT_BROKEN_PIPE
    except Exception as error:   # noqa: BLE001 - not the user's fault: a bug, told as one
        _internal_error(error)
        return EXIT_INTERNAL
    return EXIT_USAGE


def _internal_error(error):
    """A bug, not a user error: say so, with the traceback (its causes included, e.g. the one
    a Dask worker sent back), so that it can be reported and fixed."""
    print(f"ptrace: internal error: {type(error).__name__}: {error}", file=sys.stderr)
    traceback.print_exception(type(error), error, error.__traceback__, file=sys.stderr)
    print("ptrace: this is a bug in ptrace, not in your input or flags; please report it with "
          "the traceback above", file=sys.stderr, flush=True)


if __name__ == "__main__":
    sys.exit(main())
