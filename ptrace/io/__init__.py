"""Scene loading: load(path) picks the reader by the file extension."""
import os

from ..errors import SceneError
from .collada import load_collada
from .files import require_regular_file
from .meshes import MESH_EXTENSIONS, load_mesh

SUPPORTED_EXTENSIONS = (".dae",) + MESH_EXTENSIONS


def load(path):
    """Read a scene file (.dae in the CS184 dialect, or a plain mesh) into a Scene."""
    extension = os.path.splitext(str(path))[1].lower()
    if extension == ".dae" or extension in MESH_EXTENSIONS:
        require_regular_file(str(path))     # a FIFO or device would block or never end
    if extension == ".dae":
        return load_collada(path)
    if extension in MESH_EXTENSIONS:
        return load_mesh(path)
    raise SceneError(path, f"unsupported file extension {extension or '(none)'!r}; "
                           f"supported: {', '.join(SUPPORTED_EXTENSIONS)}")


__all__ = ["load", "load_collada", "load_mesh", "SUPPORTED_EXTENSIONS"]
