"""Errors a user can cause. The CLI turns each into one line on stderr and exit code 2.

Anything else that escapes is a bug in ptrace (an internal error): the CLI prints
`ptrace: internal error: ...` with the traceback and exits 1, and a Dask tile task re-raises
it chained to its cause (ptrace.distributed.TileTaskError), never as a PtraceError.
"""


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
