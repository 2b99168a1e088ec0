"""Where a render's wall time goes: the slowest phases of a render and their share of wall time.

    python -m benchmarks.profile_render [--quick] [--repeats N]

For the length of one profiled render, the callables a render runs per wave are replaced at
Python level by timing wrappers (library code is not modified; every attribute is put back in a
`finally`): the accelerator's intersect (split into camera, bounce and hemisphere rays) and
occluded, accel.build, each ptrace.integrator kernel that ptrace/paths.py calls as `k.NAME(`,
the normal-shading kernels, camera_samples and Camera.directions. The rest of the wall time is
the Python/numpy glue between them. Commands run on 2 threads after a compiling render and an
untimed warm render; each table is the profiled run with the median wall time out of --repeats.
--quick: 120x90, -s divided by 16, one repeat. Writes benchmarks/results/profile_render.md
(--output NAME).
"""
import argparse
import contextlib
import functools
import importlib
import os
import re
import time
from collections import defaultdict

import numpy as np

from . import report
from .accel_rays import scenes_dir

# name: (scene, spp, light samples, max depth, integrator, backend); all at RESOLUTION
COMMANDS = {
    "cow -s 64 -l 16 -m 6 (bvh)": ("meshedit/cow.dae", 64, 16, 6, "path", "bvh"),
    "cow -s 64 -l 16 -m 6 (embree)": ("meshedit/cow.dae", 64, 16, 6, "path", "embree"),
    "CBbunny -s 16 -l 8 -m 6 (bvh)": ("sky/CBbunny.dae", 16, 8, 6, "path", "bvh"),
    "CBbunny -s 16 -l 8 -m 6 (embree)": ("sky/CBbunny.dae", 16, 8, 6, "path", "embree"),
    "cow normals -s 1 (bvh)": ("meshedit/cow.dae", 1, 1, 1, "normals", "bvh"),
}
RESOLUTION, QUICK_RESOLUTION, QUICK_SPP_DIVISOR = (480, 360), (120, 90), 16

CAMERA_HIT = "camera rays closest hit (accelerator.intersect)"
BOUNCE_HIT = "bounce rays closest hit (accelerator.intersect)"
HEMISPHERE_HIT = "hemisphere rays closest hit (accelerator.intersect, -H)"
SHADOW_HIT = "shadow rays any-hit traversal (accelerator.occluded)"
BUILD = "acceleration structure build (accel.build)"
GLUE = "Python/numpy glue: array allocation, Rays and hits, wave and render setup"
TRAVERSAL = (CAMERA_HIT, BOUNCE_HIT, HEMISPHERE_HIT, SHADOW_HIT)
KERNEL_LABELS = {
    "surfaces": "surfaces kernel (hit points, normals, materials)",
    "add_emission": "add_emission kernel",
    "light_samples": "light_samples kernel (shadow rays, BSDF x light)",
    "hemisphere_samples": "hemisphere_samples kernel (-H)",
    "gather": "gather kernel (unoccluded light into radiance)",
    "bounce": "bounce kernel (BSDF sample, Russian roulette)",
}


class Profile:
    """Seconds and calls per phase. A phase called inside another phase is counted by the
    outer one only, so the phases never overlap and glue = wall - their sum."""

    def __init__(self):
        self.seconds = defaultdict(float)
        self.calls = defaultdict(int)
        self.wave = "bounce"   # which rays the next intersect traces: camera, bounce or direct
        self._depth = 0

    def call(self, name, function, *args, **kwargs):
        if self._depth:
            return function(*args, **kwargs)
        self._depth += 1
        start = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            self.seconds[name] += time.perf_counter() - start
            self.calls[name] += 1
            self._depth -= 1

    def wrap(self, name, function):
        @functools.wraps(function)
        def timed(*args, **kwargs):
            return self.call(name, function, *args, **kwargs)
        return timed


def integrator_kernels():
    """The ptrace.integrator functions that ptrace/paths.py calls (as `k.NAME(`), in order."""
    import inspect

    import ptrace.paths
    names = re.findall(r"\bk\.(\w+)\(", inspect.getsource(ptrace.paths))
    return [n for n in dict.fromkeys(names) if n != "primitive_scale"]   # once, in __init__


def _wrap_backend(profile, backend):
    """Time the backend's intersect and occluded (instance attributes: the class is untouched)."""
    intersect, occluded = backend.intersect, backend.occluded

    def timed_intersect(rays):
        wave = profile.wave
        if wave == "camera":          # the first intersect of PathTracer.trace
            profile.wave = "bounce"
        name = {"camera": CAMERA_HIT, "direct": HEMISPHERE_HIT}.get(wave, BOUNCE_HIT)
        return profile.call(name, intersect, rays)

    backend.intersect = timed_intersect
    backend.occluded = profile.wrap(SHADOW_HIT, occluded)
    return backend


