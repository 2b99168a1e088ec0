"""What numba's on-disk cache holds, so a cold first run can say that it is compiling."""
from .integrator import render_pixels

# A small render of scenes/cornell.dae with an empty cache on the 2-core development machine
# took 43-52 s of wall time (2026-12-02, after the estimator work and the watertight test; load
# 1-2.5; a warm run takes about 2 s): benchmarks/results/first_images.md predates that work.
COLD_COMPILE_SECONDS = 45


def is_cold(record_class, dispatcher=render_pixels):
    """True if numba's cache has no compiled render kernel for this backend's record type (the
    kernel that dominates compile time; the others come and go with it). Reads only the cache's
    index; any surprise in numba's internals counts as warm (no message rather than a wrong
    one)."""
    try:
        index = dispatcher._cache._cache_file._load_index()
    except Exception:   # noqa: BLE001 - numba internals: never let a notice break a render
        return False
    for key in index:
        signature = key[0]
        if any(getattr(t, "instance_class", None) is record_class for t in signature):
            return False
    return True

