"""Where a render's wall time goes in the megakernel (--loop megakernel), whose path loop is one
compiled kernel.

    python -m benchmarks.profile_render [--quick] [--repeats N] [--threads T]
                                        [--resolution WxH] [--only NAME ...] [--output NAME]

A render is: settings, camera and pixel grid (ptrace.rendering.renderer), accel.build, then
passes in which ptrace.rendering.tiles.TileWork.trace hands blocks of pixels to a pool of Python
threads, each running ptrace.integrator.render_pixels (nogil) that carries every path from the
camera to its end, calling the accelerator's compiled face per ray; no Python runs between
bounces. So:

1. Wall time (measured). The render's own phases (stats["phases"],
   ptrace.rendering.timing.Phases): setup, compile, build, records, render (the passes) and
   image. ptrace.rendering.tiles.render_pixels is replaced at Python level by a wrapper that
   records each call's start and end (put back in a `finally`), which splits the passes further.
   The wall time splits, exactly, into the build, compiling, the kernel records, setup and image
   assembly, the passes' time with no render_pixels call running, the time inside the calls'
   span when a thread is idle, and the calls' own seconds (thread-seconds / threads).
2. Inside the loop (measured, by differencing): the same command rendered with less work, on
   the same pixels, samples and backend: normal shading (camera rays and closest hit only),
   -m 0 (plus the surface and its emission), -m 1 (plus direct light at the first vertex) and
   the full command. Each row is a difference of median render_pixels thread-seconds.
3. The accelerator's part (estimated). One more render of the command runs uncached copies of
   the loop's compiled functions whose ray queries go through a counting face around the
   backend's: it counts closest-hit rays from the camera, closest-hit rays from surfaces and
   any-hit rays exactly, and copies every ray of a few evenly spaced blocks, in order (the same
   answers, so the same image). Those rays are replayed through the backend's compiled
   closest_hit / any_hit the way the loop runs (serial nogil calls on blocks, on a pool of
   Python threads, each call timed); thread-seconds per ray times the counts is the
   estimate. Beside it: the same rays through the batch face (backend.intersect / occluded,
   prange on numba's threading layer), and synthetic rays (accel.raygen.surface_rays)
   replayed loop-style, to show how far either would put the estimate.

Commands run on 2 threads after compiling and one untimed render. --quick: 120x90, -s divided
by 16, one repeat. Writes benchmarks/results/profile_render.md (--output NAME). A backend that
fails (the embree backend while it is being rewritten) is skipped with a note.
"""
import argparse
import contextlib
import functools
import math
import os
import threading
import time
from collections import namedtuple
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numba
import numpy as np
from numba import njit

from accel.compiled import any_hit, closest_hit, new_scratch

from . import report
from .rays import scenes_dir

# name: (scene, spp, light samples, max depth, integrator, backend); all at RESOLUTION
COMMANDS = {
    "cow -s 64 -l 16 -m 6 (bvh)": ("meshedit/cow.dae", 64, 16, 6, "path", "bvh"),
    "cow -s 64 -l 16 -m 6 (embree)": ("meshedit/cow.dae", 64, 16, 6, "path", "embree"),
    "CBbunny -s 16 -l 8 -m 6 (bvh)": ("sky/CBbunny.dae", 16, 8, 6, "path", "bvh"),
    "CBbunny -s 16 -l 8 -m 6 (embree)": ("sky/CBbunny.dae", 16, 8, 6, "path", "embree"),
    "cow normals -s 1 (bvh)": ("meshedit/cow.dae", 1, 1, 1, "normals", "bvh"),
}
RESOLUTION, QUICK_RESOLUTION, QUICK_SPP_DIVISOR = (480, 360), (120, 90), 16
CAPTURE_RAYS = 250_000     # rays of each kind copied by the counting face, at most about
REPLAY_BLOCK = 4096        # rays per timed call when they are replayed
BATCH_SECONDS, QUICK_BATCH_SECONDS = 0.3, 0.05   # least timing per replayed batch

# wall-time phases (section 1), in the order of the table
BUILD = "acceleration structure build (accel.build)"
COMPILE = "numba compiling or loading kernels from its cache (0 after the warm-up)"
RECORDS = "kernel records: scene, lights, camera, backend (ptrace.rendering.tiles.TileWork)"
SETUP = "render setup and image: settings, camera, pixel grid, sums, final image"
OUTSIDE = "passes with no render_pixels call running: pool hand-out, pass ends"
IDLE = "threads idle inside the calls' span: per-block Python, last blocks of a pass"
LOOP = "inside render_pixels (the compiled path loop), thread-seconds / threads"
WALL_PHASES = (BUILD, COMPILE, RECORDS, SETUP, OUTSIDE, IDLE, LOOP)

# ray kinds the counting face tells apart
CAMERA, BOUNCE, SHADOW = 0, 1, 2
KIND_LABELS = ("camera rays, closest hit", "rays from surfaces, closest hit (bounce rays)",
               "shadow rays, any hit")

