"""Budgets on the memory a scene file can make ptrace allocate.

A file of a few hundred KB can describe a scene that needs gigabytes: a glTF node tree that
places one mesh thousands of times, a PNG whose header declares 16384 x 16384 texels, an
environment image as large. ptrace estimates what such a scene needs before it allocates it
(triangles after instancing, texture and environment texels, the render's per-pixel buffers)
and refuses one past the budget with one line (BudgetError, a SceneError: exit code 2) that
names the file, what it would need and the flag that raises the limit, rather than failing
part-way (a MemoryError, the kernel's out-of-memory killer, minutes of swapping).

The limit is --max-memory SIZE (max_memory= in ptrace.load, ptrace.load_environment and
ptrace.render); by default half of the machine's physical memory (or of its cgroup's limit,
when lower), and no more than three quarters of the address space the process may still map
under its `ulimit -v` (RLIMIT_AS) or `ulimit -d` (RLIMIT_DATA), less what it has mapped
already: the rest is left to the Python runtime, the compiled kernels and the threads.

A texture or environment map past the budget is refused, not downsampled: a smaller image
renders a different picture than the file describes, and the user is the one to choose
between raising the limit and resizing the image (the message says both).

The byte constants below are peak resident bytes, measured (benchmarks/results/hostile_inputs.md
gives the runs) and rounded up; they are estimates, so the budget bounds memory only as well as
they hold.
"""
import contextlib
import contextvars
import os
import re

from .errors import PtraceError, SceneError

MEMORY_FRACTION = 0.5           # of physical memory (or the cgroup's limit): the default budget
ADDRESS_SPACE_FRACTION = 0.75   # of what an RLIMIT_AS or RLIMIT_DATA still leaves
# Peak bytes per triangle from reading a mesh file to the end of a render, by backend: the
# reader's arrays and transients (positions, indices, texture coordinates and normals in
# float64 and int64, trimesh's copies), the scene's arrays, the accelerator's build and its
# structure, as the trimesh readers peak (measured on a large binary PLY); the OBJ reader's
# own transients are larger, but an OBJ cannot instance and its size bounds them.
BYTES_PER_TRIANGLE = {"naive": 440, "bvh": 520, "embree": 440}
# What a loader charges a triangle before it expands instances: the least any render needs.
LOAD_BYTES_PER_TRIANGLE = min(BYTES_PER_TRIANGLE.values())
# The light BVH (--light-sampler bvh, or auto above its light count) peaks at this many bytes an
# entry while it is built (its binary tree, its wide lanes, the build's working arrays).
LIGHT_TREE_BYTES = 3000
# A texture: its linear float32 RGB texels stay (three float32s); decoding and converting them
# a band of rows at a time peaks at TEXTURE_PEAK_BYTES a texel (an image file read by
# OpenImageIO about 16; a glTF's image decoded by Pillow keeps its 8-bit pixels meanwhile).
TEXEL_BYTES, TEXTURE_PEAK_BYTES = 12, 24
# An environment map (-e): float32 radiance (12 bytes a pixel) and its float32 conditional cdfs
# (4; the density is their steps, not a table of its own) stay; reading it and building the cdfs
# a band of rows at a time peaks at ENVIRONMENT_BYTES a pixel (16.1 measured on a 16384 x 8192
# PNG: benchmarks/results/memory.md).
ENVIRONMENT_BYTES = 20
UNITS = {"": 1, "K": 2 ** 10, "M": 2 ** 20, "G": 2 ** 30, "T": 2 ** 40}
RAISE = "--max-memory SIZE (max_memory= in Python) raises it"


class BudgetError(SceneError):
    """A scene (or render) that would need more memory than its budget; loaders re-raise it
    where they would otherwise turn a reader's failure into a note."""


