"""Mitsuba shapes as world-space triangles (or an analytic sphere): obj and ply through
ptrace's own readers, rectangle, cube and disk built here, each placed by its to_world.

A shape is (vertices (V, 3), faces (F, 3), uv (F, 3, 2) or None) in world space, faces wound
so that the right-hand normal is Mitsuba's (flip_normals reverses them); uv is in ptrace's
convention (v up: v = 1 - Mitsuba's v, whose v runs down the image). face_normals gives each
triangle its own corners, so ptrace's smooth normals come out flat.
"""
import math
import os

import numpy as np

from .. import budget
from ..errors import SceneError
from . import obj, ply
from .limits import problem
from .meshes import _drop_non_finite, _read_with_trimesh, texture_coordinate_problem
from .mitsuba_serialized import serialized_triangles

DISK_SIDES = 128
BACKING = 1e-4     # how far behind an emitter its back lies, as a fraction of its size

_SQUARE = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
_SQUARE_UV = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
_QUADS = np.array([[0, 1, 2], [0, 2, 3]])


def rectangle():
    """Mitsuba's rectangle: [-1, 1]^2 in the z = 0 plane, normal +z; its (u, v) run with x and y."""
    uv = _SQUARE_UV[_QUADS]
    return _SQUARE.copy(), _QUADS.copy(), uv


# Mitsuba's cube's (u, v) on each face (axis, sign of its normal): u = (su p[iu] + 1) / 2 and
# v = (sv p[iv] + 1) / 2 as (iu, su, iv, sv), read off Mitsuba 3's cube mesh
_CUBE_UV = {(0, -1.0): (1, 1, 2, 1), (0, 1.0): (1, 1, 2, -1), (1, -1.0): (2, 1, 0, 1),
            (1, 1.0): (0, -1, 2, -1), (2, -1.0): (1, -1, 0, 1), (2, 1.0): (1, 1, 0, 1)}


def cube():
    """Mitsuba's cube: [-1, 1]^3, 24 vertices (flat faces), normals outward, each face's
    (u, v) laid out as Mitsuba's (_CUBE_UV)."""
    vertices, faces, uvs = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            square = _SQUARE.copy()
            if sign < 0:            # keep the right-hand normal outward
                square[:, 0] *= -1
            face = np.roll(square, axis + 1, axis=1)    # z -> the face's axis
            face[:, axis] = sign
            faces.append(_QUADS + len(vertices) * 4)
            vertices.append(face)
            iu, su, iv, sv = _CUBE_UV[axis, sign]
            uv = np.stack([(su * face[:, iu] + 1) / 2, (sv * face[:, iv] + 1) / 2], axis=1)
            uvs.append(uv[_QUADS])
    return np.concatenate(vertices), np.concatenate(faces), np.concatenate(uvs)


def disk():
    """Mitsuba's disk (radius 1 about the origin in z = 0, normal +z) as a polygon of
    DISK_SIDES sides of the disk's area; (u, v) = (radius, angle / 2 pi) as Mitsuba's."""
    step = 2 * math.pi / DISK_SIDES
    radius = math.sqrt(step / math.sin(step))       # the polygon's area is pi
    angles = np.arange(DISK_SIDES + 1) * step
    rim = np.stack([radius * np.cos(angles), radius * np.sin(angles), 0 * angles], axis=1)
    vertices = np.concatenate([[[0.0, 0.0, 0.0]], rim[:-1]])
    i = np.arange(DISK_SIDES)
    faces = np.stack([np.zeros(DISK_SIDES, np.int64), 1 + i, 1 + (i + 1) % DISK_SIDES], axis=1)
    share = angles / (2 * math.pi)
    uv = np.stack([np.stack([np.zeros(DISK_SIDES), 0.5 * (share[:-1] + share[1:])], axis=1),
                   np.stack([np.ones(DISK_SIDES), share[:-1]], axis=1),
                   np.stack([np.ones(DISK_SIDES), share[1:]], axis=1)], axis=1)
    return vertices, faces, uv


