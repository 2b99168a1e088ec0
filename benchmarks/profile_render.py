"""Where a render's wall time goes: its phases, and inside the path loop, each stage's.

    python -m benchmarks.profile_render [--quick] [--repeats N] [--threads T]
                                        [--resolution WxH] [--only NAME ...] [--output NAME]

A render is: settings, camera and pixel grid (ptrace.rendering.renderer), accel.build, then
passes in which ptrace.rendering.tiles.RenderJob.trace hands blocks of pixels to a pool of
Python threads, each running ptrace.kernel.wavefront.Wavefront.trace: waves of paths through
small compiled stages (nogil), which Python calls once per stage and bounce of a wave. So:

1. Wall time (measured). The render's own phases (stats["phases"],
   ptrace.rendering.timing.Phases): setup, compile, build, records, render (the passes) and
   image. Wavefront.trace is replaced at Python level by a wrapper that records each call's
   start and end (put back in a `finally`), which splits the passes further. The wall time
   splits, exactly, into the build, compiling, the kernel records, setup and image assembly,
   the passes' time with no trace call running, the time inside the calls' span when a thread
   is idle, and the calls' own seconds (thread-seconds / threads).
2. Inside the loop, by differencing (measured): the same command rendered with less work, on
   the same pixels, samples and backend: normal shading (camera rays and closest hit only),
   -m 0 (plus the surface and its emission), -m 1 (plus direct light at the first vertex) and
   the full command. Each row is a difference of median trace thread-seconds.
3. Inside the loop, by stage (measured): one more render of the command with every stage call
   timed the same way (the stages ptrace.kernel.wavefront calls, and the hit and shading
   stages it makes, wrapped for the render's length): each stage's thread-seconds, calls, and
   the paths or rays its calls ran over. The trace stages (closest and any hit, and their
   variants past cut-outs and for -H) are the accelerator's part, measured; what the stages
   leave of the loop is the Python between their calls.

Commands run on 2 threads after compiling and one untimed render. --quick: 120x90, -s divided
by 16, one repeat. Writes benchmarks/results/profile_render.md (--output NAME). A backend that
fails (the embree backend while it is being rewritten) is skipped with a note.
"""
import argparse
import contextlib
import functools
import inspect
import math
import os
import threading
import time
from dataclasses import dataclass, field

import numpy as np

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

# wall-time phases (section 1), in the order of the table
BUILD = "acceleration structure build (accel.build)"
COMPILE = "numba compiling or loading kernels from its cache (0 after the warm-up)"
RECORDS = "kernel records: scene, lights, camera, backend (ptrace.rendering.tiles.RenderJob)"
SETUP = "render setup and image: settings, camera, pixel grid, sums, final image"
OUTSIDE = "passes with no trace call running: pool hand-out, pass ends"
IDLE = "threads idle inside the calls' span: per-block Python, last blocks of a pass"
LOOP = "inside Wavefront.trace (the path loop's waves), thread-seconds / threads"
WALL_PHASES = (BUILD, COMPILE, RECORDS, SETUP, OUTSIDE, IDLE, LOOP)

# the differencing ladder (section 2): (render, label)
LADDER = (
    ("normals", "camera rays, closest hit, normal colour, accumulation (normal-shading render)"),
    ("m0", "surface at the first hit and its emission (-m 0 minus normal shading)"),
    ("m1", "direct light at the first vertex: light samples, shadow rays (-m 1 minus -m 0)"),
    ("full", "later vertices: BSDF sample, roulette, bounce rays, their direct light "
             "(full minus -m 1)"),
)

# the stages ptrace.kernel.wavefront calls by name (section 3); the trace stages are the
# accelerator's part
TRACE_STAGES = ("closest_stage", "visible_stage", "any_stage", "shadowed_stage", "probe_stage",
                "visible_probe_stage")
STAGES = ("camera_stage",) + TRACE_STAGES + (
    "probe_found_stage", "shadow_stage", "features_stage", "normals_stage", "fold_stage",
    "add_stage")
BETWEEN = "Python between the stage calls (the loop's thread-seconds minus the stages')"


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
    """Start and end (time.perf_counter) of every Wavefront.trace call, from any thread."""

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


