"""The options of `ptrace` and `ptrace view`: their flags, the types that check each flag's
value, and the one path from parsed arguments to what a render needs (its Settings, the files it
may write, the scene and the camera), so that both commands read a flag alike and refuse a bad
one with the same line. Neither command imports the other for any of this.

A user's error (a bad flag, a PtraceError) ends in one line on stderr and exit code 2, never a
traceback; anything else is a bug in ptrace: `ptrace: internal error: ...`, the traceback, and
exit code 1 (guarded).
"""
import argparse
import os
import sys
import traceback
from dataclasses import dataclass

import numpy as np

EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141   # 128 + SIGPIPE, as a shell reports a writer whose reader left


class UsageError(Exception):
    """A bad flag or flag value: told as one line, exit code 2."""


class Parser(argparse.ArgumentParser):
    def error(self, message):   # one line, not argparse's usage block
        raise UsageError(message)


# --- the types of the flags' values ------------------------------------------------------

def int_at_least(name, minimum, maximum=None):
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


def int_range(name, setting):
    """A parser of the integer setting `setting` in its ptrace.rendering.settings.RANGES range."""
    from ..rendering.settings import RANGES
    return int_at_least(name, *RANGES[setting])


def range_text(setting):
    """The range of the integer setting `setting`, as the help says it."""
    from ..rendering.settings import RANGES
    low, high = RANGES[setting]
    return f"{low} to {high:,}".replace(",", "_") if high > 10 ** 6 else f"{low} to {high}"


def positive_int(name):
    return int_at_least(name, 1)


def nonnegative_int(name):
    return int_at_least(name, 0)


def positive_float(name):
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not value > 0 or not np.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name} must be a positive number, got {text}")
        return value
    return parse


def length(name, positive):
    """A parser of a length for the flag `name`: a finite number > 0 (positive) or >= 0, of at
    most ptrace.io.limits.LIMIT (larger ones overflow what the camera's rays are made of)."""
    from ..io.limits import LIMIT

    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not (value > 0 if positive else value >= 0) or not value <= LIMIT:
            raise argparse.ArgumentTypeError(
                f"{name} must be a number {'greater than' if positive else 'from'} 0 "
                f"{'and at most' if positive else 'to'} {LIMIT:g}, got {text}")
        return value
    return parse


def define(text):
    """-D's NAME=VALUE: a Mitsuba scene's $NAME and its value, as (name, value)."""
    import re
    name, equals, value = text.partition("=")
    if not equals or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise argparse.ArgumentTypeError(f"-D must be NAME=VALUE with NAME a name of letters, "
                                         f"digits and _, got {text!r}")
    return name, value


def size(text):
    """A memory size such as 4G or 512M, in bytes (ptrace.budget.parse_size)."""
    from ..budget import parse_size
    from ..errors import PtraceError
    try:
        return parse_size(text)
    except PtraceError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


# --- the flags -----------------------------------------------------------------------------

DESCRIPTION = ("Render a CS184 COLLADA scene (or a mesh file) with a path tracer whose ray "
               "intersection is naive, a BVH, or Embree.")