def file_triangles(shape, path):
    """The triangles an obj, ply or serialized shape's file holds, counted before it is read:
    a PLY's header's faces, a serialized mesh's header, an OBJ's faces fan-triangulated (a
    face of n corners is n - 2 triangles)."""
    if shape.type == "serialized":
        return serialized_triangles(path, shape.integer("shape_index", 0))
    if shape.type == "ply":
        with open(path, "rb") as stream:
            return max(ply.read_header(path, stream.read(ply.MAX_HEADER)).get(
                "face", (0,))[0], 0)
    count = 0
    with open(path, "rb") as stream:
        for line in stream:
            if line[:1] == b"f" and line[1:2] in (b" ", b"\t"):
                count += max(len(line.split(b"#", 1)[0].split()) - 3, 0)
    return count


def mesh_file(shape, path, notes, want_uv=False):
    """(vertices, faces, uv or None) of an obj or ply file, uv as Mitsuba reads it (its v
    runs down the image)."""
    if shape.type == "obj":     # the file's texture coordinates, whatever its .mtl says
        parts = obj.read_obj(path)
        parts["uv"] = parts.get("file_uv", parts["uv"])
        count = len(parts["faces"])     # (a PLY's reader charges them before reading)
        budget.current().triangles(path, count, f"its {count:,} triangles")
    else:
        parts = _binary_ply(path)
        if parts is None:
            parts = _read_with_trimesh(path, ".ply")
        if want_uv and parts["uv"] is None:
            parts["uv"] = _ply_uv(path, parts)
    parts = _drop_non_finite(path, parts)
    if len(parts["faces"]) == 0:
        raise SceneError(path, "the file contains no triangles")
    kept = [n for n in parts["notes"] if "material" not in n.lower() and "mtl" not in n.lower()]
    notes.extend(f"{shape.where}: {n}" for n in kept)
    uv = parts["uv"]
    # ptrace's readers give the file's v; Mitsuba flips an OBJ's (flip_tex_coords), not a PLY's
    flip = shape.type == "obj" and shape.boolean("flip_tex_coords", True)
    if uv is not None:
        uv = np.array(uv, dtype=np.float64)
        if flip:
            uv[..., 1] = 1.0 - uv[..., 1]
    return np.asarray(parts["vertices"], np.float64), np.asarray(parts["faces"], np.int64), uv


PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2",
             "int16": "<i2", "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4",
             "uint": "<u4", "uint32": "<u4", "float": "<f4", "float32": "<f4",
             "double": "<f8", "float64": "<f8"}
PLY_UV = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))