# the differencing ladder (section 2): (render, label, the ray kind its extra rays are)
LADDER = (
    ("normals", "camera rays, closest hit, normal colour, accumulation (normal-shading render)",
     CAMERA),
    ("m0", "surface at the first hit and its emission (-m 0 minus normal shading)", None),
    ("m1", "direct light at the first vertex: light samples, shadow rays (-m 1 minus -m 0)",
     SHADOW),
    ("full", "later vertices: BSDF sample, roulette, bounce rays, their direct light "
             "(full minus -m 1)", None),
)


# -- 1. wall time --------------------------------------------------------------------------------

def union_seconds(intervals):
    """Seconds covered by at least one of the (start, end) intervals."""
    total, reach = 0.0, -math.inf
    for start, end in sorted(intervals):
        if end <= reach:
            continue
        total += end - max(start, reach)
        reach = end
    return total


class KernelClock:
    """Start and end (time.perf_counter) of every render_pixels call, from any thread."""

    def __init__(self):
        self.intervals = []

    def wrap(self, function):
        @functools.wraps(function)
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self.intervals.append((start, time.perf_counter()))   # list.append is atomic
        return timed


@contextlib.contextmanager
def patched(owner, name, value):
    """owner.name = value for the length of the block; the original is put back whatever
    happens."""
    original = getattr(owner, name)
    setattr(owner, name, value)
    try:
        yield original
    finally:
        setattr(owner, name, original)


@dataclass
class Run:
    """One render's measured figures."""
    image: np.ndarray
    wall: float
    stats: dict
    threads: int
    intervals: list = field(default_factory=list)

    @property
    def calls(self):
        return len(self.intervals)

    @property
    def thread_seconds(self):
        return sum(end - start for start, end in self.intervals)

    @property
    def span(self):
        return union_seconds(self.intervals)

    @property
    def rays(self):
        return int(self.stats["rays"])

    def phases(self):
        """{phase: seconds} of section 1, from the render's phases (stats["phases"]) and the
        render_pixels calls; they add up to the wall time exactly. Setup also takes the
        microseconds of the call outside the render's clock. (A call that compiles would put
        its compile seconds in both COMPILE and the calls' span: every timed render is warm.)"""
        timed = self.stats["phases"]
        span, loop = self.span, self.thread_seconds / self.threads
        setup = self.wall - sum(timed.values()) + timed["setup"] + timed["image"]
        return {BUILD: timed["build"], COMPILE: timed["compile"], RECORDS: timed["records"],
                SETUP: setup, OUTSIDE: timed["render"] - span, IDLE: span - loop, LOOP: loop}

    @property
    def busy(self):
        """Share of the threads' time inside the calls' span spent in a call."""
        span = self.span
        return self.thread_seconds / (self.threads * span) if span > 0 else 0.0


def timed_render(scene, threads, **options):
    """ptrace.render(scene, threads=threads, **options) with render_pixels timed: the
    megakernel's (loop="megakernel" unless options say otherwise), whose one compiled loop is
    what this profile splits."""
    import ptrace
    import ptrace.rendering.tiles
    clock, stats = KernelClock(), {}
    options = dict(options, loop=options.get("loop", "megakernel"))
    tiles = ptrace.rendering.tiles
    with patched(tiles, "render_pixels", clock.wrap(tiles.render_pixels)):
        start = time.perf_counter()
        image = ptrace.render(scene, threads=threads, stats=stats, **options)
        wall = time.perf_counter() - start
    return Run(image, wall, stats, threads, clock.intervals)


