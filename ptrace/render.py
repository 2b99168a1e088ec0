"""The render loop: passes of samples over the active pixels, each pass in chunks of pixels.

Python runs once per wave (a chunk's camera rays, then each bounce); numba kernels run once per
ray. Per pixel the loop keeps the sum of radiance, the sum and sum of squares of illuminance and
the sample count; adaptive sampling (-a) retires converged pixels after each pass. Random
numbers are keyed by (seed, pixel, sample, dimension), and pass sizes depend only on -s and -a,
so an image does not depend on threads, chunk size or backend.
"""
import ctypes
import sys
import time
import warnings

import numba
import numpy as np
from numba import njit, prange

import accel

from .camera import BASE_HEIGHT, BASE_WIDTH, course_camera
from .errors import PtraceError
from .paths import PathTracer
from .sampling import uniform

INTEGRATORS = ("path", "normals")
CHUNK_RAYS = 1 << 16     # rays per batch handed to the accelerator (bounds peak memory)
PASS_SAMPLES = 16        # samples per pixel per pass without -a (the unit Ctrl-C waits for)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@njit(cache=True, parallel=True)
def camera_samples(seed, pixel_x, pixel_y, width, first_sample, count, spp, out_x, out_y):
    """Image-plane points of samples first_sample .. first_sample+count-1 of each pixel (y from
    the bottom): the pixel centre when spp is 1, else uniform jitter (CS184.md 4.1)."""
    for k in prange(pixel_x.shape[0]):
        pixel = pixel_y[k] * width + pixel_x[k]
        for j in range(count):
            i = k * count + j
            if spp == 1:
                out_x[i] = pixel_x[k] + 0.5
                out_y[i] = pixel_y[k] + 0.5
            else:
                out_x[i] = pixel_x[k] + uniform(seed, pixel, first_sample + j, 0)
                out_y[i] = pixel_y[k] + uniform(seed, pixel, first_sample + j, 1)


@njit(cache=True)
def accumulate(radiance, pass_n, rows, sum_rgb, sum_l, sum_l2, count):
    """Add pass_n consecutive samples per pixel into the per-pixel sums at `rows`: radiance,
    illuminance and its square, and the count of finite samples (a sample with a non-finite
    channel is dropped); return how many were dropped. Each pixel's pass is summed from zero
    and then added, so a distributed tile's sums (a pass from zero, added by the client) are
    bit-identical to an in-process render's."""
    l0, l1, l2 = LUMINANCE[0], LUMINANCE[1], LUMINANCE[2]
    dropped = 0
    for p in range(rows.shape[0]):
        r = g = b = lum = lum2 = 0.0
        n = 0
        for i in range(p * pass_n, (p + 1) * pass_n):
            x, y, z = radiance[i, 0], radiance[i, 1], radiance[i, 2]
            if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(z)):
                dropped += 1
                continue
            value = x * l0 + y * l1 + z * l2
            r += x
            g += y
            b += z
            lum += value
            lum2 += value * value
            n += 1
        row = rows[p]
        sum_rgb[row, 0] += r
        sum_rgb[row, 1] += g
        sum_rgb[row, 2] += b
        sum_l[row] += lum
        sum_l2[row] += lum2
        count[row] += n
    return dropped


def _check_options(spp, accel_kind, integrator, width, height, crop, options):
    if not (isinstance(spp, (int, np.integer)) and spp >= 1):
        raise PtraceError(f"samples per pixel must be a positive integer, got {spp!r}")
    if accel_kind not in accel.KINDS:
        raise PtraceError(f"unknown accelerator {accel_kind!r}; choose one of {', '.join(accel.KINDS)}")
    if integrator not in INTEGRATORS:
        raise PtraceError(f"unknown integrator {integrator!r}; choose one of {', '.join(INTEGRATORS)}")
    if width < 1 or height < 1:
        raise PtraceError(f"resolution must be at least 1x1, got {width}x{height}")
    if crop is not None:
        x, y, dx, dy = crop
        if dx < 1 or dy < 1 or x < 0 or y < 0 or x + dx > width or y + dy > height:
            raise PtraceError(f"crop cell x={x} y={y} dx={dx} dy={dy} is not inside the "
                              f"{width}x{height} image")
    unknown = set(options) - {"light_samples", "max_depth", "adaptive", "hemisphere", "roulette"}
    if unknown:
        raise PtraceError(f"unknown render option(s): {', '.join(sorted(unknown))}")
    if options.get("light_samples", 1) < 1:
        raise PtraceError("light samples must be at least 1")
    if options.get("max_depth", 1) < 0:
        raise PtraceError("max depth must not be negative")
    adaptive = options.get("adaptive")
    if adaptive is not None:
        batch, tolerance = adaptive
        if batch < 1 or not tolerance > 0:
            raise PtraceError(f"adaptive sampling needs a batch >= 1 and a tolerance > 0, "
                              f"got {batch} {tolerance}")