def _binary_ply(path):
    """The parts (as ptrace.io.meshes' readers give them) of a binary little-endian PLY of
    vertices with scalar properties and triangles (a list of 3 indices a face), read straight
    into numpy, its vertices as the file has them (unmerged, as Mitsuba reads them); None for
    any other PLY, which trimesh reads. The budget is charged from the header first."""
    with open(path, "rb") as stream:
        head = stream.read(ply.MAX_HEADER)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None
    start = head.find(b"\n", end) + 1
    lines = [line.split() for line in head[:end].decode("latin-1").splitlines()[1:]]
    lines = [w for w in lines if w and w[0] not in ("comment", "obj_info")]
    if not lines or lines[0][:2] != ["format", "binary_little_endian"]:
        return None
    elements = []
    for words in lines[1:]:
        if words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            elements[-1][2].append(words[1:])
        else:
            return None
    if [e[0] for e in elements] != ["vertex", "face"]:
        return None
    (_, vertex_count, vertex_properties), (_, face_count, face_properties) = elements
    if any(len(p) != 2 or p[0] not in PLY_TYPES for p in vertex_properties):
        return None
    names = [p[1] for p in vertex_properties]
    if not {"x", "y", "z"} <= set(names) or len(set(names)) != len(names):
        return None
    if len(face_properties) != 1 or len(face_properties[0]) != 4 or \
            face_properties[0][0] != "list" or face_properties[0][3] not in (
                "vertex_indices", "vertex_index") or \
            face_properties[0][1] not in ("uchar", "uint8") or \
            face_properties[0][2] not in ("int", "int32", "uint", "uint32"):
        return None
    vertex_type = np.dtype([(name, PLY_TYPES[kind]) for kind, name in vertex_properties])
    face_type = np.dtype([("n", "u1"), ("i", PLY_TYPES[face_properties[0][2]], 3)])
    size = start + vertex_count * vertex_type.itemsize + face_count * face_type.itemsize
    if os.path.getsize(path) < size or face_count < 1:
        return None
    budget.current().triangles(path, face_count, f"its {face_count:,} faces")
    with open(path, "rb") as stream:
        stream.seek(start)
        rows = np.fromfile(stream, dtype=vertex_type, count=vertex_count)
        faces = np.fromfile(stream, dtype=face_type, count=face_count)
    if len(rows) != vertex_count or len(faces) != face_count or (faces["n"] != 3).any():
        return None
    vertices = np.stack([rows[k].astype(np.float64) for k in "xyz"], axis=1)
    faces = faces["i"].astype(np.int64)
    if faces.size and (faces.min() < 0 or faces.max() >= vertex_count):
        raise SceneError(path, "face indices out of range")
    uv = next((np.stack([rows[a], rows[b]], axis=1).astype(np.float64)[faces]
               for a, b in PLY_UV if a in names and b in names), None)
    return {"vertices": vertices, "faces": faces, "uv": uv, "notes": [],
            "material_index": np.zeros(len(faces), np.int32), "vertex_colours": None}


def _ply_uv(path, parts):
    """(F, 3, 2) texture coordinates of a PLY's corners, which ptrace's reader keeps only for a
    PLY that names a texture file: the file read again by trimesh, unprocessed, and its
    coordinates taken only if its triangles are the reader's, corner by corner; else None."""
    import trimesh
    try:
        raw = trimesh.load(path, file_type="ply", process=False)
        uv = np.asarray(raw.visual.uv, dtype=np.float64)
        faces = np.asarray(raw.faces, dtype=np.int64)
        corners = np.asarray(raw.vertices, dtype=np.float64)[faces]
    except Exception:       # noqa: BLE001 - no coordinates to be had: the caller notes it
        return None
    ours = parts["vertices"][parts["faces"]]
    if uv.shape != (len(raw.vertices), 2) or corners.shape != ours.shape or \
            not np.allclose(corners, ours):
        return None
    return uv[faces]


def placed(shape, vertices, faces, uv):
    """The triangles placed by the shape's to_world, with flip_normals and face_normals; uv
    (Mitsuba's) turned to ptrace's."""
    transform = shape.transform("to_world")
    vertices = transform.apply(vertices)
    wrong = problem(vertices)
    if wrong is not None:
        shape.fail(f"to_world places a vertex where a coordinate is out of range: {wrong}")
    faces = np.array(faces, dtype=np.int64)
    if uv is not None:
        wrong = texture_coordinate_problem(uv)
        if wrong is not None:
            shape.fail(wrong)
        uv = np.array(uv, dtype=np.float64)
        uv[..., 1] = 1.0 - uv[..., 1]
    if np.linalg.det(transform.matrix[:3, :3]) < 0:     # a mirror turns the winding
        faces = faces[:, [0, 2, 1]]
        uv = None if uv is None else uv[:, [0, 2, 1]]
    if shape.boolean("flip_normals", False):
        faces = faces[:, [0, 2, 1]]
        uv = None if uv is None else uv[:, [0, 2, 1]]
    if shape.boolean("face_normals", False):
        vertices = vertices[faces].reshape(-1, 3)
        faces = np.arange(len(faces) * 3, dtype=np.int64).reshape(-1, 3)
    return vertices, faces, uv


