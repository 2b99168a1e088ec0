"""The compiled face of every backend: one ray's closest hit and any hit, callable from numba code.

    record = accelerator.compiled                 # a namedtuple of the backend's flat arrays
    scratch = new_scratch(record)                 # once per block of rays (traversal stacks)
    t, prim, u, v = closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)
    blocked = any_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)

The answers are the batch face's (accel.Hits): the closest hit with tmin <= t <= tmax, t = inf
and prim = -1 on a miss, (u, v) barycentric for triangles and 0 for spheres.

Each backend's record is a namedtuple class of its own, registered here with its three numba
functions. The two query functions are compiled with `_nrt=False` (and so must be every function
they call that takes arrays): a numba function that is not inlined increfs and decrefs every array
it is passed, atomically, on every call; with a record of five arrays and a scratch of four, three
levels of calls per ray cost more than the traversal itself. Without NRT a function cannot allocate,
which none of them needs. The three names above are numba overloads that pick the registered
functions by the record's type, so a numba kernel written against them is compiled once per backend
(one specialisation each, each in numba's on-disk cache) and never names a backend; called from
plain Python (a kernel's py_func, in tests) they dispatch the same way.
"""
import inspect
import threading
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from numba import njit, types
from numba.extending import overload

from .interpreted import interpreted

BLOCKS_PER_THREAD = 8   # work items per thread of a batch (each makes its own scratch)

_FACES = {}      # record class -> (new_scratch, closest_hit, any_hit), numba functions


def register(record_class, new_scratch_fn, closest_hit_fn, any_hit_fn):
    """Make record_class's compiled face known (each backend module does this on import). The
    query functions' sources become the overloads of closest_hit and any_hit (_ray_query), so
    their parameters must be named as those are."""
    for function, face in ((closest_hit_fn, closest_hit), (any_hit_fn, any_hit)):
        source = getattr(function, "py_func", function)   # a function (NUMBA_DISABLE_JIT)
        if inspect.signature(source) != inspect.signature(face):
            raise TypeError(f"{source.__qualname__} must take the parameters "
                            f"{inspect.signature(face)}")
    _FACES[record_class] = (new_scratch_fn, closest_hit_fn, any_hit_fn)


def _face(record):
    """The registered functions for a record's numba type, or None (not a backend record)."""
    if isinstance(record, types.BaseNamedTuple):
        return _FACES.get(record.instance_class)
    return None


def new_scratch(record):
    """Per-block working memory of the backend (traversal stacks, a ray structure). Called from
    Python, the backend's function runs as Python: a few allocations, not worth a compile."""
    return interpreted(_FACES[type(record)][0])(record)


def closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """(t, prim, u, v) of the closest hit with tmin <= t <= tmax; (inf, -1, 0, 0) on a miss."""
    return _FACES[type(record)][1](record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)


def any_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """True if anything is hit with tmin <= t <= tmax (stops at the first hit found)."""
    return _FACES[type(record)][2](record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)


@overload(new_scratch, jit_options={"cache": True})
def _new_scratch(record):
    face = _face(record)
    if face is not None:
        function = face[0]
        return lambda record: function(record)
    return None


def _ray_query(record, which):
    """The implementation of a one-ray query (which: 1 closest hit, 2 any hit) for `record`'s
    type: the Python source of the function its backend registered, compiled here as the
    overload itself (not a call of it, which would compile the traversal once more: once in
    the backend's function, once in a wrapper around it), or None for an unregistered type."""
    face = _face(record)
    if face is not None:
        return face[which].py_func
    return None


@overload(closest_hit, jit_options={"cache": True, "_nrt": False, "forceinline": True})
def _closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    return _ray_query(record, 1)


@overload(any_hit, jit_options={"cache": True, "_nrt": False, "forceinline": True})
def _any_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    return _ray_query(record, 2)


# -- a variant chosen by a record's class, where a kernel compiles

def derives(value, cls):
    """True if `value` (a value, or a namedtuple's numba type while a kernel compiles) is of a
    class that derives from `cls`."""
    own = getattr(value, "instance_class", type(value))
    return isinstance(own, type) and issubclass(own, cls)


def _python(function):
    return getattr(function, "py_func", function)   # (a function under NUMBA_DISABLE_JIT)


def by_class(cls, its_fn, other_fn):
    """A function of (first, ...) that runs its_fn where `first` derives from `cls`, other_fn
    otherwise (numba functions of the same parameters). In numba code it is an overload that
    picks one of them by the first argument's type, so only that one compiles: a namedtuple
    class per variant makes the variant a compile-time choice."""
    def by_its_class(first, *args):
        return (its_fn if derives(first, cls) else other_fn)(first, *args)

    def choose(first, *args):
        return _python(its_fn if derives(first, cls) else other_fn)

    # numba matches an overload's parameters with its implementation's, by name
    by_its_class.__signature__ = choose.__signature__ = inspect.signature(_python(other_fn))
    overload(by_its_class, inline="always", jit_options={"cache": True})(choose)
    return by_its_class


