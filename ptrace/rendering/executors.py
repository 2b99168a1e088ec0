"""The in-process executor: every pass's blocks of pixels traced on this machine's numba threads,
through one ptrace.rendering.tiles.RenderJob. (The Dask executor, ptrace.rendering.distributed,
sends tiles of the same passes to workers that trace them through their own RenderJob.)"""
import time

from ..guiding import combine, train
from ..jit import remember_compile
from .tiles import RenderJob


def render_in_process(scene, settings, camera, pixel_x, pixel_y, passes, phases, notice=None,
                      features=None):
    """Run the pass schedule over the pixels; Ctrl-C stops between kernel calls and keeps what was
    summed. phases (a running ptrace.rendering.timing.Phases of IN_PROCESS_PHASES) gets the compile,
    build, records and render phases and the counts of passes and kernel calls. Returns the
    render's figures for stats. features: the AOVs' per-pixel sums, or None (RenderJob.trace)."""
    job = RenderJob.build(scene, settings, camera, notice, phases.enter)
    start = time.perf_counter()
    phases.counts.update(passes=0, kernel_calls=0)

    def on_block(samples):
        phases.count("kernel_calls")
        passes.update(samples)

    nonfinite = 0
    interrupted = False
    guiding = None
    try:
        phases.enter("compile")   # what the cache lacks, on every core, before the first pass
        job.compile_ahead(features is not None)
        phases.enter("render")
        start = time.perf_counter()
        if settings.guiding != "off":   # training passes, then the rest of -s with the guide
            training, guiding, images = train(job, pixel_x, pixel_y, settings.spp,
                                              settings.guiding, on_block)
            guiding["training_seconds"] = time.perf_counter() - start
            passes.spp -= training
        for first_sample, pass_n, active in passes:
            phases.count("passes")
            nonfinite += job.trace(pixel_x[active], pixel_y[active], first_sample, pass_n,
                                   passes.sums, active, on_block, features)[0]
        if guiding is not None:    # the training iterations' images, by inverse variance
            guiding["weights"] = combine(passes.sums, images)
    except KeyboardInterrupt:
        interrupted = True
    # the records were the first part of the render's seconds
    render_seconds = job.records_seconds + time.perf_counter() - start
    seconds, compiled = phases.compiled_so_far()
    if job.cold is not None and compiled and not interrupted:   # for the next cold notice
        remember_compile(job.cold, seconds)
    return dict(build_seconds=job.build_seconds, render_seconds=render_seconds,
                rays=job.rays_traced, accel=job.backend.stats(), nonfinite=nonfinite,
                interrupted=interrupted, **({} if guiding is None else {"guiding": guiding}))
