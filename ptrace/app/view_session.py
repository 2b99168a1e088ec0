"""One `ptrace view` viewer's session (Preview): its own camera, settings and render thread
over the shared scene and backends (ptrace.app.view_render). The render reuses
ptrace.rendering.tiles: the pass schedule of ptrace.render (Passes) through RenderJob.trace, in the
short kernel calls of ptrace.app.view_render.Blocks, so N samples here are bit for bit
ptrace.render's N samples. Each pass is traced into fresh sums and then added to the image's (0 + x
is x, so the bits are the same), which lets a camera move, a setting or a closed page abort a pass
at any call without leaving half a pass behind. After a reset, and while the camera moves, a
throwaway frame of 1 sample at reduced resolution is shown first.

The denoised toggle: while it is on, each full-resolution frame (not a quick one, not the rate
view) is ptrace --denoise's image of the merged passes, guided by the AOVs' sums, which the
passes accumulate beside the radiance (ptrace.features) from the start of the render: turning
the toggle on restarts a render that has no sums of them; turning it off keeps them until the
next restart, so turning it on again costs nothing. They are not accumulated always because
they cost one more ray per sample (about a quarter more render time on the Cornell box).
"""
import dataclasses
import shutil
import sys
import tempfile
import threading
import time

import numba
import numpy as np

from ..errors import PtraceError
from ..features import FEATURES, denoise
from ..rendering.tiles import Passes, new_sums
from . import view_frame, view_messages, view_render
from .view_render import Blocks, Shown, denoiser_missing, mean_image, png_bytes, write_frame

QUICK_SECONDS = 0.06            # the budget of a frame while the camera moves
PUSH_SECONDS = 0.25             # within a pass, the screen is refreshed at most this often


class _Abort(Exception):
    """Raised inside a trace when its work is no longer wanted."""


@dataclasses.dataclass
class _Job:
    """A pass schedule over some pixels (all of them, or a cell): its own sums, and the pass
    in progress (kept until merged, so an aborted pass is traced again)."""
    settings: object
    camera: object
    rows: np.ndarray            # indices into the image's pixels (bottom row first)
    sums: tuple
    passes: object
    schedule: object
    features: np.ndarray = None  # the AOVs' sums beside sums (ptrace.features), or None
    render: object = None       # its RenderJob, made by the render thread for the first pass
    current: tuple = None
    started: float = 0.0
    seconds: float = 0.0        # tracing time so far
    samples: int = 0
    rays: int = 0
    done: bool = False