def render(scene, *, spp=1, accel="bvh", integrator="path", resolution=None, seed=0,
           threads=None, crop=None, camera=None, progress=False, stats=None, client=None,
           **options):
    """Render `scene`; return linear radiance as float32 (H, W, 3), top row first.

    resolution is (W, H), default the course's 800x600 (a crop of the same focal length, not a
    rescale); crop (x, y, dx, dy) renders only that cell (y counted from the bottom, like the
    course) and returns it alone; camera overrides the course's camera; options are the light
    transport flags: light_samples (-l, default 1), max_depth (-m, default 1), adaptive (-a,
    (batch, tolerance) or None), hemisphere (-H) and roulette (default True; False runs every
    path to max_depth, for comparisons: the course has no such flag). stats, if a dict, receives build and render
    seconds, rays traced, per-pixel sample counts ("samples", (H, W)), the number of non-finite
    samples dropped, and whether Ctrl-C interrupted the render.
    """
    accel_kind = accel
    width, height = (BASE_WIDTH, BASE_HEIGHT) if resolution is None else map(int, resolution)
    _check_options(spp, accel_kind, integrator, width, height, crop, options)
    previous_threads = numba.get_num_threads()
    worker_threads = None
    if client is not None:   # threads applies on the workers, not here
        if threads is not None and threads < 1:
            raise PtraceError(f"threads must be at least 1, got {threads}")
        worker_threads, threads = threads, None
    if threads is not None:
        if not 1 <= threads <= numba.config.NUMBA_NUM_THREADS:
            raise PtraceError(f"threads must be between 1 and {numba.config.NUMBA_NUM_THREADS}, "
                              f"got {threads}")
        numba.set_num_threads(threads)
    try:
        return _render(scene, int(spp), accel_kind, integrator, width, height, int(seed), crop,
                       camera, progress, stats, options, client, worker_threads)
    finally:
        numba.set_num_threads(previous_threads)


def _converged(sum_l, sum_l2, count, tolerance, batch):
    """The course's test, 1.96 sigma / sqrt(n) <= tolerance * mu on illuminance, except that a
    pixel whose samples have all been equal (sigma = 0, typically all black) is not stopped
    before it has two batches: one batch of zeros in a dim, noisy region says little."""
    n = count.astype(np.float64)
    mean = sum_l / n
    variance = np.maximum(sum_l2 - sum_l * sum_l / n, 0.0) / np.maximum(n - 1, 1)
    sigma = np.sqrt(variance)
    return (1.96 * sigma / np.sqrt(n) <= tolerance * mean) & ((sigma > 0) | (n >= 2 * batch))


