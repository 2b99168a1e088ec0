"""Cameras a user points (look_at: --eye, --look-at, --up, --fov) and the default camera
of a scene read from a mesh file (framing_camera), beside the course's (ptrace.camera).

A course scene (.dae) keeps the course's orbit camera and its crop rule (the focal length of the
800x600 view at any -r). A mesh file has no such rule to keep: its default camera looks at the
centre of the bounding box along the world's "front" direction and stands back just far enough
that the box's eight corners fill the frame at any resolution. --fov is the vertical field of
view (the full angle from the image's bottom edge to its top edge), as glTF's yfov, OpenGL's
gluPerspective and most viewers define it.
"""
import math

import numpy as np

from .camera import BASE_HEIGHT, BASE_WIDTH, Camera, course_camera, widen_to_base_aspect
from .errors import PtraceError, SceneError
from .io.limits import problem

Y_UP = (0.0, 1.0, 0.0)
# a mesh file's default camera: its longer image side spans the course's CB camera's horizontal
# field of view, so at 800x600 it has the course's 49.13434 x 37.849 degree view
FRAMING_FOV = 49.13434
# below this sine of the angle between up and the view direction, up gives no image "up"
PARALLEL_SINE = 1e-6
# a scene without a camera spec (built by hand): its camera rays' interval
DEFAULT_ZNEAR, DEFAULT_ZFAR = 0.001, 1e6
PYTHON_NAMES = {"eye": "eye", "target": "target", "up": "up", "fov": "fov", "index": "index"}
# -r's aspect and a file camera's differ when their ratio is farther from 1 than this
ASPECT_TOLERANCE = 1e-3


def is_course_path(path):
    """Whether a scene read from this path keeps the course's camera rule: every scene but one
    read from a mesh file or a Mitsuba scene (told by the extension, as ptrace.load picks its
    reader)."""
    from .io.meshes import MESH_EXTENSIONS
    return not str(path).lower().endswith(MESH_EXTENSIONS + (".xml",))


def is_course_scene(scene):
    return is_course_path(scene.path)


def default_camera(scene, width=BASE_WIDTH, height=BASE_HEIGHT):
    """The camera render() uses when given none: the course's (course_camera, which crops the
    800x600 view at another size) for a course scene; for a mesh file, its first perspective
    camera (file_camera) if it carries one, else framing_camera."""
    if is_course_scene(scene):
        return course_camera(scene, width, height)
    if first_perspective(scene) is not None:
        return file_camera(scene, None, width, height)
    return framing_camera(scene, width, height)


def first_perspective(scene):
    """The index in scene.file_cameras of its first perspective camera, or None."""
    return next((i for i, c in enumerate(getattr(scene, "file_cameras", ()))
                 if c.kind == "perspective"), None)


def file_camera(scene, index=None, width=BASE_WIDTH, height=BASE_HEIGHT, names=PYTHON_NAMES):
    """The pinhole camera of the file's camera `index` (scene.file_cameras; None: its first
    perspective camera) at width x height: its node's position and axes, its vertical field
    of view at any size (the width's view follows from width / height, not from the file's
    aspect ratio), rays from its znear to its zfar (no zfar: past the scene's bounds); the
    focal distance of with_lens is the depth of the bounds' centre, when it is in front.
    Raises PtraceError, naming `index` as names["index"], for an index the file does not have
    and for an orthographic camera, which ptrace cannot render."""
    width, height = _size(width, height)
    cameras = getattr(scene, "file_cameras", ())
    record = _file_camera_record(scene, index, names)
    if record.kind != "perspective":
        raise PtraceError(f"{names['index']} {index}: {scene.path}'s camera {index} "
                          f"({record.name!r}) is orthographic, which ptrace cannot render (its "
                          f"cameras are pinholes and thin lenses); pick a perspective one of its "
                          f"{len(cameras)} cameras or point one with --eye")
    axes = np.asarray(record.camera_to_world, dtype=np.float64)
    position = np.asarray(record.position, dtype=np.float64)
    focal = 0.5 * height / math.tan(math.radians(record.yfov) / 2)
    forward = -axes[:, 2]
    bounds = scene.bounds()
    depth = 1.0
    zfar = record.zfar
    if bounds is not None:
        lower, upper = (np.asarray(b, dtype=np.float64) for b in bounds)
        ahead = float((0.5 * (lower + upper) - position) @ forward)
        depth = ahead if ahead > 0 and math.isfinite(ahead) else \
            max(float(np.linalg.norm(upper - lower)), 1.0)
        if zfar is None:
            with np.errstate(over="ignore"):
                reach = np.linalg.norm(_corners(lower, upper) - position, axis=1).max()
            zfar = max(DEFAULT_ZFAR, 2 * float(reach))
    zfar = DEFAULT_ZFAR if zfar is None else zfar
    which = index if index is not None else first_perspective(scene)
    where = f"the file's camera {which} ({record.name!r}, on node {record.node})"
    target = position + depth * forward
    words = problem(np.append(target, depth))
    if words is not None:    # the loader checked its position; its focus is another number
        raise SceneError(scene.path, f"{where}: its focus, the centre of the scene's bounds "
                                     f"{depth:.4g} in front of it, {words}")
    try:
        return Camera(position, target, axes, float(focal), width, height,
                      float(record.znear), float(zfar), focal_distance=depth)
    except PtraceError as error:     # a number no check above foresaw: still the file's
        raise SceneError(scene.path, f"{where}: {error}") from None


