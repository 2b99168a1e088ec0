"""Scene loading: load(path) picks the reader by the file extension."""
import os

from ..errors import SceneError, require_regular_file
from .collada import load_collada
from .meshes import MESH_EXTENSIONS, load_mesh

SUPPORTED_EXTENSIONS = (".dae",) + MESH_EXTENSIONS


def load(path, default_light=True):
    """Read a scene file (.dae in the CS184 dialect, or a plain mesh) into a Scene.

    default_light=False: a mesh file without lights gets no default ambient light (course
    scenes never get one)."""
    extension = os.path.splitext(str(path))[1].lower()
    require_regular_file(path, "scene file")
    if extension == ".dae":
        return load_collada(path)
    if extension in MESH_EXTENSIONS:
        return load_mesh(path, default_light=default_light)
    raise SceneError(path, f"unsupported file extension {extension or '(none)'!r}; "
                           f"supported: {', '.join(SUPPORTED_EXTENSIONS)}")


__all__ = ["load", "load_collada", "load_mesh", "SUPPORTED_EXTENSIONS"]
