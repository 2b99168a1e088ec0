"""Benchmark scripts. Each writes a Markdown report (and charts) into benchmarks/results/.

BENCHMARKS is the registry that `python -m benchmarks` (benchmarks/__main__.py) reads: every
benchmark module, in the order `all` runs them, with a line saying what it measures and how
`all --quick` runs it. A new benchmark module is added here (tests/test_benchmarks_quick.py
checks that every module of the package is either here or in HELPERS). Nothing is imported
until a benchmark runs.
"""
from dataclasses import dataclass


@dataclass(frozen=True)
class Benchmark:
    """One benchmark module's entry: `description` (one line, for the runner's help); `quick`,
    the arguments `all --quick` passes to its main(argv) (a tuple, or a function of the
    imported module that returns the list), or None if `all --quick` skips it (`quick_skip`
    says why); `requires`, a module that must be importable for `all` to run it; `in_all`,
    False for modules that run only by name."""
    description: str
    quick: object = ("--quick",)
    quick_skip: str = ""
    requires: str = None
    in_all: bool = True


BENCHMARKS = {
    "accel_rays": Benchmark("rays per second of every backend on course meshes and a synthetic "
                            "series, BVH builds, compile times"),
    "first_images": Benchmark("normal-shading render time per backend and CLI start-up",
                              quick=("--repeats", "1")),
    "mitsuba_reference": Benchmark("renders course scenes with Mitsuba 3 as references for "
                                   "ptrace", quick=None, requires="mitsuba",
                                   quick_skip="it rewrites tests/references/"),
    "distributed": Benchmark("the price of a local Dask cluster and a model of scaling"),
    "error_vs_time": Benchmark("relative MSE against wall time per estimator and backend, and "
                               "Mitsuba 3's"),
    "paths_per_second": Benchmark("camera paths per second of ptrace's backends and Mitsuba 3"),
    "profile_render": Benchmark("where a render's wall time goes: phases, the path loop by "
                                "differencing, the accelerator's share"),
    "view_latency": Benchmark("ptrace view: milliseconds from a camera drag to the first "
                              "refreshed image, pushed and drawn in headless chromium",
                              requires="selenium", in_all=False),
    "many_lights": Benchmark("a room of 64 area lights and 1024 emissive tiles: MSE x seconds "
                             "of each light sampler against every light at every vertex",
                             in_all=False),
    "guiding": Benchmark("path guiding: relative MSE against wall time, training included, of "
                         "unguided and guided ptrace and Mitsuba 3 on scenes lit indirectly",
                         in_all=False),
    "mitsuba_scenes": Benchmark("ptrace and Mitsuba 3 on the project's Mitsuba XML scenes: mean "
                                "ratio, per-pixel z-test and times side by side",
                                requires="mitsuba", in_all=False),
}

# modules of the package that are not benchmarks
HELPERS = ("__main__", "rays", "report", "synthetic", "templating",
           "sample_kernel",        # a profiling tool (needs perf), not a benchmark
           "guiding_diagnosis")    # a study of the learnt guide that prints only
