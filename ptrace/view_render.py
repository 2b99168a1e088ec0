"""What each `ptrace view` session renders with: the camera moves (orbit, pan and zoom about
the target, pure functions of a Camera), the reduced-resolution camera of a quick frame, the
image of a session's sums, and the accelerators every session shares (Backends)."""
import copy
import dataclasses
import threading

import numpy as np

import accel

from .camera import look_at
from .integrator import camera_record
from .jit import COLD_COMPILE_SECONDS, is_cold
from .tiles import TileWork

# --- the camera: orbit, pan and zoom about the target (pure functions of a Camera) ----------

def orbit(camera, yaw, pitch):
    """The camera turned about its target by yaw (about +Y) and pitch (radians), +Y up."""
    offset = camera.position - camera.target
    radius = np.linalg.norm(offset)
    theta = np.arctan2(offset[0], offset[2]) + yaw
    phi = np.clip(np.arccos(np.clip(offset[1] / radius, -1, 1)) + pitch, 1e-3, np.pi - 1e-3)
    position = camera.target + radius * np.array([np.sin(phi) * np.sin(theta), np.cos(phi),
                                                  np.sin(phi) * np.cos(theta)])
    return dataclasses.replace(camera, position=position,
                               camera_to_world=look_at(position, camera.target))


def pan(camera, dx, dy):
    """Position and target moved together by (dx, dy) image pixels at the target's distance."""
    distance = np.linalg.norm(camera.position - camera.target)
    right, up = camera.camera_to_world[:, 0], camera.camera_to_world[:, 1]
    shift = (distance / camera.screen_dist) * (-dx * right + dy * up)
    return dataclasses.replace(camera, position=camera.position + shift,
                               target=camera.target + shift)


def zoom(camera, factor):
    """The camera moved along its view axis to `factor` times its distance from the target."""
    position = camera.target + factor * (camera.position - camera.target)
    return dataclasses.replace(camera, position=position)


def scaled(camera, scale):
    """The same view at 1/scale of the resolution (a smaller image, not a crop)."""
    return dataclasses.replace(camera, width=max(1, camera.width // scale),
                               height=max(1, camera.height // scale),
                               screen_dist=camera.screen_dist / scale)


def mean_image(sums, width, height):
    """ptrace.render's image of these sums (rows bottom first): float32, top row first."""
    sum_rgb, count = sums[0], sums[3]
    image = np.where(count[:, None] > 0, sum_rgb / np.maximum(count, 1)[:, None], 0.0)
    return image.reshape(height, width, 3)[::-1].astype(np.float32)


class Backends:
    """Accelerators built once per (kind, BVH split) and shared by every session."""

    def __init__(self, scene, notice):
        self.scene, self.notice = scene, notice
        self.lock = threading.Lock()
        self.built, self.works = {}, {}

    def work(self, settings, camera):
        """A TileWork for these settings and camera (the scene's records built once)."""
        key = (settings.accel, settings.bvh_split)
        with self.lock:
            if key not in self.built:
                if is_cold(accel.record_class(settings.accel)):
                    self.notice(f"compiling kernels (first run only, about "
                                f"{COLD_COMPILE_SECONDS} s)")
                self.built[key] = accel.build(settings.accel, self.scene.geometry,
                                              **settings.accel_options())
                self.works[key] = TileWork(self.scene, self.built[key], settings, camera)
            work = copy.copy(self.works[key])
        work.settings, work.options = settings, settings.kernel_options()
        work.camera, work.rays_traced = camera_record(camera), 0
        return work