def file_camera_notes(scene, index, width, height):
    """What the notes say about rendering the file's camera `index` (None: its first
    perspective one) at width x height: -r's aspect in place of a different one of the
    file's, and a zfar that cuts off part of the scene's bounds."""
    record = _file_camera_record(scene, index, PYTHON_NAMES)
    where = f"the file's camera {index if index is not None else first_perspective(scene)}"
    notes = []
    if record.aspect is not None and \
            abs(math.log(width / height / record.aspect)) > ASPECT_TOLERANCE:
        across = "more" if width / height > record.aspect else "less"
        notes.append(f"{where} ({record.name!r}) has the aspect ratio {record.aspect:.4g}; "
                     f"-r {width} {height} gives {width / height:.4g}: the image keeps its "
                     f"vertical field of view ({record.yfov:.4g} degrees) and shows {across} "
                     f"across than the file's")
    bounds = scene.bounds()
    if record.zfar is not None and bounds is not None:
        nearest, reach = _distances(bounds, record.position)
        if reach > record.zfar >= nearest:   # below nearest: reach_note says nothing is seen
            notes.append(f"{where} ({record.name!r}) stops its rays at its zfar {record.zfar:g}"
                         f", nearer than the far side of the scene's bounds ({reach:.4g}): "
                         f"what lies beyond is not seen")
    return notes


def _distances(bounds, position):
    """The distances from `position` to the nearest point of the box `bounds` (0 inside it)
    and to its farthest corner."""
    lower, upper = bounds
    with np.errstate(over="ignore", invalid="ignore"):
        outside = np.maximum(np.maximum(lower - position, position - upper), 0.0)
        nearest = float(np.linalg.norm(outside))
        reach = float(np.linalg.norm(_corners(lower, upper) - position, axis=1).max())
    return nearest, reach


def reach_note(scene, camera):
    """The note, naming the scene's file, when the camera's rays (from its znear to its zfar,
    unit directions, from its lens when it has one) cannot reach anything in the scene's
    bounds, so the image shows nothing of the scene; None when they can (or it is empty)."""
    bounds = scene.bounds()
    if bounds is None:
        return None
    nearest, reach = _distances(bounds, np.asarray(camera.position, dtype=np.float64))
    lens = float(camera.lens_radius)
    nearest, reach = max(0.0, nearest - lens), reach + lens
    where = f"{scene.path}: the camera" if getattr(scene, "path", None) else "the camera"
    if camera.znear > reach:
        return (f"{where} starts its rays at its znear {camera.znear:g}, beyond the far side of "
                f"the scene's bounds ({reach:.4g} away): the scene is not seen")
    if camera.zfar < nearest:
        return (f"{where} stops its rays at its zfar {camera.zfar:g}, nearer than the scene's "
                f"bounds ({nearest:.4g} away): the scene is not seen")
    return None


