"""The camera flags of `ptrace` (and, through ptrace.app.options.build_parser, of `ptrace view`):
-c's course camera file, --eye/--look-at/--up/--fov's pointed camera (ptrace.pointing),
--camera-index's file camera, -b/-d's thin lens, and the checks that refuse flags which do not
go together in one line. camera_from_flags is the one step both commands take after loading
the scene and adding -e's environment, so it also applies what -e and --no-default-light say
about a mesh file's default light."""
import argparse

import numpy as np


def _vector(name):
    """A parser of X,Y,Z: three finite numbers, for the flag `name`."""
    def parse(text):
        parts = text.split(",")
        try:
            values = [float(part) for part in parts]
        except ValueError:
            values = None
        if values is None or len(values) != 3 or not np.isfinite(values).all():
            raise argparse.ArgumentTypeError(f"{name} must be three finite numbers X,Y,Z, got "
                                             f"{text!r}")
        return tuple(values)
    return parse


# The narrowest --fov: a view this narrow frames a scene from about 57.3 / MIN_FOV = 5.7e10
# times its size away; narrower, from beyond 1e12 times (where float64 cannot place hits
# faithfully, ptrace.pointing's note) and, for a large scene, beyond ptrace.io.limits.LIMIT,
# which was refused as a focal distance (-d) that was never given
MIN_FOV = 1e-9


def _fov(text):
    try:
        value = float(text)
    except ValueError:
        value = None
    if value is None or not 0 < value < 180:
        raise argparse.ArgumentTypeError(f"--fov must be a number of degrees greater than 0 and "
                                         f"less than 180, got {text!r}")
    if value < MIN_FOV:
        raise argparse.ArgumentTypeError(
            f"--fov {text}: narrower than {MIN_FOV:g} degrees, the camera would stand more than "
            f"1e10 times the scene's size away to frame it (float64 cannot place hits that far "
            f"faithfully)")
    return value


VECTOR_FLAGS = ("--eye", "--look-at", "--up")
# flags whose value may start with '-' and is then refused for what it is (`-e -1,0,0` as a
# negative colour, `--max-memory -1G` as no size), not as argparse's "expected one argument"
ATTACHED_FLAGS = VECTOR_FLAGS + ("-e", "--environment", "--max-memory")
POINTING_NAMES = {"eye": "--eye", "target": "--look-at", "up": "--up", "fov": "--fov",
                  "index": "--camera-index"}


def attach_negative_vectors(argv):
    """argv with `--eye -1,2,3` (or `-e -1,0,0`) written `--eye=-1,2,3`: argparse takes a
    value that starts with '-' and is not a plain number for a flag, not for the vector it
    is."""
    out = list(argv)
    for i, token in enumerate(out[:-1]):
        if token in ATTACHED_FLAGS and out[i + 1][:2] in ("-0", "-1", "-2", "-3", "-4", "-5",
                                                        "-6", "-7", "-8", "-9", "-."):
            out[i] = f"{token}={out[i + 1]}"
            out[i + 1] = None
    return [token for token in out if token is not None]


# the camera flags, in --help's order: (flag, metavar, help)
CAMERA_FLAGS = (
    ("--eye", "X,Y,Z",
     "point a camera: stand it here (a pinhole on every scene kind; for -b and -d too)"),
    ("--look-at", "X,Y,Z",
     "with --eye: the point at the image's centre (default: the centre of the scene's bounds)"),
    ("--up", "X,Y,Z",
     "the world's up, above the image's centre (default 0,1,0); without --eye, a mesh file's "
     "default camera takes it as the file's up (a Z-up file: 0,0,1, seen from -Y)"),
    ("--fov", "DEGREES",
     "the vertical field of view of --eye's camera (without --eye, of a mesh file's default "
     "camera), from the image's bottom edge to its top edge, 0 < DEGREES < 180 (default: the "
     "longer image side spans the scene camera's horizontal view at 800x600, 49.13434 degrees "
     "for a mesh file)"),
    ("--camera-index", "N",
     "render the file's own camera N (glTF cameras, counted from 0 in the file's node order; "
     "default: its first perspective camera, if it has one)"),
)


def add_camera_flags(parser):
    """--eye, --look-at, --up, --fov and --camera-index on `parser`."""
    kinds = {"--fov": _fov, "--camera-index": _index}
    for flag, metavar, text in CAMERA_FLAGS:
        kind = kinds[flag] if flag in kinds else _vector(flag)
        parser.add_argument(flag, type=kind, default=None, metavar=metavar, help=text)


