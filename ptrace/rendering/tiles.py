"""The work of a render, apart from who runs it: the pass schedule with adaptive sampling's
decisions between passes, and the render job (RenderJob: the backend built once, the kernel's
records, and the trace of a set of pixels as waves through the compiled stages) that the in-process
executor, a Dask worker (for one tile) and the viewer's sessions run.

Knows nothing of Dask. Per pixel a render keeps four sums: radiance (RGB), illuminance and its
square, and the count of finite samples; every pass adds each pixel's pass sum, summed from
zero, so a tile computed elsewhere and added later gives the same bits as one computed here.
"""
import threading
import time
from concurrent.futures import ThreadPoolExecutor, wait

import numba
import numpy as np

import accel

from ..integrator import camera_record, scene_records
from ..jit import cold, compile_estimate
from ..kernel import wavefront
from ..kernel.ahead import compile_ahead, processes

PASS_SAMPLES = 16        # samples per pixel per pass without -a (the unit Ctrl-C waits for)
NO_FEATURES = np.zeros((0, 8))   # a block's features when no AOVs are asked for
BLOCK_PATHS = 4096       # (pixel, sample) pairs per kernel call (at least one pixel): Ctrl-C
                         # and the progress bar act between calls; a call holds no memory that
                         # depends on -s, -l or -m (a path keeps its state in registers)


def new_sums(n_pixels):
    """Zeroed per-pixel sums (rgb, l, l2, count) for n_pixels pixels."""
    return (np.zeros((n_pixels, 3)), np.zeros(n_pixels), np.zeros(n_pixels),
            np.zeros(n_pixels, dtype=np.int64))


def converged(sum_l, sum_l2, count, tolerance, batch):
    """The course's test, 1.96 sigma / sqrt(n) <= tolerance * mu on illuminance, except that a
    pixel whose samples have all been equal (sigma = 0, typically all black) is not stopped
    before it has two batches: one batch of zeros in a dim, noisy region says little."""
    n = count.astype(np.float64)
    mean = sum_l / n
    variance = np.maximum(sum_l2 - sum_l * sum_l / n, 0.0) / np.maximum(n - 1, 1)
    sigma = np.sqrt(variance)
    return (1.96 * sigma / np.sqrt(n) <= tolerance * mean) & ((sigma > 0) | (n >= 2 * batch))


class Passes:
    """The pass schedule, shared by every executor: pass sizes depend only on -s and -a; after
    each pass, adaptive sampling retires the converged active pixels."""

    def __init__(self, settings, sums, bar=None):
        self.spp = settings.spp
        adaptive = settings.adaptive
        self.batch = adaptive[0] if adaptive is not None else min(self.spp, PASS_SAMPLES)
        self.tolerance = None if adaptive is None else adaptive[1]
        self.sums, self.bar = sums, bar
        self.active = np.arange(sums[1].shape[0])
        self.done = 0

    def __iter__(self):
        """Yield (first_sample, pass_n, active pixel indices) until every pixel is done."""
        while self.done < self.spp and self.active.size:
            pass_n = min(self.batch, self.spp - self.done)
            yield self.done, pass_n, self.active
            self.done += pass_n
            if self.tolerance is not None and self.done < self.spp:
                _, sum_l, sum_l2, count = self.sums
                a = self.active
                stop = converged(sum_l[a], sum_l2[a], count[a], self.tolerance, self.batch)
                if self.bar is not None:
                    self.bar.update(int(stop.sum()) * (self.spp - self.done))
                self.active = a[~stop]

    @property
    def adaptive(self):
        return self.tolerance is not None

    def fixed(self):
        """The whole schedule up front (only without adaptive sampling)."""
        if self.adaptive:
            raise RuntimeError("an adaptive schedule is decided pass by pass")
        schedule, done = [], 0
        while done < self.spp:
            pass_n = min(self.batch, self.spp - done)
            schedule.append((done, pass_n))
            done += pass_n
        return schedule

    def update(self, samples):
        if self.bar is not None:
            self.bar.update(samples)


class _Threads:
    """A pool of Python threads that trace blocks of pixels (each block's waves through stage
    kernels compiled with nogil): one block at a time per thread, handed out as threads free
    up, so both cores stay busy to the end however uneven the blocks' cost. Used instead of
    numba's prange, whose parallel lowering costs compile time and which splits a range
    statically. Resized to numba's thread count (-t) on each use."""

    def __init__(self):
        self.pool, self.size = None, 0

    def get(self, size):
        if self.pool is None or self.size != size:
            if self.pool is not None:
                self.pool.shutdown(wait=True)
            self.pool, self.size = ThreadPoolExecutor(size, thread_name_prefix="ptrace"), size
        return self.pool


_threads = _Threads()


def _run_blocks(function, blocks):
    """Run function(start, end) for every block on numba's thread count of threads; yield each
    result in block order. If interrupted (Ctrl-C), cancel what has not started and wait for
    the blocks running, so nothing writes into the sums after the caller returns."""
    threads = numba.get_num_threads()
    if threads == 1 or len(blocks) == 1:
        for start, end in blocks:
            yield function(start, end)
        return
    pool = _threads.get(threads)
    futures = [pool.submit(function, start, end) for start, end in blocks]
    try:
        for future in futures:
            yield future.result()
    finally:
        for future in futures:
            future.cancel()
        wait(futures)