def _file_camera_record(scene, index, names):
    cameras = getattr(scene, "file_cameras", ())
    if index is None:
        index = first_perspective(scene)
        if index is None:
            raise PtraceError(f"{scene.path} has no perspective camera of its own")
    if not cameras:
        raise PtraceError(f"{names['index']} {index}: {scene.path} has no cameras of its own "
                          f"(glTF files can carry them)")
    if not (isinstance(index, (int, np.integer)) and 0 <= index < len(cameras)):
        which = "index 0" if len(cameras) == 1 else f"indices 0 to {len(cameras) - 1}"
        raise PtraceError(f"{names['index']} {index}: {scene.path} has {len(cameras)} "
                          f"camera{'s' if len(cameras) > 1 else ''} ({which})")
    return cameras[index]


def vector(value, name):
    """value as three finite float64 numbers, or a PtraceError naming it."""
    try:
        out = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        out = None
    if out is None or out.shape != (3,) or not np.isfinite(out).all():
        raise PtraceError(f"{name} must be three finite numbers (x, y, z), got {value!r}")
    return out


def unit(value, name, what="a direction"):
    """value (3 finite numbers) scaled to length 1, or a PtraceError if it is zero."""
    value = vector(value, name)
    largest = np.abs(value).max()
    if not largest > 0:
        raise PtraceError(f"{name} must be {what}, not (0, 0, 0)")
    scaled = value / largest   # no overflow or underflow in the norm
    return scaled / np.linalg.norm(scaled)


def _length(value):
    """|value| without overflow or underflow in the squares."""
    largest = float(np.abs(value).max())
    return largest * float(np.linalg.norm(value / largest)) if largest > 0 else 0.0


def axes_from(backward, up, names, what):
    """Camera-to-world axes (columns right, up, backward) for a camera whose view direction is
    -backward (unit) with `up` (unit) above the image's centre, or a PtraceError naming the
    flags in `what` when up is parallel to the view direction."""
    right = np.cross(up, backward)
    sine = np.linalg.norm(right)
    if not sine > PARALLEL_SINE:
        raise PtraceError(f"{names['up']} is parallel to the view direction ({what}), so it "
                          f"says nothing about which way is up in the image: give an up that "
                          f"points across the view")
    right = right / sine
    return np.stack([right, np.cross(backward, right), backward], axis=1)


def _focal(fov, height, names):
    """The focal length in pixels giving a vertical field of view of fov degrees."""
    if not (isinstance(fov, (int, float, np.integer, np.floating)) and 0 < fov < 180):
        raise PtraceError(f"{names['fov']} must be a number of degrees greater than 0 and less "
                          f"than 180, got {fov!r}")
    focal = 0.5 * height / math.tan(math.radians(fov) / 2)
    if not 0 < focal < math.inf:
        raise PtraceError(f"{names['fov']} {fov!r} is too small to give a finite focal length")
    return focal


def _size(width, height):
    for value in (width, height):
        if not (isinstance(value, (int, np.integer)) and value >= 1):
            raise PtraceError(f"a camera's width and height must be whole numbers of pixels, at "
                              f"least 1, got {width}x{height}")
    return int(width), int(height)


def _clip(scene):
    spec = scene.camera
    return (DEFAULT_ZNEAR, DEFAULT_ZFAR) if spec is None else (float(spec.znear),
                                                                float(spec.zfar))


def _bounds(scene):
    bounds = scene.bounds()
    if bounds is None:
        raise SceneError(scene.path, "the scene has no geometry to point the camera at")
    lower, upper = (np.asarray(b, dtype=np.float64) for b in bounds)
    return lower, upper


def _corners(lower, upper):
    return np.array([[(lower, upper)[i >> k & 1][k] for k in range(3)] for i in range(8)])


