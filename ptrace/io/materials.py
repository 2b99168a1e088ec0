"""What mesh files' materials share: their textures as linear RGB, conductors from a colour,
and the checks every material value passes.

The format readers (ptrace.io.obj, ptrace.io.gltf, ptrace.io.ply) decide what each field of
their format means to ptrace and note every field they approximate or ignore; docs/usage.md's
table "What mesh files' materials become" is the summary of their rules.
"""
import math

import numpy as np

from .. import budget
from ..scene import REPEAT
from .bands import band_rows, read_bands
from .limits import LIMIT, LIMIT_WORDS, problem
from .quiet import library_output

MIN_ALPHA = 0.01          # a roughness of 0 becomes this Beckmann alpha (0 has no density)
DEFAULT_ALBEDO = 0.5      # the diffuse material of a geometry without one (docs/usage.md says so)




class TexturePool:
    """The textures a file's materials use, each image converted once to linear RGB."""

    def __init__(self, path=None):
        """path: the model file, named by a refusal of the memory budget (ptrace.budget)."""
        self.images, self.wraps, self.names, self._index = [], [], [], {}
        self.path = path

    def add(self, image, srgb, wrap=(REPEAT, REPEAT), name="", key=None, encoded=None):
        """Index of the texture of a PIL image or an (H, W, C) array; srgb says whether its
        values are sRGB-encoded (colour textures) or linear (glTF's metallicRoughness), and
        encoded (see linear_rgb) whether float values came from integers. The same image (or
        the same key) with the same options is converted once. Raises ValueError if the image
        cannot be decoded, BudgetError if a PIL image (decoded only here) would pass the
        memory budget."""
        key = (key if key is not None else id(image), srgb, tuple(wrap))
        if key not in self._index:
            if hasattr(image, "size") and hasattr(image, "mode"):    # a PIL image, not decoded
                budget.current().image(self.path or name, *image.size, f"{name!r}")
            self._append(key, linear_rgb(image, srgb, encoded), wrap, name)
        return self._index[key]

    def add_file(self, path, srgb, wrap=(REPEAT, REPEAT), name="", what="", model=None):
        """Index of the texture of an image file (read_texture_file: decoded and converted a
        band of rows at a time); the same file with the same options is read once. Raises
        ValueError if it cannot be read, BudgetError as read_image_file does."""
        key = (path, srgb, tuple(wrap))
        if key not in self._index:
            self._append(key, read_texture_file(path, srgb, what, model), wrap, name)
        return self._index[key]

    def _append(self, key, pixels, wrap, name):
        self._index[key] = len(self.images)
        self.images.append(pixels)
        self.wraps.append(tuple(wrap))
        self.names.append(name)

    def mean(self, index):
        """The mean linear colour of texture `index`."""
        return np.mean(self.images[index].reshape(-1, 3), axis=0, dtype=np.float64)


def _stored_values(image):
    """(H, W, C) array of an image's stored values (a PIL image's as numpy sees them), the
    divisor that scales integers to [0, 1] (None: floats, taken as they are), and whether the
    values came from integers. Every PNG colour type becomes colour here: a palette image is
    expanded through its palette (its values are indices, not grey levels), 16-bit grey
    (Pillow's I;16 modes, or I) is scaled by 65535, 1-bit by 1; CMYK and YCbCr JPEGs are
    converted to RGB."""
    if hasattr(image, "mode"):                       # a PIL image
        mode = image.mode
        if mode in ("P", "PA"):
            image = image.convert("RGBA")
        elif mode in ("CMYK", "YCbCr", "LAB", "HSV"):
            image = image.convert("RGB")
        elif mode == "1":
            image = image.convert("L")
        pixels = np.asarray(image)
        if mode.startswith("I;16") or mode == "I":
            return pixels.reshape(pixels.shape[:2] + (1,)), 65535.0, True
        if mode == "F":
            return pixels.reshape(pixels.shape[:2] + (1,)), None, False
    else:
        pixels = np.asarray(image)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.ndim != 3 or pixels.shape[0] == 0 or pixels.shape[1] == 0:
        raise ValueError(f"an image of shape {pixels.shape} is not a picture")
    if pixels.dtype == np.uint8:
        return pixels, 255.0, True
    if pixels.dtype == np.uint16:
        return pixels, 65535.0, True
    if pixels.dtype == bool:
        return pixels, 1.0, True
    return pixels, None, False


