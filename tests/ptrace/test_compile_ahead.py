"""A cold render's kernels compiled ahead, on several processes (ptrace.kernel.ahead): each kernel
is compiled by the one process that claims it, a worker's kernels reach the render through
numba's on-disk cache, and what a worker cannot do the render compiles itself. (That the list
of kernels is the render's: test_wavefront's test_the_kernels_compiled_ahead_are_those_a_render_
calls.)"""
import os
import pickle
import subprocess
import sys
import tempfile
import time

import numpy as np

from ptrace.kernel import ahead

PROBE = '''
from numba import njit


@njit(cache=True)
def first(x):
    return x + 1.0


@njit(cache=True)
def second(values):
    return values.sum() * 2.0
'''


def probe_module(tmp_path, monkeypatch, name):
    """A module of two small cached kernels, importable here and by worker processes."""
    (tmp_path / f"{name}.py").write_text(PROBE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(tmp_path)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    module = __import__(name)
    return module, [(module.first, (1.5,)), (module.second, (np.arange(4.0),))]


def test_a_worker_compiles_the_kernels_it_claims_into_the_cache_and_skips_the_claimed(
        tmp_path, monkeypatch):
    module, calls = probe_module(tmp_path, monkeypatch, "ahead_probe_worker")
    kernels = ahead.missing(calls)
    assert [dispatcher for dispatcher, _ in kernels] == [module.first, module.second]
    claims = tmp_path / "claims"
    claims.mkdir()
    (claims / "0").touch()     # `first` is another process's
    with open(claims / "kernels.pickle", "wb") as file:
        pickle.dump([(ahead._reference(d), types) for d, types in kernels], file)
    worker = subprocess.run([sys.executable, "-m", "ptrace.kernel.ahead", str(claims)],
                            capture_output=True, text=True, timeout=300)
    assert worker.returncode == 0, worker.stderr
    # the worker compiled `second` alone, into the cache: this process loads it from there
    assert ahead.missing(calls) == [kernels[0]]
    assert module.second(np.arange(4.0)) == 12.0
    assert module.second.stats.cache_hits and not module.second.stats.cache_misses
    assert (claims / "1").exists()


def test_compile_ahead_leaves_every_kernel_compiled_here_or_cached_and_no_process_behind(
        tmp_path, monkeypatch):
    module, calls = probe_module(tmp_path, monkeypatch, "ahead_probe_both")
    before = set(os.listdir(tempfile.gettempdir()))
    assert ahead.compile_ahead(calls, workers=2) == 2
    assert ahead.missing(calls) == []
    assert module.first(1.5) == 2.5 and module.second(np.arange(4.0)) == 12.0
    # the folder of claims is gone (the workers were waited for)
    assert not {name for name in set(os.listdir(tempfile.gettempdir())) - before
                if name.startswith("ptrace-compile-")}
    # with one process, or nothing missing, nothing is compiled ahead
    assert ahead.compile_ahead(calls, workers=2) == 0


def test_a_call_of_a_plain_function_is_left_to_the_render(tmp_path, monkeypatch):
    """A stage wrapped in a plain function (as benchmarks.profile_render times them) has no
    kernel of its own to compile ahead: it is skipped, and the dispatchers beside it are not."""
    module, calls = probe_module(tmp_path, monkeypatch, "ahead_probe_wrapped")

    def wrapper(*args):
        return module.first(*args)

    kernels = ahead.missing([(wrapper, (1.5,))] + calls[1:])
    assert [dispatcher for dispatcher, _ in kernels] == [module.second]


def test_one_process_compiles_nothing_ahead(tmp_path, monkeypatch):
    module, calls = probe_module(tmp_path, monkeypatch, "ahead_probe_one")
    monkeypatch.setenv(ahead.PROCESSES_VARIABLE, "1")
    assert ahead.processes() == 1 and ahead.compile_ahead(calls) == 0
    assert len(ahead.missing(calls)) == 2
    monkeypatch.setenv(ahead.PROCESSES_VARIABLE, "3")
    assert ahead.processes() == 3


WAITER = '''
import numpy as np
import ptrace  # noqa: F401 - ptrace.jit's cache behaviour
import {name} as probe
print("ready", flush=True)
probe.second(np.arange(4.0))
print(sum(probe.second.stats.cache_hits.values()),
      sum(probe.second.stats.cache_misses.values()), flush=True)
'''


def test_a_process_that_lacks_a_kernel_another_is_compiling_waits_and_loads_it(
        tmp_path, monkeypatch):
    """The second of two processes that lack the same kernel at once does not compile it too:
    it waits on the kernel's lock (ptrace.jit) and loads what the first saves. (Without the
    lock, the waiter compiles it: 0 hits, 1 miss.)"""
    import fcntl

    from ptrace import jit
    module, calls = probe_module(tmp_path, monkeypatch, "ahead_probe_lock")
    dispatcher, types = ahead.missing(calls)[1]
    path = jit._compile_lock_path(dispatcher, types)
    assert path is not None and path.startswith(dispatcher._cache._cache_path)
    with open(path, "ab") as held:
        fcntl.flock(held, fcntl.LOCK_EX)     # as if this process were compiling it
        waiter = subprocess.Popen([sys.executable, "-c", WAITER.format(name=module.__name__)],
                                  stdout=subprocess.PIPE, text=True)
        try:
            assert waiter.stdout.readline().strip() == "ready"
            time.sleep(2.0)
            assert waiter.poll() is None     # waiting on the lock, not compiling
            # compiled and saved while the lock is held (numba's compile, without the lock)
            type(dispatcher).compile.__wrapped__(dispatcher, types)
        except BaseException:
            waiter.kill()
            raise
    out, _ = waiter.communicate(timeout=120)
    assert tuple(map(int, out.split())) == (1, 0), out
