"""render(): validate the settings, pick an executor, assemble the image.

The work itself is ptrace.rendering.tiles (the pass schedule and the render job, through the
wavefront's compiled stages, ptrace.kernel); an executor runs it in this process
(ptrace.rendering.executors) or on a Dask cluster (ptrace.rendering.distributed), and
ptrace.rendering.timing clocks the phases. Random numbers are keyed by (seed, pixel, sample,
dimension), and pass sizes depend only on -s and -a, so an image does not depend on threads, chunks,
tiles or backend.
"""
import math
import sys
import warnings

import numba
import numpy as np

from ..budget import Budget, check_render, size_text
from ..camera import BASE_HEIGHT, BASE_WIDTH
from ..errors import PtraceError
from ..features import FEATURES, aov_images
from ..jit import cache_notes
from ..pointing import default_camera
from .executors import render_in_process
from .settings import Settings
from .tiles import Passes, new_sums
from .timing import DASK_PHASES, IN_PROCESS_PHASES, Phases

MAX_SIDE = 1 << 20   # pixels per side of the image (-r), a crop's window included
# bytes held per rendered pixel: the pixel coordinates, the sums (rgb, l, l2, count), the image in
# float64 and float32, the sample counts and the output file's pixels (the feature buffers add
# FEATURE_BYTES); a render whose buffers pass the memory budget (ptrace.budget: by default half the
# machine's memory) is refused rather than left to fail (or swap) part-way
PIXEL_BYTES, FEATURE_BYTES = 160, 128


def check_frame(width, height, crop=None, features=False, max_memory=None):
    """Refuse an image size or crop the render cannot make: each side from 1 to MAX_SIDE, the
    crop inside the image, and the per-pixel buffers of the rendered cell within the memory
    budget (ptrace.budget; max_memory as there); the message says how much they would need.
    Returns the bytes of those buffers."""
    for value in (width, height):
        if not (isinstance(value, (int, np.integer)) and 1 <= value <= MAX_SIDE):
            raise PtraceError(f"resolution (-r) must be from 1 to {MAX_SIDE} pixels per side, "
                              f"got {width}x{height}")
    if crop is not None:
        x, y, dx, dy = crop
        if dx < 1 or dy < 1 or x < 0 or y < 0 or x + dx > width or y + dy > height:
            raise PtraceError(f"crop cell x={x} y={y} dx={dx} dy={dy} is not inside the "
                              f"{width}x{height} image")
    pixels = int(crop[2]) * int(crop[3]) if crop is not None else int(width) * int(height)
    need = pixels * (PIXEL_BYTES + (FEATURE_BYTES if features else 0))
    budget = Budget.of(max_memory)
    if need > budget.limit:
        raise PtraceError(f"a {pixels}-pixel render: the image buffers would need "
                          f"{size_text(need)}, more than {budget.describe()}; render a "
                          f"smaller -r or a crop (-p), or raise --max-memory")
    return need


# Embree computes in float32. Its triangle test forms products of three lengths (a ray's
# distance to the hit times the triangle's edge cross product, about twice that in all): past
# float32's largest number (3.4e38) they overflow and the hit is lost (measured: a square OBJ
# framed by the default camera renders black with embree from 5e12 across, 4.8e12 renders as
# with bvh; random rays at a cube lose hits from 4.4e12 across, at a square from 5e12; the
# warning's bound starts at 3.2e12 and 3.6e12: benchmarks/results/hostile_inputs.md)
FLOAT32_MAX = float(np.finfo(np.float32).max)
EMBREE_PRODUCT_FACTOR = 2.0
CHUNK_TRIANGLES = 1 << 20     # the exact check's triangles at a time (bounded temporaries)


def embree_overflow(geometry):
    """None, or (largest triangle's edge cross product, the triangles' box diagonal, the bound
    on Embree's product) when Embree's float32 triangle test can overflow on this geometry and
    lose hits. The bound takes a ray's distance to a hit as at most three diagonals of the
    triangles' box: accel.embree moves an origin farther than its scale (under two diagonals)
    from the box to where the ray enters it, and the hit lies within one more diagonal."""
    if geometry.triangle_count == 0:
        return None
    vertices, faces = geometry.vertices, geometry.faces
    # first a bound from every vertex's box (the cross product is at most its diagonal squared):
    # the scenes far below the limit pay two passes over the vertices and no more
    diagonal = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    if not EMBREE_PRODUCT_FACTOR * 3.0 * diagonal ** 3 > FLOAT32_MAX:
        return None
    largest, lower, upper = 0.0, np.full(3, np.inf), np.full(3, -np.inf)
    for start in range(0, len(faces), CHUNK_TRIANGLES):
        corners = vertices[faces[start:start + CHUNK_TRIANGLES]]
        lower = np.minimum(lower, corners.min(axis=(0, 1)))
        upper = np.maximum(upper, corners.max(axis=(0, 1)))
        cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        largest = max(largest, float(np.sqrt(np.einsum("ij,ij->i", cross, cross)).max()))
    diagonal = float(np.linalg.norm(upper - lower))      # the triangles' own box
    product = EMBREE_PRODUCT_FACTOR * 3.0 * diagonal * largest
    return (largest, diagonal, product) if product > FLOAT32_MAX else None


