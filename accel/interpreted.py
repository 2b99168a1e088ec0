"""A numba function run as plain Python: for work too small to pay for its compile.

    boxes = interpreted(_primitive_boxes)(vertices, faces, centers, radii, pad)

runs the function's own source by the interpreter, with every numba function it calls run the same
way, so the answer is the compiled function's, bit for bit (IEEE arithmetic is the same either
way; the tests compare the two), without compiling anything. A build of a few hundred primitives
takes milliseconds so, where compiling it the first time takes seconds (numba compiles each
function on first use, and a fresh install compiles everything it runs).

Only functions written for it qualify: loops over numpy arrays and scalars, and numba functions
of the same kind, named as globals of their module (not through closures). A numba intrinsic
has no Python body; the one the build uses (numba's bitcast, `viewer`) is given one here.
"""
import types

import numpy as np
from numba.core.dispatcher import Dispatcher
from numba.cpython.unsafe.numbers import viewer


def _bitcast(value, dtype):
    """numba's `viewer` (numba.cpython.unsafe.numbers) in Python: value's bits as a dtype."""
    return np.array(value).view(dtype)[()]


# Work of at most this many items (primitives, lights) runs as Python where a caller asks for it
# (sized): well under a second for the BVH's build, the slowest per item (about 0.2 ms per
# primitive), where compiling it costs seconds.
SMALL = 1024

_INTRINSICS = {id(viewer): _bitcast}   # id: an intrinsic need not be hashable
_MADE = {}   # dispatcher -> its interpreted function


def interpreted(function):
    """The numba function `function` as a plain Python function (made once, then reused)."""
    if not isinstance(function, Dispatcher):   # already Python (NUMBA_DISABLE_JIT)
        return function
    made = _MADE.get(function)
    if made is None:
        source = function.py_func
        names = dict(source.__globals__)
        made = types.FunctionType(source.__code__, names, source.__name__, source.__defaults__,
                                  source.__closure__)
        _MADE[function] = made   # before the callees: a function may call itself
        for name, value in source.__globals__.items():
            if isinstance(value, Dispatcher):
                names[name] = interpreted(value)
            elif id(value) in _INTRINSICS:
                names[name] = _INTRINSICS[id(value)]
    return made


def sized(function, n):
    """`function` for n items of work: interpreted if n <= SMALL, else the compiled one."""
    return interpreted(function) if n <= SMALL else function
