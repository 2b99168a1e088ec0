"""Scene loading: load(path) picks the reader by the file extension."""
import os

from .. import budget
from ..errors import SceneError, require_regular_file
from .collada import load_collada
from .meshes import MESH_EXTENSIONS, load_mesh

SUPPORTED_EXTENSIONS = (".dae",) + MESH_EXTENSIONS


def load(path, default_light=True, max_memory=None):
    """Read a scene file (.dae in the CS184 dialect, or a plain mesh) into a Scene.

    default_light=False: a mesh file without lights gets no default ambient light (course
    scenes never get one). max_memory (bytes, a size such as "4G", or a ptrace.budget.Budget;
    default half the machine's memory, see ptrace.budget): a file whose triangles after
    instancing or whose textures would need more is refused (a BudgetError) before they are
    allocated."""
    extension = os.path.splitext(str(path))[1].lower()
    require_regular_file(path, "scene file")
    with budget.using(max_memory):
        if extension == ".dae":
            return load_collada(path)
        if extension in MESH_EXTENSIONS:
            return load_mesh(path, default_light=default_light)
    raise SceneError(path, f"unsupported file extension {extension or '(none)'!r}; "
                           f"supported: {', '.join(SUPPORTED_EXTENSIONS)}")


__all__ = ["load", "load_collada", "load_mesh", "SUPPORTED_EXTENSIONS"]
