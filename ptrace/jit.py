"""What numba's on-disk cache holds, so a cold first run can say that it is compiling."""
from .integrator import render_pixels

# The README's render with an empty cache on the 2-core development machine spent about this long
# compiling (benchmarks/results/first_images.md: cold wall minus warm wall).
COLD_COMPILE_SECONDS = 35


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