def scene_warnings(scene, settings):
    """What a user should hear about this scene and these settings before a render."""
    out = []
    overflow = embree_overflow(scene.geometry) if settings.accel == "embree" else None
    if overflow is not None:
        cross, diagonal, product = overflow
        out.append(f"--accel embree computes in float32, and this scene's triangles are too "
                   f"large for it: the largest spans about {math.sqrt(cross):.3g} (its edges' "
                   f"cross product {cross:.3g}) in a scene {diagonal:.3g} across, and Embree's "
                   f"products of such lengths (up to {product:.3g}) pass float32's "
                   f"{FLOAT32_MAX:.3g}: it can lose hits and draw those triangles black; "
                   f"--accel bvh computes in float64")
    emitters = np.isin(scene.material_index,
                       np.nonzero(scene.materials.emits())[0]).any()
    if settings.integrator == "path" and not emitters and len(scene.lights) == 0:
        out.append("the scene has no light and no emissive surface: the image will be black")
    elif settings.integrator == "path" and settings.hemisphere and settings.max_depth >= 1:
        if not emitters and scene.environment is None:
            out.append("hemisphere sampling (-H) sees only emissive geometry and an environment "
                       "and this scene has neither (its lights are point, directional, ambient "
                       "or area lights without a mesh): direct light will be black")
    return out


def render(scene, *, spp=None, accel="bvh", integrator="path", resolution=None, seed=0,
           threads=None, crop=None, camera=None, progress=False, stats=None, client=None,
           notice=None, aovs=None, max_memory=None, **options):
    """Render `scene`; return linear radiance as float32 (H, W, 3), top row first.

    spp (default 1), max_depth and rr_depth not given, and resolution and the thin lens
    without a camera, are the scene's own (scene.render_defaults: a Mitsuba scene's film,
    sampler, integrator and thinlens sensor) where it has them.
    resolution is (W, H), default the camera's own size, or without a camera the course's
    800x600; camera (a ptrace.Camera: ptrace.course_camera, ptrace.look_at, ...) replaces
    the scene's default camera (ptrace.pointing.default_camera: the course's for a course scene,
    a size other than 800x600 being a crop of the same focal length, not a rescale; for a mesh
    file, one that frames the scene's bounds at that size), and a given resolution other than
    its own keeps its focal length in pixels; crop (x, y, dx, dy) renders only that cell (y
    counted from the bottom, like the course) and returns it alone; options are the light transport
    flags of ptrace.rendering.settings.Settings: light_samples (-l, default 1), max_depth (-m,
    default 1), adaptive (-a, (batch, tolerance) or None), hemisphere (-H) and roulette
    (default True; False runs every path to max_depth, for comparisons: the course has no such
    flag), direct, sampler, rr_depth, hide_emitters (a Mitsuba scene's own unless given) and
    bvh_split ("mean" or "sah", with accel="bvh"). stats,
    if a dict, receives build and render seconds, rays traced, per-pixel sample counts
    ("samples", (H, W)), the number of non-finite samples dropped, whether Ctrl-C interrupted
    the render, "phases" ({phase: wall seconds} of ptrace.rendering.timing.IN_PROCESS_PHASES, or
    DASK_PHASES with a client: they cover this call without overlapping) and "counts" (passes
    and kernel calls in-process, functions numba compiled; tasks on Dask). client renders on a
    Dask cluster; notice, if given, is called with a one-line message when the kernels must be
    compiled first (a cold numba cache). aovs, if a dict, receives the feature buffers of
    ptrace.features ("albedo" and "normal" (H, W, 3), "depth" (H, W)), averaged per pixel over
    the same samples as the image, at the cost of one more ray per sample (in-process only);
    the image is the same bits with or without them. max_memory (bytes, a size such as "4G", or
    a ptrace.budget.Budget; default half the machine's memory, see ptrace.budget) bounds the
    estimate of what the render needs (the scene, the backend's structure, the per-pixel
    buffers): past it, a BudgetError names the scene and the figures.
    """
    phases = Phases(IN_PROCESS_PHASES if client is None else DASK_PHASES)
    phases.enter("setup")
    try:
        defaults = getattr(scene, "render_defaults", None) or {}
        spp = defaults.get("spp", 1) if spp is None else spp
        for name in ("max_depth", "rr_depth", "hide_emitters"):
            if name in defaults:
                options.setdefault(name, defaults[name])
        settings = Settings.from_options(spp=spp, accel=accel, integrator=integrator, seed=seed,
                                         **options)
        if resolution is not None:
            width, height = resolution
        elif camera is not None:
            width, height = camera.width, camera.height
        elif "resolution" in defaults:
            width, height = defaults["resolution"]
        else:
            width, height = BASE_WIDTH, BASE_HEIGHT
        buffers = check_frame(width, height, crop, features=aovs is not None,
                              max_memory=max_memory)
        check_render(scene, settings.accel, buffers, max_memory,
                     settings.light_tree_entries(scene))
        width, height = int(width), int(height)
        previous_threads = numba.get_num_threads()
        worker_threads = None
        if client is not None:   # threads applies on the workers, not here
            if threads is not None and threads < 1:
                raise PtraceError(f"threads must be at least 1, got {threads}")
            worker_threads, threads = threads, None
        if threads is not None:
            if not 1 <= threads <= numba.config.NUMBA_NUM_THREADS:
                raise PtraceError(f"threads must be between 1 and "
                                  f"{numba.config.NUMBA_NUM_THREADS}, got {threads}")
            numba.set_num_threads(threads)
        try:
            image = _render(scene, settings, width, height, crop, camera, progress, stats,
                            client, worker_threads, notice, phases, aovs)
            for text in cache_notes(clear=True):   # a fallback cache folder, a file recompiled
                warnings.warn(text, RuntimeWarning, stacklevel=2)
            return image
        finally:
            numba.set_num_threads(previous_threads)
    finally:
        phases.stop()
        if stats is not None:
            stats.update(phases=dict(phases.seconds), counts=dict(phases.counts))


