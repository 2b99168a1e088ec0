"""The in-process executor: every pass's tile work on this machine's numba threads. (The Dask
executor is ptrace.distributed; both run ptrace.tiles.)"""
import time

import accel

from .jit import COLD_COMPILE_SECONDS, is_cold
from .tiles import TileWork


def render_in_process(scene, settings, camera, pixel_x, pixel_y, passes, notice=None):
    """Run the pass schedule over the pixels; Ctrl-C stops between kernel calls and keeps what
    was summed. Returns the render's figures for stats."""
    if notice is not None and is_cold(accel.record_class(settings.accel)):
        notice(f"compiling kernels (first run only, about {COLD_COMPILE_SECONDS} s)")
    start = time.perf_counter()
    backend = accel.build(settings.accel, scene.geometry, **settings.accel_options())
    build_seconds = time.perf_counter() - start
    start = time.perf_counter()
    work = TileWork(scene, backend, settings, camera)
    nonfinite = 0
    interrupted = False
    try:
        for first_sample, pass_n, active in passes:
            nonfinite += work.trace(pixel_x[active], pixel_y[active], first_sample, pass_n,
                                    passes.sums, active, passes.update)
    except KeyboardInterrupt:
        interrupted = True
    return dict(build_seconds=build_seconds, render_seconds=time.perf_counter() - start,
                rays=work.rays_traced, accel=backend.stats(), nonfinite=nonfinite,
                interrupted=interrupted)
