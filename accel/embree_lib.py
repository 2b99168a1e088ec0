"""Embree 4's C library for accel.embree: found inside the embreex wheel, loaded, its ctypes
prototypes and enum values, its two ray queries declared for numba, and the building and release
of a scene.

Separate from accel.embree because it is the binding to a foreign library (what C declares and
how the handles live and die), while accel.embree holds what the backend computes with it.

The library is the libembree4 shipped inside the embreex wheel (embreex.libs/, found next to the
installed embreex package); embreex's Python modules are not imported. The scene is built from
Python through ctypes: the robust scene flag, one triangle geometry over shared float32 vertex
(padded by 16 bytes, as Embree requires) and uint32 index buffers, kept alive by the accelerator
and released with it (the record's scene handle is valid only while the accelerator lives).
"""
import ctypes
import glob
import importlib.util
import os

from llvmlite import binding as llvm
from numba import types

# -- the library ---------------------------------------------------------------------------------

_PATTERNS = ("embreex.libs/libembree4*.so*", "embreex/.dylibs/libembree4*.dylib",
             "embreex.libs/embree4*.dll")


def find_library():
    """Path of the libembree4 inside the embreex wheel; ImportError naming where it looked."""
    spec = importlib.util.find_spec("embreex")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("accel.embree needs the libembree4 of the embreex wheel, but embreex "
                          "is not installed (pip install embreex)")
    places = sorted({os.path.dirname(os.path.abspath(p)) for p in spec.submodule_search_locations})
    for place in places:
        for pattern in _PATTERNS:
            found = sorted(glob.glob(os.path.join(place, pattern)))
            if found:
                return found[-1]
    raise ImportError(f"accel.embree: no libembree4 found in {', '.join(places)} "
                      f"(looked for {', '.join(_PATTERNS)})")


def _load(path):
    try:
        lib = ctypes.CDLL(path)
    except OSError as error:
        raise ImportError(f"accel.embree: cannot load {path}: {error}") from None
    llvm.load_library_permanently(path)     # numba kernels resolve rtcIntersect1 etc. by name
    handle, c_uint, c_size = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
    prototypes = {
        "rtcNewDevice": (handle, [ctypes.c_char_p]),
        "rtcReleaseDevice": (None, [handle]),
        "rtcGetDeviceError": (ctypes.c_int, [handle]),
        "rtcNewScene": (handle, [handle]),
        "rtcSetSceneFlags": (None, [handle, ctypes.c_int]),
        "rtcCommitScene": (None, [handle]),
        "rtcReleaseScene": (None, [handle]),
        "rtcNewGeometry": (handle, [handle, ctypes.c_int]),
        "rtcSetSharedGeometryBuffer": (None, [handle, ctypes.c_int, c_uint, ctypes.c_int,
                                              handle, c_size, c_size, c_size]),
        "rtcCommitGeometry": (None, [handle]),
        "rtcAttachGeometry": (c_uint, [handle, handle]),
        "rtcReleaseGeometry": (None, [handle]),
    }
    for name, (restype, argtypes) in prototypes.items():
        function = getattr(lib, name)
        function.restype, function.argtypes = restype, argtypes
    if hasattr(lib, "rtcGetDeviceLastErrorMessage"):            # Embree 4.3 and later
        lib.rtcGetDeviceLastErrorMessage.restype = ctypes.c_char_p
        lib.rtcGetDeviceLastErrorMessage.argtypes = [handle]
    return lib


LIBRARY_PATH = find_library()
_LIB = _load(LIBRARY_PATH)

# enum values of embree4/rtcore_*.h
RTC_GEOMETRY_TYPE_TRIANGLE = 0
RTC_BUFFER_TYPE_INDEX = 0
RTC_BUFFER_TYPE_VERTEX = 1
RTC_FORMAT_UINT3 = 0x5003
RTC_FORMAT_FLOAT3 = 0x9003
RTC_SCENE_FLAG_ROBUST = 1 << 2
RTC_INVALID_GEOMETRY_ID = 0xFFFFFFFF
_ERRORS = {1: "unknown error", 2: "invalid argument", 3: "invalid operation",
           4: "out of memory", 5: "unsupported CPU", 6: "cancelled"}

# void rtcIntersect1(RTCScene, RTCRayHit*, RTCIntersectArguments*) and rtcOccluded1(RTCScene,
# RTCRay*, RTCOccludedArguments*): every pointer passed as an integer (the same on x86-64)
rtc_intersect1 = types.ExternalFunction("rtcIntersect1",
                                        types.void(types.intp, types.intp, types.intp))
rtc_occluded1 = types.ExternalFunction("rtcOccluded1",
                                       types.void(types.intp, types.intp, types.intp))


# -- building ------------------------------------------------------------------------------------


def _check(device, step):
    error = _LIB.rtcGetDeviceError(device)
    if error:
        message = ""
        if hasattr(_LIB, "rtcGetDeviceLastErrorMessage"):
            message = (_LIB.rtcGetDeviceLastErrorMessage(device) or b"").decode(errors="replace")
        raise RuntimeError(f"Embree failed at {step}: {_ERRORS.get(error, f'error {error}')}"
                           + (f" ({message})" if message else ""))


def _release(scene, device, *buffers):
    """Release the Embree scene, then its device; the buffers it shared live until then."""
    if scene:
        _LIB.rtcReleaseScene(scene)
    if device:
        _LIB.rtcReleaseDevice(device)


def _build_scene(vertices, indices):
    """(device, scene) handles of a committed robust scene over shared float32 vertices (with the
    16 bytes of padding) and uint32 (F, 3) indices."""
    device = _LIB.rtcNewDevice(None)
    if not device:
        _check(None, "rtcNewDevice")
        raise RuntimeError("Embree failed at rtcNewDevice")
    scene = None
    try:
        scene = _LIB.rtcNewScene(device)
        _check(device, "rtcNewScene")
        _LIB.rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST)
        geometry = _LIB.rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE)
        _check(device, "rtcNewGeometry")
        _LIB.rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                        vertices.ctypes.data, 0, 12, (vertices.size - 4) // 3)
        _LIB.rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                        indices.ctypes.data, 0, 12, indices.shape[0])
        _LIB.rtcCommitGeometry(geometry)
        _LIB.rtcAttachGeometry(scene, geometry)
        _LIB.rtcReleaseGeometry(geometry)
        _LIB.rtcCommitScene(scene)
        _check(device, "building the scene")
    except BaseException:
        _release(scene, device)
        raise
    return device, scene