class StageClock:
    """Thread-seconds, calls and work items (the paths or rays of each call: its number n, or
    count for the camera and fold stages; none for add_stage) of every stage, by name, from any
    thread."""

    def __init__(self):
        self.seconds, self.calls, self.items = {}, {}, {}
        self._lock = threading.Lock()

    def wrap(self, name, stage):
        names = list(inspect.signature(getattr(stage, "py_func", stage)).parameters)
        where = names.index("n") if "n" in names else names.index("count")

        @functools.wraps(stage)
        def timed(*args):
            start = time.perf_counter()
            try:
                return stage(*args)
            finally:
                seconds = time.perf_counter() - start
                with self._lock:
                    self.seconds[name] = self.seconds.get(name, 0.0) + seconds
                    self.calls[name] = self.calls.get(name, 0) + 1
                    if np.ndim(args[where]) == 0:
                        self.items[name] = self.items.get(name, 0) + int(args[where])
        return timed

    @contextlib.contextmanager
    def timing(self):
        """Every stage ptrace.kernel.wavefront calls, timed for the length of the block: the
        module's stage functions, and the hit, light and shading stages its Wavefront makes."""
        from ptrace.kernel import wavefront
        from ptrace.scene import BSDF_NAMES
        hit_stage, shading_stage = wavefront.hit_stage, wavefront.shading_stage
        light_stage = wavefront.light_stage

        def hit(*args):
            return self.wrap("hit_stage", hit_stage(*args))

        def light(*args):
            return self.wrap("light_stage", light_stage(*args))

        def shading(kind, *args):
            return self.wrap(f"shading: {BSDF_NAMES[kind]}", shading_stage(kind, *args))

        with contextlib.ExitStack() as stack:
            for name in STAGES:
                stack.enter_context(patched(wavefront, name,
                                            self.wrap(name, getattr(wavefront, name))))
            stack.enter_context(patched(wavefront, "hit_stage", hit))
            stack.enter_context(patched(wavefront, "light_stage", light))
            stack.enter_context(patched(wavefront, "shading_stage", shading))
            yield self


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
    stages: StageClock = None

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
        Wavefront.trace calls; they add up to the wall time exactly. Setup also takes the
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


def timed_render(scene, threads, stages=None, **options):
    """ptrace.render(scene, threads=threads, **options) with Wavefront.trace timed, and every
    stage too if `stages` (a StageClock) is given."""
    import ptrace
    from ptrace.kernel.wavefront import Wavefront
    clock, stats = KernelClock(), {}
    with patched(Wavefront, "trace", clock.wrap(Wavefront.trace)), \
            (stages.timing() if stages is not None else contextlib.nullcontext()):
        start = time.perf_counter()
        image = ptrace.render(scene, threads=threads, stats=stats, **options)
        wall = time.perf_counter() - start
    return Run(image, wall, stats, threads, clock.intervals, stages)