def _wrap_tracer(profile, tracer):
    """Mark which rays the tracer's next intersect call traces (untimed wrappers)."""
    trace, direct = tracer.trace, tracer._direct

    def marked_trace(*args, **kwargs):
        profile.wave = "camera"
        return trace(*args, **kwargs)

    def marked_direct(*args, **kwargs):
        previous, profile.wave = profile.wave, "direct"
        try:
            return direct(*args, **kwargs)
        finally:
            profile.wave = previous

    tracer.trace, tracer._direct = marked_trace, marked_direct
    return tracer


@contextlib.contextmanager
def profiling(profile):
    """Install the timing wrappers on the module and class attributes a render looks up at call
    time; put every original back on exit, whatever happens."""
    import accel
    import ptrace.camera
    import ptrace.integrator
    import ptrace.paths
    render_module = importlib.import_module("ptrace.render")   # ptrace.render is the function
    saved = []

    def patch(owner, name, value):
        saved.append((owner, name, getattr(owner, name)))
        setattr(owner, name, value)

    build, make_tracer = accel.build, render_module.make_tracer

    def timed_build(*args, **kwargs):
        return _wrap_backend(profile, profile.call(BUILD, build, *args, **kwargs))

    def marked_make_tracer(*args, **kwargs):
        return _wrap_tracer(profile, make_tracer(*args, **kwargs))

    try:
        patch(accel, "build", timed_build)
        patch(render_module, "make_tracer", marked_make_tracer)
        for name in integrator_kernels():
            label = KERNEL_LABELS.get(name, f"{name} kernel")
            patch(ptrace.integrator, name, profile.wrap(label, getattr(ptrace.integrator, name)))
        for name in ("shading_normals", "normal_colours"):
            patch(ptrace.paths, name, profile.wrap(f"{name} kernel (normal shading)",
                                                   getattr(ptrace.paths, name)))
        patch(render_module, "camera_samples",
              profile.wrap("camera_samples kernel", render_module.camera_samples))
        patch(ptrace.camera.Camera, "directions",
              profile.wrap("camera ray directions (Camera.directions kernel)",
                           ptrace.camera.Camera.directions))
        yield profile
    finally:
        for owner, name, value in reversed(saved):
            setattr(owner, name, value)


def profiled_render(scene, **options):
    """ptrace.render(scene, **options) under the wrappers: (image, wall seconds, Profile)."""
    import ptrace
    profile = Profile()
    with profiling(profile):
        start = time.perf_counter()
        image = ptrace.render(scene, **options)
        wall = time.perf_counter() - start
    return image, wall, profile


def table_rows(wall, profile):
    """(phase, calls, seconds, share of wall %) sorted by seconds, the glue row included."""
    rows = [(name, profile.calls[name], s, 100 * s / wall) for name, s in profile.seconds.items()]
    glue = wall - sum(profile.seconds.values())
    rows.append((GLUE, None, glue, 100 * glue / wall))
    return sorted(rows, key=lambda row: -row[2])


def command_section(name, options, wall, profile, plain_wall, identical, repeats):
    rows = table_rows(wall, profile)
    overhead = 100 * (wall - plain_wall) / plain_wall
    lines = [f"## {name}", "",
             f"{options['resolution'][0]}x{options['resolution'][1]}, -s {options['spp']}, "
             f"{options['threads']} threads. Wall {wall:.2f} s (median of {repeats} profiled "
             f"run{'s' if repeats > 1 else ''}); un-profiled wall {plain_wall:.2f} s (wrapping "
             f"overhead {overhead:+.1f}%, which includes run-to-run noise); profiled and "
             f"un-profiled images {'identical' if identical else 'DIFFERENT'}.", "",
             "| phase | calls | seconds | share of wall % |", "|---|---:|---:|---:|"]
    for phase, calls, seconds, share in rows:
        lines.append(f"| {phase} | {'' if calls is None else f'{calls:,}'} | {seconds:.3f} | "
                     f"{share:.1f} |")
    lines += ["", "Three slowest parts:", ""]
    for i, (phase, calls, seconds, share) in enumerate(rows[:3], 1):
        per_call = "" if calls is None else (f", {calls:,} call{'s' if calls > 1 else ''}, "
                                             f"{1e3 * seconds / calls:.1f} ms per call")
        lines.append(f"{i}. {phase}: {seconds:.3f} s, {share:.1f}% of wall{per_call}")
    return lines + [""]