class RenderJob:
    """What rendering any set of pixels needs beside the pixels, kept fixed while a render runs:
    the backend (built once for the scene and settings), the scene's kernel records, the
    settings' kernel options and the camera's record. The in-process executor, a Dask worker and
    the viewer's sessions all trace through a RenderJob, so their per-pixel arithmetic is the
    same; they differ only in where the blocks of pixels go. Never pickled: each process builds
    its own (RenderJob.build). rays_traced counts the rays of every trace() so far."""

    cold = None   # what numba's cache lacked when RenderJob.build made it (ptrace.jit.cold)

    def __init__(self, scene, backend, settings, camera, records=None):
        """A job on a built backend; records: the scene's records (scene_records) for these
        settings' choice of light tree, or None to make them here."""
        if records is None:
            records = scene_records(scene, settings.uses_light_tree(scene))
        self.scene, self.backend, self.settings, self.records = scene, backend, settings, records
        self.accel = backend.compiled
        self.options = settings.kernel_options()
        self.camera = camera_record(camera)
        self.rays_traced = 0
        self.build_seconds = self.records_seconds = 0.0
        self.wavefront = wavefront.Wavefront(records, self.options, self.camera, self.accel,
                                             wavefront.used_kinds(scene),
                                             wavefront.simple(scene),
                                             settings.light_mode(scene),
                                             settings.guiding != "off",
                                             wavefront.angular_spots(scene),
                                             wavefront.exact_glass(scene))
        self._counting = threading.Lock()

    @classmethod
    def build(cls, scene, settings, camera, notice=None, lap=None):
        """Build the backend (accel.build, of the settings' kind and options) and the job on it.
        notice(message), if given, hears that the kernels must be compiled first (a cold numba
        cache); lap(phase), if given, is called as the "compile" check, the "build" and the
        "records" begin (ptrace.rendering.timing.Phases.enter). The job's build_seconds and
        records_seconds are the wall time of the build and of the records."""
        lap = lap if lap is not None else (lambda phase: None)
        lap("compile")
        # (only where someone hears of it: a Dask worker's job compiles without a word)
        cold_kernels = cold(accel.record_class(settings.accel)) if notice is not None else None
        if cold_kernels is not None:
            estimate = f"about {compile_estimate(cold_kernels):.0f} s"
            notice(f"compiling kernels (first run only, {estimate})" if cold_kernels == "first"
                   else f"compiling the {settings.accel} backend's kernels (first run with it "
                        f"only, {estimate})")
        lap("build")
        start = time.perf_counter()
        backend = accel.build(settings.accel, scene.geometry, **settings.accel_options())
        build_seconds = time.perf_counter() - start
        lap("records")
        start = time.perf_counter()
        job = cls(scene, backend, settings, camera)
        job.build_seconds, job.records_seconds = build_seconds, time.perf_counter() - start
        job.cold = cold_kernels   # what the cache lacked: ptrace.jit.cold
        return job

    def compile_ahead(self, aovs=False):
        """Compile, before the first trace, the kernels this job's renders call that numba's
        cache lacks, on every core (ptrace.kernel.ahead); aovs: the renders ask for AOVs.
        Returns how many were compiled so (none with one compile process: then the kernels are
        not even listed)."""
        if processes() < 2:
            return 0
        return compile_ahead(self.wavefront.kernels(aovs))

    def reused(self, settings, camera):
        """A job for other settings of the same backend (kind and options) and another camera,
        without building anything again: the backend, and the scene's records unless the
        settings choose lights by the light tree where this job does not (or the reverse), are
        this job's; the kernel options and the camera's record are the new ones'."""
        if (settings.accel, settings.accel_options()) != \
                (self.settings.accel, self.settings.accel_options()):
            raise ValueError(f"a job on a {self.settings.accel} backend cannot be reused for "
                             f"{settings.accel} {settings.accel_options()}")
        lights = (settings.integrator, settings.light_sampler)
        same = lights == (self.settings.integrator, self.settings.light_sampler) or \
            settings.uses_light_tree(self.scene) == self.settings.uses_light_tree(self.scene)
        return RenderJob(self.scene, self.backend, settings, camera,
                         self.records if same else None)

    def trace(self, pixel_x, pixel_y, first_sample, pass_n, sums, rows, on_chunk=None,
              features=None):
        """Trace samples first_sample .. first_sample + pass_n - 1 of the given pixels (y from
        the bottom) and add each pixel's sums into `sums` at `rows`. Work goes to the kernel in
        blocks of about BLOCK_PATHS paths (whole pixels), on all threads; on_chunk(samples) is
        called after each block, in order. features, if given, an (N, 8) array beside the sums,
        gets the per-pixel sums of the AOVs (ptrace.features). Returns (non-finite samples
        dropped, rays traced) of this call. A call keeps its state to itself (and the count of
        rays_traced is locked), so several threads may trace one job at once."""
        sum_rgb, sum_l, sum_l2, count = sums
        pixel_x = np.ascontiguousarray(pixel_x, dtype=np.int64)
        pixel_y = np.ascontiguousarray(pixel_y, dtype=np.int64)
        rows = np.ascontiguousarray(rows, dtype=np.int64)
        first_sample, pass_n = int(first_sample), int(pass_n)
        features = NO_FEATURES if features is None else features

        def block(start, end):
            return end - start, self.wavefront.trace(
                pixel_x[start:end], pixel_y[start:end], rows[start:end], first_sample, pass_n,
                sum_rgb, sum_l, sum_l2, count, features)

        size = max(1, BLOCK_PATHS // pass_n)
        blocks = [(start, min(start + size, pixel_x.shape[0]))
                  for start in range(0, pixel_x.shape[0], size)]
        dropped = traced = 0
        for pixels, (block_dropped, rays) in _run_blocks(block, blocks):
            dropped += block_dropped
            traced += rays
            with self._counting:
                self.rays_traced += rays
            if on_chunk is not None:
                on_chunk(pixels * pass_n)
        return dropped, traced


TileWork = RenderJob   # the name benchmarks and tests use
