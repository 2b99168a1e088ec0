"""The render loop: camera rays in chunks of pixels, one batched intersect per chunk, shading
kernels on the hits, per-pixel means. Python runs once per chunk; numba kernels once per ray."""
import time

import numba
import numpy as np
from numba import njit, prange

import accel

from .camera import BASE_HEIGHT, BASE_WIDTH, course_camera
from .errors import PtraceError
from .sampling import uniform
from .shading import normal_colours, shading_normals

INTEGRATORS = ("path", "normals")
CHUNK_RAYS = 1 << 16   # rays per batch: bounds memory at about 200 bytes x 65536 per array set


@njit(cache=True, parallel=True)
def camera_samples(seed, pixel_x, pixel_y, width, spp, out_x, out_y):
    """Image-plane points for spp samples of each pixel (y from the bottom): the pixel centre
    when spp is 1, else uniform jitter from the counter-based hash (CS184.md 4.1)."""
    for k in prange(pixel_x.shape[0]):
        pixel = pixel_y[k] * width + pixel_x[k]
        for s in range(spp):
            i = k * spp + s
            if spp == 1:
                out_x[i] = pixel_x[k] + 0.5
                out_y[i] = pixel_y[k] + 0.5
            else:
                out_x[i] = pixel_x[k] + uniform(seed, pixel, s, 0)
                out_y[i] = pixel_y[k] + uniform(seed, pixel, s, 1)


def _check_options(spp, accel_kind, integrator, width, height, crop):
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


def render(scene, *, spp=1, accel="bvh", integrator="path", resolution=None, seed=0,
           threads=None, crop=None, camera=None, progress=False, stats=None, **options):
    """Render `scene`; return linear radiance as float32 (H, W, 3), top row first.

    resolution is (W, H), default the course's 800x600 (a crop of the same focal length, not a
    rescale); crop (x, y, dx, dy) renders only that cell (y counted from the bottom, like the
    course) and returns it alone; camera overrides the course's camera; stats, if a dict, is
    filled with build and render seconds and rays traced. options carry the light-transport
    flags (light_samples, max_depth, adaptive, hemisphere).
    """
    accel_kind = accel
    width, height = (BASE_WIDTH, BASE_HEIGHT) if resolution is None else map(int, resolution)
    _check_options(spp, accel_kind, integrator, width, height, crop)
    if integrator == "path":
        raise PtraceError("the path integrator is not there yet (light transport is the next "
                          "milestone); use --integrator normals")
    previous_threads = numba.get_num_threads()
    if threads is not None:
        if not 1 <= threads <= numba.config.NUMBA_NUM_THREADS:
            raise PtraceError(f"threads must be between 1 and {numba.config.NUMBA_NUM_THREADS}, "
                              f"got {threads}")
        numba.set_num_threads(threads)
    try:
        return _render(scene, spp, accel_kind, width, height, int(seed), crop, camera,
                       progress, stats)
    finally:
        numba.set_num_threads(previous_threads)


def _render(scene, spp, accel_kind, width, height, seed, crop, camera, progress, stats):
    camera = course_camera(scene, width, height) if camera is None else camera.resized(width, height)
    x0, y0, cell_w, cell_h = crop if crop is not None else (0, 0, width, height)
    start = time.perf_counter()
    backend = accel.build(accel_kind, scene.geometry)
    build_seconds = time.perf_counter() - start

    start = time.perf_counter()
    ys, xs = np.mgrid[y0:y0 + cell_h, x0:x0 + cell_w]
    pixel_x = xs.reshape(-1).astype(np.int64)
    pixel_y = ys.reshape(-1).astype(np.int64)
    n_pixels = pixel_x.shape[0]
    image = np.zeros((n_pixels, 3))
    per_chunk = max(1, CHUNK_RAYS // spp)
    chunks = range(0, n_pixels, per_chunk)
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n_pixels, unit="px", unit_scale=True, leave=False)
    rays_traced = 0
    geometry = scene.geometry
    for first in chunks:
        last = min(first + per_chunk, n_pixels)
        cx, cy = pixel_x[first:last], pixel_y[first:last]
        n = (last - first) * spp
        sx, sy = np.empty(n), np.empty(n)
        camera_samples(seed, cx, cy, width, spp, sx, sy)
        directions = camera.directions(sx, sy)
        origins = np.broadcast_to(camera.position, directions.shape)
        rays = accel.Rays(origins, directions, camera.znear, camera.zfar)
        hits = backend.intersect(rays)
        rays_traced += n
        normals = shading_normals(scene.vertex_normals, geometry.faces, geometry.centers,
                                  geometry.radii, rays.origins, rays.directions, hits.t,
                                  hits.prim, hits.u, hits.v, np.empty((n, 3)))
        colours = normal_colours(normals, hits.prim, np.empty((n, 3)))
        image[first:last] = colours.reshape(last - first, spp, 3).mean(axis=1)
        if bar is not None:
            bar.update(last - first)
    if bar is not None:
        bar.close()
    render_seconds = time.perf_counter() - start
    if stats is not None:
        stats.update(build_seconds=build_seconds, render_seconds=render_seconds,
                     rays=rays_traced, accel=backend.stats())
    # rows were generated bottom row first; the returned image has the top row first
    return image.reshape(cell_h, cell_w, 3)[::-1].astype(np.float32)
