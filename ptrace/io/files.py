"""The files a model refers to (an OBJ's .mtl and textures, a glTF's buffers and images), and
readers' failures in words.

A model file is untrusted input, and so is every name in it. A referenced file is read only
if it lies inside the model's own folder (after resolving `..` and symbolic links) and is a
regular file: an absolute path or one that climbs out of the folder is refused, and a FIFO or
a device is never opened (opening a FIFO blocks until a writer comes; a device can stream
forever). Windows paths (`.\\textures\\skin.jpg`) are read with `/` for `\\`, and an absolute
path (`C:\\work\\skin.jpg`, `/home/me/skin.jpg`) is looked for by its base name in the model's
folder, where exporters' users usually copy the textures.
"""
import os
import stat
import urllib.parse

from ..errors import SceneError


def require_regular_file(path):
    """Raise SceneError unless path names an existing regular file (checked with stat, which
    never blocks: a FIFO or device is refused before anything opens it)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise SceneError(path, "no such file") from None
    except OSError as error:
        raise SceneError(path, f"cannot read the file: {error.strerror or error}") from None
    if stat.S_ISDIR(mode):
        raise SceneError(path, "is a directory, not a scene file")
    if not stat.S_ISREG(mode):
        raise SceneError(path, f"is {_kind(mode)}, not a regular file: ptrace reads scenes "
                               f"only from regular files")


def read_bytes(path):
    """The whole of a regular file (SceneError if it is not one or cannot be read)."""
    require_regular_file(path)
    try:
        with open(path, "rb") as stream:
            return stream.read()
    except OSError as error:
        raise SceneError(path, f"cannot read the file: {error.strerror or error}") from None


def _kind(mode):
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def resolve_reference(directory, reference, uri=False, base=None):
    """(path, None, remark) of the file a model names as `reference` (relative to `base`,
    by default `directory`), inside `directory` (the model's folder); or (None, reason, None)
    when it may not or cannot be read. `remark` (or None) says how the name was read when
    that was not literally (an absolute path found by its base name in `directory`).
    uri: the name is a URI reference (glTF), so %-escapes are decoded first."""
    name = str(reference).strip()
    if uri:
        name = urllib.parse.unquote(name)
    if not name:
        return None, "is an empty file name", None
    if "\x00" in name:
        return None, "contains a NUL character", None
    name = name.replace("\\", "/")
    remark = None
    drive = len(name) > 1 and name[1] == ":" and name[0].isalpha()
    if name.startswith("/") or drive:
        base = name.rsplit("/", 1)[-1]
        if not base:
            return None, "is an absolute path, outside the model's folder", None
        name, remark = base, "an absolute path: read by its base name from the model's folder"
    root = os.path.realpath(directory)
    start = root if remark else os.path.realpath(base or directory)
    path = os.path.realpath(os.path.join(start, name))
    if os.path.commonpath([root, path]) != root:
        return None, "is outside the model's folder", None
    try:
        mode = os.stat(path).st_mode
    except OSError:
        if remark or "/" not in name.strip("/"):
            where = "the model's folder" if remark else "the model's folder (as named)"
            return None, f"was not found in {where}", None
        # a path relative to where the exporter ran (`scenes/box.mtl` beside scenes/box.obj)
        found, _, _ = resolve_reference(directory, name.rsplit("/", 1)[-1], base=base)
        if found is None:
            return None, "was not found in the model's folder (as named, nor by its base " \
                         "name)", None
        return found, None, "not found as named: read by its base name from the model's folder"
    if not stat.S_ISREG(mode):
        return None, f"is {_kind(mode)}, not a regular file", None
    return path, None, remark


def describe_failure(error):
    """A reader's exception (trimesh's, numpy's, Pillow's) as words a user can act on: what
    kind of thing went wrong, then the reader's own message if it has one. Never the bare
    name of a Python exception class."""
    message = str(error).strip()
    if isinstance(error, MemoryError):
        return "it needs more memory than is available"
    if isinstance(error, UnicodeError):
        return "it is not text in a known encoding"
    if isinstance(error, ImportError):
        return f"a module the reader needs is not installed ({message})"
    if isinstance(error, FileNotFoundError):
        name = getattr(error, "filename", None) or message
        return f"a file it refers to was not found ({name})"
    if isinstance(error, OSError):
        return f"a file could not be read ({error.strerror or message})"
    if isinstance(error, KeyError):
        return f"an entry the format requires is missing ({message or 'unnamed'})"
    if isinstance(error, IndexError):
        return "an index in the file points past the end of the data it indexes" + \
            (f" ({message})" if message else "")
    if isinstance(error, AssertionError):
        return "its data is inconsistent (the reader's own consistency check failed" + \
            (f": {message})" if message else ")")
    if isinstance(error, AttributeError):
        return "a value in it has the wrong type" + (f" ({message})" if message else "")
    if isinstance(error, (ValueError, TypeError)):
        return f"its data is malformed ({message})" if message else "its data is malformed"
    if isinstance(error, (OverflowError, ZeroDivisionError, ArithmeticError)):
        return "its numbers are out of range" + (f" ({message})" if message else "")
    words = message or "no message"
    return f"the reader failed ({words})"


def trimesh_resolver(directory, uri=False):
    """A trimesh resolver that reads only regular files inside the model's folder (names
    are URIs, %-escaped, when uri)."""
    import trimesh.resolvers

    class FolderResolver(trimesh.resolvers.Resolver):
        def __init__(self):
            self.parent = directory

        def get(self, name):
            where, reason, _ = resolve_reference(directory, name, uri=uri)
            if where is None:
                raise FileNotFoundError(f"{name!r} {reason}")
            with open(where, "rb") as stream:
                return stream.read()

        def keys(self):
            return iter(())

        def write(self, name, data):
            raise PermissionError("ptrace does not write beside the model")

        def namespaced(self, namespace):
            return self

    return FolderResolver()
