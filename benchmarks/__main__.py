"""Run the benchmarks: all of them in sequence, or one by name.

    python -m benchmarks all [--quick] [--output-dir DIR]
    python -m benchmarks NAME [ARGS...]        # the same as python -m benchmarks.NAME ARGS...

`all` runs, in order, accel_rays, first_images, seed_commands, mitsuba_reference (only when
mitsuba is importable), stability, then any other benchmarks/*.py module with a main(argv);
a module that does not exist is skipped with a printed line, and a failing module is reported
and the rest still run (the exit code is 1 if any failed). Modules are imported lazily.

--quick makes every run short: modules that take --quick get it, first_images gets --repeats 1,
seed_commands runs its first two commands with -s divided by 64 on bvh and embree, and
mitsuba_reference is skipped (it would overwrite the reference EXR that the tests compare
against). Quick reports and charts go to --output-dir (default: a new temporary directory,
printed), never over the full ones in benchmarks/results/; without --quick they go to
benchmarks/results/ unless --output-dir is given. The directory is redirected by pointing
benchmarks.report.RESULTS at it for the whole run, which every module writes through.
"""
import argparse
import importlib
import importlib.util
import inspect
import pkgutil
import sys
import tempfile
import time
import traceback
from pathlib import Path

from . import report

ORDER = ["accel_rays", "first_images", "seed_commands", "mitsuba_reference", "stability"]
NOT_BENCHMARKS = {"__main__", "report", "synthetic", "templating",
                  "stability_light",   # part of stability's report (runs alone by name)
                  "side_by_side"}      # needs an older checkout to compare with
RUN_BY_NAME_ONLY = {"stability_light", "side_by_side"}   # not in `all`, but `NAME` runs them


def names():
    """ORDER, then every other module of the package, alphabetically."""
    here = [m.name for m in pkgutil.iter_modules([str(Path(__file__).parent)])]
    return ORDER + sorted(n for n in here if n not in ORDER and n not in NOT_BENCHMARKS)


def takes(module, option):
    """Whether a module's command line has `option` (its source names the flag)."""
    try:
        return f'"{option}"' in inspect.getsource(module)
    except (OSError, TypeError):
        return False


def quick_args(name, module):
    if takes(module, "--quick"):
        return ["--quick"]
    if name == "first_images":
        return ["--repeats", "1"]
    if name == "seed_commands":
        return ["--spp-scale", "64", "--backends", "bvh", "embree",
                "--only", *list(module.COMMANDS)[:2]]
    return []


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
    if name == "mitsuba_reference":
        if quick:
            print(f"--- {name}: skipped in --quick (it rewrites benchmarks/references/)",
                  flush=True)
            return
        if importlib.util.find_spec("mitsuba") is None:
            print(f"--- {name}: skipped (mitsuba is not installed)", flush=True)
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
        print("\nbenchmarks: " + ", ".join(names()))
        return 0
    name, rest = argv[0], argv[1:]
    if name == "all":
        return run_all(rest)
    if (name in NOT_BENCHMARKS and name not in RUN_BY_NAME_ONLY) \
            or importlib.util.find_spec(f"benchmarks.{name}") is None:
        print(f"unknown benchmark {name!r}; choose all or one of {', '.join(names())}")
        return 2
    result = importlib.import_module(f"benchmarks.{name}").main(rest)
    return result if isinstance(result, int) else 0


if __name__ == "__main__":
    sys.exit(main())
