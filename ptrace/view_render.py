"""What each `ptrace view` session renders with: the camera moves (orbit, pan and zoom about
the target, pure functions of a Camera), the reduced-resolution camera of a quick frame, the
image of a session's sums, its denoised image (the optional pyoidn), a frame's PNG bytes, and
the accelerators every session shares (Backends)."""
import collections
import copy
import dataclasses
import os
import threading

import numpy as np

import accel

from .camera import look_at
from .errors import PtraceError
from .features import denoise, denoised_path
from .image import write_image
from .integrator import camera_record
from .jit import COLD_COMPILE_SECONDS, is_cold
from .tiles import TileWork

ESTIMATORS = ("mis", "light", "hemisphere")
MODES = ("image", "rate", "normals")
# a frame as shown: radiance top row first, samples, target spp, the rate image (rate view),
# exposure, the AOV images (while their sums are kept) and the denoised radiance (toggle on)
Shown = collections.namedtuple("Shown", "radiance counts spp rate exposure aovs denoised")

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


def denoiser_missing():
    """None when the denoised view can work, else its one-line reason (pyoidn is missing)."""
    from .features import require_denoiser
    try:
        require_denoiser()
    except PtraceError:
        return ('the denoised view needs Intel Open Image Denoise\'s Python package: '
                'pip install "ptrace[denoise]" (or pip install pyoidn)')
    return None


def settings_of(settings, mode, message):
    """(settings, view) of a page's settings message: the settings changed (validated) and the
    view (image, rate or normals; the normals view is the normals integrator)."""
    changes = {}
    for name in ("spp", "max_depth", "light_samples"):
        if name in message:
            changes[name] = int(message[name])
    if "estimator" in message:
        if message["estimator"] not in ESTIMATORS:
            raise PtraceError(f"unknown estimator {message['estimator']!r}")
        changes["hemisphere"] = message["estimator"] == "hemisphere"
        if message["estimator"] != "hemisphere":
            changes["direct"] = message["estimator"]
    if "accel" in message:
        changes["accel"] = message["accel"]
        if message["accel"] != "bvh":
            changes["bvh_split"] = "mean"
    mode = message.get("mode", mode)
    if mode not in MODES:
        raise PtraceError(f"unknown view {mode!r}")
    if mode != "rate":
        changes["integrator"] = "normals" if mode == "normals" else "path"
    return dataclasses.replace(settings, **changes), mode


def write_frame(frame, outputs, denoised):
    """Save's files of a Shown frame: the PNG its pixels (course_8bit, or the rate image), the
    EXR its radiance times 2**exposure; with denoised (the toggle), NAME_denoised.png and .exr
    of its denoised radiance the same way (denoised here in the rate view, which shows none).
    Returns (the reply, notes for it)."""
    gain = np.float32(2.0 ** frame.exposure)
    png, exr = outputs
    write_image(png, frame.radiance * gain, eight_bit=frame.rate)
    write_image(exr, frame.radiance * gain)
    reply = {"type": "saved", "png": os.path.abspath(png), "exr": os.path.abspath(exr)}
    if denoised and frame.aovs is None:
        return reply, ["no denoised image: that render has no AOVs"]
    if denoised:
        image = frame.denoised
        if image is None:
            image = denoise(frame.radiance, frame.aovs["albedo"], frame.aovs["normal"])
        reply["denoised"] = [os.path.abspath(denoised_path(path)) for path in outputs]
        for path in reply["denoised"]:
            write_image(path, image * gain)
    return reply, []


def png_bytes(pixels, directory):
    """PNG bytes of 8-bit pixels (the same pixels write_image writes; zlib level 1, fast),
    through a file in directory (OpenImageIO writes files)."""
    import OpenImageIO as oiio
    path = os.path.join(directory, "frame.png")
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, oiio.UINT8)
    spec.attribute("png:compressionLevel", 1)
    output = oiio.ImageOutput.create(path)
    if output is None or not output.open(path, spec) or not output.write_image(
            np.ascontiguousarray(pixels)):
        raise RuntimeError(f"cannot encode a frame: {oiio.geterror()}")
    output.close()
    with open(path, "rb") as handle:
        return handle.read()


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