class Preview:
    """One viewer's render: settings, camera, the image's sums, and the thread that renders.
    Messages (dicts from the page) go to handle(), which returns a reply or None; frames go to
    publish(stats, png bytes) from the render thread, notices and errors to publish(dict, None).
    """

    def __init__(self, scene, settings, camera, backends, publish, *, threads=None, crop=None,
                 outputs=("view.png", "view.exr"), denoise=False):
        self.scene, self.backends, self.publish = scene, backends, publish
        self.threads, self.outputs = threads, outputs
        self.settings, self.camera, self.home = settings, camera, camera
        self.width, self.height = camera.width, camera.height
        view_render.check_settings(scene, settings, view_render.FLAG_NAMES)
        self.mode = "normals" if settings.integrator == "normals" else "image"
        self.exposure, self.paused, self.stopped, self.moving = 0.0, False, False, False
        self.cond = threading.Condition()
        # generation counts changes: work of an older generation is abandoned at its next block
        self.generation, self.redraw = 0, None      # redraw: None, "frame" or "image"
        self.request, self.request_at = 0, None     # the last camera message, for latency
        self.paths_per_second = 2e5                 # measured; sizes the quick frames
        self.show_seconds = 0.0                     # the last progress frame's cost
        self.fallback = None            # the quick frame, shown where nothing is summed yet
        self.shown = None               # a Shown
        self.accumulated = None         # the last shown that was no quick frame (Save's)
        self.seq = 0
        self.sums = new_sums(self.width * self.height)
        self.missing = denoiser_missing()
        if denoise and self.missing:
            raise PtraceError(self.missing)
        self.denoise = denoise                          # the toggle; the image's AOV sums:
        self.features = np.zeros((self.width * self.height, FEATURES)) if denoise else None
        self.merged, self.last_denoised = 0, (None, None)   # changes of the sums; a cache
        self.job, self.blocks = None, None      # blocks: the render thread's Blocks
        self.temporary = tempfile.mkdtemp(prefix="ptrace-view-")
        self._reset(crop)
        self.thread = threading.Thread(target=self._run, name="ptrace-view", daemon=True)
        self.thread.start()

    # --- requests (from the IOLoop's thread) -----------------------------------------------

    def handle(self, message):
        """Act on one message of the page (checked by ptrace.app.view_messages.check first: a bad
        one raises PtraceError and changes nothing); returns the reply or None."""
        message = view_messages.check(message)
        kind = message["type"]
        if kind == "probe":
            return self.probe(message["x"], message["y"])
        if kind == "save":
            return self.save()
        with self.cond:
            if kind == "camera":
                self._camera(message)
            elif kind == "settings":
                self._settings(message)
            elif kind == "cell":
                x, y, dx, dy = (message[k] for k in ("x", "y", "dx", "dy"))
                if dx < 1 or dy < 1 or x < 0 or y < 0 or x + dx > self.width \
                        or y + dy > self.height:
                    raise PtraceError(f"cell {x} {y} {dx} {dy} is not inside the image")
                self._reset((x, y, dx, dy))
            elif kind == "pause":
                self.paused = message["paused"]
                self._redraw("image")
            elif kind == "exposure":
                self.exposure = float(np.clip(message["stops"], -20, 20))
                self._redraw("image")
            else:
                raise PtraceError(f"unknown message type {kind!r}")
            self.cond.notify_all()
        return None

    def _redraw(self, what):
        """Abandon the work under way (a pass is traced again) and show the image again, or a
        new quick frame ("frame" wins over "image")."""
        self.generation += 1
        self.redraw = "frame" if "frame" in (what, self.redraw) else what

    def _camera(self, message):
        self.camera = view_render.moved(      # raises, keeping the camera, if not usable
            self.camera, self.home, message["op"], message.get("dx", 0.0),
            message.get("dy", 0.0), message.get("factor", 1.0))
        self.request, self.request_at = message.get("id", 0), time.perf_counter()
        if not message.get("moving"):
            self._reset(None)
        elif not self.moving:       # the first move abandons the pass under way
            self.moving = True
            self._redraw("frame")
        else:                       # later ones let the quick frame under way finish
            self.redraw = "frame"

    def _settings(self, message):
        settings, mode = view_render.settings_of(self.scene, self.settings, self.mode,
                                                 message)       # checks them
        denoise = message.get("denoise", self.denoise)
        if denoise and self.missing:
            raise PtraceError(self.missing)
        self.mode, self.denoise = mode, denoise
        if settings != self.settings or (denoise and self.features is None):
            self.settings = settings
            self._reset(None)
        else:
            self._redraw("image")

    def _reset(self, cell):
        """Start over: the whole image (cell None: sums cleared, a quick frame first) or one
        cell (x, y, dx, dy from the bottom: only its pixels are traced again)."""
        self.merged += 1
        if cell is None:
            rows = np.arange(self.width * self.height)
            for array in self.sums:
                array[...] = 0
            self.features = np.zeros((rows.size, FEATURES)) if self.denoise else None
            self.fallback, self.moving = None, False
            self._redraw("frame")
        else:
            self.generation += 1
            x, y, dx, dy = cell
            ys, xs = np.mgrid[y:y + dy, x:x + dx]
            rows = (ys * self.width + xs).reshape(-1)
        sums = new_sums(rows.shape[0])
        passes = Passes(self.settings, sums)
        features = None if self.features is None else np.zeros((rows.size, FEATURES))
        self.job = _Job(self.settings, self.camera, rows, sums, passes, iter(passes), features)

    def stop(self):
        with self.cond:
            self.stopped = True
            self.generation += 1
            self.cond.notify_all()

    def join(self, timeout=None):
        self.thread.join(timeout)
        if not self.thread.is_alive():
            shutil.rmtree(self.temporary, ignore_errors=True)

    def running(self):
        """Whether the render thread (and so any kernel call of this session) still runs."""
        return self.thread.is_alive()

    def probe(self, x, y):
        return view_render.probe(self.shown, x, y)

    def save(self):
        """PNG and EXR of the last full-resolution frame: what is on screen, except that a quick
        frame (while the camera moves, or just after a reset) is never saved; the frame before
        it is, and the reply says so. The PNG is that frame's pixels (the same course_8bit or
        rate_colours pixels it was sent as), the EXR its linear radiance times 2**exposure.
        With the denoised toggle on, NAME_denoised.png and .exr too (the same way)."""
        shown, accumulated = self.shown, self.accumulated
        if accumulated is None:
            raise PtraceError("nothing to save yet")
        reply, notes = write_frame(accumulated, self.outputs, self.denoise)
        if accumulated is not shown:
            notes.insert(0, "the last full-resolution render, not the quick frame on screen")
        if notes:
            reply["note"] = "; ".join(notes)
        return reply

    # --- the render thread -----------------------------------------------------------------

    def _run(self):
        if self.threads is not None:
            numba.set_num_threads(self.threads)
        self.blocks = Blocks(numba.get_num_threads())
        try:
            while self._step():
                pass
        finally:                    # the session's threads and files end with this thread
            self.blocks.close()
            shutil.rmtree(self.temporary, ignore_errors=True)

    def _step(self):
        """Wait for work, do one piece of it (a frame, a redraw or a pass); False once stopped."""
        with self.cond:
            while not self.stopped and self.redraw is None and (
                    self.paused or self.job.done or self.moving):
                self.cond.wait()
            if self.stopped:
                return False
            generation, job, redraw, self.redraw = self.generation, self.job, self.redraw, None
            camera, settings, moving = self.camera, self.settings, self.moving
        try:
            if redraw == "frame":
                self._frame(generation, camera, settings, job, moving)
            elif redraw == "image":
                self._show(generation, job, None, "redraw")
            else:
                self._pass(generation, job)
        except _Abort:
            pass
        except Exception as error:   # noqa: BLE001 - told to the page; the server goes on
            if not isinstance(error, PtraceError):
                error = f"internal error: {type(error).__name__}: {error}"
                print(f"ptrace: {error}", file=sys.stderr, flush=True)
            self.publish({"type": "error", "message": str(error)}, None)
            with self.cond:
                job.done = True
        return True

    def _check(self, generation):
        if self.generation != generation or self.stopped:
            raise _Abort

    def _frame(self, generation, camera, settings, job, moving):
        """A throwaway frame of 1 sample per pixel, at the resolution that takes about
        QUICK_SECONDS at the last speed measured: while the camera moves, and after a reset
        (then shown where no pass has summed yet)."""
        scale = int(np.ceil(np.sqrt(self.width * self.height
                                    / max(self.paths_per_second * QUICK_SECONDS, 1.0))))
        small = view_render.scaled(camera, max(1, scale))
        one = dataclasses.replace(settings, spp=1, adaptive=None)
        render = self.backends.job(one, small)
        ys, xs = np.mgrid[0:small.height, 0:small.width]
        sums = new_sums(xs.size)
        start = time.perf_counter()
        self.blocks.trace(render, xs.reshape(-1), ys.reshape(-1), 0, 1, sums, np.arange(xs.size),
                          view_render.path_rays(self.scene, one), lambda: self._check(generation))
        self.paths_per_second = xs.size / max(time.perf_counter() - start, 1e-6)
        image = mean_image(sums, small.width, small.height)
        scale = max(1, scale)
        full = view_render.upscaled(image, scale, self.width, self.height)
        if not moving:
            with self.cond:
                self._check(generation)
                self.fallback, self.merged = full, self.merged + 1
        # the page scales the small image up (nearest pixel); nothing is summed yet
        self._show(generation, job, None, "quick", override=(image, scale, full))

    def _pass(self, generation, job):
        if job.current is None:
            job.current = next(job.schedule, None)
            if job.current is None:
                with self.cond:
                    job.done = True
                self._show(generation, job, None, "done")
                return
        first, n, active = job.current
        if job.render is None:    # one for every pass of the job: nothing is built again
            job.render = self.backends.job(job.settings, job.camera)
        rows = job.rows[active]
        temp = new_sums(active.shape[0])
        features = None if job.features is None else np.zeros((active.shape[0], FEATURES))
        progress = {"pixels": 0, "last": time.perf_counter()}
        start = time.perf_counter()

        def on_block(pixels, rays):
            self._check(generation)
            progress["pixels"] += pixels
            now = time.perf_counter()
            if now - progress["last"] > max(PUSH_SECONDS, 4 * self.show_seconds):
                self._show(generation, job, (active, temp, features, progress["pixels"]),
                           "progress", rays=rays, seconds=now - start)
                progress["last"] = time.perf_counter()
                self.show_seconds = progress["last"] - now

        path = view_render.path_rays(self.scene, job.settings, features is not None)
        rays = self.blocks.trace(job.render, rows % self.width, rows // self.width, first, n, temp,
                                 np.arange(active.shape[0]), path,
                                 lambda: self._check(generation), on_block, features)
        seconds = time.perf_counter() - start
        self.paths_per_second = n * active.shape[0] / max(seconds, 1e-6)
        with self.cond:
            self._check(generation)
            for total, part in zip(job.sums, temp):
                total[active] += part          # what ptrace.render adds: 0 + x is x
            for full, part in zip(self.sums, job.sums):
                full[job.rows] = part
            if features is not None:
                job.features[active] += features
                self.features[job.rows] = job.features
            self.merged += 1
            job.seconds += seconds
            job.rays += rays
            job.samples += n * active.shape[0]
            job.current = None
        self._show(generation, job, None, "pass")

    def _show(self, generation, job, partial, kind, override=None, rays=0, seconds=0.0):
        """Build the frame (the summed image, with the finished blocks of the pass under way if
        partial; ptrace.app.view_frame draws it and writes its stats), encode it as a PNG and
        publish it with its stats."""
        with self.cond:
            self._check(generation)
            rgb, counts = self.sums[0].copy(), self.sums[3].copy()
            features = None if self.features is None or override is not None \
                else self.features.copy()
            done_samples, merged = job.samples, None if partial is not None else self.merged
            if partial is not None:
                active, temp, temp_features, pixels = partial
                rows, mine = job.rows[active[:pixels]], active[:pixels]
                rgb[rows] = job.sums[0][mine] + temp[0][:pixels]
                counts[rows] = job.sums[3][mine] + temp[3][:pixels]
                if features is not None:
                    features[rows] = job.features[mine] + temp_features[:pixels]
                done_samples += pixels * job.current[1]
            exposure, mode, fallback, denoise = self.exposure, self.mode, self.fallback, \
                self.denoise
            request, request_at, paused = self.request, self.request_at, self.paused
            moving = self.moving
            if kind in ("quick", "pass"):
                self.request_at = None
        w, h = self.width, self.height
        spp = job.settings.spp
        radiance, counts, encoded, rate, scale, aovs, denoised = view_frame.draw(
            rgb, counts, features, w, h, spp, exposure, mode, fallback, override,
            denoise, lambda radiance, aovs: self._denoised(radiance, aovs, merged))
        png = png_bytes(encoded, self.temporary)
        seconds, rays = job.seconds + seconds, job.rays + rays
        self.seq += 1
        self.shown = Shown(radiance, counts, spp, rate, exposure, aovs, denoised)
        if override is None:
            self.accumulated = self.shown
        state = "paused" if paused else "moving" if moving else \
            "done" if job.done else "rendering"
        stats = view_frame.stats(
            seq=self.seq, kind=kind, width=w, height=h, scale=scale, quick=override is not None,
            pixels=job.rows.size, done_samples=done_samples, spp=spp, mode=mode,
            denoised=denoised is not None, exposure=exposure, seconds=seconds, rays=rays,
            state=state, request=request, request_at=request_at)
        self.publish(stats, png)

    def _denoised(self, radiance, aovs, merged):
        """The denoised radiance, computed again only when the sums changed (merged is their
        change count, None for a frame within a pass): exposure and view changes reuse it."""
        if merged is not None and self.last_denoised[0] == merged:
            return self.last_denoised[1]
        denoised = denoise(radiance, aovs["albedo"], aovs["normal"])
        if merged is not None:
            self.last_denoised = (merged, denoised)
        return denoised
