"""Write the meshes and images the Mitsuba test scenes (scenes/mitsuba/*.xml) read: a torus as
torus.obj (with texture coordinates), torus.ply (binary, positions only) and torus.serialized
(Mitsuba's zlib-compressed format, version 4, with texture coordinates), a 16 x 16 PNG texture
(grid.png), a 16 x 16 PNG opacity mask (holes.png) and a 64 x 32 lat-long EXR environment
(sky.exr). Everything is computed, nothing random: running it again writes the same files.

    python scenes/mitsuba/make_assets.py [--output-dir DIR]    (default: this folder)
"""
import argparse
import math
import struct
import zlib
from pathlib import Path

import numpy as np


def torus(rings=16, sides=12, major=1.0, minor=0.35):
    """(vertices (V, 3), uv (V, 2), faces (F, 3)) of a torus about +y, its seam vertices
    doubled so that the texture coordinates run from 0 to 1."""
    u = np.linspace(0.0, 1.0, rings + 1)
    v = np.linspace(0.0, 1.0, sides + 1)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    a, b = 2 * math.pi * uu, 2 * math.pi * vv
    radius = major + minor * np.cos(b)
    vertices = np.stack([radius * np.cos(a), minor * np.sin(b), radius * np.sin(a)], axis=-1)
    index = np.arange((rings + 1) * (sides + 1)).reshape(rings + 1, sides + 1)
    corner = index[:-1, :-1].ravel()
    right, up, both = index[1:, :-1].ravel(), index[:-1, 1:].ravel(), index[1:, 1:].ravel()
    faces = np.concatenate([np.stack([corner, up, both], 1), np.stack([corner, both, right], 1)])
    return vertices.reshape(-1, 3), np.stack([uu, vv], -1).reshape(-1, 2), faces


def write_obj(path, vertices, uv, faces):
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"vt {s:.6f} {t:.6f}" for s, t in uv]
    lines += ["f " + " ".join(f"{i + 1}/{i + 1}" for i in face) for face in faces]
    path.write_text("\n".join(lines) + "\n")


def write_ply(path, vertices, faces):
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n"
            f"property float x\nproperty float y\nproperty float z\nelement face {len(faces)}\n"
            f"property list uchar int vertex_indices\nend_header\n").encode()
    body = np.asarray(vertices, "<f4").tobytes()
    rows = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    rows["n"], rows["i"] = 3, faces
    path.write_bytes(head + body + rows.tobytes())


def write_serialized(path, vertices, uv, faces):
    """One mesh, format version 4, single precision, with texture coordinates."""
    body = struct.pack("<I", 0x1000 | 0x0002) + b"torus\0"
    body += struct.pack("<QQ", len(vertices), len(faces))
    body += np.asarray(vertices, "<f4").tobytes() + np.asarray(uv, "<f4").tobytes()
    body += np.asarray(faces, "<u4").tobytes()
    chunk = struct.pack("<HH", 0x041C, 4) + zlib.compress(body, 9)
    path.write_bytes(chunk + struct.pack("<QI", 0, 1))


def write_image(path, pixels):
    import OpenImageIO as oiio
    pixels = np.ascontiguousarray(pixels)
    kind = oiio.FLOAT if pixels.dtype == np.float32 else oiio.UINT8
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], kind))
    out.write_image(pixels)
    out.close()


def grid():
    """16 x 16 sRGB texels: an orange and blue grid with a white corner cell."""
    y, x = np.mgrid[0:16, 0:16]
    image = np.where(((x // 4 + y // 4) % 2 == 0)[..., None], [230, 120, 40], [40, 90, 200])
    image[:4, :4] = 255
    return image.astype(np.uint8)


def holes():
    """16 x 16 grey opacity: a disk of holes (0) in an opaque (255) square."""
    y, x = np.mgrid[0:16, 0:16]
    inside = (x - 7.5) ** 2 + (y - 7.5) ** 2 < 30
    return np.repeat(np.where(inside, 0, 255)[..., None], 3, axis=2).astype(np.uint8)


def sky():
    """64 x 32 linear lat-long: a blue sky over a dark ground and one bright warm patch."""
    rows, columns = 32, 64
    theta = (np.arange(rows) + 0.5) / rows * math.pi
    image = np.zeros((rows, columns, 3), np.float32)
    image[:] = np.where((theta < math.pi / 2)[:, None, None], [0.4, 0.6, 1.0], [0.15, 0.12, 0.1])
    image[6:10, 40:46] = [40.0, 30.0, 20.0]
    return image


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", default=str(Path(__file__).resolve().parent))
    folder = Path(parser.parse_args(argv).output_dir)
    folder.mkdir(parents=True, exist_ok=True)
    vertices, uv, faces = torus()
    write_obj(folder / "torus.obj", vertices, uv, faces)
    write_ply(folder / "torus.ply", vertices, faces)
    write_serialized(folder / "torus.serialized", vertices, uv, faces)
    write_image(folder / "grid.png", grid())
    write_image(folder / "holes.png", holes())
    write_image(folder / "sky.exr", sky())


if __name__ == "__main__":
    main()
