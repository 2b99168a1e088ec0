"""Scene loading: load(path) picks the reader by the file extension."""
import os

from .. import budget
from ..errors import SceneError, require_regular_file
from .collada import load_collada
from .meshes import MESH_EXTENSIONS, load_mesh
from .mitsuba import load_mitsuba

SUPPORTED_EXTENSIONS = (".dae",) + MESH_EXTENSIONS + (".xml",)


def load(path, default_light=True, max_memory=None, defines=None):
    """Read a scene file (.dae in the CS184 dialect, a plain mesh, or a Mitsuba .xml scene)
    into a Scene.

    default_light=False: a mesh file without lights gets no default ambient light (course
    scenes never get one). max_memory (bytes, a size such as "4G", or a ptrace.budget.Budget;
    default half the machine's memory, see ptrace.budget): a file whose triangles after
    instancing or whose textures would need more is refused (a BudgetError) before they are
    allocated. defines ({name: value}, the CLI's -D): the $name values of a Mitsuba scene
    (ptrace.io.mitsuba), ahead of its <default>s; another file takes none."""
    extension = os.path.splitext(str(path))[1].lower()
    require_regular_file(path, "scene file")
    if defines and extension != ".xml":
        raise SceneError(path, "-D (defines) applies to Mitsuba .xml scenes only")
    with budget.using(max_memory):
        if extension == ".dae":
            return load_collada(path)
        if extension in MESH_EXTENSIONS:
            return load_mesh(path, default_light=default_light)
        if extension == ".xml":
            return load_mitsuba(path, defines)
    raise SceneError(path, f"unsupported file extension {extension or '(none)'!r}; "
                           f"supported: {', '.join(SUPPORTED_EXTENSIONS)}")


__all__ = ["load", "load_collada", "load_mesh", "load_mitsuba", "SUPPORTED_EXTENSIONS"]