def look_at(scene, eye, target=None, up=Y_UP, fov=None, width=BASE_WIDTH, height=BASE_HEIGHT,
            names=PYTHON_NAMES):
    """A pinhole camera at `eye` looking at `target` (default: the centre of the scene's
    bounds), with the direction `up` (default +Y) above the image's centre, rendering width x
    height pixels. fov is the vertical field of view in degrees, 0 < fov < 180; None: the longer
    image side spans the horizontal field of view of the scene's default camera at 800x600 (the
    course file's hfov, widened to 4:3; 49.13434 degrees for a mesh file). Camera rays run from
    the scene camera's znear to its zfar, the latter extended if needed to reach past the
    scene's bounds; with_lens(radius) without a distance focuses at the target. Render it at its
    own size (render(scene, camera=...) without a resolution does): another resolution keeps its
    focal length in pixels, as for every Camera. Raises PtraceError, naming the value (names:
    how to call eye, target, up and fov in messages), for a number that is not finite, eye at
    the target, or up zero or parallel to the view."""
    width, height = _size(width, height)
    centre = None
    if target is None:
        lower, upper = _bounds(scene)
        centre = target = 0.5 * (lower + upper)
    eye, target, axes = view_axes(eye, target, up, names, centre is not None)
    if fov is None:
        focal = max(width, height) / (2 * _default_tan_long(scene))
    else:
        focal = _focal(fov, height, names)
    distance = _length(target - eye)
    znear, zfar = _clip(scene)
    bounds = scene.bounds()
    if bounds is not None:
        with np.errstate(over="ignore"):
            reach = np.linalg.norm(_corners(*bounds) - eye, axis=1).max()
        zfar = max(zfar, 2 * float(reach))
    return Camera(eye, target, axes, float(focal), width, height, znear, zfar,
                  focal_distance=distance)


def view_axes(eye, target, up=Y_UP, names=PYTHON_NAMES, centre=False):
    """(eye, target, camera-to-world axes) of a camera at eye looking at target with up above
    the image's centre, each checked: three finite numbers, eye not at target, up neither zero
    nor parallel to the view; a PtraceError names the value (centre: the target is the centre
    of the scene's bounds, not a value given)."""
    eye = vector(eye, names["eye"])
    target = vector(target, names["target"])
    with np.errstate(over="ignore"):
        view = target - eye
    if not np.abs(view).max() > 0:
        where = f"{names['eye']} is the centre of the scene's bounds, where the camera looks " \
                f"unless given {names['target']}" if centre else \
                f"{names['eye']} and {names['target']} are the same point"
        raise PtraceError(f"{where}: the camera has no direction to look in")
    if not np.isfinite(view).all():
        raise PtraceError(f"{names['eye']} and {names['target']} are too far apart to subtract")
    backward = unit(-view, names["eye"])
    axes = axes_from(backward, unit(Y_UP if up is None else up, names["up"]), names,
                     f"from {names['eye']} to " + ("the centre of the scene's bounds" if centre
                                                   else names["target"]))
    return eye, target, axes


def _default_tan_long(scene):
    """tan(half the default camera's horizontal field of view at 800x600)."""
    if is_course_scene(scene) and scene.camera is not None:
        hfov, _ = widen_to_base_aspect(scene.camera.hfov, scene.camera.vfov)
        return math.tan(math.radians(hfov) / 2)
    return math.tan(math.radians(FRAMING_FOV) / 2)


def front_for(up):
    """The direction a framing camera looks from, for a world whose up is `up` (unit): +Z (the
    glTF "front") turned by the smallest rotation that takes +Y to up; for up -Y, the half turn
    about +X. A Z-up file (--up 0,0,1) is seen from -Y, as Blender's front view sees it."""
    y = np.array(Y_UP)
    z = np.array([0.0, 0.0, 1.0])
    cosine = float(up @ y)
    if cosine < -1 + 1e-12:
        return -z
    axis = np.cross(y, up)   # R = I + [v]x + [v]x^2 / (1 + c), with v = y x up, c = y . up
    turned = z + np.cross(axis, z) + np.cross(axis, np.cross(axis, z)) / (1 + cosine)
    return turned / np.linalg.norm(turned)


def _face_normals(geometry, chunk=1 << 16):
    """The triangles' (unnormalised) normals, a chunk of triangles at a time."""
    vertices, faces = np.asarray(geometry.vertices), np.asarray(geometry.faces)
    for first in range(0, faces.shape[0], chunk):
        corners = vertices[faces[first:first + chunk]]
        yield np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])