def sphere(shape):
    """(centre, radius) in world space of a <shape type="sphere">; a to_world that does not
    scale uniformly is refused (ptrace's spheres are round)."""
    transform = shape.transform("to_world")
    centre = shape.point("center", np.zeros(3))
    radius = shape.float("radius", 1.0)
    if not radius > 0:
        shape.fail(f"radius {radius:g} must be positive")
    linear = transform.matrix[:3, :3]
    gram = linear.T @ linear
    scale = math.sqrt(float(np.trace(gram)) / 3)
    if not np.allclose(gram, scale * scale * np.eye(3), rtol=0, atol=1e-6 * scale * scale):
        shape.fail("to_world scales the sphere unevenly (an ellipsoid); ptrace's spheres are "
                   "round")
    shape.boolean("flip_normals", False)
    centre, radius = transform.apply(centre)[0], radius * scale
    wrong = problem(np.append(centre, radius))
    if wrong is not None:
        shape.fail(f"to_world places the sphere out of range: {wrong}")
    return centre, radius


def backing(vertices, faces, uv):
    """The back of a one-sided emitter: each triangle, unshared, moved BACKING of the shape's
    size behind its front (along its own normal) and wound the other way, so that ptrace's
    two-sided emission reaches only the front and the back reflects."""
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    size = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    corners = corners - BACKING * size * normals[:, None, :]
    behind = corners[:, [0, 2, 1]].reshape(-1, 3)
    return behind, np.arange(len(behind), dtype=np.int64).reshape(-1, 3), \
        None if uv is None else uv[:, [0, 2, 1]]


MERGE_LIMIT = 200_000


def closed(vertices, faces):
    """Whether the triangles close a surface consistently wound: every directed edge once,
    and its reverse once too (so that no ray from outside reaches a back). Their vertex
    indices are tried first; then the vertices on edges left unpaired (a file's vertices
    split at seams or corners), up to MERGE_LIMIT of them, are merged by position (within
    1e-7 of their spread) and the
    edges tried again. A mesh not found closed gets a back it may not need, which costs
    triangles, not a wrong image."""
    if not len(faces):
        return False
    faces = np.asarray(faces, dtype=np.int64)
    unpaired = _unpaired(faces)
    if unpaired is None:
        return False        # an edge twice the same way: not a consistent closed surface
    if not len(unpaired):
        return True
    if len(unpaired) > MERGE_LIMIT:
        return False
    rows = np.asarray(vertices, dtype=np.float64)[unpaired]
    # positions within 1e-7 of the mesh's size are one (cos 2 pi is not quite cos 0)
    size = float(np.ptp(rows, axis=0).max()) or 1.0
    rows = np.round(rows / (1e-7 * size))
    order = np.lexsort((rows[:, 2], rows[:, 1], rows[:, 0]))
    ordered = rows[order]
    start = np.ones(len(rows), dtype=bool)
    start[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    first = np.maximum.accumulate(np.where(start, np.arange(len(rows)), 0))
    canonical = np.arange(int(faces.max()) + 1, dtype=np.int64)
    canonical[unpaired[order]] = unpaired[order][first]     # one index per position
    merged = canonical[faces]
    again = _unpaired(merged)
    return again is not None and not len(again)


def _unpaired(f):
    """The vertices of the directed edges whose reverse is missing (sorted, unique), or None
    when an edge appears twice the same way or a triangle repeats a vertex."""
    n = int(f.max()) + 1
    a = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    b = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    if (a == b).any():
        return None
    keys = a * n + b
    ordered = np.sort(keys)
    if (ordered[1:] == ordered[:-1]).any():
        return None
    reverse = b * n + a
    at = np.minimum(np.searchsorted(ordered, reverse), len(ordered) - 1)
    missing = ordered[at] != reverse
    return np.unique(np.concatenate([a[missing], b[missing]]))
