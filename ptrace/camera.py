"""The course's camera (docs/course.md#camera), its settings file (#camera-file), and
camera rays (#camera-rays).

The course ignores where the camera node is. It takes d, the direction from the world origin to
one unit in front of the camera, and places an orbit camera at the centre of the scene's bounding
box plus 1.5 times the box diagonal along d, looking at that centre with +Y up. The focal length in
pixels is fixed from the file's field of view at 800x600; another resolution keeps it, so a
W x H render is the central W x H window of the 800 x 600 view.
"""
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from .errors import PtraceError, SceneError, require_regular_file
from .io.limits import LIMIT, problem

BASE_WIDTH, BASE_HEIGHT = 800, 600
# how far a camera's axes may be from unit length and right angles (a file's rounding; the
# course writes six digits)
ROTATION_TOLERANCE = 1e-3
FOCAL_DISTANCE = 4.7   # the course's default -d (its -b defaults to 0.25 in 3-2; ours to 0)


@dataclass(frozen=True)
class Camera:
    position: np.ndarray        # (3,)
    target: np.ndarray          # (3,)
    camera_to_world: np.ndarray  # (3, 3): columns are the camera's x, y and z (backward) axes
    screen_dist: float          # focal length in pixels
    width: int
    height: int
    znear: float
    zfar: float
    # the thin lens (the course's -b and -d, Project 3-2 Part 4): rays leave a disc of this
    # radius about the position and meet on the plane focal_distance in front; 0 is a pinhole
    lens_radius: float = 0.0
    focal_distance: float = FOCAL_DISTANCE

    def __post_init__(self):
        radius, distance = float(self.lens_radius), float(self.focal_distance)
        if not 0.0 <= radius <= LIMIT:
            raise PtraceError(f"the lens radius (-b) must be a number from 0 to {LIMIT:g}, got "
                              f"{self.lens_radius!r}")
        if not 0.0 < distance <= LIMIT:
            raise PtraceError(f"the focal distance (-d) must be a number greater than 0 and at "
                              f"most {LIMIT:g}, got {self.focal_distance!r}")
        rotation = np.asarray(self.camera_to_world, dtype=np.float64)
        if rotation.shape != (3, 3) or not np.isfinite(rotation).all() or not np.allclose(
                rotation.T @ rotation, np.eye(3), atol=ROTATION_TOLERANCE) \
                or not np.linalg.det(rotation) > 0:
            raise PtraceError("the camera's rotation (camera-to-world) must be a rotation: "
                              "three unit axes at right angles, right-handed (a degenerate one "
                              "gives no rays)")
        for name in ("position", "target"):
            words = problem(getattr(self, name))
            if words is not None:
                raise PtraceError(f"the camera's {name}: {words}")
        if not 0 < float(self.screen_dist) < np.inf:
            raise PtraceError(f"the camera's screen distance must be a finite number > 0, got "
                              f"{self.screen_dist!r}")
        object.__setattr__(self, "lens_radius", radius)
        object.__setattr__(self, "focal_distance", distance)

    def with_lens(self, lens_radius=None, focal_distance=None):
        """This camera with a thin lens of that radius focused at that distance (either kept as
        it is when None)."""
        return replace(self, lens_radius=self.lens_radius if lens_radius is None else lens_radius,
                       focal_distance=self.focal_distance if focal_distance is None
                       else focal_distance)

    @property
    def hfov(self):
        return float(np.degrees(2 * np.arctan(self.width / (2 * self.screen_dist))))

    @property
    def vfov(self):
        return float(np.degrees(2 * np.arctan(self.height / (2 * self.screen_dist))))

    def resized(self, width, height):
        """Same focal length in pixels, another window (docs/course.md#focal-length)."""
        return replace(self, width=int(width), height=int(height))

    def project(self, points):
        """Image points (px, py) of world points (N, 3), y counted from the bottom, in pixels
        (the frame spans 0..width and 0..height), and their depths along the view axis (a
        point at depth <= 0 is not in front of the camera and its image point means nothing):
        the inverse of directions for the pinhole."""
        local = (np.asarray(points, dtype=np.float64).reshape(-1, 3)
                 - np.asarray(self.position, dtype=np.float64)) @ self.camera_to_world
        depth = -local[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            px = 0.5 * self.width + self.screen_dist * local[:, 0] / depth
            py = 0.5 * self.height + self.screen_dist * local[:, 1] / depth
        return px, py, depth

    def directions(self, px, py):
        """World directions (unit) through image points (px, py); y counted from the bottom
        (the pinhole's: from the position, whatever the lens)."""
        px = np.ascontiguousarray(px, dtype=np.float64)
        py = np.ascontiguousarray(py, dtype=np.float64)
        out = np.empty(px.shape + (3,))
        _directions(px.reshape(-1), py.reshape(-1), 0.5 * self.width, 0.5 * self.height,
                    self.screen_dist, np.ascontiguousarray(self.camera_to_world, dtype=np.float64),
                    out.reshape(-1, 3))
        return out


@njit(cache=True)   # serial: a prange loop's parallel lowering costs seconds of compile
def _directions(px, py, half_width, half_height, screen_dist, camera_to_world, out):
    # (2u - 1) tan(hfov / 2) with u = px / W is (px - W/2) / screen_dist; written this way a
    # pixel of a W x H window gets bit-identical rays to the same pixel of the 800 x 600 view.
    # A kernel rather than numpy: per-pixel arithmetic in one pass, no temporaries.
    m = camera_to_world
    for i in range(px.shape[0]):
        sx = (px[i] - half_width) / screen_dist
        sy = (py[i] - half_height) / screen_dist
        x = sx * m[0, 0] + sy * m[0, 1] - m[0, 2]
        y = sx * m[1, 0] + sy * m[1, 1] - m[1, 2]
        z = sx * m[2, 0] + sy * m[2, 1] - m[2, 2]
        norm = np.sqrt(x * x + y * y + z * z)
        out[i, 0] = x / norm
        out[i, 1] = y / norm
        out[i, 2] = z / norm


def look_at(position, target):
    """Camera-to-world axes looking from position at target with +Y up (the course's rule)."""
    backward = position - target
    backward = backward / np.linalg.norm(backward)
    up = np.array([0.0, 1.0, 0.0])
    right = np.cross(up, backward)
    if np.linalg.norm(right) < 1e-12:   # looking straight up or down: any right will do
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(backward, right), backward], axis=1)


