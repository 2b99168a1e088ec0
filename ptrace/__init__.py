"""ptrace: a physically based path tracer (CS184 semantics) on a pluggable ray accelerator."""
# first: numba's cache set up (a fallback folder, unreadable files recompiled) before any kernel
from . import jit  # noqa: F401, I001
from .camera import Camera, course_camera
from .environment import Environment, load_environment
from .errors import PtraceError, SceneError
from .image import show
from .io import load
from .pointing import default_camera, framing_camera, look_at
from .rendering.renderer import render
from .rendering.settings import Settings
from .scene import Scene

__all__ = ["Camera", "Environment", "PtraceError", "SceneError", "Scene", "Settings",
           "course_camera", "default_camera", "framing_camera", "load", "load_environment",
           "look_at", "render", "show"]