def median_run(runs, key):
    return sorted(runs, key=key)[len(runs) // 2]


# -- 3. the counting face ------------------------------------------------------------------------
#
# The counting render runs copies of the path loop's compiled functions (render_pixels and
# every ptrace.integrator function on the way to a ray query) whose closest_hit and any_hit are
# the counting ones below: each query is counted by kind in its block's row, copied out for a
# few blocks, then answered by the backend's own compiled face. The copies and the counting
# functions are compiled without numba's on-disk cache, and nothing is registered with
# accel.compiled: a cache index of ptrace or accel that named a type of this module could not
# be read by a process that cannot import it, and numba reads the whole index before it looks
# for an entry. The backend's own functions are called only with the backend's own record.
# Ray fields: origin (3), direction (3), tmin, tmax.

RAY_FIELDS = 8
CountingRecord = namedtuple("CountingRecord", ["inner", "camera", "counts", "offsets",
                                               "capacity", "rays"])


@njit(_nrt=False)
def _tally(record, row, kind, ox, oy, oz, dx, dy, dz, tmin, tmax):
    n = record.counts[row, kind]
    record.counts[row, kind] = n + 1
    base = record.offsets[row, kind]
    if base >= 0 and n < record.capacity[kind]:
        out = record.rays
        i = base + n
        out[i, 0], out[i, 1], out[i, 2] = ox, oy, oz
        out[i, 3], out[i, 4], out[i, 5] = dx, dy, dz
        out[i, 6], out[i, 7] = tmin, tmax


@njit(_nrt=False)
def _counting_closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    eye = record.camera
    kind = CAMERA if ox == eye[0] and oy == eye[1] and oz == eye[2] else BOUNCE
    _tally(record, scratch[1], kind, ox, oy, oz, dx, dy, dz, tmin, tmax)
    return closest_hit(record.inner, scratch[0], ox, oy, oz, dx, dy, dz, tmin, tmax)


@njit(_nrt=False)
def _counting_any_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    _tally(record, scratch[1], SHADOW, ox, oy, oz, dx, dy, dz, tmin, tmax)
    return any_hit(record.inner, scratch[0], ox, oy, oz, dx, dy, dz, tmin, tmax)


def loop_functions(namespace):
    """Names of a namespace's (a module's vars) compiled functions that reach a ray query:
    those whose code names closest_hit, any_hit or another such function."""
    from numba.core.dispatcher import Dispatcher
    functions = {name: value for name, value in namespace.items()
                 if isinstance(value, Dispatcher)}
    reach, found = {"closest_hit", "any_hit"}, set()
    while True:
        more = {name for name, f in functions.items() if name not in found
                and reach & set(f.py_func.__code__.co_names)}
        if not more:
            return found
        found |= more
        reach |= more


@functools.lru_cache(maxsize=None)
def counting_loop():
    """An uncached copy of ptrace.integrator.render_pixels that queries through the counting
    face (compiled on first call, once per backend and process)."""
    import types

    import ptrace.cutouts as cutouts
    import ptrace.integrator as integrator
    # the loop's module and the one its ray queries go through (cut-out surfaces), as one
    # namespace: the copies call each other by name
    namespace = dict(vars(cutouts), **vars(integrator))
    names = loop_functions(namespace)
    if "render_pixels" not in names:
        raise RuntimeError("ptrace.integrator.render_pixels no longer reaches closest_hit")
    functions = dict(namespace)
    namespace.update(closest_hit=_counting_closest_hit, any_hit=_counting_any_hit)
    for name in names:
        f = functions[name]
        code = f.py_func
        copy = types.FunctionType(code.__code__, namespace, code.__name__, code.__defaults__,
                                  code.__closure__)
        options = {k: v for k, v in f.targetoptions.items() if k not in ("cache", "nopython")}
        namespace[name] = njit(**options)(copy)
    return namespace["render_pixels"]


def planned_blocks(n_pixels, spp):
    """render_pixels calls a render of n_pixels pixels makes without -a: ptrace.rendering.tiles'
    pass schedule, blocks of max(1, BLOCK_PATHS // pass_n) pixels."""
    import ptrace
    from ptrace.rendering import tiles
    passes = tiles.Passes(ptrace.Settings(spp=spp), tiles.new_sums(n_pixels)).fixed()
    return sum(-(-n_pixels // max(1, tiles.BLOCK_PATHS // pass_n)) for _, pass_n in passes)


class RayCounter:
    """The counting face's state for one render: per-block counts by kind, and copies of every
    ray of each kind from evenly spaced blocks (at most capacity[kind] rays of a block, about
    `target` rays of a kind in all)."""

    def __init__(self, eye, blocks, capacity, target=CAPTURE_RAYS):
        self.eye = np.ascontiguousarray(eye, dtype=np.float64)
        self.blocks = blocks
        rows = 2 * blocks + 64            # room if ptrace.rendering.tiles splits finer than planned
        self._lock, self.used = threading.Lock(), 0   # rows handed out
        self.counts = np.zeros((rows + 1, 3), dtype=np.int64)
        self.offsets = np.full((rows + 1, 3), -1, dtype=np.int64)
        self.capacity = np.asarray(capacity, dtype=np.int64)
        self.captured_rows = []
        total = 0
        for kind in range(3):
            wanted = max(1, min(blocks, -(-target // max(1, int(self.capacity[kind])))))
            chosen = np.unique(np.linspace(0, blocks - 1, wanted).round().astype(np.int64))
            self.captured_rows.append(chosen)
            for row in chosen:
                self.offsets[row, kind] = total
                total += int(self.capacity[kind])
        self.rays = np.zeros((total, RAY_FIELDS))

    def record(self, inner):
        return CountingRecord(inner, self.eye, self.counts, self.offsets, self.capacity,
                              self.rays)

    def new_scratch(self, record):
        """What ptrace.rendering.tiles calls once per block: the backend's scratch and the block's
        row (the last row takes any overflow; check() then refuses the run)."""
        with self._lock:
            row, self.used = self.used, self.used + 1
        return new_scratch(record.inner), np.int64(min(row, self.counts.shape[0] - 1))

    def check(self):
        if self.used > self.counts.shape[0] - 1:
            raise RuntimeError(f"{self.used} render_pixels calls, more than the counting face "
                               f"has rows for ({self.counts.shape[0] - 1}): counts would race")
        return self.used

    def totals(self):
        """Rays traced by kind: (camera, bounce, shadow)."""
        return tuple(int(n) for n in self.counts[:-1].sum(axis=0))

    def captured(self, kind):
        """The copied rays of one kind, block by block in the order they were traced."""
        import accel
        parts = []
        for row in self.captured_rows[kind]:
            n = min(int(self.counts[row, kind]), int(self.capacity[kind]))
            base = int(self.offsets[row, kind])
            parts.append(self.rays[base:base + n])
        rays = np.concatenate(parts) if parts else np.zeros((0, RAY_FIELDS))
        return accel.Rays(rays[:, 0:3], rays[:, 3:6], rays[:, 6].copy(), rays[:, 7].copy())


class _Counted:
    """A built backend whose compiled face is the counting one."""

    def __init__(self, backend, record):
        self._backend, self.compiled = backend, record

    def __getattr__(self, name):
        return getattr(self._backend, name)


def counted_render(scene, threads, counter, **options):
    """A render through the counting face: (Run, the backend it built). accel.build,
    ptrace.rendering.tiles.render_pixels and ptrace.rendering.tiles.new_scratch are replaced for
    its length."""
    import accel
    import ptrace.rendering.tiles
    build, built = accel.build, []

    def counting_build(*args, **kwargs):
        backend = build(*args, **kwargs)
        built.append(backend)
        return _Counted(backend, counter.record(backend.compiled))

    loop = counting_loop()
    with patched(accel, "build", counting_build), \
            patched(ptrace.rendering.tiles, "new_scratch", counter.new_scratch), \
            patched(ptrace.rendering.tiles, "render_pixels", loop):
        run = timed_render(scene, threads, **options)
    counter.check()
    return run, built[0]


def counting_plan(scene, options, rays_traced):
    """A RayCounter for this command: capacities from the rays a plain render traced."""
    from ptrace.camera import course_camera
    width, height = options["resolution"]
    pixels, spp = width * height, options["spp"]
    blocks = planned_blocks(pixels, spp)
    camera_per_block = -(-pixels * spp // blocks)
    rest_per_block = max(0, rays_traced - pixels * spp) / blocks
    capacity = [2 * camera_per_block + 16] + [int(1.25 * rest_per_block) + 64] * 2
    eye = course_camera(scene, width, height).position
    return RayCounter(eye, blocks, capacity)


@njit(nogil=True, _nrt=False)   # uncached: it links the backend's traversal
def _replay(record, scratch, rays, start, end, shadow):
    """Rays start .. end - 1 through the compiled face, as the path loop calls it: serial, one
    ray at a time, without the GIL. Returns a checksum so that nothing is optimised away."""
    total = 0.0
    for i in range(start, end):
        if shadow:
            if any_hit(record, scratch, rays[i, 0], rays[i, 1], rays[i, 2], rays[i, 3],
                       rays[i, 4], rays[i, 5], rays[i, 6], rays[i, 7]):
                total += 1.0
        else:
            t, prim, u, v = closest_hit(record, scratch, rays[i, 0], rays[i, 1], rays[i, 2],
                                        rays[i, 3], rays[i, 4], rays[i, 5], rays[i, 6],
                                        rays[i, 7])
            total += prim
    return total


def ray_array(rays):
    """An accel.Rays as the (n, 8) array the counting face copies rays into."""
    return np.ascontiguousarray(np.column_stack([rays.origins, rays.directions, rays.tmin,
                                                 rays.tmax]))


def _repeat(run, min_seconds):
    """Median of run()'s results over at least 3 runs and min_seconds of wall time, after one
    untimed run (which compiles on first use)."""
    run()
    results, start = [], time.perf_counter()
    while len(results) < 3 or time.perf_counter() - start < min_seconds:
        results.append(run())
    return float(np.median(results))


def replay_seconds(record, rays, kind, threads, min_seconds):
    """Thread-seconds per ray of the compiled face on these rays ((n, 8) array), run the way
    ptrace.rendering.tiles runs render_pixels: blocks of REPLAY_BLOCK rays in order, a fresh
    scratch per block, on a pool of `threads` Python threads; each block's call is timed."""
    n = rays.shape[0]
    blocks = [(start, min(start + REPLAY_BLOCK, n)) for start in range(0, n, REPLAY_BLOCK)]
    shadow = kind == SHADOW

    def block(bounds):
        scratch = new_scratch(record)
        start = time.perf_counter()
        _replay(record, scratch, rays, bounds[0], bounds[1], shadow)
        return time.perf_counter() - start

    with ThreadPoolExecutor(threads) as pool:
        return _repeat(lambda: sum(pool.map(block, blocks)), min_seconds) / n


def batch_face_seconds(backend, rays, kind, threads, min_seconds):
    """Thread-seconds per ray (wall x threads / n) of backend.intersect or backend.occluded,
    the batch face (prange over blocks of 64 rays on numba's threading layer)."""
    face = backend.occluded if kind == SHADOW else backend.intersect

    def run():
        start = time.perf_counter()
        face(rays)
        return time.perf_counter() - start

    previous = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        return _repeat(run, min_seconds) * threads / len(rays)
    finally:
        numba.set_num_threads(previous)


def synthetic_rays(geometry, kind, n):
    from accel import raygen
    return raygen.surface_rays(geometry, n, seed=7 + kind)


@dataclass
class Estimate:
    """Section 3 for one command: exact counts, replayed rays, thread-seconds per ray."""
    counts: tuple
    replayed: tuple
    per_ray: tuple            # thread-seconds per ray replayed loop-style (None: no rays)
    batch_face: tuple         # the same rays through backend.intersect / occluded
    synthetic: tuple          # synthetic rays replayed loop-style (None for camera rays)
    run: Run                  # the counting render

    def seconds(self, kind, count=None):
        per_ray = self.per_ray[kind]
        n = self.counts[kind] if count is None else count
        return 0.0 if not n or per_ray is None else n * per_ray

    @property
    def traversal(self):
        return sum(self.seconds(k) for k in range(3))


def estimate(scene, options, threads, rays_traced, min_seconds):
    counter = counting_plan(scene, options, rays_traced)
    run, backend = counted_render(scene, threads, counter, **options)
    counts = counter.totals()
    record = backend.compiled
    replayed, per_ray, batch, synthetic = [], [], [], []
    for kind in range(3):
        rays = counter.captured(kind)
        replayed.append(len(rays))
        if not (len(rays) and counts[kind]):
            per_ray.append(None)
            batch.append(None)
            synthetic.append(None)
            continue
        per_ray.append(replay_seconds(record, ray_array(rays), kind, threads, min_seconds))
        batch.append(batch_face_seconds(backend, rays, kind, threads, min_seconds))
        synthetic.append(None if kind == CAMERA else replay_seconds(
            record, ray_array(synthetic_rays(scene.geometry, kind, len(rays))), kind, threads,
            min_seconds))
    return Estimate(counts, tuple(replayed), tuple(per_ray), tuple(batch), tuple(synthetic),
                    run)


# -- 2. the differencing ladder ------------------------------------------------------------------

def ladder_options(options):
    """The renders of the ladder for a path command: same pixels, samples and backend."""
    return {"normals": dict(options, integrator="normals"), "m0": dict(options, max_depth=0),
            "m1": dict(options, max_depth=1), "full": options}


def ladder_rows(loop, rays, estimate_=None):
    """Rows (label, rays, thread-s, traversal estimate, rest estimate) of section 2, from the
    median loop thread-seconds and rays traced of each ladder render. The rows add up to the
    full command's figures (a telescoping sum); the last row is the total."""
    rows, previous_loop, previous_rays = [], 0.0, 0
    counts = estimate_.counts if estimate_ is not None else None
    for name, label, kind in LADDER:
        extra_rays = rays[name] - previous_rays
        seconds = loop[name] - previous_loop
        traversal = None
        if estimate_ is not None:
            if kind is not None:
                traversal = estimate_.seconds(kind, extra_rays)
            elif name == "m0":
                traversal = 0.0
            else:   # full minus -m 1: the bounce rays and the shadow rays past the first vertex
                first_shadow = rays["m1"] - rays["m0"]
                traversal = (estimate_.seconds(BOUNCE) +
                             estimate_.seconds(SHADOW, counts[SHADOW] - first_shadow))
        rest = None if traversal is None else seconds - traversal
        rows.append((label, extra_rays, seconds, traversal, rest))
        previous_loop, previous_rays = loop[name], rays[name]
    total_traversal = None if estimate_ is None else sum(r[3] for r in rows)
    rows.append(("total: the full command's loop", rays["full"], loop["full"], total_traversal,
                 None if total_traversal is None else loop["full"] - total_traversal))
    return rows


# -- the report ----------------------------------------------------------------------------------

@dataclass
class Profile:
    """What profile_command measured for one command."""
    options: dict
    repeats: int
    full: Run                 # the full command's timed run with the median wall time
    plain: Run                # the same, without the render_pixels wrapper
    ladder: dict              # variant -> loop thread-seconds of each run
    rows: list = None         # ladder_rows (path commands)
    estimate: Estimate = None
    note: str = ""            # why there is no estimate

    def loop_wall(self, thread_seconds):
        """Thread-seconds of the ladder as wall seconds of the full run's loop phase."""
        total = self.rows[-1][2] if self.rows else self.full.thread_seconds
        return thread_seconds * self.full.phases()[LOOP] / total if total else 0.0


def _pct(part, whole):
    return 100 * part / whole if whole else 0.0


def _cell(value, digits=3):
    return "" if value is None else f"{value:.{digits}f}"


def wall_table(run):
    phases = run.phases()
    lines = ["| phase (all measured) | seconds | share of wall % |", "|---|---:|---:|"]
    for phase in WALL_PHASES:
        lines.append(f"| {phase} | {phases[phase]:.3f} | {_pct(phases[phase], run.wall):.1f} |")
    lines.append(f"| total: wall time of ptrace.render | {run.wall:.3f} | 100.0 |")
    return lines


def loop_table(profile):
    """Sections 2 and 3 in one table. Share of wall: a row's part of the loop phase."""
    rows, wall = profile.rows, profile.full.wall
    total = rows[-1][2]
    lines = ["| part of the path loop | rays traced | loop thread-s (measured) | share of loop % "
             "| share of wall % | accelerator thread-s (estimate) | rest thread-s (estimate) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for label, rays, seconds, traversal, rest in rows:
        lines.append(f"| {label} | {rays:,} | {seconds:.3f} | {_pct(seconds, total):.1f} | "
                     f"{_pct(profile.loop_wall(seconds), wall):.1f} | {_cell(traversal)} | "
                     f"{_cell(rest)} |")
    return lines


def kinds_table(est, loop_seconds):
    def micro(value):
        return _cell(None if value is None else 1e6 * value)

    lines = ["| ray kind | rays traced (counted) | rays replayed | µs per ray, thread: render's "
             "rays, loop-style | render's rays, batch face | synthetic rays, loop-style | "
             "thread-s (estimate) | share of loop % |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for kind in range(3):
        seconds = est.seconds(kind)
        lines.append(f"| {KIND_LABELS[kind]} | {est.counts[kind]:,} | {est.replayed[kind]:,} | "
                     f"{micro(est.per_ray[kind])} | {micro(est.batch_face[kind])} | "
                     f"{micro(est.synthetic[kind])} | {seconds:.3f} | "
                     f"{_pct(seconds, loop_seconds):.1f} |")
    return lines


def slowest_parts(profile):
    """The three largest parts of the wall time at the finest grain there is: (label, wall
    seconds, "measured" or "estimate")."""
    phases = profile.full.phases()
    parts = [(phase, seconds, "measured") for phase, seconds in phases.items() if phase != LOOP]
    rows = profile.rows
    if rows is not None and rows[-1][3] is not None:
        for label, _, _, traversal, rest in rows[:-1]:
            parts.append((f"{label}: accelerator", profile.loop_wall(traversal), "estimate"))
            parts.append((f"{label}: the rest", profile.loop_wall(rest), "estimate"))
    elif rows is not None:
        parts += [(label, profile.loop_wall(seconds), "measured")
                  for label, _, seconds, _, _ in rows[:-1]]
    elif profile.estimate is not None:
        traversal = profile.estimate.traversal
        parts.append((f"{LOOP}: accelerator", profile.loop_wall(traversal), "estimate"))
        parts.append((f"{LOOP}: the rest", profile.loop_wall(profile.full.thread_seconds -
                                                              traversal), "estimate"))
    else:
        parts.append((LOOP, phases[LOOP], "measured"))
    return sorted(parts, key=lambda part: -part[1])[:3]


def command_section(name, profile):
    options, full, plain, repeats = profile.options, profile.full, profile.plain, profile.repeats
    rows, est = profile.rows, profile.estimate
    width, height = options["resolution"]
    pixels = width * height
    flags = (f"-s {options['spp']}" if options["integrator"] == "normals" else
             f"-s {options['spp']} -l {options['light_samples']} -m {options['max_depth']}")
    same = np.array_equal(full.image, plain.image)
    lines = [f"## {name}", "",
             f"{width}x{height}, {options['integrator']} {flags}, {options['accel']}, "
             f"{full.threads} threads. Wall {full.wall:.3f} s (the timed run with the median "
             f"wall of {repeats}); un-profiled wall {plain.wall:.3f} s; profiled and "
             f"un-profiled images {'identical' if same else 'DIFFERENT'}. {full.rays:,} rays "
             f"traced ({full.rays / (pixels * options['spp']):.2f} per path), {full.calls:,} "
             f"render_pixels calls, threads busy {100 * full.busy:.1f}% of the calls' span.",
             "", "### Wall time", ""] + wall_table(full) + [""]
    if rows is not None:
        lines += ["### Inside the loop: differencing (measured), the accelerator (estimated)", "",
                  f"Loop thread-seconds are medians of {repeats} render{'s' * (repeats > 1)} of "
                  "each variant; a row is the difference between a variant and the one before "
                  "it, so a part smaller than the run-to-run noise can come out negative. "
                  "Accelerator: the row's rays times the replayed thread-seconds per ray of "
                  "their kind (below); rest = measured minus that: shading, sampling, camera "
                  "rays, accumulation. Share of wall: the row's part of the loop phase.", ""]
        lines += loop_table(profile) + [""]
        spread = ", ".join(f"{key} {min(values):.3f}-{max(values):.3f}"
                           for key, values in profile.ladder.items())
        lines += [f"Loop thread-seconds over the runs (min-max): {spread}.", ""]
    if est is not None:
        counted = sum(est.counts)
        lines += ["### The accelerator by ray kind (estimate)", ""]
        lines += kinds_table(est, full.thread_seconds) + [""]
        checks = [f"counted rays {counted:,} {'=' if counted == full.rays else '!='} rays "
                  f"traced {full.rays:,}",
                  f"camera rays {est.counts[CAMERA]:,} "
                  f"{'=' if est.counts[CAMERA] == pixels * options['spp'] else '!='} pixels x spp",
                  "counting-face image "
                  f"{'identical' if np.array_equal(est.run.image, plain.image) else 'DIFFERENT'}"]
        if rows is not None:
            checks.append(f"the normal-shading render's loop {rows[0][2]:.3f} thread-s against "
                          f"its estimated camera-ray traversal {rows[0][3]:.3f}")
        lines += ["Checks: " + "; ".join(checks) + ".", ""]
    elif profile.note:
        lines += [f"No accelerator estimate: {profile.note}.", ""]
    lines += ["Three slowest parts:", ""]
    for i, (label, seconds, how) in enumerate(slowest_parts(profile), 1):
        lines.append(f"{i}. {label}: {seconds:.3f} s, {_pct(seconds, full.wall):.1f}% of wall "
                     f"({how})")
    return lines + [""]


def summary_table(results):
    lines = ["## Summary", "",
             "Shares of wall time. Build, glue (compiling, kernel records, setup, passes outside "
             "the calls, idle threads) and loop are measured; the accelerator's share of the "
             "loop is an estimate.", "",
             "| command | backend | wall s | build % | glue % | loop % | accelerator % of loop "
             "(estimate) | threads busy % |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for name, profile in results.items():
        command, backend = name.rsplit(" (", 1)
        backend = backend.rstrip(")")
        if isinstance(profile, str):
            lines.append(f"| {command} | {backend} | skipped | | | | | |")
            continue
        run, est = profile.full, profile.estimate
        phases = run.phases()
        glue = sum(phases[phase] for phase in (COMPILE, RECORDS, SETUP, OUTSIDE, IDLE))
        accelerator = "" if est is None else f"{_pct(est.traversal, run.thread_seconds):.1f}"
        lines.append(f"| {command} | {backend} | {run.wall:.3f} | "
                     f"{_pct(phases[BUILD], run.wall):.1f} | {_pct(glue, run.wall):.1f} | "
                     f"{_pct(phases[LOOP], run.wall):.1f} | {accelerator} | "
                     f"{100 * run.busy:.1f} |")
    return lines + [""]


METHOD = (
    "Method. Measured: the wall time of ptrace.render; its phases (stats['phases']: setup, "
    "compile, build, records, render, image); the start and end of every "
    "ptrace.rendering.tiles.render_pixels call, from a Python-level wrapper that is put back "
    "afterwards (library code is unchanged). The calls run on {threads} Python threads at once, "
    "so the wall time splits exactly into: build; compiling; kernel records; setup and image "
    "assembly; passes with no call running; the calls' span minus their thread-seconds / threads "
    "(threads idle); and the calls' thread-seconds / threads (the loop). Measured by "
    "differencing: the same command as normal shading, -m 0, -m 1 and in full, on the same "
    "pixels, samples and backend (a path's first vertices do not depend on -m, so each "
    "variant does a prefix of the next one's work); each row is a "
    "difference of median loop thread-seconds and of the exact rays traced (stats). "
    "Estimated: the accelerator's thread-seconds. One more render of the command runs copies "
    "of the loop's compiled functions whose ray queries go through a counting face (the "
    "backend's answers, so the same image; compiled once per backend and process, without "
    "numba's disk cache): it counts camera, bounce and shadow queries exactly and copies every "
    "ray of evenly spaced blocks. Those rays, replayed in order through the backend's compiled "
    "closest_hit / any_hit as the loop calls them (serial nogil calls on blocks of {block} "
    "rays, a pool of {threads} Python threads, each call timed), give thread-seconds per ray, "
    "times the counts. The estimate leaves out what the loop pays and a replay does not "
    "(caches shared with shading; a path's rays alternate kinds), so it is a guide, not a "
    "measurement; the normal-shading check compares it with a measured loop that is mostly "
    "camera-ray traversal. Beside it: the batch face on the same rays (backend.intersect / "
    "occluded: prange over 64-ray blocks on numba's threading layer, wall x threads / rays; "
    "its static split suffers most from a busy machine) and synthetic rays "
    "(accel.raygen.surface_rays: random points on triangles, random directions, no tmax) "
    "replayed loop-style. Scenes are loaded and kernels compiled before timing; each command "
    "runs once untimed first. Thread-seconds include any wait for a core: load average (1 min) "
    "{load_start:.2f} at the start, {load_end:.2f} at the end.")


def profile_command(scene, options, threads, repeats, min_seconds, log):
    """Measure one command: its ladder of variants (or the command alone for normal
    shading), an un-profiled run, and the accelerator estimate. Returns a Profile."""
    import ptrace
    log("compiling and warming up")
    tiny = dict(options, spp=2, max_depth=min(options["max_depth"], 2), resolution=(8, 6))
    ptrace.render(scene, threads=threads, **tiny)
    ptrace.render(scene, threads=threads, **options)
    start = time.perf_counter()
    image = ptrace.render(scene, threads=threads, **options)
    plain = Run(image, time.perf_counter() - start, {}, threads)
    path = options["integrator"] != "normals"
    variants = ladder_options(options) if path else {"full": options}
    runs = {key: [] for key in variants}
    for i in range(repeats):
        for key, variant in variants.items():
            runs[key].append(timed_render(scene, threads, **variant))
        log(f"run {i + 1}/{repeats}: wall {runs['full'][-1].wall:.3f} s")
    full = median_run(runs["full"], key=lambda run: run.wall)
    ladder = {key: [run.thread_seconds for run in group] for key, group in runs.items()}
    profile = Profile(options, repeats, full, plain, ladder)
    log("counting rays (compiling the counting face on first use) and replaying them")
    try:
        profile.estimate = estimate(scene, options, threads, full.rays, min_seconds)
    except Exception as error:   # noqa: BLE001 - the measured parts stand without it
        profile.note = f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}"
        log(f"no accelerator estimate ({profile.note})")
    if path:
        loop = {key: float(np.median(values)) for key, values in ladder.items()}
        rays = {key: group[0].rays for key, group in runs.items()}
        profile.rows = ladder_rows(loop, rays, profile.estimate)
    return profile


def parse_resolution(text):
    width, height = (int(part) for part in text.lower().split("x"))
    return width, height


def main(argv=None):
    import ptrace
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="120x90, -s / 16, one repeat")
    parser.add_argument("--repeats", type=int, default=None, help="runs per render variant")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--resolution", type=parse_resolution, default=None,
                        help="WxH instead of 480x360 (120x90 with --quick)")
    parser.add_argument("--only", nargs="*", default=None, help="command names to run")
    parser.add_argument("--output", default="profile_render.md")
    args = parser.parse_args(argv)
    repeats = args.repeats or (1 if args.quick else 3)
    resolution = args.resolution or (QUICK_RESOLUTION if args.quick else RESOLUTION)
    min_seconds = QUICK_BATCH_SECONDS if args.quick else BATCH_SECONDS
    names = args.only or list(COMMANDS)
    unknown = [name for name in names if name not in COMMANDS]
    if unknown:
        parser.error(f"unknown command(s) {unknown}; choose from {list(COMMANDS)}")
    scenes, results, sections = {}, {}, []
    load_start = os.getloadavg()[0]
    for name in names:
        relpath, spp, light_samples, depth, integrator, backend = COMMANDS[name]
        if relpath not in scenes:
            scenes[relpath] = ptrace.load(os.path.join(scenes_dir(), relpath))
        options = dict(spp=max(1, spp // QUICK_SPP_DIVISOR) if args.quick else spp,
                       light_samples=light_samples, max_depth=depth, integrator=integrator,
                       accel=backend, resolution=resolution)

        def log(message, name=name):
            print(f"{name}: {message}", flush=True)

        try:
            profile = profile_command(scenes[relpath], options, args.threads, repeats,
                                      min_seconds, log)
        except Exception as error:   # noqa: BLE001 - a backend under rewrite must not stop the rest
            if backend != "embree":
                raise
            note = f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}"
            log(f"skipped: accel='embree' failed ({note})")
            results[name] = note
            sections += [f"## {name}", "", f"Skipped: `accel=\"embree\"` failed ({note}).", ""]
            continue
        results[name] = profile
        sections += command_section(name, profile)
        for label, seconds, how in slowest_parts(profile):
            print(f"    {_pct(seconds, profile.full.wall):5.1f}%  {seconds:7.3f} s  {label} "
                  f"({how})", flush=True)
    lines = [report.header("Where a render's time goes: wall-time phases, the path loop by "
                           "differencing, the accelerator's estimated share"),
             METHOD.format(threads=args.threads, block=REPLAY_BLOCK, load_start=load_start,
                           load_end=os.getloadavg()[0]),
             "", f"{args.threads} threads; {resolution[0]}x{resolution[1]}"
             + (", --quick: -s divided by 16" if args.quick else "") + ".", ""]
    lines += summary_table(results) + sections
    path = report.write(args.output, "\n".join(lines))
    print(f"wrote {path}", flush=True)
    return path


if __name__ == "__main__":
    main()