# -- the batch face on top of the compiled one (for backends without a batch kernel of their own)
# Plain nogil kernels over a range of rays, run on numba's thread count of Python threads
# (in_blocks), not prange: numba's parallel lowering compiled each of them for 3-4 s, once per
# backend record and ray layout, where a serial loop compiles in a fraction of a second.

@njit(cache=True, nogil=True)
def intersect_batch(record, origins, directions, tmin, tmax, out_t, out_prim, out_u, out_v,
                    start, end):
    """closest_hit for rays start .. end - 1 of a batch."""
    scratch = new_scratch(record)
    for r in range(start, end):
        t, prim, u, v = closest_hit(record, scratch, origins[r, 0], origins[r, 1],
                                    origins[r, 2], directions[r, 0], directions[r, 1],
                                    directions[r, 2], tmin[r], tmax[r])
        out_t[r] = t
        out_prim[r] = prim
        out_u[r] = u
        out_v[r] = v


@njit(cache=True, nogil=True)
def occluded_batch(record, origins, directions, tmin, tmax, out, start, end):
    """any_hit for rays start .. end - 1 of a batch."""
    scratch = new_scratch(record)
    for r in range(start, end):
        out[r] = any_hit(record, scratch, origins[r, 0], origins[r, 1], origins[r, 2],
                         directions[r, 0], directions[r, 1], directions[r, 2], tmin[r], tmax[r])


_pool = {"size": 0, "pool": None}
_pool_lock = threading.Lock()


def in_blocks(kernel, n, *args):
    """kernel(*args, start, end) over rays 0 .. n - 1 in BLOCKS_PER_THREAD blocks per thread of
    numba's thread count (numba.get_num_threads(), as -t sets it), at least 64 rays each,
    handed out to the threads as they free up; a kernel compiled with nogil runs them side by
    side. On an interrupt, the blocks not started are cancelled and the running ones awaited,
    so nothing writes after it returns."""
    threads = numba.get_num_threads()
    size = max(64, -(-n // (threads * BLOCKS_PER_THREAD)))
    blocks = [(start, min(n, start + size)) for start in range(0, n, size)]
    if threads == 1 or len(blocks) <= 1:
        for start, end in blocks:
            kernel(*args, start, end)
        return
    with _pool_lock:
        if _pool["size"] != threads:
            if _pool["pool"] is not None:
                _pool["pool"].shutdown(wait=True)
            _pool["pool"] = ThreadPoolExecutor(threads, thread_name_prefix="accel")
            _pool["size"] = threads
        pool = _pool["pool"]
    futures = [pool.submit(kernel, *args, start, end) for start, end in blocks]
    try:
        for future in futures:
            future.result()
    finally:
        for future in futures:
            future.cancel()
        for future in futures:
            if not future.cancelled():
                future.exception()


def run_intersect(record, rays, hits_class):
    """The batch intersect of a backend through its compiled face."""
    n = len(rays)
    hits = hits_class(np.empty(n), np.empty(n, dtype=np.int64), np.empty(n), np.empty(n))
    in_blocks(intersect_batch, n, record, rays.origins, rays.directions, rays.tmin, rays.tmax,
              hits.t, hits.prim, hits.u, hits.v)
    return hits


def run_occluded(record, rays):
    """The batch occluded of a backend through its compiled face."""
    out = np.empty(len(rays), dtype=np.bool_)
    in_blocks(occluded_batch, len(rays), record, rays.origins, rays.directions, rays.tmin,
              rays.tmax, out)
    return out


class CompiledFace:
    """What every backend's Python face shares: batch queries through its compiled record
    (`self.compiled`, the same functions the path loop calls) and the geometry's counts in
    stats(). A backend sets compiled, geometry, kind and _build_seconds."""

    def intersect(self, rays):
        """The batch closest hit through the compiled face, as the path loop calls it."""
        from .types import Hits
        rays.validate()
        return run_intersect(self.compiled, rays, Hits)

    def occluded(self, rays):
        rays.validate()
        return run_occluded(self.compiled, rays)

    def geometry_stats(self):
        """stats()'s common part: kind, primitive counts and the build's seconds."""
        return {"kind": self.kind, "primitives": self.geometry.primitive_count,
                "triangles": self.geometry.triangle_count, "spheres": self.geometry.sphere_count,
                "build_seconds": self._build_seconds}
