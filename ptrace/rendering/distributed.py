"""Render tiles x passes on a Dask distributed cluster, bit-identical to an in-process render.

Imported only when a render is given a client (or the CLI --workers / --scheduler), so the
default mode never imports dask. Install the extra with `pip install "ptrace[dist]"`.

The unit of work is one tile (a contiguous run of the image's pixels, bottom row first) for one
pass; a task returns per-pixel sums of radiance, of illuminance and of its square, and sample
counts, traced by a ptrace.rendering.tiles.RenderJob as in-process. The client adds them into
the image in a fixed (pass, tile) order, whatever order tasks finish in, and each pixel's
arithmetic is then the in-process one: previous sum + this pass's sum. Adaptive sampling decides
convergence after each pass's merge, exactly as in-process (so adaptive passes run one after
another); without -a, passes are submitted ahead while about 4 tasks per worker are in flight.

The scene is scattered to every worker once; a worker builds its RenderJob (the acceleration
structure and the kernel's records) once per (scene, accelerator) and keeps the last few (its
numba cache stays warm between renders).
"""
import collections
import contextlib
import logging
import math
import os
import socket
import threading
import time
import uuid
import warnings

import numba
import numpy as np

from ..errors import PtraceError
from .tiles import RenderJob, new_sums

TASK_RAYS = 1 << 19       # rays per task: about 0.1-0.3 s of work at 2-5 M rays/s
CONNECT_TIMEOUT = 10      # seconds to reach a scheduler before giving up
INSTALL_HINT = 'distributed rendering needs Dask: pip install "ptrace[dist]"'

_jobs = collections.OrderedDict()    # (scene key, accel kind, bvh split) -> (token, RenderJob)
_lock = threading.Lock()             # one tile at a time per worker process: numba runs threads
_KEEP = 2
builds = 0                           # acceleration structures built by this process (tests)


class TileTaskError(RuntimeError):
    """A tile task failed for a reason that is not the user's (an internal error); names the
    tile and pass, and its __cause__ is the worker's exception with the worker's traceback."""


class _DropSyncCancelRace(logging.Filter):
    """Drops one log record: when Ctrl-C interrupts a blocking client call, the cancel callback
    of distributed.utils.sync (dask/distributed 2024-2026) can run before its coroutine has
    assigned `future`, and tornado logs the resulting NameError with a traceback on the user's
    terminal. The interrupt itself is handled (ptrace cancels its tasks and writes what was
    merged); every other record passes."""

    def filter(self, record):
        error = record.exc_info[1] if record.exc_info else None
        return not (isinstance(error, NameError) and "'future'" in str(error))


@contextlib.contextmanager
def dropping_the_sync_cancel_race():
    """While inside, the "tornado.application" logger drops the record described in
    _DropSyncCancelRace; on leaving, the logger is as it was. Nothing is installed on import:
    render_passes enters this for the render, and the CLI for its client's whole life (the
    record can come while the client shuts down)."""
    logger = logging.getLogger("tornado.application")
    race = _DropSyncCancelRace()
    logger.addFilter(race)
    try:
        yield race
    finally:
        logger.removeFilter(race)


def _dask():
    try:
        import dask.distributed as dd
    except ImportError:
        raise PtraceError(INSTALL_HINT) from None
    return dd


def local_client(workers, dashboard=False):
    """A local cluster of `workers` processes bound to 127.0.0.1 (no dashboard unless asked,
    and then on loopback too), one task thread each; returns (client, cluster)."""
    dd = _dask()
    if dashboard:
        options = {"dashboard_address": "127.0.0.1:8787"}
    else:   # the scheduler's HTTP server (health, metrics) still runs: random loopback port
        options = {"dashboard_address": None,
                   "scheduler_kwargs": {"dashboard": False, "dashboard_address": "127.0.0.1:0"}}
    cluster = dd.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                              host="127.0.0.1", silence_logs=logging.ERROR, **options)
    return dd.Client(cluster), cluster


def shutdown(client, cluster=None):
    """Close the client and a local cluster; a slow or failed close (a loaded machine, workers
    still finishing cancelled tasks) is a one-line warning, never an error after a render."""
    for part in (client, cluster):
        if part is None:
            continue
        try:
            part.close(timeout=30)
        except Exception as error:   # noqa: BLE001 - whatever dask raises while closing
            name = "client" if part is client else "cluster"
            warnings.warn(f"the Dask {name} did not close cleanly: {type(error).__name__} "
                          f"{error}".strip(), RuntimeWarning, stacklevel=2)


