"""ptrace: a physically based path tracer (CS184 semantics) on a pluggable ray accelerator."""
from .errors import PtraceError, SceneError
from .io import load
from .renderer import render
from .settings import Settings
from .scene import Scene

__all__ = ["PtraceError", "SceneError", "Scene", "Settings", "load", "render"]
