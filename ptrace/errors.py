"""Errors a user can cause. The CLI turns each into one line on stderr and exit code 2.

Anything else that escapes is a bug in ptrace (an internal error): the CLI prints
`ptrace: internal error: ...` with the traceback and exits 1, and a Dask tile task re-raises
it chained to its cause (ptrace.rendering.distributed.TileTaskError), never as a PtraceError.
"""
import os
import stat


class PtraceError(Exception):
    """Base class for every error ptrace reports to a user."""


class SceneError(PtraceError):
    """A scene file could not be read: names the file and the element at fault."""

    def __init__(self, path, message):
        self.path = str(path)
        self.message = message
        super().__init__(f"{self.path}: {message}")

    def __reduce__(self):   # picklable (a Dask worker sends it back whole)
        return type(self), (self.path, self.message)


def require_regular_file(path, what):
    """Refuse, before anything opens it, a path that exists but is not a regular file: a FIFO
    or /dev/stdin would block the reader for ever, a directory or a device is never a scene,
    environment or camera file. A missing path is left to the reader (its own message)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return
    if not stat.S_ISREG(mode):
        kind = ("a directory" if stat.S_ISDIR(mode) else "a FIFO (named pipe)"
                if stat.S_ISFIFO(mode) else "a device" if stat.S_ISCHR(mode) or
                stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else "not a file")
        raise SceneError(path, f"the {what} must be a regular file, but this is {kind}")