def connect(address, timeout=CONNECT_TIMEOUT):
    """A client of the scheduler at `address` (tcp:// or tls://); one-line error if it does not
    answer within `timeout` seconds."""
    dd = _dask()
    refused = _refused(address, timeout)
    if refused:     # nothing listens there: said now, not after Dask's retries until timeout
        raise PtraceError(f"cannot reach the Dask scheduler at {address}: {refused}")
    try:
        return dd.Client(address, timeout=f"{timeout}s")
    except (OSError, TimeoutError, ValueError) as error:
        detail = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise PtraceError(f"cannot reach the Dask scheduler at {address} within {timeout} s "
                          f"({detail})") from None


def _refused(address, timeout):
    """Why a tcp:// scheduler address refuses a connection outright (nothing listens at its
    port, or its host is unknown), else None (reached, another scheme, or slower to answer:
    Dask's own connect decides)."""
    if not address.startswith("tcp://"):
        return None
    host, _, port = address[len("tcp://"):].rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=min(timeout, 2)):
            return None
    except ConnectionRefusedError:
        return "connection refused (is the scheduler running, and on that port?)"
    except socket.gaierror as error:
        return f"unknown host {host!r} ({error.strerror})"
    except (OSError, ValueError):
        return None


def default_worker_threads(client):
    """Numba threads per task: each worker's share of its machine's cores."""
    info = client.scheduler_info()["workers"]
    per_host = collections.Counter(w["host"] for w in info.values())
    if per_host and all(host in ("127.0.0.1", "localhost") for host in per_host):
        return max(1, (os.cpu_count() or 1) // max(per_host.values()))
    return None   # remote machines: numba's default, all of the worker's cores


def _job(scene, request):
    """This worker's RenderJob for a render's request: its backend built once per (scene key,
    accelerator, BVH split), the last _KEEP kept; a later render of the same key reuses that
    backend (and the scene's records) with its own settings and camera. Returns (the job,
    seconds spent building for it)."""
    global builds
    settings = request["settings"]
    key = (request["scene_key"], settings.accel, settings.bvh_split)
    if key not in _jobs:
        job = RenderJob.build(scene, settings, request["camera"])
        builds += 1
        _jobs[key] = (request["token"], job)
        while len(_jobs) > _KEEP:
            _jobs.popitem(last=False)
        return job, job.build_seconds
    token, job = _jobs[key]
    if token != request["token"]:
        job = job.reused(settings, request["camera"])
        _jobs[key] = (request["token"], job)
    return job, 0.0


def tile_task(scene, request, pass_index, tile_index, first_sample, pass_n, pixel_x, pixel_y):
    """Run on a worker: sums for one tile of one pass (see the module docstring)."""
    try:
        with _lock:
            job, build_seconds = _job(scene, request)
            threads = request["threads"]
            if threads is not None:
                numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
            n = pixel_x.shape[0]
            sums = new_sums(n)
            start = time.perf_counter()
            nonfinite, rays = job.trace(pixel_x, pixel_y, first_sample, pass_n, sums,
                                        np.arange(n))
            seconds = time.perf_counter() - start
            return sums, nonfinite, rays, build_seconds, seconds
    except Exception as error:
        where = (f"tile {tile_index} (pixels {pixel_y[0]}:{pixel_x[0]} .., {len(pixel_x)} of "
                 f"them) of pass {pass_index} (samples {first_sample}.."
                 f"{first_sample + pass_n - 1}) on {socket.gethostname()} pid {os.getpid()}")
        if isinstance(error, PtraceError):   # the user's: one line, now naming the tile
            raise PtraceError(f"{where}: {error}") from error
        # a bug: not the user's fault, so not a PtraceError; Dask carries the cause and its
        # traceback (the worker's frames) back to the client, where the CLI prints both
        raise TileTaskError(f"{where} failed: {type(error).__name__}: {error}") from error


def tile_pixels(n_pixels, rays_per_path, pass_n, workers):
    """Pixels per tile: enough for about TASK_RAYS rays (a task of at least ~100 ms), but no
    more than gives two tiles per worker, so small images still spread."""
    size = math.ceil(TASK_RAYS / (rays_per_path * pass_n))
    size = min(size, math.ceil(n_pixels / (2 * max(1, workers))))
    return max(1, size)


def render_passes(client, scene, settings, camera, pixel_x, pixel_y, passes, phases,
                  worker_threads=None):
    """Run the pass schedule as tiles x passes on the cluster; the settings travel whole. Ctrl-C
    (KeyboardInterrupt) cancels the tasks and keeps what was merged. phases (a running
    ptrace.rendering.timing.Phases of DASK_PHASES) gets the scatter and render phases and the count
    of tasks. Returns the render's figures for stats."""
    phases.enter("render")
    with dropping_the_sync_cancel_race():
        outcome = _render_passes(client, scene, settings, camera, pixel_x, pixel_y, passes,
                                 worker_threads)
    # the executor's first seconds were the scatter (timed by it)
    phases.seconds["render"] -= outcome["scatter_seconds"]
    phases.seconds["scatter"] += outcome["scatter_seconds"]
    phases.count("tasks", outcome["tasks"])
    return outcome


def _render_passes(client, scene, settings, camera, pixel_x, pixel_y, passes, worker_threads):
    dd = _dask()
    start = time.perf_counter()
    workers = len(client.scheduler_info()["workers"])
    if workers == 0:
        raise PtraceError(f"the Dask cluster at {client.scheduler.address} has no workers")
    token = uuid.uuid4().hex
    scene_future = client.scatter(scene, broadcast=True, hash=False)
    rays_per_path = settings.rays_per_path(scene)
    request = dict(token=token, scene_key=scene_future.key, settings=settings, camera=camera,
                   threads=worker_threads if worker_threads is not None
                   else default_worker_threads(client))
    [request_future] = client.scatter([request], broadcast=True, hash=False)
    totals = dict(nonfinite=0, rays=0, build_seconds=0.0, task_seconds=[], tasks=0,
                  merge_seconds=0.0, scatter_seconds=time.perf_counter() - start)
    interrupted = False
    pending = {}   # key -> future not merged yet (dropping a future frees its result)

    def submit(pass_index, first_sample, pass_n, active):
        """Submit one pass's tiles; return [(rows, key, samples per pixel)] in tile order."""
        size = tile_pixels(active.size, rays_per_path, pass_n, workers)
        tiles = []
        for tile_index, first in enumerate(range(0, active.size, size)):
            rows = active[first:first + size]
            key = f"ptrace-tile-{token}-{pass_index}-{tile_index}"
            pending[key] = client.submit(tile_task, scene_future, request_future, pass_index,
                                         tile_index, first_sample, pass_n, pixel_x[rows],
                                         pixel_y[rows], key=key, pure=False)
            tiles.append((rows, key, pass_n))
        return tiles

    def merge(tiles):
        """Add each tile's sums in tile order, as soon as every earlier tile is in, whatever
        order they finish in."""
        sum_rgb, sum_l, sum_l2, count = passes.sums
        finished = set()
        position = 0
        for future in dd.as_completed([pending[key] for _, key, _ in tiles]):
            finished.add(future.key)
            while position < len(tiles) and tiles[position][1] in finished:
                rows, key, pass_n = tiles[position]
                (rgb, lum, lum2, n), nonfinite, rays, build, seconds = pending.pop(key).result()
                merge_start = time.perf_counter()
                sum_rgb[rows] += rgb
                sum_l[rows] += lum
                sum_l2[rows] += lum2
                count[rows] += n
                totals["nonfinite"] += nonfinite
                totals["rays"] += rays
                totals["build_seconds"] = max(totals["build_seconds"], build)
                totals["task_seconds"].append(seconds)
                totals["tasks"] += 1
                passes.update(rows.size * pass_n)
                position += 1
                totals["merge_seconds"] += time.perf_counter() - merge_start

    try:
        if passes.adaptive:
            for pass_index, (first_sample, pass_n, active) in enumerate(passes):
                merge(submit(pass_index, first_sample, pass_n, active))
        else:   # keep a window of passes in flight, so workers never wait on a merge
            schedule = passes.fixed()
            window = collections.deque()
            for pass_index in range(len(schedule)):
                ahead = pass_index + len(window)
                while ahead < len(schedule) and (not window or len(pending) < 4 * workers + 16):
                    window.append(submit(ahead, *schedule[ahead], passes.active))
                    ahead += 1
                merge(window.popleft())
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if pending:
            client.cancel(list(pending.values()))
            pending.clear()
        client.cancel([scene_future, request_future])
    task_seconds = sorted(totals.pop("task_seconds"))
    return dict(totals, render_seconds=time.perf_counter() - start, accel={},
                interrupted=interrupted, workers=workers, task_seconds_total=sum(task_seconds),
                median_task_seconds=task_seconds[len(task_seconds) // 2] if task_seconds else 0.0)