def _index(text):
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < 0:
        raise argparse.ArgumentTypeError(f"--camera-index must be a whole number, 0 or more, "
                                         f"got {text!r}")
    return value


def check_pointing(args):
    """Refuse, before the scene is read, camera flags that do not go together: -c with
    --eye/--look-at/--up/--fov, --look-at without --eye, --up or --fov without --eye on a course
    scene (which keeps the course's camera), and an --eye, --look-at and --up that give no view."""
    from ..errors import PtraceError
    from ..pointing import is_course_path, view_axes
    given = [flag for flag, value in (("--eye", args.eye), ("--look-at", args.look_at),
                                      ("--up", args.up), ("--fov", args.fov)) if value is not None]
    if args.camera is not None and given:
        raise PtraceError(f"-c (a camera file) and {given[0]} both give the camera: use one")
    index = getattr(args, "camera_index", None)
    if index is not None and (given or args.camera is not None):
        raise PtraceError(f"--camera-index and {given[0] if given else '-c'} both give the "
                          f"camera: use one")
    if index is not None and is_course_path(args.scene):
        raise PtraceError("--camera-index: a course scene (.dae) keeps the course's camera; "
                          "file cameras are read from glTF files")
    if getattr(args, "no_default_light", False) and is_course_path(args.scene):
        raise PtraceError("--no-default-light: a course scene (.dae) has no default light (its "
                          "lights are the file's)")
    if args.look_at is not None and args.eye is None:
        raise PtraceError("--look-at needs --eye (where the camera stands)")
    if args.eye is None and given and is_course_path(args.scene):
        raise PtraceError(f"{given[0]} without --eye: a course scene (.dae) keeps the course's "
                          f"camera; give --eye to point one")
    if args.eye is not None and args.look_at is not None:
        view_axes(args.eye, args.look_at, args.up, POINTING_NAMES)


def camera_from_flags(scene, args, width, height):
    """The camera the flags give (-c, --eye/--look-at/--up/--fov, --camera-index, -b/-d) at
    width x height, or the scene's default camera (ptrace.pointing.default_camera). First, a
    mesh file's default light is dropped from the scene when -e gave it an environment or
    --no-default-light is given (its note says so)."""
    from ..camera import load_camera_settings
    from ..io.default_light import without_default_light
    from ..pointing import (
        default_camera,
        file_camera,
        file_camera_notes,
        first_perspective,
        framing_camera,
        is_course_scene,
        look_at,
        reach_note,
    )
    if not is_course_scene(scene):
        if getattr(args, "no_default_light", False):
            without_default_light(scene, "--no-default-light")
        elif scene.environment is not None:
            without_default_light(scene, "-e's environment lights the scene in its place")
    index = getattr(args, "camera_index", None)
    file_index = None
    if args.camera is not None:
        camera = load_camera_settings(args.camera, width, height)
    elif args.eye is not None:
        camera = look_at(scene, args.eye, args.look_at, args.up, args.fov, width, height,
                                names=POINTING_NAMES)
    elif args.up is not None or args.fov is not None:   # a mesh file (check_pointing)
        camera = framing_camera(scene, width, height, args.up, args.fov, names=POINTING_NAMES)
    elif index is not None:
        camera = file_camera(scene, index, width, height, names=POINTING_NAMES)
        file_index = index
    else:
        camera = default_camera(scene, width, height)
        if not is_course_scene(scene):
            file_index = first_perspective(scene)
    if file_index is not None:
        scene.notes.extend(file_camera_notes(scene, file_index, width, height))
    if args.lens_radius is not None or args.focal_distance is not None:
        camera = camera.with_lens(args.lens_radius, args.focal_distance)
    for note in (up_note(scene, args.up), reach_note(scene, camera)):
        if note is not None:
            scene.notes.append(note)
    return camera


def up_note(scene, up):
    """The note that --up turns the camera and not the lights that are about world +Y (the
    ambient light's hemisphere, -e's sky), when up is not +Y and the scene has such a light."""
    from ..pointing import Y_UP, unit
    from ..scene import AMBIENT, ENVIRONMENT
    if up is None or unit(up, "--up") @ np.array(Y_UP) > 1 - 1e-12:
        return None
    kinds = set(np.asarray(scene.lights.kind).tolist())
    which = [what for kind, what in ((AMBIENT, "the ambient light's hemisphere"),
                                     (ENVIRONMENT, "-e's environment")) if kind in kinds]
    if not which:
        return None
    return (f"--up turns the camera, not the lighting: {' and '.join(which)} "
            f"{'stays' if len(which) == 1 else 'stay'} about world +Y")
