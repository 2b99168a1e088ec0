"""The modules that moved into ptrace.app and ptrace.rendering keep working under their old names.

`import ptrace.cli`, `from ptrace.settings import Settings`, `from ptrace import tiles` and the
attribute `ptrace.renderer` all give the moved module itself (the same object, so what a caller
patches there is what ptrace runs), with one DeprecationWarning that names the new path. The
old names are a meta-path finder's aliases, not files: nothing is imported until one is asked
for, and each old name is imported (and warned about) once per process.
"""
import importlib
import importlib.abc
import importlib.util
import os
import sys
import warnings

_APP = ("cli", "cli_camera", "options", "view", "view_messages", "view_render", "view_session")
_RENDERING = ("distributed", "executors", "renderer", "settings", "tiles", "timing")

MOVED = {f"ptrace.{name}": f"ptrace.app.{name}" for name in _APP}
MOVED.update({f"ptrace.{name}": f"ptrace.rendering.{name}" for name in _RENDERING})

_HERE = os.path.dirname(os.path.abspath(__file__))
_SKIPPED = (os.path.join(_HERE, "_moved.py"), os.path.join(_HERE, "__init__.py"),
            os.path.dirname(importlib.__file__) + os.sep)


def _warn(old, new):
    """One DeprecationWarning, attributed to the line that named the old module (the frames
    of this file, of the package's __getattr__ and of the import system are skipped)."""
    frame, level = sys._getframe(1), 2
    while frame is not None:
        name = frame.f_code.co_filename
        if "importlib" in name and "_bootstrap" in name:
            frame = frame.f_back   # warnings skips the import system's frames itself
        elif name.startswith(_SKIPPED):
            frame, level = frame.f_back, level + 1
        else:
            break
    warnings.warn(f"{old} has moved to {new}; import it from there (the old name is "
                  f"deprecated)", DeprecationWarning, stacklevel=level)


class _Alias(importlib.abc.Loader):
    """Loads an old name as the module at its new path, unchanged (its __name__, __spec__ and
    __file__ stay the new module's)."""

    def __init__(self, new):
        self.new = new

    def create_module(self, spec):
        module = importlib.import_module(self.new)
        _warn(spec.name, self.new)
        return module

    def exec_module(self, module):
        pass   # the new module is already executed


class MovedFinder(importlib.abc.MetaPathFinder):
    """Finds the old names of moved modules (and only those)."""

    def find_spec(self, fullname, path=None, target=None):
        new = MOVED.get(fullname)
        if new is None:
            return None
        return importlib.util.spec_from_loader(fullname, _Alias(new))


def install():
    """Put the finder first on sys.meta_path (once), ahead of any stale file by an old name."""
    if not any(isinstance(finder, MovedFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, MovedFinder())


def moved_attribute(package, name):
    """The package's module-level __getattr__: `ptrace.<old name>` imports the moved module
    under its old name (which warns); any other missing name is an AttributeError."""
    if f"{package}.{name}" in MOVED:
        return importlib.import_module(f"{package}.{name}")
    raise AttributeError(f"module {package!r} has no attribute {name!r}")