def _scaled(stored, divisor):
    """float32 values in [0, 1] (integers) or as they are (floats) of stored values."""
    if divisor == 255.0:
        return stored.astype(np.float32) / 255.0
    if divisor == 65535.0:
        return (stored.astype(np.float64) / 65535.0).astype(np.float32)
    return stored.astype(np.float32)


def image_values(image):
    """(H, W, C) float32 values in [0, 1] of a PIL image or an array, and whether they came
    from integers (8- or 16-bit: encoded values, sRGB for colour) rather than floats; the
    colour types as _stored_values takes them."""
    stored, divisor, from_integers = _stored_values(image)
    return _scaled(stored, divisor), from_integers


def _linear_band(values, decode):
    """(h, W, 3) float32 linear RGB of a band of (h, W, C) float32 values: grey becomes grey in
    every channel, alpha is dropped; with decode, the values are decoded from sRGB by
    OpenImageIO's colour conversion. ValueError for a value that is not finite or beyond
    ptrace.io.limits.LIMIT."""
    import OpenImageIO as oiio
    if values.shape[2] in (1, 2):      # grey (and alpha): the grey in every channel
        values = np.repeat(values[:, :, :1], 3, axis=2)
    values = np.ascontiguousarray(values[:, :, :3], dtype=np.float32)
    if decode:
        buffer = oiio.ImageBuf(values)
        converted = oiio.ImageBufAlgo.colorconvert(buffer, "sRGB", "linear")
        if converted.has_error:
            raise ValueError(converted.geterror())
        values = converted.get_pixels(oiio.FLOAT).reshape(values.shape)
    if not np.isfinite(values).all():
        raise ValueError("the image has NaN or infinite values")
    words = problem(values)      # finite, but an emission it scales would overflow
    if words is not None:
        raise ValueError(f"the image's values: {words}")
    return values


def linear_rgb(image, srgb, encoded=None):
    """(H, W, 3) float32 linear RGB of an image (PIL or array; 8- or 16-bit or float), top row
    first: grey becomes grey in every channel, alpha is dropped. With srgb, integer-encoded
    values are decoded from sRGB by OpenImageIO's colour conversion
    (ImageBufAlgo.colorconvert), not a formula of ours; float images are linear already.
    encoded overrides whether the values came from integers (an image file's values that
    OpenImageIO has already scaled to floats). Converted a band of rows at a time into the
    result: the float working copies stay a few MiB."""
    stored, divisor, from_integers = _stored_values(image)
    encoded = from_integers if encoded is None else encoded
    height, width = stored.shape[:2]
    result = np.empty((height, width, 3), np.float32)
    step = band_rows(width)
    for start in range(0, height, step):
        result[start:start + step] = _linear_band(_scaled(stored[start:start + step], divisor),
                                                  srgb and encoded)
    return result


def _open_image(path, model, what):
    """(reader, spec) of an image file opened by OpenImageIO, its size charged to the budget
    (read_image_file says how). The caller closes the reader."""
    import OpenImageIO as oiio
    with library_output() as printed:     # libpng's own lines: folded into the message
        reader = oiio.ImageInput.open(path)
        error = (oiio.geterror() or "not a readable image") if reader is None else None
    if error is not None:
        raise ValueError(printed.one_line(error) or "not a readable image")
    spec = reader.spec()
    if spec.width <= 0 or spec.height <= 0 or spec.nchannels <= 0:
        reader.close()
        raise ValueError("the image has no pixels")
    try:
        budget.current().image(model or path, spec.width, spec.height, what or repr(path))
    except BaseException:
        reader.close()
        raise
    return reader, spec


