"""Mitsuba's `serialized` meshes: a file of one or more zlib-compressed binary meshes.

The layout (Mitsuba's documentation of the serialized plugin): each mesh starts with the
uint16 format id 0x041C and a uint16 version (3 or 4), then a zlib stream holding a uint32 of
flags (0x0001 vertex normals, 0x0002 texture coordinates, 0x0008 vertex colours, 0x0010 face
normals, 0x1000 single precision, 0x2000 double), in version 4 the mesh's name ending in a NUL
byte, the vertex and triangle counts (uint64 each), the positions, normals, texture
coordinates and colours (3, 3, 2 and 3 numbers a vertex, as present), and the triangles' vertex
indices (uint32, or uint64 when there are more than 2^32 vertices). The file ends with the
byte offset of each mesh (uint64 in version 4, uint32 in version 3) and the number of meshes
(uint32). All little-endian.

A file that lies about its sizes (counts its data cannot hold, offsets past its end, indices
past its vertices) is refused in one line before anything of the claimed size is allocated.
"""
import struct
import zlib

import numpy as np

from .. import budget
from ..errors import SceneError
from .files import read_bytes
from .limits import problem

FORMAT_ID = 0x041C
HAS_NORMALS, HAS_UV, HAS_COLOURS, FACE_NORMALS, SINGLE, DOUBLE = \
    0x0001, 0x0002, 0x0008, 0x0010, 0x1000, 0x2000
MAX_NAME = 1 << 16


def read_serialized(path, index=0):
    """(vertices (V, 3), faces (F, 3), uv (F, 3, 2) as Mitsuba reads them or None, face
    normals flag) of mesh `index` of a serialized file."""
    compressed, version, fail = _locate(path, index)
    return _mesh(path, compressed, version, fail)


def serialized_triangles(path, index=0):
    """The number of triangles mesh `index` of a serialized file claims, from its header
    alone (its sizes checked against what its compressed bytes can hold)."""
    compressed, version, fail = _locate(path, index)
    return _header(compressed, version, fail)[4]


def _locate(path, index):
    """(the compressed bytes of mesh `index`, its format version, the SceneError maker)."""
    data = read_bytes(path)
    fail = lambda message: SceneError(path, f"serialized mesh: {message}")   # noqa: E731
    if len(data) < 8:
        raise fail("the file is too short to hold a mesh")
    count = struct.unpack_from("<I", data, len(data) - 4)[0]
    version = struct.unpack_from("<H", data, 2)[0] if len(data) >= 4 else 0
    if struct.unpack_from("<H", data, 0)[0] != FORMAT_ID or version not in (3, 4):
        raise fail("not a Mitsuba serialized file (its format id or version is wrong)")
    width = 8 if version == 4 else 4
    table = len(data) - 4 - width * count
    if count < 1 or table < 0:
        raise fail(f"its table of meshes claims {count} meshes, which the file cannot hold")
    if not 0 <= index < count:
        raise fail(f"shape_index {index} is not one of its {count} meshes")
    start = struct.unpack_from("<Q" if width == 8 else "<I", data, table + width * index)[0]
    if start + 4 > table:
        raise fail(f"mesh {index} starts at byte {start}, past the end of the meshes")
    return data[start + 4:table], struct.unpack_from("<H", data, start + 2)[0], fail


def _header(compressed, version, fail):
    """(the zlib stream, its first bytes, where the data starts in them, flags, triangles,
    vertices, bytes of the data) of a mesh's compressed bytes, its sizes checked."""
    stream = zlib.decompressobj()
    try:
        head = stream.decompress(compressed, 4 + MAX_NAME + 16)
    except zlib.error as error:
        raise fail(f"its compressed data is corrupt ({error})") from None
    if len(head) < 4:
        raise fail("its compressed data ends before the mesh's flags")
    flags = struct.unpack_from("<I", head, 0)[0]
    at = 4
    if version == 4:
        end = head.find(b"\x00", at)
        if end < 0:
            raise fail("its mesh name has no end")
        at = end + 1
    if len(head) < at + 16:
        raise fail("its compressed data ends before the mesh's sizes")
    vertices, triangles = struct.unpack_from("<QQ", head, at)
    at += 16
    real = 8 if flags & DOUBLE else 4
    per_vertex = 3 + 3 * bool(flags & HAS_NORMALS) + 2 * bool(flags & HAS_UV) + \
        3 * bool(flags & HAS_COLOURS)
    index = 8 if vertices > 0xFFFFFFFF else 4
    need = vertices * per_vertex * real + triangles * 3 * index
    # a zlib stream expands at most about 1032 times: sizes beyond that are lies
    if need > 1100 * len(compressed) + 1024:
        raise fail(f"it claims {vertices:,} vertices and {triangles:,} triangles, more than "
                   f"its {len(compressed):,} compressed bytes can hold")
    return stream, head, at, flags, triangles, vertices, need


def _mesh(path, compressed, version, fail):
    stream, head, at, flags, triangles, vertices, need = _header(compressed, version, fail)
    index = 8 if vertices > 0xFFFFFFFF else 4
    budget.current().triangles(path, triangles, f"its {triangles:,} triangles")
    body, more = head[at:], need + 1 - (len(head) - at)
    try:
        if more > 0:
            body += stream.decompress(stream.unconsumed_tail, more)
    except zlib.error as error:
        raise fail(f"its compressed data is corrupt ({error})") from None
    if len(body) < need:
        raise fail(f"it claims {vertices:,} vertices and {triangles:,} triangles, but its data "
                   f"holds {len(body):,} of the {need:,} bytes they need")
    kind = "<f8" if flags & DOUBLE else "<f4"
    offset = 0

    def take(columns, dtype, rows):
        nonlocal offset
        size = np.dtype(dtype).itemsize * columns * rows
        out = np.frombuffer(body, dtype=dtype, count=columns * rows, offset=offset)
        offset += size
        return out.reshape(rows, columns)
    positions = take(3, kind, vertices).astype(np.float64)
    if flags & HAS_NORMALS:
        take(3, kind, vertices)
    uv = take(2, kind, vertices).astype(np.float64) if flags & HAS_UV else None
    if flags & HAS_COLOURS:
        take(3, kind, vertices)
    faces = take(3, "<u8" if index == 8 else "<u4", triangles).astype(np.int64)
    if faces.size and faces.max() >= vertices:
        raise fail(f"a triangle uses vertex {int(faces.max())}, past its {vertices:,} vertices")
    wrong = problem(positions)
    if wrong is not None:
        raise fail(f"a position: {wrong}")
    return positions, faces, None if uv is None else uv[faces], bool(flags & FACE_NORMALS)
