"""Image output through OpenImageIO: the course's 8-bit PNG curve, or linear float EXR.

Files are written whole or not at all: into a temporary file beside the target, checked (the
writer's error state, fsync, the file read back), then renamed. A temporary file's name carries
the host and the process id of its writer (.ptrace-HOST-PID-XXXXXXXX.exr), so that a run killed
before it could remove its own (kill -9) does not leave it for good: the next write into that
folder removes the temporary files of this host's processes that have ended.
"""
import os
import re
import socket
import tempfile

import numpy as np

from .errors import PtraceError
from .io.quiet import library_output

FORMATS = (".png", ".exr")


def course_8bit(radiance):
    """floor(255 * min(1, (sqrt(2) * L) ** (1/2.2))) per channel (docs/course.md#output-files);
    NaN -> 255."""
    radiance = np.asarray(radiance, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        curve = np.power(np.sqrt(2.0) * np.maximum(radiance, 0.0), 1 / 2.2)
    curve = np.where(np.isnan(radiance), 1.0, np.minimum(curve, 1.0))
    return np.floor(255 * curve).astype(np.uint8)


def rate_colours(rate):
    """The course's sample-rate ramp (docs/course.md#output-files): blue (0) to green (0.5) to
    red (1), 8-bit."""
    rate = np.clip(np.asarray(rate, dtype=np.float64), 0.0, 1.0)[..., None]
    low = np.concatenate([np.zeros_like(rate), 2 * rate, 1 - 2 * rate], axis=-1)
    high = np.concatenate([2 * rate - 1, 2 - 2 * rate, np.zeros_like(rate)], axis=-1)
    return np.floor(255 * np.where(rate <= 0.5, low, high)).astype(np.uint8)


def rate_path(path):
    """FILE.png -> FILE_rate.png (the course's name for the rate image)."""
    root, _ = os.path.splitext(os.fspath(path))
    return root + "_rate.png"


def check_output_path(path):
    """Refuse, before anything is rendered, an output path that cannot be written: a wrong
    extension, a missing or unwritable folder (tried by creating and removing a file there, so
    a read-only filesystem counts too), or a directory or other non-file at the path."""
    path = os.fspath(path)
    extension = os.path.splitext(path)[1].lower()
    if extension not in FORMATS:
        raise PtraceError(f"{path}: output must end in {' or '.join(FORMATS)}")
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise PtraceError(f"cannot write {path}: the folder {directory} does not exist")
    if os.path.isdir(path):
        raise PtraceError(f"cannot write {path}: it is a directory")
    if os.path.lexists(path) and not os.path.islink(path) and not os.path.isfile(path):
        raise PtraceError(f"cannot write {path}: it exists and is not a regular file")
    try:
        handle, probe = tempfile.mkstemp(prefix=_temporary_prefix() + "probe-", dir=directory)
        os.close(handle)
        os.remove(probe)
    except OSError as error:
        raise PtraceError(f"cannot write {path}: cannot create a file in {directory} "
                          f"({_reason(error)})") from None
    return extension


def _host():
    """This machine's name as a temporary file's name may hold it (no '-' or '/')."""
    return re.sub(r"[^A-Za-z0-9_.]", "_", socket.gethostname() or "host")[:64]


def _temporary_prefix():
    """.ptrace-HOST-PID-: how this process's temporary files start."""
    return f".ptrace-{_host()}-{os.getpid()}-"


TEMPORARY = re.compile(r"\.ptrace-(?P<host>[A-Za-z0-9_.]+)-(?P<pid>\d+)-")


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True     # another user's process (or a pid the system cannot take): kept
    return True


def remove_dead_temporaries(directory):
    """Remove the temporary files in `directory` that this host's ptrace processes left when
    they were killed before they could (their process has ended); best effort, and never a
    file of a process still running, of another host or of another user. Returns their names."""
    removed = []
    host = _host()
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    for name in names:
        match = TEMPORARY.match(name)
        if match is None or match["host"] != host or _alive(int(match["pid"])):
            continue
        path = os.path.join(directory, name)
        try:
            if os.lstat(path).st_uid == os.getuid():
                os.remove(path)
                removed.append(name)
        except OSError:
            pass
    return removed


def _reason(error):
    """An OSError in the words a user reads: 'no space left on device', 'permission denied'."""
    text = error.strerror or str(error) or type(error).__name__
    return text[:1].lower() + text[1:]


def _pixels(path, extension, radiance, eight_bit, extra):
    """(pixels (H, W, C), OpenImageIO type, channel names) of what write_image writes."""
    import OpenImageIO as oiio
    if eight_bit is not None:
        pixels, pixel_type = np.ascontiguousarray(eight_bit, dtype=np.uint8), oiio.UINT8
    elif extension == ".png":
        pixels, pixel_type = course_8bit(radiance), oiio.UINT8
    else:
        pixels, pixel_type = np.ascontiguousarray(radiance, dtype=np.float32), oiio.FLOAT
    names = ["R", "G", "B"][:pixels.shape[2]]
    if extra:
        from .features import AOV_CHANNELS
        if extension != ".exr":
            raise PtraceError(f"{path}: extra channels need an .exr output")
        layers = [pixels]
        for name, array in extra:
            array = np.asarray(array, dtype=np.float32)
            layers.append(array.reshape(array.shape[:2] + (-1,)))
            names += AOV_CHANNELS[name]
        pixels = np.ascontiguousarray(np.concatenate(layers, axis=2))
    return pixels, pixel_type, names


class _WriteFailed(Exception):
    """A write that did not produce a whole file (the reason in words)."""


def _write_temporary(temporary, pixels, pixel_type, names, extension=None):
    """Write pixels into `temporary` and prove that they are there: OpenImageIO's error state
    after every call (on a full disk its write and close can return success while it records
    the short write), fsync (a filesystem may report a lost write only then), and the file read
    back whole with the same size and channels. extension (".png", ".exr") names the format
    when the temporary file's name has none (/proc/self/fd/N)."""
    import OpenImageIO as oiio
    height, width, channels = pixels.shape
    output = oiio.ImageOutput.create(extension[1:] if extension else temporary)
    if output is None:
        raise _WriteFailed(oiio.geterror() or "no image writer for this format")
    spec = oiio.ImageSpec(width, height, channels, pixel_type)
    if channels == len(names):
        spec.channelnames = tuple(names)
    opened = False
    try:
        opened = bool(output.open(temporary, spec))
        if not opened:
            raise _WriteFailed(output.geterror() or "cannot open the file")
        if not output.write_image(pixels) or output.has_error:
            raise _WriteFailed(output.geterror() or "the pixels were not written")
    finally:
        if opened:
            closed = output.close()
    if not closed or output.has_error:
        raise _WriteFailed(output.geterror() or "the file could not be closed")
    with open(temporary, "rb") as handle:
        os.fsync(handle.fileno())
        size = os.fstat(handle.fileno()).st_size
    if size <= 0:
        raise _WriteFailed("the file is empty after writing")
    check = oiio.ImageBuf(temporary)
    back = None if check.has_error else check.get_pixels(pixel_type)
    if back is None or check.has_error or back.shape != pixels.shape:
        check.geterror()   # read, so that OpenImageIO does not print it when check is freed
        raise _WriteFailed("the file does not read back whole")


def _failure(path, directory, error):
    """One line for a failed write; a full filesystem is named as such whatever the writer said."""
    if isinstance(error, OSError):
        reason = _reason(error)
    else:
        reason = (str(error).strip().splitlines() or ["unknown error"])[0]
    try:
        stat = os.statvfs(directory)
        if stat.f_bavail * stat.f_frsize < 64 * 1024:
            reason = "no space left on device"
    except OSError:
        pass
    return PtraceError(f"cannot write {path}: {reason}")


def write_images(images):
    """Write several images, each a dict of write_image's keywords (path, radiance, eight_bit,
    extra), whole or not at all: all are written to temporary files beside their targets and
    checked, and only then renamed over them, so a failure leaves every old file byte-identical
    and no temporary file behind (whatever the way out, Ctrl-C included).

    Where the system and the filesystem have them, the temporary files have no name (O_TMPFILE)
    until they are whole: a process killed while it writes (kill -9) leaves nothing in the
    folder. Elsewhere they are named .ptrace-HOST-PID-*, and the next write into the folder
    removes those of ended processes (remove_dead_temporaries)."""
    staged = []   # [temporary file's name, path, descriptor of an unnamed one or None]
    try:
        for image in images:
            path = os.fspath(image["path"])
            extension = check_output_path(path)
            pixels, pixel_type, names = _pixels(path, extension, image.get("radiance"),
                                                image.get("eight_bit"), image.get("extra", ()))
            directory = os.path.dirname(os.path.abspath(path))
            remove_dead_temporaries(directory)
            unnamed = _unnamed(directory)
            if unnamed is not None:
                temporary = f"/proc/self/fd/{unnamed}"
            else:
                try:
                    handle, temporary = tempfile.mkstemp(prefix=_temporary_prefix(),
                                                         suffix=extension, dir=directory)
                    os.close(handle)
                except OSError as error:
                    raise _failure(path, directory, error) from None
            staged.append([temporary, path, unnamed])
            try:
                with library_output():    # the writers' own lines: their errors are read
                    _write_temporary(temporary, pixels, pixel_type, names,   # from OIIO's state
                                     extension)
                if unnamed is not None:
                    os.fchmod(unnamed, 0o644)
                else:
                    os.chmod(temporary, 0o644)
            except (OSError, _WriteFailed) as error:
                raise _failure(path, directory, error) from None
        for entry in staged:
            temporary, path, unnamed = entry
            directory = os.path.dirname(os.path.abspath(path))
            try:
                if unnamed is not None:    # a name at last: the path itself if it is new
                    temporary = entry[0] = _link(unnamed, directory, path)
                if temporary is not None:
                    os.replace(temporary, path)
            except OSError as error:
                raise _failure(path, directory, error) from None
            _sync_directory(directory)
    finally:
        for temporary, _, unnamed in staged:
            if unnamed is not None:
                os.close(unnamed)
            if temporary is not None and not temporary.startswith("/proc/") and \
                    os.path.lexists(temporary):
                os.remove(temporary)
    return [path for _, path, _ in staged]


def _unnamed(directory):
    """A descriptor of a new file without a name in `directory` (O_TMPFILE, written through
    /proc/self/fd), or None where the system or the filesystem has no such files."""
    flag = getattr(os, "O_TMPFILE", None)
    if flag is None or not os.path.isdir("/proc/self/fd"):
        return None
    try:
        return os.open(directory, flag | os.O_WRONLY | getattr(os, "O_CLOEXEC", 0), 0o644)
    except OSError:    # EOPNOTSUPP, EISDIR (an old kernel), ...
        return None


def _link(unnamed, directory, path):
    """Give the unnamed file a name: `path` itself when nothing is there (None: done), else a
    temporary name beside it for the rename over the old file (returned)."""
    source = f"/proc/self/fd/{unnamed}"
    root = os.open("/", os.O_RDONLY)   # a src_dir_fd makes os.link call linkat, which follows
    try:                               # /proc's link to the file (link() would not)
        try:
            os.link(source, path, src_dir_fd=root, follow_symlinks=True)
            return None
        except FileExistsError:
            pass
        extension = os.path.splitext(path)[1]
        while True:
            named = os.path.join(directory, _temporary_prefix() + os.urandom(4).hex() +
                                 extension)
            try:
                os.link(source, named, src_dir_fd=root, follow_symlinks=True)
                return named
            except FileExistsError:
                continue
    finally:
        os.close(root)


def _sync_directory(directory):
    """fsync a folder after a rename into it, so the new name survives a crash (best effort:
    not every filesystem lets a folder be opened for it)."""
    try:
        handle = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(handle)
    except OSError:
        pass
    finally:
        os.close(handle)


def write_image(path, radiance, eight_bit=None, extra=()):
    """Write (H, W, 3) linear radiance, top row first, as .png (course curve) or .exr (float),
    whole or not at all (write_images).

    eight_bit, if given, is written as it is instead (for the rate image). extra, for an .exr:
    (name, (H, W) or (H, W, 3) array) pairs written as more channels after R, G, B, named by
    ptrace.features.AOV_CHANNELS (albedo.R, normal.X, depth.Z, ...)."""
    write_images([dict(path=path, radiance=radiance, eight_bit=eight_bit, extra=extra)])
    return os.fspath(path)


def read_image(path):
    """(H, W, C) float32 pixels of an image file (PNG values scaled to [0, 1])."""
    import OpenImageIO as oiio
    with library_output() as printed:    # libpng's own lines: folded into the one line
        buffer = oiio.ImageBuf(os.fspath(path))
        pixels = None if buffer.has_error else buffer.get_pixels(oiio.FLOAT)
        error = buffer.geterror() if buffer.has_error or pixels is None else None
    if error is not None:
        raise PtraceError(f"{path}: cannot read image "
                          f"({printed.one_line(error) or 'not a readable image'})")
    return pixels


class Shown:
    """An image that shows itself in Jupyter (IPython calls _repr_png_): the course's 8-bit
    curve of linear radiance times 2**exposure. ptrace.show(image) makes one; ptrace.render
    keeps returning the plain array."""

    def __init__(self, radiance, exposure=0.0):
        self.radiance = np.asarray(radiance, dtype=np.float32) * np.float32(2.0 ** exposure)

    def png(self):
        """The PNG file's bytes (written whole through write_image, then read back)."""
        with tempfile.TemporaryDirectory(prefix="ptrace-show-") as directory:
            path = os.path.join(directory, "image.png")
            write_image(path, self.radiance)
            with open(path, "rb") as handle:
                return handle.read()

    def _repr_png_(self):
        return self.png()


def show(radiance, exposure=0.0):
    """An object that displays `radiance` ((H, W, 3) linear, top row first) in a notebook with
    the course's curve, exposure in stops; in plain Python, .png() gives the PNG's bytes."""
    return Shown(radiance, exposure)

