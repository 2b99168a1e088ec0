"""The clock of a render's phases (Phases) that ptrace.render reports in its stats: wall seconds
per phase, numba's compiling counted apart, and counts."""
import threading
import time

from numba.core import event

# A render's phases, in the order they run; they cover the call to ptrace.render without gaps.
# setup: settings, frame, camera, warnings, pixel grid, sums, pass schedule. compile: the cold
# cache check, and every second in which a thread is inside numba's compiler (compiling, or
# loading kernels from numba's on-disk cache), whichever phase it happens in (the path loop
# compiles on its first call, in the passes; a backend's build kernels in accel.build).
# build: accel.build. records: the scene's, camera's and backend's kernel records (RenderJob).
# render: the passes (the compiled path loop on blocks of pixels, adaptive decisions between
# passes). image: the mean per pixel, the stats, the image in top-row-first order.
IN_PROCESS_PHASES = ("setup", "compile", "build", "records", "render", "image")
# On a Dask cluster: scatter sends the scene and the render's request to the workers; render is
# the rest of the executor (tiles submitted and merged; the workers' builds and compiles happen
# inside it).
DASK_PHASES = ("setup", "scatter", "render", "image")
_COMPILER_EVENTS = ("numba:compiler_lock", "numba:compile")


class _CompilerClock(event.Listener):
    """Seconds in which at least one thread is inside numba's compiler lock (the union of the
    "numba:compiler_lock" events of every thread: compiling, loading from the on-disk cache, or
    waiting for either) and the number of functions compiled ("numba:compile" events). Called
    from whichever thread compiles."""

    def __init__(self):
        self._lock = threading.Lock()
        self._inside, self._since, self._seconds = 0, 0.0, 0.0
        self.compiled = 0

    def on_start(self, ev):
        with self._lock:
            if ev.kind == "numba:compile":
                self.compiled += 1
                return
            if self._inside == 0:
                self._since = time.perf_counter()
            self._inside += 1

    def on_end(self, ev):
        with self._lock:
            if ev.kind == "numba:compile" or self._inside == 0:   # (began before we listened)
                return
            self._inside -= 1
            if self._inside == 0:
                self._seconds += time.perf_counter() - self._since

    def seconds(self):
        """Seconds so far, an interval still open included."""
        with self._lock:
            open_ = time.perf_counter() - self._since if self._inside else 0.0
            return self._seconds + open_


class Phases:
    """Wall seconds per phase of one render, and counts (like pbrt's stats timers and counters
    or Mitsuba's ScopedPhase). Phases are laps: enter(name) ends the running phase and starts
    `name`, stop() ends the last, so the phases cover the time from the first enter to stop()
    with no gap or overlap, and a phase entered twice adds up. If "compile" is one of the names,
    numba's compiler events are listened to from the first enter to stop() (the listener is
    removed by stop(), which must be called), and the seconds in which any thread is inside
    numba's compiler go to "compile" instead of the running phase; counts["compiled"] is then
    the number of functions numba compiled (0 when every kernel came from its cache)."""

    def __init__(self, names):
        self.seconds = dict.fromkeys(names, 0.0)
        self.counts = {"compiled": 0} if "compile" in names else {}
        self._clock = _CompilerClock() if "compile" in names else None
        self._running = None
        self._since = self._compiling_since = 0.0

    def _compiling(self):
        return self._clock.seconds() if self._clock is not None else 0.0

    def enter(self, name):
        if name not in self.seconds:
            raise KeyError(f"{name!r} is not one of the phases {tuple(self.seconds)}")
        if self._running is None and self._clock is not None:
            for kind in _COMPILER_EVENTS:
                event.register(kind, self._clock)
        self._close()
        self._running = name

    def _close(self):
        now, compiling = time.perf_counter(), self._compiling()
        if self._running is not None:
            jit = compiling - self._compiling_since
            self.seconds[self._running] += now - self._since - jit
            if self._clock is not None:
                self.seconds["compile"] += jit
        self._since, self._compiling_since = now, compiling

    def stop(self):
        """End the running phase and stop listening to numba; does nothing if not running."""
        if self._running is None:
            return
        self._close()
        self._running = None
        if self._clock is not None:
            for kind in _COMPILER_EVENTS:
                event.unregister(kind, self._clock)
            self.counts["compiled"] = self._clock.compiled

    def compiled_so_far(self):
        """(seconds, functions) of numba's compiling from the first enter until now."""
        if self._running is not None:
            self._close()
        return self.seconds.get("compile", 0.0), self._clock.compiled if self._clock else 0

    def count(self, name, n=1):
        self.counts[name] = self.counts.get(name, 0) + n