def widen_to_base_aspect(hfov_degrees, vfov_degrees):
    """Widen (hfov, vfov) to 4:3 along whichever axis is too narrow; return both in degrees."""
    tan_h = np.tan(np.radians(hfov_degrees) / 2)
    tan_v = np.tan(np.radians(vfov_degrees) / 2)
    aspect = BASE_WIDTH / BASE_HEIGHT
    if tan_h / tan_v > aspect:
        tan_v = tan_h / aspect
    else:
        tan_h = tan_v * aspect
    return np.degrees(2 * np.arctan(tan_h)), np.degrees(2 * np.arctan(tan_v))


def course_camera(scene, width=BASE_WIDTH, height=BASE_HEIGHT):
    """The camera the course builds for this scene (docs/course.md#orbit-camera)."""
    spec = scene.camera
    bounds = scene.bounds()
    if spec is None:
        raise SceneError(scene.path, "the scene has no camera")
    if bounds is None:
        raise SceneError(scene.path, "the scene has no geometry to point the camera at")
    lower, upper = bounds
    target = 0.5 * (lower + upper)
    radius = 1.5 * float(np.linalg.norm(upper - lower))
    view = np.asarray(spec.view_point, dtype=np.float64)
    if not np.linalg.norm(view) > 0:
        raise SceneError(scene.path, "the camera looks from the world origin at itself "
                                     "(its view point is the origin), so it has no direction")
    d = view / np.linalg.norm(view)
    phi = np.arccos(np.clip(d[1], -1.0, 1.0))
    theta = np.arctan2(d[0], d[2])
    position = target + radius * np.array([np.sin(phi) * np.sin(theta), np.cos(phi),
                                           np.sin(phi) * np.cos(theta)])
    _, vfov = widen_to_base_aspect(spec.hfov, spec.vfov)
    screen_dist = BASE_HEIGHT / (2 * np.tan(np.radians(vfov) / 2))
    camera = Camera(position, target, look_at(position, target), float(screen_dist),
                    BASE_WIDTH, BASE_HEIGHT, float(spec.znear), float(spec.zfar))
    return camera.resized(width, height)


def load_camera_settings(path, width, height):
    """Read the course's camera settings file (the `D` key's dump, docs/course.md#camera-file)."""
    require_regular_file(path, "camera settings file")
    try:
        with open(path) as handle:
            numbers = np.array(handle.read().split(), dtype=np.float64)
    except OSError as error:
        raise PtraceError(f"{path}: cannot read camera settings ({error.strerror})") from None
    except ValueError:
        raise PtraceError(f"{path}: camera settings must be whitespace-separated numbers") from None
    if numbers.size < 28:
        raise PtraceError(f"{path}: camera settings need at least 28 numbers "
                          f"(hFov vFov aspect near far / pos target / phi theta r minR maxR / "
                          f"3x3 rotation / screenW screenH screenDist), found {numbers.size}")
    if not np.isfinite(numbers[:30]).all():
        raise PtraceError(f"{path}: camera settings contain NaN or infinite numbers")
    words = problem(numbers[:30])
    if words is not None:
        raise PtraceError(f"{path}: camera settings: {words}")
    near, far = numbers[3], numbers[4]
    position, target = numbers[5:8], numbers[8:11]
    rotation = numbers[16:25].reshape(3, 3)
    screen_dist = numbers[27]
    if not screen_dist > 0:
        raise PtraceError(f"{path}: screenDist must be positive, found {screen_dist}")
    lens = {}
    if numbers.size >= 30:   # focalDistance lensRadius (every dump has them; 3-2 uses them)
        lens = dict(focal_distance=float(numbers[28]), lens_radius=float(numbers[29]))
    try:
        return Camera(position, target, rotation, float(screen_dist), int(width), int(height),
                      float(near), float(far), **lens)
    except PtraceError as error:
        raise PtraceError(f"{path}: {error}") from None
