"""What each `ptrace view` session renders with: the camera moves (orbit, pan and zoom about
the target, pure functions of a Camera, and the guard that keeps a session's camera usable),
the reduced-resolution camera of a quick frame, the image of a session's sums, its denoised
image (the optional pyoidn), a frame's PNG bytes, the bounds on what a session may ask for
(resolution, samples, the rays of one path), the kernel calls of a pass in blocks small enough
that a closed page stops within one (Blocks), and the render jobs whose backends every session
shares (Backends)."""
import collections
import dataclasses
import math
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np

from ..budget import machine_memory as physical_memory  # (the name tests patch)
from ..camera import look_at
from ..errors import PtraceError
from ..features import denoise, denoised_path
from ..image import write_image
from ..rendering.tiles import BLOCK_PATHS, RenderJob

ESTIMATORS = ("mis", "light", "hemisphere")
MODES = ("image", "rate", "normals")
ZOOM_RANGE = (1e-4, 1e4)    # the target's distance, as a multiple of the starting view's
PAN_RANGE = 1e4             # how far the target may move, in starting distances
MAX_SPP = 2 ** 32           # the sampler's distinct samples per pixel (its indices wrap there)
MAX_SEED = 2 ** 63 - 1      # the kernels' 64-bit integers
BLOCK_RAYS = 1 << 19        # the most rays one kernel call may trace (paths x path_rays): what
                            # a closed page may still wait for, per thread
BLOCK_SECONDS = 0.1         # and, once a call has been timed, about this long
NAIVE_PRIMITIVES_PER_RAY = 64   # a naive ray tests every primitive: this many cost about one
                                # accelerated ray
VIEW_BYTES_PER_PIXEL = 1024  # a session's per-pixel buffers at their peak, rounded up: the
                             # sums of the image, of its job and of the pass under way, the
                             # AOVs' sums beside each (denoised toggle), the frames kept, shown,
                             # encoded and saved (tracemalloc's peak of a whole render and Save)
MEMORY_FRACTION = 0.5       # what every session's buffers together may take of the memory
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


def moved(camera, home, op, dx=0.0, dy=0.0, factor=1.0):
    """The camera after one move of the page: orbit by (dx, dy) pixels (half a turn per image
    width), pan by (dx, dy) pixels, zoom by factor (0.1 to 10 per move, the target's distance
    kept within ZOOM_RANGE of home's, the session's first camera), or "still" (unchanged).
    Raises PtraceError, and the caller keeps its camera, when the result would not be a usable
    camera: any number not finite, or the target more than PAN_RANGE home distances from
    home's (so no sequence of moves can break a session's camera)."""
    reference = float(np.linalg.norm(home.position - home.target))
    try:
        camera = _moved(camera, op, dx, dy, factor, reference)
    except PtraceError as error:   # a camera ptrace.camera refuses to make (not finite, ...)
        if "unknown camera operation" in str(error):
            raise
        camera = None
    with np.errstate(all="ignore"):
        usable = camera is not None and all(np.isfinite(part).all() for part in
                                            (camera.position, camera.target,
                                             camera.camera_to_world)) \
            and np.linalg.norm(camera.position - camera.target) > 0 \
            and np.linalg.norm(camera.target - home.target) <= PAN_RANGE * reference
    if not usable:
        raise PtraceError(f"camera {op} refused: the view would not be usable (numbers not "
                          f"finite, or the target more than {PAN_RANGE:g} view distances away)")
    return camera


def _moved(camera, op, dx, dy, factor, reference):
    with np.errstate(all="ignore"):
        if op == "orbit":
            camera = orbit(camera, -dx * np.pi / camera.width, -dy * np.pi / camera.width)
        elif op == "pan":
            camera = pan(camera, dx, dy)
        elif op == "zoom":
            distance = np.linalg.norm(camera.position - camera.target)
            wanted = np.clip(distance * np.clip(factor, 0.1, 10.0), ZOOM_RANGE[0] * reference,
                             ZOOM_RANGE[1] * reference)
            camera = zoom(camera, wanted / distance)
        elif op != "still":
            raise PtraceError(f"unknown camera operation {op!r}")
    return camera