def parse_size(text):
    """Bytes of a size such as 4G, 512M, 1.5GiB, 800000000 (K, M, G, T: powers of 1024);
    PtraceError naming --max-memory for anything else, or a size of 0."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([kKmMgGtT]?)(?:i?[bB])?\s*", str(text))
    value = float(match.group(1)) * UNITS[match.group(2).upper()] if match else 0.0
    if not 1 <= value < 2 ** 63:
        raise PtraceError(f"--max-memory must be a size such as 4G, 512M or 1.5G (K, M, G, T: "
                          f"powers of 1024), got {str(text)[:40]!r}")
    return int(value)


def size_text(nbytes):
    """A byte count in words: 1.5 GiB, 300 MiB."""
    for unit, scale in (("TiB", 2 ** 40), ("GiB", 2 ** 30), ("MiB", 2 ** 20), ("KiB", 2 ** 10)):
        if nbytes >= scale:
            return f"{nbytes / scale:,.1f} {unit}"
    return f"{int(nbytes)} bytes"


def machine_memory():
    """Bytes of memory this process may use: the machine's physical memory, or a smaller cgroup
    limit (a container's)."""
    total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    try:
        with open("/sys/fs/cgroup/memory.max") as handle:
            limit = handle.read().strip()
        if limit.isdigit():
            total = min(total, int(limit))
    except OSError:
        pass
    return total


def _mapped():
    """(VmSize, VmData) of this process in bytes (0 where /proc does not say)."""
    found = {"VmSize": 0, "VmData": 0}
    try:
        with open("/proc/self/status") as handle:
            for line in handle:
                key, _, value = line.partition(":")
                if key in found:
                    found[key] = int(value.split()[0]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return found["VmSize"], found["VmData"]


def default_limit():
    """(bytes, the rule in words) of the default budget (the module's docstring says it)."""
    memory = machine_memory()
    limit = int(MEMORY_FRACTION * memory)
    rule = f"half of this machine's {size_text(memory)}"
    try:
        import resource
        size, data = _mapped()
        for name, which, used in (("ulimit -v", resource.RLIMIT_AS, size),
                                  ("ulimit -d", resource.RLIMIT_DATA, data)):
            soft = resource.getrlimit(which)[0]
            if soft != resource.RLIM_INFINITY and soft >= 0:
                room = int(ADDRESS_SPACE_FRACTION * max(soft - used, 0))
                if room < limit:
                    limit = room
                    rule = (f"{ADDRESS_SPACE_FRACTION:.0%} of the {size_text(soft - used)} "
                            f"the {name} limit leaves")
    except (ImportError, OSError, ValueError):
        pass
    return max(limit, 1), rule


class Budget:
    """A memory limit and what the scene being read has been charged against it so far."""

    def __init__(self, limit, rule):
        self.limit, self.rule, self.spent = int(limit), rule, 0

    @classmethod
    def of(cls, max_memory=None):
        """The budget of a max_memory argument: None (the default limit), bytes (an int), a
        size such as "4G", or a Budget (itself, so one budget can span load and render)."""
        if isinstance(max_memory, Budget):
            return max_memory
        if max_memory is None:
            return cls(*default_limit())
        if isinstance(max_memory, str):
            return cls(parse_size(max_memory), "--max-memory")
        if isinstance(max_memory, bool) or not isinstance(max_memory, int) or max_memory < 1:
            raise PtraceError(f"max_memory must be a number of bytes (at least 1) or a size "
                              f"such as '4G', got {max_memory!r}")
        return cls(max_memory, "--max-memory")

    def describe(self):
        return f"the memory budget of {size_text(self.limit)} ({self.rule})"

    def charge(self, path, what, resident, transient=0):
        """Add `resident` bytes (what stays) to the scene's account; BudgetError naming path
        and `what` if they, with `transient` bytes needed meanwhile, pass the limit."""
        resident, transient = int(resident), int(transient)
        total = self.spent + resident + transient
        if total > self.limit:
            rest = f" ({size_text(total)} with the rest of the scene)" \
                if size_text(total) != size_text(resident + transient) else ""
            raise BudgetError(path, f"{what} would need about {size_text(resident + transient)}"
                                    f"{rest}, more than {self.describe()}; {RAISE}")
        self.spent += resident

    def triangles(self, path, count, what):
        """Charge `count` triangles (what: a noun phrase that says them) before a loader
        allocates them."""
        self.charge(path, what, count * LOAD_BYTES_PER_TRIANGLE)

    def image(self, path, width, height, what):
        """Charge a width x height texture (what: a noun phrase naming it) before it is
        decoded."""
        texels = int(width) * int(height)
        self.charge(path, f"the {width}x{height} texture {what}", texels * TEXEL_BYTES,
                    texels * (TEXTURE_PEAK_BYTES - TEXEL_BYTES))


_ACTIVE = contextvars.ContextVar("ptrace_budget", default=None)


@contextlib.contextmanager
def using(max_memory):
    """Make the budget of max_memory the one current() returns while the block runs."""
    budget = Budget.of(max_memory)
    token = _ACTIVE.set(budget)
    try:
        yield budget
    finally:
        _ACTIVE.reset(token)


def current():
    """The budget of the load under way (using()), else a fresh default one."""
    budget = _ACTIVE.get()
    return budget if budget is not None else Budget.of(None)


def check_render(scene, accel, buffer_bytes, max_memory=None, light_entries=0):
    """Refuse a render whose estimate passes the budget: the scene's triangles with the
    backend's structure (BYTES_PER_TRIANGLE), its texels, its environment map, the render's
    per-pixel buffers (buffer_bytes) and its light BVH's entries, if it builds one."""
    budget = Budget.of(max_memory)
    triangles = int(scene.triangle_count)
    texels = int(scene.textures.texels.shape[0]) if scene.textures is not None else 0
    environment = 0 if scene.environment is None else \
        int(scene.environment.image.shape[0] * scene.environment.image.shape[1])
    need = (triangles * BYTES_PER_TRIANGLE.get(accel, max(BYTES_PER_TRIANGLE.values()))
            + texels * TEXEL_BYTES + environment * ENVIRONMENT_BYTES + int(buffer_bytes)
            + int(light_entries) * LIGHT_TREE_BYTES)
    if need > budget.limit:
        parts = [f"{triangles:,} triangles with --accel {accel}"] + \
            ([f"{texels:,} texels"] if texels else []) + \
            ([f"an environment of {environment:,} pixels"] if environment else []) + \
            ([f"a light BVH of {light_entries:,} lights"] if light_entries else []) + \
            [f"{size_text(buffer_bytes)} of image buffers"]
        raise BudgetError(scene.path, f"rendering it would need about {size_text(need)} "
                                      f"({', '.join(parts)}), more than {budget.describe()}; "
                                      f"{RAISE}")