def _render(scene, settings, width, height, crop, camera, progress, stats, client,
            worker_threads, notice, phases, aovs):
    if camera is None:      # with the scene's own thin lens (a Mitsuba thinlens sensor's)
        defaults = getattr(scene, "render_defaults", None) or {}
        camera = default_camera(scene, width, height).with_lens(
            defaults.get("lens_radius"), defaults.get("focal_distance"))
    else:
        camera = camera.resized(width, height)
    x0, y0, cell_w, cell_h = crop if crop is not None else (0, 0, width, height)
    for message in scene_warnings(scene, settings):
        warnings.warn(message, RuntimeWarning, stacklevel=4)
    ys, xs = np.mgrid[y0:y0 + cell_h, x0:x0 + cell_w]
    pixel_x = xs.reshape(-1).astype(np.int64)
    pixel_y = ys.reshape(-1).astype(np.int64)
    n_pixels = pixel_x.shape[0]
    sums = new_sums(n_pixels)
    if settings.guiding != "off" and client is not None:
        raise PtraceError("guiding (--guiding) renders in-process only, not on a Dask cluster")
    if aovs is not None and client is not None:
        raise PtraceError("AOVs (--aov, --denoise) are rendered in-process only, not on a Dask "
                          "cluster")
    features = np.zeros((n_pixels, FEATURES)) if aovs is not None else None
    bar = None
    if progress:
        # tqdm.auto: the notebook's widget under Jupyter, the terminal's bar elsewhere
        from tqdm.auto import tqdm
        bar = tqdm(total=n_pixels * settings.spp, unit="spl", unit_scale=True, leave=False,
                   file=sys.stderr)
    passes = Passes(settings, sums, bar)
    try:
        if client is None:
            outcome = render_in_process(scene, settings, camera, pixel_x, pixel_y, passes,
                                        phases, notice, features)
        else:
            from . import distributed
            outcome = distributed.render_passes(client, scene, settings, camera, pixel_x,
                                                pixel_y, passes, phases, worker_threads)
    finally:
        if bar is not None:
            bar.close()
    phases.enter("image")
    sum_rgb, count = sums[0], sums[3]
    image = np.where(count[:, None] > 0, sum_rgb / np.maximum(count, 1)[:, None], 0.0)
    if aovs is not None:
        aovs.update(aov_images(features, count, (cell_h, cell_w)))
    if stats is not None:
        stats.update(outcome, spp=settings.spp,
                     samples=count.reshape(cell_h, cell_w)[::-1].copy())
    # rows were generated bottom row first; the returned image has the top row first
    return image.reshape(cell_h, cell_w, 3)[::-1].astype(np.float32)