def traversal_summary(results):
    """Per scene, the traversal share and wall time on each backend."""
    lines = ["## Traversal share by backend", "",
             "Traversal = closest-hit plus any-hit calls on the accelerator.", "",
             "| command | backend | wall s | traversal s | traversal share % |",
             "|---|---|---:|---:|---:|"]
    for name, (wall, profile) in results.items():
        command, backend = name.rsplit(" (", 1)
        traversal = sum(profile.seconds.get(phase, 0.0) for phase in TRAVERSAL)
        lines.append(f"| {command} | {backend.rstrip(')')} | {wall:.2f} | {traversal:.2f} | "
                     f"{100 * traversal / wall:.1f} |")
    return lines + [""]


def main(argv=None):
    import ptrace
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="120x90, -s / 16, one repeat")
    parser.add_argument("--repeats", type=int, default=None, help="profiled runs per command")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--only", nargs="*", default=None, help="command names to run")
    parser.add_argument("--output", default="profile_render.md")
    args = parser.parse_args(argv)
    repeats = args.repeats or (1 if args.quick else 3)
    resolution = QUICK_RESOLUTION if args.quick else RESOLUTION
    scenes, results, sections = {}, {}, []
    load_at_start = os.getloadavg()[0]
    for name in args.only or list(COMMANDS):
        relpath, spp, light_samples, depth, integrator, backend = COMMANDS[name]
        if relpath not in scenes:
            scenes[relpath] = ptrace.load(os.path.join(scenes_dir(), relpath))
        scene = scenes[relpath]
        options = dict(spp=max(1, spp // QUICK_SPP_DIVISOR) if args.quick else spp,
                       light_samples=light_samples, max_depth=depth, integrator=integrator,
                       accel=backend, resolution=resolution, threads=args.threads)
        print(f"{name}: compiling and warming up", flush=True)
        ptrace.render(scene, **dict(options, spp=2, max_depth=min(depth, 2), resolution=(8, 6)))
        ptrace.render(scene, **options)
        start = time.perf_counter()
        plain_image = ptrace.render(scene, **options)
        plain_wall = time.perf_counter() - start
        print(f"{name}: un-profiled {plain_wall:.2f} s", flush=True)
        runs = []
        for i in range(repeats):
            image, wall, profile = profiled_render(scene, **options)
            runs.append((wall, profile, np.array_equal(image, plain_image)))
            print(f"{name}: profiled run {i + 1}/{repeats} {wall:.2f} s", flush=True)
        wall, profile, _ = sorted(runs, key=lambda run: run[0])[len(runs) // 2]
        identical = all(run[2] for run in runs)
        results[name] = (wall, profile)
        sections += command_section(name, options, wall, profile, plain_wall, identical, repeats)
        for phase, calls, seconds, share in table_rows(wall, profile)[:3]:
            print(f"    {share:5.1f}%  {seconds:7.3f} s  {phase}", flush=True)
    lines = [report.header("Where a render's time goes: phases and their share of wall time"),
             "Method: for the length of one render, every callable a render runs per wave of "
             "rays is replaced at Python level by a wrapper that adds its time.perf_counter() "
             "seconds and a call count to a phase (module and class attributes are patched and "
             "restored afterwards; library code is unchanged): the accelerator's intersect, "
             "split by who asks (camera rays: the first intersect of each PathTracer.trace; "
             "bounce rays; hemisphere rays under -H) and occluded (shadow rays), accel.build, "
             "each ptrace.integrator kernel that ptrace/paths.py calls, the normal-shading "
             "kernels, camera_samples and Camera.directions. A traversal phase includes its "
             "backend's Python around the traversal (ray validation, allocating hits; for "
             "Embree, float32 conversion and its thread pool). The numba kernels run in parallel "
             "on all threads, so a phase's seconds are the wall seconds of its calls, not CPU "
             "seconds. The glue row is wall time minus the sum of the phases: numpy between the "
             "kernels (allocating path state, building Rays and hits, the per-wave Python in "
             "ptrace/paths.py, the per-pixel accumulation kernel) and "
             "per-render setup. Scenes are loaded and kernels compiled before timing; each "
             f"command runs once untimed first. {args.threads} threads; "
             + ("--quick: 120x90, -s divided by 16. " if args.quick else "480x360. ")
             + f"Load average (1 min) {load_at_start:.2f} at the start, {os.getloadavg()[0]:.2f} "
             "at the end: another busy process on these cores stalls every parallel kernel "
             "call (each waits for all its threads), which inflates the small kernels' shares.",
             ""]
    lines += traversal_summary(results) + sections
    path = report.write(args.output, "\n".join(lines))
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
