"""Errors a user can cause. The CLI turns each into one line on stderr and exit code 2."""


class PtraceError(Exception):
    """Base class for every error ptrace reports to a user."""


class SceneError(PtraceError):
    """A scene file could not be read: names the file and the element at fault."""

    def __init__(self, path, message):
        self.path = str(path)
        self.message = message
        super().__init__(f"{self.path}: {message}")
