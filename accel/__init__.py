"""accel: geometry only. Rays in, hits out; knows nothing of light or colour.

    accel.build(kind, geometry, **options) -> Accelerator
    Accelerator.intersect(rays) -> Hits      closest hit with tmin <= t <= tmax
    Accelerator.occluded(rays) -> bool array any hit with tmin <= t <= tmax
    Accelerator.stats() -> dict
    Accelerator.compiled                     its compiled face's record (accel.compiled): one
                                             ray's closest hit and any hit from numba code

A new backend is one module and one line in _BACKENDS.
"""
import importlib

from .types import Geometry, Hits, Rays

KINDS = ("naive", "bvh", "embree")

# kind -> (module, class); modules are imported on first use so `naive` never loads Embree.
_BACKENDS = {
    "naive": ("accel.naive", "NaiveAccelerator"),
    "bvh": ("accel.bvh", "BVHAccelerator"),
    "embree": ("accel.embree", "EmbreeAccelerator"),
}


def build(kind, geometry, **options):
    """Build the accelerator `kind` ("naive", "bvh" or "embree") over `geometry`."""
    if kind not in _BACKENDS:
        raise ValueError(f"unknown accelerator {kind!r}; choose one of {', '.join(KINDS)}")
    if not isinstance(geometry, Geometry):
        raise TypeError("geometry must be an accel.Geometry")
    module_name, class_name = _BACKENDS[kind]
    backend = getattr(importlib.import_module(module_name), class_name)
    return backend(geometry, **options)


def record_class(kind):
    """The namedtuple class of backend `kind`'s compiled face (accel.compiled), without building."""
    if kind not in _BACKENDS:
        raise ValueError(f"unknown accelerator {kind!r}; choose one of {', '.join(KINDS)}")
    module_name, class_name = _BACKENDS[kind]
    return getattr(importlib.import_module(module_name), class_name).record_class


__all__ = ["Geometry", "Rays", "Hits", "KINDS", "build", "record_class"]