def build_parser(prog="ptrace", description=DESCRIPTION):
    """The parser of `ptrace`'s flags (`ptrace view` adds its own to the same)."""
    import accel

    from ..codes import AUTO_EVERY_LIGHT, AUTO_MANY
    from ..rendering.renderer import MAX_SIDE, PIXEL_BYTES
    from ..rendering.settings import (
        BVH_SPLITS,
        DIRECT,
        GUIDING,
        INTEGRATORS,
        LIGHT_SAMPLER_CODES,
        LIGHT_SAMPLERS,
        SAMPLERS,
    )
    from .cli_camera import add_camera_flags
    many = next(name for name, code in LIGHT_SAMPLER_CODES.items() if code == AUTO_MANY)
    parser = Parser(prog=prog, description=description)
    add = parser.add_argument
    add("scene", help="scene file: .dae (CS184 COLLADA) or .obj .ply .stl .glb .gltf")
    add("-t", "--threads", type=positive_int("threads"), default=None,
        help="render threads (default: all cores; with --workers or --scheduler, threads per "
             "task on each worker, default its share of its machine's cores)")
    add("-s", "--spp", type=int_range("samples per pixel (-s)", "spp"), default=None,
        help=f"camera rays per pixel, {range_text('spp')} (default 1, or a Mitsuba scene's "
             f"sample_count)")
    add("-l", "--light-samples", type=int_range("light samples (-l)", "light_samples"),
        default=1, help=f"samples per area light per shading point, "
                        f"{range_text('light_samples')} (default 1)")
    add("-m", "--max-depth", type=int_range("max depth (-m)", "max_depth"), default=None,
        help=f"maximum ray depth, {range_text('max_depth')} (default 1, or a Mitsuba scene's "
             f"max_depth - 1)")
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
    add("--guiding", choices=GUIDING, default="off",
        help="path guiding: on (training passes, up to a quarter of -s and at most 32, learn "
             "where light comes from; the rest sample bounces from the guide and the BSDF), "
             "auto (2 unguided samples first; on where their bounces could gain from a "
             "guide, their headroom above 32, and training lowers the variance) or off (the "
             "default); "
             "in-process renders of the path integrator without -H or -a")
    add("-r", "--resolution", nargs=2, type=int_at_least("resolution (-r)", 1, MAX_SIDE),
        metavar=("W", "H"), default=None,
        help=f"image size, 1 to {MAX_SIDE} per side and the image buffers (about "
             f"{PIXEL_BYTES} bytes a pixel) within --max-memory; a course scene's "
             f"camera (and -c's) keeps the focal length, so it crops; a mesh file's default "
             f"camera and --eye's frame the view at any size (default 800 600, or a Mitsuba "
             f"scene's film)")
    add("-f", "--output", default=None, metavar="FILE",
        help="output image, .png (the course's 8-bit curve) or .exr (linear float); "
             "default SCENE_NAME.png in the current directory")
    add("-p", "--crop", nargs=4, type=nonnegative_int("crop"), metavar=("X", "Y", "DX", "DY"),
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
    add("-b", "--lens-radius", type=length("the lens radius (-b)", positive=False),
        default=None, metavar="R",
        help="thin-lens aperture radius (the course's 3-2 -b; default 0: a pinhole, or the -c "
             "file's lensRadius)")
    add("-d", "--focal-distance", type=length("the focal distance (-d)", positive=True),
        default=None, metavar="D",
        help="thin-lens focal distance along the view axis (the course's -d; default 4.7, or "
             "the -c file's focalDistance, or for --eye and a mesh file's default camera the "
             "distance to the point looked at)")
    add("--accel", choices=accel.KINDS, default="bvh",
        help="ray intersection backend (default bvh)")
    add("--bvh-split", choices=BVH_SPLITS, default="mean",
        help="with --accel bvh: mean (split at the mean centroid; default) or sah "
             "(binned surface area heuristic)")
    add("--seed", type=int_range("seed (--seed)", "seed"), default=0,
        help=f"random seed, {range_text('seed')} (default 0)")
    add("--integrator", choices=INTEGRATORS, default="path",
        help="path (light transport) or normals (the course's normal shading)")
    add("--aov", default=None, metavar="LIST",
        help="feature buffers to add to an .exr output as extra channels, any of albedo, normal, "
             "depth (first hit, averaged per pixel like the radiance; one more ray per sample)")
    add("--denoise", action="store_true",
        help="also write FILE_denoised (Intel Open Image Denoise guided by the albedo and "
             "normal AOVs; biased, so the noisy image is kept; needs pip install "
             "\"ptrace[denoise]\")")
    add("--max-memory", type=size, default=None, metavar="SIZE",
        help="memory budget, e.g. 4G or 512M: a scene whose triangles after instancing, "
             "textures, environment map and image buffers are estimated to need more is "
             "refused before they are allocated (default: half the machine's memory, or 3/4 of "
             "what a ulimit -v leaves)")
    add("-D", dest="defines", action="append", type=define, default=None,
        metavar="NAME=VALUE",
        help="a Mitsuba scene's $NAME is VALUE, ahead of the file's <default> (as mitsuba's "
             "-D); may be given more than once")
    add("--info", action="store_true", help="print a JSON summary of the scene and exit")
    add("-q", "--quiet", action="store_true",
        help="no progress bar, compile notice or notes of what the loader ignored or assumed")
    dist = parser.add_argument_group("distributed rendering (needs: pip install \"ptrace[dist]\")")
    where = dist.add_mutually_exclusive_group()
    where.add_argument("--workers", type=positive_int("workers"), default=None, metavar="N",
                       help="render on a local Dask cluster of N worker processes (127.0.0.1)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="render on an existing Dask cluster, e.g. tcp://host:8786 or tls://")
    dist.add_argument("--dashboard", action="store_true",
                      help="with --workers: serve Dask's dashboard on 127.0.0.1:8787")
    return parser


# the values of -s, -m and -r when neither the command line nor the scene gives them
FALLBACKS = {"spp": 1, "max_depth": 1, "resolution": (800, 600)}


def parse(parser, argv):
    """The arguments of argv (a vector flag's negative value attached: `--eye -1,2,3`), -a's
    two words read as (batch, tolerance)."""
    from .cli_camera import attach_negative_vectors
    args = parser.parse_args(attach_negative_vectors(argv))
    check_numbers(args)
    # the flags given, which a scene's own render settings never override (scene_defaults)
    args.given = {name for name in FALLBACKS if getattr(args, name, None) is not None}
    for name, value in FALLBACKS.items():
        if getattr(args, name, None) is None:
            setattr(args, name, value)
    if args.adaptive is not None:
        batch = int_range("adaptive batch (-a)", "spp")(args.adaptive[0])
        tolerance = positive_float("adaptive tolerance")(args.adaptive[1])
        args.adaptive = (batch, tolerance)
    return args


def check_numbers(args):
    """Refuse, in one line naming the flag, a vector flag (--eye, --look-at, --up) or -e's
    colour whose numbers are finite but beyond ptrace.io.limits.LIMIT (the camera's distance
    and every sample would overflow: a black image), and -e's empty file name."""
    from ..io.limits import problem
    for flag, name in (("--eye", "eye"), ("--look-at", "look_at"), ("--up", "up")):
        value = getattr(args, name, None)
        words = None if value is None else problem(value)
        if words is not None:
            raise UsageError(f"{flag} {','.join(f'{v:g}' for v in value)}: {words}")
    text = getattr(args, "environment", None)
    if text is None:
        return
    if not text.strip():
        raise UsageError("-e: the environment is empty: give an image file or a colour R,G,B")
    try:
        colour = [float(part) for part in text.split(",")]
    except ValueError:
        return   # a file name
    words = problem(colour)
    if words is None and min(colour) < 0.0:
        words = f"{min(colour):g} is negative (a colour is at least 0)"
    if words is not None:
        raise UsageError(f"-e {text}: the environment's colour: {words}")


# --- from the arguments to a render --------------------------------------------------------

@dataclass
class Plan:
    """What the flags ask of a render, checked before the scene is read: settings (None with
    --info, which renders nothing), the budget, the image path (-f or SCENE_NAME.png), the
    files the command may write (each checked writable), the AOVs asked for and the bytes of
    the image buffers."""
    settings: object
    budget: object
    output: str
    files: list
    aov_names: tuple
    buffers: int


def settings_of(args):
    """The Settings of the parsed flags."""
    from ..rendering.settings import Settings
    return Settings.from_options(
        spp=args.spp, accel=args.accel, integrator=args.integrator, seed=args.seed,
        light_samples=args.light_samples, max_depth=args.max_depth, adaptive=args.adaptive,
        hemisphere=args.hemisphere, direct=args.direct, sampler=args.sampler,
        light_sampler=args.light_sampler, bvh_split=args.bvh_split,
        guiding=getattr(args, "guiding", "off"),
        hide_emitters=getattr(args, "hide_emitters", False),
        **({"rr_depth": args.rr_depth} if getattr(args, "rr_depth", None) else {}))


def plan(args, files_of):
    """Check the flags before the scene is read: the output's format, --aov's names (they need
    an .exr output), --denoise's library, every file files_of(output) says the command may
    write, the settings and the image buffers against --max-memory (with --denoise or --aov,
    the AOVs' buffers too); with --info only the output's format and --aov. Returns a Plan."""
    from ..budget import Budget
    from ..errors import PtraceError
    from ..features import require_denoiser
    from ..image import FORMATS, check_output_path
    from ..rendering.renderer import check_frame
    budget = Budget.of(args.max_memory)     # one budget: the scene, -e and the render
    output = args.output
    if output is None:
        output = os.path.splitext(os.path.basename(args.scene))[0] + ".png"
    if os.path.splitext(output)[1].lower() not in FORMATS:
        raise PtraceError(f"{output}: output must end in {' or '.join(FORMATS)}")
    aov_names = ()
    if args.aov is not None:
        from ..features import parse_aovs
        try:
            aov_names = parse_aovs(args.aov)
        except ValueError as error:
            raise UsageError(str(error)) from None
        if not output.lower().endswith(".exr"):
            raise PtraceError(f"{output}: --aov adds channels to an .exr output; use -f "
                              f"NAME.exr")
    if args.denoise:
        require_denoiser()
    files = list(files_of(output))
    settings, buffers = None, 0
    if not args.info:   # every file the command may write, checked before anything is rendered
        for path in files:
            check_output_path(path)
        settings = settings_of(args)
        buffers = check_frame(*args.resolution, args.crop,
                              features=bool(aov_names or args.denoise), max_memory=budget)
    return Plan(settings, budget, output, files, aov_names, buffers)


def scene_defaults(args, scene):
    """Take the scene's own render settings (Scene.render_defaults: a Mitsuba scene's film,
    sampler, integrator and thin lens) for -r, -s, -m, the roulette depth, -b and -d where the
    command line did not give them (args.given; -b and -d: None). Returns whether any was taken."""
    defaults = getattr(scene, "render_defaults", None) or {}
    given = getattr(args, "given", set(FALLBACKS))
    taken = False
    for name in ("resolution", "spp", "max_depth", "rr_depth"):
        if name in defaults and name not in given:
            setattr(args, name, tuple(defaults[name]) if name == "resolution" else
                    defaults[name])
            taken = True
    if defaults.get("hide_emitters"):       # (no flag: the file's own)
        args.hide_emitters = True
        taken = True
    for name in ("lens_radius", "focal_distance"):     # a Mitsuba thinlens's, for -b and -d
        if name in defaults and getattr(args, name, None) is None:
            setattr(args, name, defaults[name])
            taken = True
    return taken


def scene_and_camera(args, budget, job=None):
    """The scene of the flags (its file, -e's environment, a mesh file's default light unless
    --no-default-light) and the camera they give at -r's size (ptrace.app.cli_camera). The
    scene's own render settings fill in -r, -s and -m where they were not given
    (scene_defaults); job (the Plan) then gets the settings and buffers of the result."""
    from .. import load
    from .cli_camera import camera_from_flags, check_pointing
    check_pointing(args)
    scene = load(args.scene, default_light=not args.no_default_light, max_memory=budget,
                 defines=dict(getattr(args, "defines", None) or ()))
    if scene_defaults(args, scene) and job is not None and job.settings is not None:
        from ..rendering.renderer import check_frame
        job.settings = settings_of(args)
        job.buffers = check_frame(*args.resolution, args.crop,
                                  features=bool(job.aov_names or args.denoise),
                                  max_memory=budget)
    black = False
    if args.environment is not None:
        from ..environment import load_environment
        environment = load_environment(args.environment, max_memory=budget)
        black = not environment.image.max() > 0.0
        scene = scene.with_environment(environment)
    width, height = args.resolution
    camera = camera_from_flags(scene, args, width, height)   # (it drops the default light)
    if black:
        scene.notes.append(_black_environment_note(scene, args.environment))
    note = sight_note(scene, camera)
    if note is not None:
        scene.notes.append(note)
    return scene, camera


def _black_environment_note(scene, spec):
    """The note for an -e that is black everywhere (-e 0,0,0, or an image of zeros): it lights
    nothing, and when nothing else does either the image is black (the renderer's own warning
    for a scene without light does not see it, as the environment is a light)."""
    from ..scene import ENVIRONMENT
    emitters = np.isin(scene.material_index, np.nonzero(scene.materials.emits())[0]).any()
    alone = not (scene.lights.kind != ENVIRONMENT).any() and not emitters
    return (f"-e {spec}: the environment is black everywhere: it lights nothing"
            + ("; the scene has no other light and no emissive surface: the image will be "
               "black" if alone else ""))


# a lens radius more than this many times the focal distance gets sight_note's note
LENS_RATIO = 1e6
# how many times the scene's size a camera (or its lens's edge) may be from it: float64 rounds
# a hit point that far away by 1e-4 of the scene's size (its 2^-53 relative precision), beyond
# which nothing of it can be rendered faithfully
FARTHEST = 1e12


def sight_note(scene, camera):
    """A note when the camera shows nothing of the scene although every number is within
    range: the scene's bounds all behind it, all outside the image, or spanning less than a
    pixel; or the camera (or its lens's edge) more than FARTHEST times the bounds' size away.
    None when the scene is in view (or has no bounds)."""
    bounds = scene.bounds()
    if bounds is None:
        return None
    lower, upper = (np.asarray(b, dtype=np.float64) for b in bounds)
    corners = np.array([[(lower, upper)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    size = float(np.linalg.norm(upper - lower))
    distance = float(np.linalg.norm(corners - camera.position, axis=1).max())
    reach = max(distance, float(camera.lens_radius))
    what = "the camera shows nothing of the scene"
    if size > 0 and reach > FARTHEST * size:
        by = "its lens's edge is" if camera.lens_radius > distance else "it is"
        return (f"{what}: {by} {reach:.3g} from the scene's bounds, {reach / size:.2g} times "
                f"their size (more than {FARTHEST:g} times: float64 cannot place hits that "
                f"far faithfully)")
    radius, focus = float(camera.lens_radius), float(camera.focal_distance)
    if radius > LENS_RATIO * focus:
        # a ray from the lens at r from its centre through the focus leaves atan(focus / r)
        # from the lens's plane: more than 1e-3 of it only for r < 1e3 focus, a share of the
        # disc's area below (1e3 focus / radius)^2 < 1e-6
        return (f"the lens radius (-b) {radius:g} is more than {LENS_RATIO:g} times the focal "
                f"distance {focus:g}: all but a millionth of the lens's rays leave within 0.06 "
                f"degrees of its plane: the image is all but black unless the scene lies in "
                f"that plane")
    px, py, depth = camera.project(corners)
    if not (depth > 0).any():
        return f"{what}: the scene's bounds are all behind the camera"
    if not (depth > 0).all():
        return None    # the camera among the bounds: something is in view
    if px.max() < 0 or px.min() > camera.width or py.max() < 0 or py.min() > camera.height:
        return f"{what}: the scene's bounds are all outside the image"
    span = max(px.max() - px.min(), py.max() - py.min())
    if span < 1.0:
        return (f"{what}: its bounds span {span:.2g} of a pixel in the image ({distance:.3g} "
                f"away, {size:.3g} across)")
    return None


# --- the end of a command ------------------------------------------------------------------

def guarded(command, interrupted="interrupted"):
    """command()'s exit code, or the one of what it raised: a user's error as one line and 2,
    Ctrl-C as `ptrace: <interrupted>` and 130, a reader that left (`ptrace --info X | head`)
    as 141, and anything else as a bug (internal_error) and 1."""
    from ..errors import PtraceError
    try:
        return command()
    except (UsageError, argparse.ArgumentTypeError, PtraceError) as error:
        print(f"ptrace: error: {error}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"ptrace: {interrupted}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:   # the reader has gone, as with any tool
        try:
            sys.stdout = open(os.devnull, "w")   # so Python's exit flush does not fail again
        except OSError:
            pass
        return EXIT_BROKEN_PIPE
    except Exception as error:   # noqa: BLE001 - not the user's fault: a bug, told as one
        internal_error(error)
        return EXIT_INTERNAL


def internal_error(error):
    """A bug, not a user error: say so, with the traceback (its causes included, e.g. the one
    a Dask worker sent back), so that it can be reported and fixed."""
    print(f"ptrace: internal error: {type(error).__name__}: {error}", file=sys.stderr)
    traceback.print_exception(type(error), error, error.__traceback__, file=sys.stderr)
    print("ptrace: this is a bug in ptrace, not in your input or flags; please report it with "
          "the traceback above", file=sys.stderr, flush=True)
