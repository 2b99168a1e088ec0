"""Image output through OpenImageIO: the course's 8-bit PNG curve, or linear float EXR.

Files are written whole or not at all: into a temporary file beside the target, then renamed.
"""
import os
import tempfile

import numpy as np

from .errors import PtraceError

FORMATS = (".png", ".exr")


def course_8bit(radiance):
    """floor(255 * min(1, (sqrt(2) * L) ** (1/2.2))) per channel (docs/course.md#output-files); NaN -> 255."""
    radiance = np.asarray(radiance, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        curve = np.power(np.sqrt(2.0) * np.maximum(radiance, 0.0), 1 / 2.2)
    curve = np.where(np.isnan(radiance), 1.0, np.minimum(curve, 1.0))
    return np.floor(255 * curve).astype(np.uint8)


def rate_colours(rate):
    """The course's sample-rate ramp (docs/course.md#output-files): blue (0) to green (0.5) to red (1), 8-bit."""
    rate = np.clip(np.asarray(rate, dtype=np.float64), 0.0, 1.0)[..., None]
    low = np.concatenate([np.zeros_like(rate), 2 * rate, 1 - 2 * rate], axis=-1)
    high = np.concatenate([2 * rate - 1, 2 - 2 * rate, np.zeros_like(rate)], axis=-1)
    return np.floor(255 * np.where(rate <= 0.5, low, high)).astype(np.uint8)


def rate_path(path):
    """FILE.png -> FILE_rate.png (the course's name for the rate image)."""
    root, _ = os.path.splitext(os.fspath(path))
    return root + "_rate.png"


def write_image(path, radiance, eight_bit=None, extra=()):
    """Write (H, W, 3) linear radiance, top row first, as .png (course curve) or .exr (float).

    eight_bit, if given, is written as it is instead (for the rate image). extra, for an .exr:
    (name, (H, W) or (H, W, 3) array) pairs written as more channels after R, G, B, named by
    ptrace.features.AOV_CHANNELS (albedo.R, normal.X, depth.Z, ...)."""
    import OpenImageIO as oiio
    path = os.fspath(path)
    extension = os.path.splitext(path)[1].lower()
    if extension not in FORMATS:
        raise PtraceError(f"{path}: output must end in {' or '.join(FORMATS)}")
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise PtraceError(f"{path}: output directory {directory} does not exist")
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
    height, width, channels = pixels.shape
    try:
        handle, temporary = tempfile.mkstemp(prefix=".ptrace-", suffix=extension, dir=directory)
        os.close(handle)
    except OSError as error:
        raise PtraceError(f"{path}: cannot write to {directory} ({error.strerror})") from None
    try:
        output = oiio.ImageOutput.create(temporary)
        spec = oiio.ImageSpec(width, height, channels, pixel_type)
        if channels == len(names):
            spec.channelnames = tuple(names)
        if output is None or not output.open(temporary, spec):
            message = oiio.geterror() if output is None else output.geterror()
            raise PtraceError(f"{path}: cannot write image ({message})")
        ok = output.write_image(pixels)
        output.close()
        if not ok:
            raise PtraceError(f"{path}: cannot write image ({output.geterror()})")
        os.chmod(temporary, 0o644)
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.remove(temporary)
    return path


def read_image(path):
    """(H, W, C) float32 pixels of an image file (PNG values scaled to [0, 1])."""
    import OpenImageIO as oiio
    buffer = oiio.ImageBuf(os.fspath(path))
    if buffer.has_error:
        raise PtraceError(f"{path}: cannot read image ({buffer.geterror()})")
    return buffer.get_pixels(oiio.FLOAT)


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

