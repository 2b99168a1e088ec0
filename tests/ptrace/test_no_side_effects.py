"""A library changes nothing process-wide behind its user's back: importing
ptrace (with its CLI and distributed modules) and rendering in-process leaves the logging
configuration, warning filters, signal handlers, numpy's error state, numba's thread count, the
floating-point mode and the environment as they were. (malloc's settings cannot be read back;
no module calls mallopt any more.) Only the CLI (ptrace.app.cli.main), which owns its process, may
change them, and a distributed render scopes its one logging filter to itself (see
test_distributed.py)."""
import json
import pathlib
import subprocess
import sys

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"

# Run in a fresh interpreter, so that the import itself is what is measured. numpy and numba
# are imported before the first look: their own import-time set-up is theirs, not ptrace's.
CHILD = r"""
import faulthandler, json, logging, os, signal, sys, threading, warnings
import numpy as np
import numba

WATCHED = ["root", "tornado", "tornado.application", "tornado.access", "tornado.general",
           "distributed", "distributed.utils", "dask", "numba", "py.warnings", "ptrace", "accel"]


def describe(logger):
    return dict(level=logger.level, disabled=logger.disabled, propagate=logger.propagate,
                filters=[f"{type(f).__module__}.{type(f).__qualname__}" for f in logger.filters],
                handlers=[(f"{type(h).__module__}.{type(h).__qualname__}", h.level,
                           len(h.filters)) for h in logger.handlers])


def state():
    loggers = {name: describe(logging.getLogger(None if name == "root" else name))
               for name in WATCHED}
    # any logger anyone configured (a handler, a filter, a level), whoever created it
    configured = {name: describe(logger) for name, logger in
                  logging.Logger.manager.loggerDict.items()
                  if isinstance(logger, logging.Logger)
                  and (logger.handlers or logger.filters or logger.level or logger.disabled)}
    return dict(
        loggers=loggers, configured=configured, disable=logging.root.manager.disable,
        warning_filters=[repr(f) for f in warnings.filters],
        showwarning=warnings.showwarning is ORIGINAL_SHOWWARNING,
        signals={s.name: repr(signal.getsignal(s)) for s in
                 (signal.SIGINT, signal.SIGTERM, signal.SIGCHLD, signal.SIGPIPE)},
        excepthook=sys.excepthook is sys.__excepthook__,
        threading_excepthook=repr(threading.excepthook),
        faulthandler=faulthandler.is_enabled(),
        numpy_errors=np.geterr(), print_options=repr(np.get_printoptions()),
        numba_threads=numba.get_num_threads(), recursion_limit=sys.getrecursionlimit(),
        # this thread's floating-point mode: flush-to-zero would give 0.0 (argv[2] is "1.0",
        # read at run time so the product is not folded when the code is compiled)
        subnormals=5e-324 * float(sys.argv[2]) != 0.0,
        environment=dict(os.environ))


ORIGINAL_SHOWWARNING = warnings.showwarning
before = state()
import ptrace
import ptrace.app.cli
import ptrace.rendering.distributed
rays, lit = [], []
scene = ptrace.load(sys.argv[1])
for backend in ("bvh", "embree"):   # the embree library is loaded and its device made
    stats = {}
    with warnings.catch_warnings(record=True):   # the render's own warnings, if any
        image = ptrace.render(scene, spp=2, max_depth=2, resolution=(8, 6), threads=1,
                              accel=backend, stats=stats)
    rays.append(int(stats["rays"]))
    lit.append(bool(image.max() > 0))
after = state()
print(json.dumps(dict(before=before, after=after, rays=rays, lit=lit)))
"""


def test_import_and_render_change_nothing_process_wide():
    result = subprocess.run([sys.executable, "-c", CHILD, str(SHIPPED), "1.0"],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert min(report["rays"]) > 0 and all(report["lit"])   # it did render, on both backends
    assert report["before"]["subnormals"]
    before, after = report["before"], report["after"]
    for key in before:
        assert after[key] == before[key], (key, before[key], after[key])