def median_run(runs, key):
    return sorted(runs, key=key)[len(runs) // 2]


def planned_blocks(n_pixels, spp):
    """Wavefront.trace calls a render of n_pixels pixels makes without -a: ptrace.rendering.tiles'
    pass schedule, blocks of max(1, BLOCK_PATHS // pass_n) pixels."""
    import ptrace
    from ptrace.rendering import tiles
    passes = tiles.Passes(ptrace.Settings(spp=spp), tiles.new_sums(n_pixels)).fixed()
    return sum(-(-n_pixels // max(1, tiles.BLOCK_PATHS // pass_n)) for _, pass_n in passes)



# -- 2 and 3. inside the loop ------------------------------------------------------------------

def ladder_options(options):
    """The renders of the ladder for a path command: same pixels, samples and backend."""
    return {"normals": dict(options, integrator="normals"), "m0": dict(options, max_depth=0),
            "m1": dict(options, max_depth=1), "full": options}


def ladder_rows(loop, rays):
    """Rows (label, rays, thread-s) of section 2, from the median loop thread-seconds and rays
    traced of each ladder render. The rows add up to the full command's figures (a telescoping
    sum); the last row is the total."""
    rows, previous_loop, previous_rays = [], 0.0, 0
    for name, label in LADDER:
        rows.append((label, rays[name] - previous_rays, loop[name] - previous_loop))
        previous_loop, previous_rays = loop[name], rays[name]
    rows.append(("total: the full command's loop", rays["full"], loop["full"]))
    return rows


def stage_rows(run):
    """Rows (stage, calls, items, thread-s) of section 3, the slowest first, then the Python
    between the stage calls and the loop's total."""
    clock = run.stages
    rows = sorted(((name, clock.calls[name], clock.items.get(name), clock.seconds[name])
                   for name in clock.seconds), key=lambda row: -row[3])
    staged = sum(row[3] for row in rows)
    return rows + [(BETWEEN, None, None, run.thread_seconds - staged),
                   ("total: the loop", None, None, run.thread_seconds)]


def accelerator_seconds(run):
    """The trace stages' thread-seconds (measured)."""
    return sum(seconds for name, seconds in run.stages.seconds.items() if name in TRACE_STAGES)


# -- the report ----------------------------------------------------------------------------------

@dataclass
class Profile:
    """What profile_command measured for one command."""
    options: dict
    repeats: int
    full: Run                 # the full command's timed run with the median wall time
    plain: Run                # the same, without the trace wrapper
    ladder: dict              # variant -> loop thread-seconds of each run
    staged: Run               # the full command with every stage timed
    rows: list = None         # ladder_rows (path commands)

    def loop_wall(self, thread_seconds, run=None):
        """Thread-seconds of the loop (of `run`, default the full run) as wall seconds of the
        full run's loop phase."""
        total = (run or self.full).thread_seconds
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
    """Section 2. Share of wall: a row's part of the loop phase."""
    rows = profile.rows
    total = rows[-1][2]
    lines = ["| part of the path loop | rays traced | loop thread-s | share of loop % "
             "| share of wall % |", "|---|---:|---:|---:|---:|"]
    for label, rays, seconds in rows:
        lines.append(f"| {label} | {rays:,} | {seconds:.3f} | {_pct(seconds, total):.1f} | "
                     f"{_pct(profile.loop_wall(seconds), profile.full.wall):.1f} |")
    return lines


def stage_table(profile):
    """Section 3: each stage of the stage-timed run."""
    run = profile.staged
    total = run.thread_seconds
    lines = ["| stage | calls | paths or rays | thread-s | share of loop % | ns per path or ray |",
             "|---|---:|---:|---:|---:|---:|"]
    for name, calls, items, seconds in stage_rows(run):
        per = f"{1e9 * seconds / items:.0f}" if items else ""
        lines.append(f"| {name} | {'' if calls is None else f'{calls:,}'} | "
                     f"{'' if items is None else f'{items:,}'} | {seconds:.3f} | "
                     f"{_pct(seconds, total):.1f} | {per} |")
    return lines


def slowest_parts(profile):
    """The three largest parts of the wall time at the finest grain there is: (label, wall
    seconds, "measured")."""
    phases = profile.full.phases()
    parts = [(phase, seconds, "measured") for phase, seconds in phases.items() if phase != LOOP]
    parts += [(f"{LOOP}: {name}", profile.loop_wall(seconds, profile.staged), "measured")
              for name, _, _, seconds in stage_rows(profile.staged)[:-1]]
    return sorted(parts, key=lambda part: -part[1])[:3]


def command_section(name, profile):
    options, full, plain, repeats = profile.options, profile.full, profile.plain, profile.repeats
    width, height = options["resolution"]
    pixels = width * height
    flags = (f"-s {options['spp']}" if options["integrator"] == "normals" else
             f"-s {options['spp']} -l {options['light_samples']} -m {options['max_depth']}")
    same = np.array_equal(full.image, plain.image) and \
        np.array_equal(profile.staged.image, plain.image)
    lines = [f"## {name}", "",
             f"{width}x{height}, {options['integrator']} {flags}, {options['accel']}, "
             f"{full.threads} threads. Wall {full.wall:.3f} s (the timed run with the median "
             f"wall of {repeats}); un-profiled wall {plain.wall:.3f} s; profiled and "
             f"un-profiled images {'identical' if same else 'DIFFERENT'}. {full.rays:,} rays "
             f"traced ({full.rays / (pixels * options['spp']):.2f} per path), {full.calls:,} "
             f"trace calls, threads busy {100 * full.busy:.1f}% of the calls' span.",
             "", "### Wall time", ""] + wall_table(full) + [""]
    if profile.rows is not None:
        lines += ["### Inside the loop, by differencing", "",
                  f"Loop thread-seconds are medians of {repeats} render{'s' * (repeats > 1)} of "
                  "each variant; a row is the difference between a variant and the one before "
                  "it, so a part smaller than the run-to-run noise can come out negative. "
                  "Share of wall: the row's part of the loop phase.", ""]
        lines += loop_table(profile) + [""]
        spread = ", ".join(f"{key} {min(values):.3f}-{max(values):.3f}"
                           for key, values in profile.ladder.items())
        lines += [f"Loop thread-seconds over the runs (min-max): {spread}.", ""]
    staged = profile.staged
    traced = sum(staged.stages.items.get(name, 0) for name in TRACE_STAGES)
    share = _pct(accelerator_seconds(staged), staged.thread_seconds)
    lines += ["### Inside the loop, by stage", "",
              f"One more render of the command with every stage call timed (wall "
              f"{staged.wall:.3f} s, loop {staged.thread_seconds:.3f} thread-s). The trace "
              f"stages (the accelerator) took {share:.1f}% of the loop; their rays {traced:,} "
              f"{'=' if traced == staged.rays else '!='} rays traced {staged.rays:,}.", ""]
    lines += stage_table(profile) + [""]
    lines += ["Three slowest parts:", ""]
    for i, (label, seconds, how) in enumerate(slowest_parts(profile), 1):
        lines.append(f"{i}. {label}: {seconds:.3f} s, {_pct(seconds, full.wall):.1f}% of wall "
                     f"({how})")
    return lines + [""]


def summary_table(results):
    lines = ["## Summary", "",
             "Shares of wall time, all measured. Glue: compiling, kernel records, setup, passes "
             "outside the calls, idle threads; accelerator: the trace stages' share of the "
             "loop.", "",
             "| command | backend | wall s | build % | glue % | loop % | accelerator % of loop "
             "| threads busy % |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for name, profile in results.items():
        command, backend = name.rsplit(" (", 1)
        backend = backend.rstrip(")")
        if isinstance(profile, str):
            lines.append(f"| {command} | {backend} | skipped | | | | | |")
            continue
        run = profile.full
        phases = run.phases()
        glue = sum(phases[phase] for phase in (COMPILE, RECORDS, SETUP, OUTSIDE, IDLE))
        accelerator = _pct(accelerator_seconds(profile.staged), profile.staged.thread_seconds)
        lines.append(f"| {command} | {backend} | {run.wall:.3f} | "
                     f"{_pct(phases[BUILD], run.wall):.1f} | {_pct(glue, run.wall):.1f} | "
                     f"{_pct(phases[LOOP], run.wall):.1f} | {accelerator:.1f} | "
                     f"{100 * run.busy:.1f} |")
    return lines + [""]


METHOD = (
    "Method. Measured: the wall time of ptrace.render; its phases (stats['phases']: setup, "
    "compile, build, records, render, image); the start and end of every "
    "ptrace.kernel.wavefront.Wavefront.trace call (one per block of pixels), from a "
    "Python-level wrapper that is put back afterwards (library code is unchanged). The calls "
    "run on {threads} Python threads at once, so the wall time splits exactly into: build; "
    "compiling; kernel records; setup and image assembly; passes with no call running; the "
    "calls' span minus their thread-seconds / threads (threads idle); and the calls' "
    "thread-seconds / threads (the loop). By differencing: the same command as normal shading, "
    "-m 0, -m 1 and in full, on the same pixels, samples and backend (a path's first vertices "
    "do not depend on -m, so each variant does a prefix of the next one's work); each row is a "
    "difference of median loop thread-seconds and of the exact rays traced (stats). By stage: "
    "one more render with every stage call wrapped the same way (the stage functions "
    "ptrace.kernel.wavefront calls and the hit and shading stages it makes): thread-seconds, "
    "calls and the paths or rays each call ran over; the wrappers' own time falls in the "
    "Python between the calls. Scenes are loaded and kernels compiled before timing; each "
    "command runs once untimed first. Thread-seconds include any wait for a core: load average "
    "(1 min) {load_start:.2f} at the start, {load_end:.2f} at the end.")


def profile_command(scene, options, threads, repeats, log):
    """Measure one command: its ladder of variants (or the command alone for normal
    shading), an un-profiled run, and a stage-timed run. Returns a Profile."""
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
    log("timing every stage")
    staged = timed_render(scene, threads, stages=StageClock(), **options)
    profile = Profile(options, repeats, full, plain, ladder, staged)
    if path:
        loop = {key: float(np.median(values)) for key, values in ladder.items()}
        rays = {key: group[0].rays for key, group in runs.items()}
        profile.rows = ladder_rows(loop, rays)
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
            profile = profile_command(scenes[relpath], options, args.threads, repeats, log)
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
                           "differencing and by stage"),
             METHOD.format(threads=args.threads, load_start=load_start,
                           load_end=os.getloadavg()[0]),
             "", f"{args.threads} threads; {resolution[0]}x{resolution[1]}"
             + (", --quick: -s divided by 16" if args.quick else "") + ".", ""]
    lines += summary_table(results) + sections
    path = report.write(args.output, "\n".join(lines))
    print(f"wrote {path}", flush=True)
    return path


if __name__ == "__main__":
    main()