def _encoded(spec):
    import OpenImageIO as oiio
    return spec.format.basetype in (oiio.UINT8, oiio.UINT16, oiio.INT8, oiio.INT16)


def read_image_file(path, what="", model=None):
    """The pixels of an image file on disk, read by OpenImageIO (PNG of every colour type,
    JPEG, TGA, BMP, TIFF, EXR, HDR, ...): (H, W, C) float32 in the file's own scale, and
    whether the file stores integers (whose values are then sRGB-encoded colour). Raises
    ValueError with OpenImageIO's message if it cannot be read, and BudgetError naming model
    (default path) and `what` (how the model uses it) if its size, read from its header before
    any pixel is decoded, passes the memory budget. The caller has checked that path is a
    regular file inside the model's folder."""
    reader, spec = _open_image(path, model, what)
    try:
        pixels = np.empty((spec.height, spec.width, spec.nchannels), np.float32)
        for start, band in read_bands(reader, spec, spec.nchannels):
            pixels[start:start + len(band)] = band
    finally:
        reader.close()
    return pixels, _encoded(spec)


def read_texture_file(path, srgb, what="", model=None):
    """(H, W, 3) float32 linear RGB of an image file, as linear_rgb(read_image_file(...))
    gives it (with srgb, integer-encoded values decoded from sRGB), decoded and converted a
    band of rows at a time: reading it needs little more than its result. Raises as
    read_image_file does."""
    reader, spec = _open_image(path, model, what)
    try:
        result = np.empty((spec.height, spec.width, 3), np.float32)
        decode = srgb and _encoded(spec)
        for start, band in read_bands(reader, spec, min(spec.nchannels, 3)):
            result[start:start + len(band)] = _linear_band(band, decode)
    finally:
        reader.close()
    return result


def conductor_from_colour(colour):
    """(eta, k) per channel of a conductor whose reflectance at normal incidence is `colour`
    (Gulbrandsen 2014, "Artist Friendly Metallic Fresnel", with the edge tint 1): the course's
    microfacet BSDF takes a conductor's eta and k, glTF and OBJ give a colour."""
    r = np.clip(np.asarray(colour, dtype=np.float64)[:3], 1e-4, 0.999)
    eta = (1.0 - r) / (1.0 + r)
    k = np.sqrt(np.maximum(r * (eta + 1.0) ** 2 - (eta - 1.0) ** 2, 0.0) / (1.0 - r))
    return eta, k


def check_numbers(values, what, low=None, high=None):
    """The values as floats, or a message (str) saying what is wrong with them: a value that is
    NaN, infinite, of magnitude above ptrace.io.limits.LIMIT, or outside [low, high] has no
    meaning a renderer could guess, so the caller refuses the file with this message rather
    than render a wrong or black image (or overflow)."""
    numbers = []
    for value in values:
        try:
            numbers.append(float(value))
        except (TypeError, ValueError, OverflowError):
            return f"{what} has {str(value)[:40]!r} where a number belongs"
    for value in numbers:
        if not math.isfinite(value):
            return f"{what} has a NaN or infinite value ({_listed(numbers)})"
        if abs(value) > LIMIT:     # finite, but its products would overflow (ptrace.io.limits)
            return f"{what} {_listed(numbers)}: {value:g} is {LIMIT_WORDS}"
        if low is not None and value < low or high is not None and value > high:
            span = (f"[{low:g}, {high:g}]" if low is not None and high is not None else
                    f"at least {low:g}" if low is not None else f"at most {high:g}")
            return f"{what} {_listed(numbers)} is out of range (must be {span})"
    return numbers


def _listed(numbers):
    return " ".join(f"{v:g}" for v in numbers)
