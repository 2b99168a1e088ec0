"""Run the benchmarks: all of them in sequence, or one by name.

    python -m benchmarks all [--quick] [--output-dir DIR]
    python -m benchmarks NAME [ARGS...]        # the same as python -m benchmarks.NAME ARGS...

`all` runs, in order, the benchmarks of the registry (benchmarks.BENCHMARKS) that are in
`all`: mitsuba_reference only when mitsuba is importable; a module that does not exist is
skipped with a printed line, and a failing module is reported and the rest still run (the exit
code is 1 if any failed). Modules are imported lazily. `NAME` runs any registered benchmark.

--quick makes every run short with the arguments the registry gives each module (--quick for
those that take it; first_images gets --repeats 1), and skips mitsuba_reference (it would
overwrite the reference EXR that the tests compare against). Quick reports and charts go to
--output-dir (default: a new temporary directory, printed), never over the full ones in
benchmarks/results/; without --quick they go to benchmarks/results/ unless --output-dir is
given. The directory is redirected by pointing benchmarks.report.RESULTS at it for the whole
run, which every module writes through.
"""
import argparse
import importlib
import importlib.util
import sys
import tempfile
import time
import traceback
from pathlib import Path

from . import BENCHMARKS, report


def names():
    """The benchmarks `all` runs, in order."""
    return [name for name, benchmark in BENCHMARKS.items() if benchmark.in_all]


def quick_args(name, module):
    """The arguments of `name`'s main(argv) under `all --quick` (from the registry)."""
    quick = BENCHMARKS[name].quick
    return list(quick(module) if callable(quick) else quick)


def run_all(argv):
    parser = argparse.ArgumentParser(prog="python -m benchmarks all")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--output-dir", default=None)
    args = parser.parse_args(argv)
    output_dir = args.output_dir
    if args.quick and output_dir is None:
        output_dir = tempfile.mkdtemp(prefix="ptrace-benchmarks-")
    if output_dir is not None:
        Path(output_dir).mkdir(parents=True, exist_ok=True)
        print(f"reports go to {Path(output_dir).resolve()}", flush=True)
    failed = []
    results = report.RESULTS
    if output_dir is not None:
        report.RESULTS = Path(output_dir).resolve()
    try:
        for name in names():
            run_one(name, args.quick, failed)
    finally:
        report.RESULTS = results
    if failed:
        print(f"failed: {', '.join(failed)}")
        return 1
    return 0


def run_one(name, quick, failed):
    """Run one module in `all`, or print why it is skipped; failures go to `failed`."""
    if importlib.util.find_spec(f"benchmarks.{name}") is None:
        print(f"--- {name}: skipped (no module benchmarks/{name}.py)", flush=True)
        return
    benchmark = BENCHMARKS.get(name)
    if benchmark is not None and quick and benchmark.quick is None:
        print(f"--- {name}: skipped in --quick ({benchmark.quick_skip})", flush=True)
        return
    if benchmark is not None and benchmark.requires is not None \
            and importlib.util.find_spec(benchmark.requires) is None:
        print(f"--- {name}: skipped ({benchmark.requires} is not installed)", flush=True)
        return
    module = importlib.import_module(f"benchmarks.{name}")
    if not callable(getattr(module, "main", None)):
        print(f"--- {name}: skipped (no main(argv))", flush=True)
        return
    module_args = quick_args(name, module) if quick else []
    print(f"--- {name} {' '.join(module_args)}", flush=True)
    start = time.perf_counter()
    try:
        module.main(module_args)
    except SystemExit as error:
        if error.code:
            print(f"--- {name}: exited with {error.code}", flush=True)
            failed.append(name)
    except Exception:   # noqa: BLE001 - report it and run the rest
        traceback.print_exc()
        failed.append(name)
    print(f"--- {name}: {time.perf_counter() - start:.0f} s", flush=True)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        print("\nbenchmarks:")
        for name, benchmark in BENCHMARKS.items():
            print(f"  {name:18} {benchmark.description}"
                  + ("" if benchmark.in_all else " (by name only, not in `all`)"))
        return 0
    name, rest = argv[0], argv[1:]
    if name == "all":
        return run_all(rest)
    if name not in BENCHMARKS or importlib.util.find_spec(f"benchmarks.{name}") is None:
        print(f"unknown benchmark {name!r}; choose all or one of {', '.join(BENCHMARKS)}")
        return 2
    result = importlib.import_module(f"benchmarks.{name}").main(rest)
    return result if isinstance(result, int) else 0


if __name__ == "__main__":
    sys.exit(main())