def trace_pixels(tracer, camera, seed, width, spp, pixel_x, pixel_y, first_sample, pass_n,
                 sums, where, on_chunk=None):
    """Trace samples first_sample .. first_sample+pass_n-1 of the given pixels (y from the
    bottom) and add, per pixel, the sum over those samples of radiance, of illuminance and of
    its square, and the count of finite samples into sums = (rgb, l, l2, count) at rows `where`.
    Work goes to the tracer in chunks of about CHUNK_RAYS rays (bounding memory); a chunk's
    sums are added as soon as it is done, and on_chunk(samples) is called after each. Returns
    the number of non-finite samples dropped. In-process renders and distributed tiles both
    run this, so their per-pixel arithmetic is the same."""
    sum_rgb, sum_l, sum_l2, count = sums
    nonfinite = 0
    per_chunk = max(1, (CHUNK_RAYS // tracer.rays_per_path) // pass_n)
    for first in range(0, pixel_x.shape[0], per_chunk):
        px, py = pixel_x[first:first + per_chunk], pixel_y[first:first + per_chunk]
        rows = where[first:first + per_chunk]
        n = px.size * pass_n
        sx, sy = np.empty(n), np.empty(n)
        camera_samples(seed, px, py, width, first_sample, pass_n, spp, sx, sy)
        directions = camera.directions(sx, sy)
        rays = accel.Rays(np.broadcast_to(camera.position, directions.shape), directions,
                          camera.znear, camera.zfar)
        pixel_ids = np.repeat(py * width + px, pass_n)
        sample_ids = np.tile(np.arange(first_sample, first_sample + pass_n), px.size)
        radiance = tracer.trace(pixel_ids, sample_ids, rays)
        nonfinite += accumulate(radiance, pass_n, rows, sum_rgb, sum_l, sum_l2, count)
        if on_chunk is not None:
            on_chunk(n)
    return nonfinite


_MALLOC_TUNED = False


def keep_freed_memory():
    """Ask glibc's malloc to keep freed memory for reuse instead of handing it back to the OS.

    Every wave allocates and frees arrays of a few MB (rays, hits, path state). By default glibc
    returns the top of its heap to the OS once 2x the largest such array is free, and the next
    wave page-faults all of it back in, zeroed: on the cow command at 480x360 that was 760,000
    page faults and a quarter of the wall time (6.1 s against 4.4 s kept; peak memory the
    same, 199 MB). A fixed mmap threshold (32 MB, glibc's largest) keeps those arrays in the
    heap, and a 1 GB trim threshold keeps the heap. Process-wide and idempotent; nothing on
    other C libraries."""
    global _MALLOC_TUNED
    if _MALLOC_TUNED or not sys.platform.startswith("linux"):
        return
    _MALLOC_TUNED = True
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):   # not glibc (musl has no mallopt)
        return
    M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
    mallopt(M_MMAP_THRESHOLD, 32 << 20)
    mallopt(M_TRIM_THRESHOLD, 1 << 30)


def make_tracer(scene, backend, seed, integrator, options):
    keep_freed_memory()
    return PathTracer(scene, backend, seed, integrator,
                      light_samples=int(options.get("light_samples", 1)),
                      max_depth=int(options.get("max_depth", 1)),
                      hemisphere=bool(options.get("hemisphere", False)),
                      roulette=bool(options.get("roulette", True)))


def _render(scene, spp, accel_kind, integrator, width, height, seed, crop, camera, progress,
            stats, options, client, worker_threads):
    camera = course_camera(scene, width, height) if camera is None else camera.resized(width, height)
    x0, y0, cell_w, cell_h = crop if crop is not None else (0, 0, width, height)
    # the client side needs a tracer only for its warnings and rays per path
    tracer = make_tracer(scene, None, seed, integrator, options)
    for message in tracer.warnings:
        warnings.warn(message, RuntimeWarning, stacklevel=3)
    adaptive = options.get("adaptive")
    batch = int(adaptive[0]) if adaptive is not None else min(spp, PASS_SAMPLES)
    ys, xs = np.mgrid[y0:y0 + cell_h, x0:x0 + cell_w]
    pixel_x = xs.reshape(-1).astype(np.int64)
    pixel_y = ys.reshape(-1).astype(np.int64)
    n_pixels = pixel_x.shape[0]
    sums = (np.zeros((n_pixels, 3)), np.zeros(n_pixels), np.zeros(n_pixels),
            np.zeros(n_pixels, dtype=np.int64))
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n_pixels * spp, unit="spl", unit_scale=True, leave=False,
                   file=sys.stderr)
    passes = Passes(spp, batch, None if adaptive is None else adaptive[1], sums, bar)
    if client is not None:
        from . import distributed
        outcome = distributed.render_passes(client, scene, accel_kind, integrator, options,
                                            seed, width, spp, camera, tracer.rays_per_path,
                                            pixel_x, pixel_y, passes, worker_threads)
    else:
        outcome = _render_in_process(scene, accel_kind, integrator, options, seed, width, spp,
                                     camera, pixel_x, pixel_y, passes)
    if bar is not None:
        bar.close()
    sum_rgb, count = sums[0], sums[3]
    image = np.where(count[:, None] > 0, sum_rgb / np.maximum(count, 1)[:, None], 0.0)
    if stats is not None:
        stats.update(outcome, spp=spp, samples=count.reshape(cell_h, cell_w)[::-1].copy())
    # rows were generated bottom row first; the returned image has the top row first
    return image.reshape(cell_h, cell_w, 3)[::-1].astype(np.float32)


class Passes:
    """The pass schedule, shared by in-process and distributed renders: pass sizes depend only
    on -s and -a; after each pass, adaptive sampling retires the converged active pixels."""

    def __init__(self, spp, batch, tolerance, sums, bar):
        self.spp, self.batch, self.tolerance, self.sums, self.bar = spp, batch, tolerance, sums, bar
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
                stop = _converged(sum_l[a], sum_l2[a], count[a], self.tolerance, self.batch)
                if self.bar is not None:
                    self.bar.update(int(stop.sum()) * (self.spp - self.done))
                self.active = a[~stop]

    @property
    def adaptive(self):
        return self.tolerance is not None

    def fixed(self):
        """The whole schedule up front (only without adaptive sampling)."""
        assert not self.adaptive
        schedule, done = [], 0
        while done < self.spp:
            pass_n = min(self.batch, self.spp - done)
            schedule.append((done, pass_n))
            done += pass_n
        return schedule

    def update(self, samples):
        if self.bar is not None:
            self.bar.update(samples)


def _render_in_process(scene, accel_kind, integrator, options, seed, width, spp, camera,
                       pixel_x, pixel_y, passes):
    start = time.perf_counter()
    backend = accel.build(accel_kind, scene.geometry)
    build_seconds = time.perf_counter() - start
    start = time.perf_counter()
    tracer = make_tracer(scene, backend, seed, integrator, options)
    nonfinite = 0
    interrupted = False
    try:
        for first_sample, pass_n, active in passes:
            nonfinite += trace_pixels(tracer, camera, seed, width, spp, pixel_x[active],
                                      pixel_y[active], first_sample, pass_n, passes.sums, active,
                                      passes.update)
    except KeyboardInterrupt:
        interrupted = True
    return dict(build_seconds=build_seconds, render_seconds=time.perf_counter() - start,
                rays=tracer.rays_traced, accel=backend.stats(), nonfinite=nonfinite,
                interrupted=interrupted)
