"""A cold render's kernels compiled ahead of it, on every core.

numba compiles one function at a time, on one thread, and most of a cold start is its compiler.
The stage kernels of a render do not depend on one another's compiled code, so they can be
compiled side by side, in processes: compile_ahead takes the kernels a render will call, with
the argument types it will call them with (ptrace.kernel.wavefront.Wavefront.kernels), keeps
those that numba's on-disk cache lacks, and, when there are two or more and more than one core,
starts worker processes (python -m ptrace.kernel.ahead) on the same list. Each process, this one
included, claims the next kernel no process has claimed (a file created exclusively in a folder
of claims) and compiles it into numba's cache, until none is left; this one then waits for the
workers, and the render loads their kernels from the cache on its first calls. A worker that
fails costs nothing but time: what it did not save, the render compiles itself. The kernels and
the images are the same whatever the number of processes."""
import os
import pickle
import shutil
import subprocess
import sys
import tempfile

import numba
from numba.core.dispatcher import Dispatcher

# PTRACE_COMPILE_PROCESSES: how many processes compile a cold render's kernels (this one
# included); default: the cores this process may run on
PROCESSES_VARIABLE = "PTRACE_COMPILE_PROCESSES"


def processes():
    """The number of processes that compile a cold render's kernels (PROCESSES_VARIABLE, else
    the cores this process may run on)."""
    text = os.environ.get(PROCESSES_VARIABLE, "").strip()
    if text:
        try:
            return max(1, int(text))
        except ValueError:
            pass
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:   # not Linux
        return os.cpu_count() or 1


def _reference(dispatcher):
    """How a worker process finds `dispatcher`: a module's function by its name, or a kernel
    made by one of ptrace.kernel's factories by the factory's arguments; None for any other."""
    from . import lighting, shading, stages
    for factory, made in ((shading.shading_stage, shading._STAGES),
                          (lighting.light_stage, lighting._LIGHT_STAGES),
                          (stages.hit_stage, stages._HIT_STAGES)):
        for key, kernel in made.items():
            if kernel is dispatcher:
                return ("made", factory.__module__, factory.__name__, key)
    function = dispatcher.py_func
    if "<locals>" in function.__qualname__:
        return None
    return ("function", function.__module__, function.__qualname__)


def _resolve(reference):
    import importlib
    module = importlib.import_module(reference[1])
    if reference[0] == "made":
        return getattr(module, reference[2])(*reference[3])
    return getattr(module, reference[2])


def _cached(dispatcher, types):
    """Whether numba's cache holds dispatcher's kernel for these argument types (read from its
    index; any surprise in numba's internals counts as not cached)."""
    try:
        cache = dispatcher._cache
        key = cache._index_key(types, dispatcher.targetctx.codegen())
        return key in cache._cache_file._load_index()
    except Exception:   # noqa: BLE001 - numba internals: compile rather than guess
        return False


def missing(calls):
    """Of calls ([(dispatcher, args)]), the kernels neither compiled in this process nor in
    numba's cache: [(dispatcher, argument types)], in the order given, each once. A call of
    anything but a numba dispatcher (a benchmark's timing wrapper, NUMBA_DISABLE_JIT's plain
    functions) has nothing to compile ahead: it is left to the render's first call."""
    found, seen = [], set()
    for dispatcher, args in calls:
        if not isinstance(dispatcher, Dispatcher):
            continue
        types = tuple(dispatcher.typeof_pyval(value) for value in args)
        if (id(dispatcher), types) in seen or types in dispatcher.overloads:
            continue
        seen.add((id(dispatcher), types))
        if getattr(dispatcher, "_cache", None) is None or not _cached(dispatcher, types):
            found.append((dispatcher, types))
    return found


def _claim_and_compile(claims, kernels):
    """Compile, one by one, the kernels ([(dispatcher, types)]) that no other process has
    claimed in the folder `claims`."""
    for number, (dispatcher, types) in enumerate(kernels):
        try:
            os.close(os.open(os.path.join(claims, str(number)), os.O_CREAT | os.O_EXCL))
        except FileExistsError:
            continue
        dispatcher.compile(types)


def compile_ahead(calls, workers=None):
    """Compile the kernels of calls ([(dispatcher, args)], Wavefront.kernels) that numba's cache
    lacks, on `workers` processes in all (default processes()), this one among them. Returns
    how many kernels were compiled so: none for one process, fewer than two missing, or no
    on-disk cache (the render then compiles on its first calls, as it would have)."""
    workers = processes() if workers is None else workers
    if workers < 2:
        return 0
    kernels = missing(calls)
    if len(kernels) < 2 or not _caching(kernels):
        return 0
    # the kernels a worker can find (the others compile on the render's first calls), in the
    # same order in every process: a claim's number names the same kernel in each
    found = [(_reference(dispatcher), (dispatcher, types)) for dispatcher, types in kernels]
    found = [(reference, kernel) for reference, kernel in found if reference is not None]
    kernels = [kernel for _reference_, kernel in found]
    shared = [(reference, types) for reference, (_dispatcher, types) in found]
    claims = tempfile.mkdtemp(prefix="ptrace-compile-")
    started = []
    try:
        with open(os.path.join(claims, "kernels.pickle"), "wb") as file:
            pickle.dump(shared, file)
        env = dict(os.environ)
        if numba.config.CACHE_DIR:   # the folder this process chose (ptrace.jit)
            env["NUMBA_CACHE_DIR"] = numba.config.CACHE_DIR
        for _ in range(min(workers, len(shared)) - 1):
            try:
                started.append(subprocess.Popen(
                    [sys.executable, "-m", "ptrace.kernel.ahead", claims], env=env,
                    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL))
            except OSError:   # no process to be had: this one compiles alone
                break
        _claim_and_compile(claims, kernels)
        for worker in started:
            worker.wait()
    finally:
        for worker in started:
            if worker.poll() is None:
                worker.kill()
                worker.wait()
        shutil.rmtree(claims, ignore_errors=True)
    return len(kernels)


def _caching(kernels):
    """Whether the kernels' cache is on disk where another process finds it."""
    return all(getattr(dispatcher, "_cache", None) is not None and
               type(dispatcher._cache).__name__ != "NullCache" for dispatcher, _ in kernels)


def _worker(claims):
    from .. import jit  # noqa: F401 - numba's cache as ptrace keys it (imported by ptrace too)
    with open(os.path.join(claims, "kernels.pickle"), "rb") as file:
        shared = pickle.load(file)
    _claim_and_compile(claims, [(_resolve(reference), types) for reference, types in shared])


if __name__ == "__main__":
    _worker(sys.argv[1])