def _face_on(scene, backward, up):
    """(backward, up) for a framing camera: as given, unless the scene is a flat model (triangles
    only, every one of them parallel to one plane) whose plane holds the view direction, which
    the camera would see edge-on as nothing. Then it looks from the plane's normal (the side of
    up, or else of backward), with up above the image's centre unless up is near that normal;
    then the old view's far side is at the image's top (a model lying flat under a Y-up camera
    is seen from above, its -Z side at the top)."""
    geometry = scene.geometry
    if geometry.faces.shape[0] == 0 or np.asarray(geometry.radii).shape[0] > 0:
        return backward, up
    total, along, longest, normal = 0.0, 0.0, -1.0, None
    for normals in _face_normals(geometry):
        lengths = np.linalg.norm(normals, axis=1)
        total += float(lengths.sum())
        along += float(np.abs(normals @ backward).sum())
        k = int(np.argmax(lengths))
        if lengths[k] > longest:      # the first longest face's normal, as argmax finds it
            longest, normal = float(lengths[k]), normals[k]
    if not total > 0.0 or along > 1e-9 * total:
        return backward, up
    normal = normal / longest
    across = sum(float(np.linalg.norm(np.cross(normals, normal), axis=1).sum())
                 for normals in _face_normals(geometry))
    if across > 1e-9 * total:
        return backward, up     # not flat: faces in several orientations, all edge-on (a fence)
    side = float(normal @ up)
    if abs(side) > 1e-12:
        normal = normal if side > 0 else -normal
    image_up = -backward if abs(float(normal @ up)) > 0.5 else up
    return normal, image_up


def framing_camera(scene, width=BASE_WIDTH, height=BASE_HEIGHT, up=Y_UP, fov=None,
                   names=PYTHON_NAMES):
    """A mesh file's default camera: looking at the centre of the scene's bounds from
    front_for(up) (the +Z side with +Y up), with up above the image's centre, just far enough
    away that the projections of the bounds' eight corners lie inside the width x height frame
    and touch its edge (on one axis, on at least one side). A flat model seen edge-on from there
    is seen from its plane's normal instead (_face_on). fov is the vertical field of view in
    degrees; None: the longer image side spans FRAMING_FOV. Camera rays run from the scene
    camera's znear (made smaller if needed to reach the nearest corner's depth) to its zfar
    (made larger if needed to reach past the farthest corner)."""
    width, height = _size(width, height)
    lower, upper = _bounds(scene)
    up = unit(Y_UP if up is None else up, names["up"])
    backward, view_up = _face_on(scene, front_for(up), up)
    axes = axes_from(backward, view_up, names, "the default camera's")
    if fov is None:
        focal = max(width, height) / (2 * math.tan(math.radians(FRAMING_FOV) / 2))
    else:
        focal = _focal(fov, height, names)
    centre = 0.5 * (lower + upper)
    local = (_corners(lower, upper) - centre) @ axes   # (x right, y up, z toward the camera)
    # a corner at depth D - z projects |x| focal / (D - z) pixels from the centre: it reaches
    # the frame's edge at D = z + |x| focal / (W / 2), and inside it for any larger D
    need = np.maximum(local[:, 2] + np.abs(local[:, 0]) * focal / (0.5 * width),
                      local[:, 2] + np.abs(local[:, 1]) * focal / (0.5 * height))
    distance = float(need.max())
    diagonal = float(np.linalg.norm(upper - lower))
    nearest = distance - float(local[:, 2].max())
    if not nearest > 1e-9 * max(diagonal, 1e-300):   # the box seen end on: a point or a line
        distance = float(local[:, 2].max()) + max(diagonal, 1.0)
        nearest = distance - float(local[:, 2].max())
    position = centre + distance * backward
    znear, zfar = _clip(scene)
    znear = min(znear, 0.5 * nearest)
    zfar = max(zfar, 2 * (distance + diagonal))
    return Camera(position, centre, axes, float(focal), width, height, znear, zfar,
                  focal_distance=distance)