def scaled(camera, scale):
    """The same view at 1/scale of the resolution (a smaller image, not a crop)."""
    return dataclasses.replace(camera, width=max(1, camera.width // scale),
                               height=max(1, camera.height // scale),
                               screen_dist=camera.screen_dist / scale)


def upscaled(image, scale, width, height):
    """A quick frame's small image scaled up (nearest pixel) to width x height, black beyond."""
    full = np.zeros((height, width, 3), np.float32)
    big = np.repeat(np.repeat(image, scale, axis=0), scale, axis=1)
    full[:big.shape[0], :big.shape[1]] = big[:height, :width]
    return full


def mean_image(sums, width, height):
    """ptrace.render's image of these sums (rows bottom first): float32, top row first."""
    sum_rgb, count = sums[0], sums[3]
    image = np.where(count[:, None] > 0, sum_rgb / np.maximum(count, 1)[:, None], 0.0)
    return image.reshape(height, width, 3)[::-1].astype(np.float32)


def denoiser_missing():
    """None when the denoised view can work, else its one-line reason (pyoidn is missing)."""
    from ..features import require_denoiser
    try:
        require_denoiser()
    except PtraceError:
        return ('the denoised view needs Intel Open Image Denoise\'s Python package: '
                'pip install "ptrace[denoise]" (or pip install pyoidn)')
    return None


PAGE_NAMES = {"spp": "samples", "seed": "seed", "light_samples": "light samples",
              "max_depth": "depth"}
FLAG_NAMES = {"spp": "-s", "seed": "--seed", "light_samples": "-l", "max_depth": "-m"}


def settings_of(scene, settings, mode, message):
    """(settings, view) of a page's settings message (checked by ptrace.app.view_messages): the
    settings changed, validated as Settings and check_settings validate them, and the view
    (image, rate or normals; the normals view is the normals integrator)."""
    changes = {name: message[name] for name in ("spp", "max_depth", "light_samples")
               if name in message}
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
    settings = dataclasses.replace(settings, **changes)
    check_settings(scene, settings, PAGE_NAMES)
    return settings, mode


def page_settings(settings, mode, denoise):
    """A session's settings as the page's fields show them (in its hello, and beside an error
    reply, so that a refused value does not stay in its field)."""
    return {"spp": settings.spp, "max_depth": settings.max_depth,
            "light_samples": settings.light_samples,
            "estimator": "hemisphere" if settings.hemisphere else settings.direct,
            "accel": settings.accel, "mode": mode, "denoise": denoise}


def path_rays(scene, settings, features=False):
    """The most rays one path of these settings may trace, counted in accelerated rays: its
    first vertex's rays (Settings.rays_per_path: the camera or BSDF ray and the light samples of
    every light) at each vertex up to max_depth, one more with the AOVs; with the naive backend
    a ray counts as its primitives / NAIVE_PRIMITIVES_PER_RAY."""
    vertices = 1 if settings.integrator == "normals" else max(1, settings.max_depth)
    rays = settings.rays_per_path(scene) * vertices + int(features)
    if settings.accel == "naive":
        primitives = scene.triangle_count + scene.sphere_count
        rays *= max(1, math.ceil(primitives / NAIVE_PRIMITIVES_PER_RAY))
    return rays


def check_settings(scene, settings, names):
    """Raise PtraceError, naming the flag or field (names: FLAG_NAMES or PAGE_NAMES), for
    settings a session cannot render: samples per pixel beyond the sampler's MAX_SPP, a seed
    beyond the kernels' integers, or paths whose rays (path_rays, with the AOVs) pass
    BLOCK_RAYS, the budget of one kernel call, which no block can be smaller than."""
    if settings.spp > MAX_SPP:
        raise PtraceError(f"{names['spp']} must be from 1 to {MAX_SPP:,}, got {settings.spp:,}")
    if settings.seed > MAX_SEED:
        raise PtraceError(f"{names['seed']} must be from 0 to {MAX_SEED:,}, got "
                          f"{settings.seed:,}")
    rays = path_rays(scene, settings, features=True)
    if rays > BLOCK_RAYS:
        backend = " with the naive backend" if settings.accel == "naive" else ""
        raise PtraceError(
            f"{names['light_samples']} {settings.light_samples:,} and {names['max_depth']} "
            f"{settings.max_depth:,}{backend}: one path may trace {rays:,} rays on this scene, "
            f"more than the viewer's {BLOCK_RAYS:,} per kernel call (a closed page waits for "
            f"one call); lower them")


def sessions_that_fit(width, height, most, what):
    """How many sessions (at most `most`) of width x height pixels fit, with their per-pixel
    buffers (VIEW_BYTES_PER_PIXEL), in MEMORY_FRACTION of physical_memory(); raises PtraceError
    naming `what` (the flag) when not even one does."""
    memory = physical_memory()
    need = width * height * VIEW_BYTES_PER_PIXEL
    fit = int(memory * MEMORY_FRACTION // need)
    if fit < 1:
        raise PtraceError(
            f"{what} {width} {height}: a viewer's per-pixel buffers would need "
            f"{need / 2 ** 30:,.1f} GiB ({width * height:,} pixels at about "
            f"{VIEW_BYTES_PER_PIXEL} bytes), more than {MEMORY_FRACTION:.0%} of this machine's "
            f"{memory / 2 ** 30:,.1f} GiB of memory")
    return min(most, fit)


def probe(shown, x, y):
    """The reply to a click: radiance (linear, before exposure) and samples of pixel (x, y from
    the bottom) of a Shown frame."""
    height, width = shown.counts.shape if shown is not None else (0, 0)
    if not (0 <= x < width and 0 <= y < height):
        raise PtraceError(f"pixel {x} {y} is not in the image")
    row = height - 1 - y
    return {"type": "probe", "x": x, "y": y, "radiance": shown.radiance[row, x].tolist(),
            "samples": int(shown.counts[row, x])}


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


class Blocks:
    """A session's kernel calls (RenderJob.trace on a few pixels at a time, each call one of
    the job's blocks, run on the session's own threads): a pass of some pixels is cut into
    calls of at most BLOCK_RAYS rays (paths x path_rays) and, once calls have been timed, of
    about BLOCK_SECONDS. check() runs before every call, in whichever thread makes it: whatever
    it raises (the session abandoning the work) ends the pass after the calls under way, so a
    closed page waits for at most one call per thread. A pass whose samples per pixel do not fit
    one call is traced one sample per call (a pixel's calls in sample order), which adds the
    same bits as one call of them all: the kernel sums a pixel's samples from zero in sample
    order and adds that sum to the pixel's row, and the pass's sums start at zero."""

    def __init__(self, threads):
        self.pool = None if threads == 1 else ThreadPoolExecutor(
            threads, thread_name_prefix="ptrace-view-block")
        self.seconds_per_ray = 0.0      # measured by the last call long enough to time

    def paths_per_call(self, rays_per_path):
        paths = BLOCK_RAYS // rays_per_path
        if self.seconds_per_ray > 0:
            paths = min(paths, int(BLOCK_SECONDS / (self.seconds_per_ray * rays_per_path)))
        return max(1, min(BLOCK_PATHS, paths))

    def trace(self, job, pixel_x, pixel_y, first, n, sums, rows, rays_per_path, check,
              on_pixels=None, features=None):
        """RenderJob.trace's samples first .. first + n - 1 of these pixels into sums (and
        features) at rows, in calls as above; on_pixels(count, rays so far) after each run of
        pixels is done, in the order given. Returns the rays traced."""
        paths = self.paths_per_call(rays_per_path)
        split = n > paths
        size = paths if split else max(1, paths // n)

        def run(start, end):
            rays = 0
            for sample, count in ((s, 1) for s in range(first, first + n)) if split \
                    else ((first, n),):
                check()
                began = time.perf_counter()
                rays += job.trace(pixel_x[start:end], pixel_y[start:end], sample, count, sums,
                                  rows[start:end], None, features)[1]
                seconds = time.perf_counter() - began
                if seconds > 1e-3:          # shorter calls time mostly their overhead
                    self.seconds_per_ray = seconds / ((end - start) * count * rays_per_path)
            return end - start, rays

        chunks = [(start, min(start + size, len(pixel_x)))
                  for start in range(0, len(pixel_x), size)]
        futures = [] if self.pool is None else [self.pool.submit(run, *c) for c in chunks]
        done = (future.result() for future in futures) if futures \
            else (run(*chunk) for chunk in chunks)
        rays = 0
        try:
            for pixels, traced in done:
                rays += traced
                if on_pixels is not None:
                    on_pixels(pixels, rays)
        finally:
            for future in futures:
                future.cancel()
            wait(futures)
        return rays

    def close(self):
        if self.pool is not None:
            self.pool.shutdown(wait=True)


class Backends:
    """Render jobs, one built per (kind, BVH split) on first use and shared by every session:
    a session's job reuses that one's backend and scene records with its own settings and
    camera (RenderJob.reused), so neither a camera move nor a setting rebuilds them."""

    def __init__(self, scene, notice):
        self.scene, self.notice = scene, notice
        self.lock = threading.Lock()
        self.built = {}

    def job(self, settings, camera):
        """A RenderJob for these settings and camera (the backend built once per kind)."""
        key = (settings.accel, settings.bvh_split)
        with self.lock:
            if key not in self.built:
                self.built[key] = RenderJob.build(self.scene, settings, camera, self.notice)
                self.built[key].compile_ahead()   # what the cache lacks, on every core
            built = self.built[key]
        return built.reused(settings, camera)
