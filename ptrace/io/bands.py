"""Images decoded a band of rows at a time, so that a texture's or an environment map's working
arrays stay a few MiB whatever the image's size."""
import numpy as np

from .quiet import library_output

BAND_TEXELS = 1 << 18     # texels a band of rows holds while an image is read or its tables made


def band_rows(columns):
    """Rows of `columns` texels in a band."""
    return max(1, BAND_TEXELS // max(int(columns), 1))


def read_bands(reader, spec, channels):
    """The image's pixels, (h, W, channels) float32 in the file's own scale, a band of rows
    (whole tile rows for a tiled file) at a time. ValueError if they cannot be decoded."""
    import OpenImageIO as oiio
    step = band_rows(spec.width)
    if spec.tile_height > 0:
        step = max(spec.tile_height, step - step % spec.tile_height)
    for start in range(0, spec.height, step):
        end = min(start + step, spec.height)
        with library_output() as printed:
            if spec.tile_width > 0:
                pixels = reader.read_tiles(0, 0, spec.x, spec.x + spec.width, spec.y + start,
                                           spec.y + end, spec.z, spec.z + max(spec.depth, 1),
                                           0, channels, oiio.FLOAT)
            else:
                pixels = reader.read_scanlines(0, 0, spec.y + start, spec.y + end, spec.z, 0,
                                               channels, oiio.FLOAT)
            error = reader.geterror() if reader.has_error or pixels is None else None
        if error is not None or pixels is None:
            raise ValueError(printed.one_line(error) or "its pixels could not be decoded")
        yield start, np.asarray(pixels, dtype=np.float32).reshape(end - start, spec.width,
                                                                  channels)
