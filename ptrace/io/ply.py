"""PLY files: the header read before trimesh reads the data, and vertex colours under the
names writers use.

trimesh reads a PLY of points or of triangle strips into nothing, which ptrace would report
as "no triangles" without saying why, and it reads vertex colours only as `red green blue`:
float `r g b` (and `diffuse_red ...`) it drops without a word. So the header is read here
first: a file with no faces is refused with the reason, and the colour properties are found
by any of their common names and read from trimesh's raw element data.
"""
import numpy as np

from accel.types import MAX_VERTICES

from ..errors import SceneError

COLOUR_NAMES = (("red", "green", "blue"), ("r", "g", "b"),
                ("diffuse_red", "diffuse_green", "diffuse_blue"),
                ("color_0", "color_1", "color_2"))
INTEGER_RANGE = {"uchar": 255, "uint8": 255, "char": 127, "int8": 127, "ushort": 65535,
                 "uint16": 65535, "short": 32767, "int16": 32767}
MAX_HEADER = 1 << 20


def read_header(path, data):
    """{element name: (count, {property name: type})} of a PLY file's header, checked: a file
    that is not PLY, or has no faces (only points, or triangle strips), is refused with the
    reason. Also "texture": whether a comment names a texture file, and "notes"."""
    if not data.startswith(b"ply") or data[3:4] not in (b"\n", b"\r", b" ", b"\t"):
        raise SceneError(path, "is not a PLY file: it does not start with the line 'ply'")
    end = data.find(b"end_header", 0, MAX_HEADER)
    if end < 0:
        raise SceneError(path, "is not a valid PLY file: its header has no 'end_header' line")
    elements, current = {}, None
    texture = False
    for line in data[:end].decode("latin-1").splitlines()[1:]:
        words = line.split()
        if words[:1] == ["comment"] and "texturefile" in line.lower():
            texture = True
        if not words or words[0] in ("comment", "obj_info", "format"):
            continue
        if words[0] == "element" and len(words) >= 3:
            try:
                count = int(words[2])
            except ValueError:
                raise SceneError(path, f"PLY header: element {words[1]!r} has the count "
                                       f"{words[2][:20]!r}, not a whole number") from None
            current = elements.setdefault(words[1], (count, {}))
        elif words[0] == "property" and current is not None and len(words) >= 3:
            current[1][words[-1]] = words[1] if words[1] != "list" else "list"
    vertex_count = elements.get("vertex", (0, {}))[0]
    if vertex_count > MAX_VERTICES:
        raise SceneError(path, f"PLY header: {vertex_count:,} vertices, more than the "
                               f"{MAX_VERTICES:,} that ptrace's int32 faces can index")
    faces, face_properties = elements.get("face", (0, {}))
    if faces <= 0:
        if elements.get("tristrips", (0, {}))[0] > 0:
            raise SceneError(path, "holds its faces as triangle strips (a 'tristrips' "
                                   "element): triangle strips are not supported")
        vertices = elements.get("vertex", (0, {}))[0]
        if vertices > 0:
            raise SceneError(path, f"contains only points ({vertices} vertices, no faces): "
                                   f"ptrace renders surfaces")
        raise SceneError(path, "the file contains no triangles (no vertices and no faces)")
    names = next((n for n in COLOUR_NAMES if all(p in face_properties for p in n)), None)
    if names is not None:
        elements["notes"] = [f"PLY: per-face colours ({' '.join(names)}) ignored"]
    elements["texture"] = texture     # a 'comment TextureFile name' line names an image
    return elements


def vertex_colours(path, elements, raw, notes):
    """(V, 4) uint8 RGBA vertex colours of the file's colour properties (any of the names in
    COLOUR_NAMES, integer or float), or None. Integer colours are scaled by their type's
    maximum; float colours are taken as 0 to 1 (0 to 255 if any exceeds 1, noted)."""
    properties = elements.get("vertex", (0, {}))[1]
    names = next((n for n in COLOUR_NAMES if all(p in properties for p in n)), None)
    if names is None:
        return None
    try:
        values = np.column_stack([np.asarray(raw["vertex"]["data"][n], dtype=np.float64)
                                  .reshape(-1) for n in names])
    except (KeyError, TypeError, ValueError):
        notes.append("PLY: vertex colour properties present but unreadable: ignored")
        return None
    kind = properties[names[0]]
    if kind in INTEGER_RANGE:
        values = values / INTEGER_RANGE[kind]
    elif values.size and np.nanmax(values) > 1.0:
        values = values / 255.0
        notes.append(f"PLY: float vertex colours ({' '.join(names)}) above 1 read as 0 to 255")
    if not np.isfinite(values).all():
        raise SceneError(path, "vertex colours have NaN or infinite values")
    rgba = np.full((len(values), 4), 255, np.uint8)
    rgba[:, :3] = np.round(np.clip(values, 0.0, 1.0) * 255).astype(np.uint8)
    return rgba


SCALAR_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
                "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
                "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
                "float64": "f8"}
# vertex properties that the trimesh reader would make more of than positions (colours,
# texture coordinates, normals): a file with any of them is read through trimesh
ATTRIBUTE_NAMES = {name for names in COLOUR_NAMES for name in names} | {
    "s", "t", "u", "v", "texture_u", "texture_v", "texture_s", "texture_t", "nx", "ny", "nz"}
MERGE_DIGITS = 8     # trimesh's merge of vertices: positions equal to 1e-8 are one vertex
CHUNK = 1 << 20      # faces converted a chunk at a time


def read_plain_binary(path, data):
    """The parts of a binary PLY file of triangles and positions alone (a vertex element of
    scalar properties with x, y, z and none of ATTRIBUTE_NAMES, then a face element of one
    list of three indices per face, no other element and no texture comment), read straight
    from the file's bytes into the flat arrays: positions as float64, faces as int32. The
    faces with a NaN or infinite corner are kept and counted (ptrace.io.meshes drops them),
    and vertices at the same position (to 1e-8) are merged into one, first one first, as
    the trimesh reader merges them. None for any other PLY: trimesh reads it."""
    end = data.find(b"end_header", 0, MAX_HEADER)
    if end < 0:
        return None
    start = data.find(b"\n", end) + 1
    if start <= 0:
        return None
    order, elements, current, endian = [], {}, None, None
    for line in data[:end].decode("latin-1").splitlines()[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            if "texturefile" in line.lower():
                return None
            continue
        if words[0] == "format":
            endian = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(
                words[1] if len(words) > 1 else "")
        elif words[0] == "element" and len(words) == 3:
            current = []
            order.append(words[1])
            elements[words[1]] = (int(words[2]), current)
        elif words[0] == "property" and current is not None:
            current.append(words[1:])
        else:
            return None
    if endian is None or order != ["vertex", "face"]:
        return None
    (n_vertices, vertex_properties), (n_faces, face_properties) = \
        elements["vertex"], elements["face"]
    if n_vertices < 0 or n_faces < 0 or n_vertices > MAX_VERTICES:
        return None     # read_header refuses more vertices than int32 faces index
    names = [p[-1] for p in vertex_properties]
    if any(len(p) != 2 or p[0] not in SCALAR_TYPES for p in vertex_properties) or \
            not {"x", "y", "z"} <= set(names) or ATTRIBUTE_NAMES & set(names) or \
            len(set(names)) != len(names):
        return None
    if len(face_properties) != 1 or len(face_properties[0]) != 4 or \
            face_properties[0][0] != "list" or \
            face_properties[0][3] not in ("vertex_indices", "vertex_index") or \
            face_properties[0][1] not in SCALAR_TYPES or face_properties[0][2] not in \
            SCALAR_TYPES or SCALAR_TYPES[face_properties[0][2]][0] == "f":
        return None
    vertex_type = np.dtype([(p[1], endian + SCALAR_TYPES[p[0]]) for p in vertex_properties])
    face_type = np.dtype([("n", endian + SCALAR_TYPES[face_properties[0][1]]),
                          ("i", endian + SCALAR_TYPES[face_properties[0][2]], 3)])
    size = n_vertices * vertex_type.itemsize
    if start + size + n_faces * face_type.itemsize != len(data):
        return None     # polygons other than triangles, or a short file: trimesh's to read
    rows = np.frombuffer(data, vertex_type, n_vertices, start)
    records = np.frombuffer(data, face_type, n_faces, start + size)
    if n_faces and not (records["n"] == 3).all():
        return None
    vertices = np.empty((n_vertices, 3))
    for axis, name in enumerate("xyz"):
        vertices[:, axis] = rows[name]
    faces = np.empty((n_faces, 3), np.int32)
    for first in range(0, n_faces, CHUNK):
        chunk = records["i"][first:first + CHUNK]
        if chunk.min() < 0 or chunk.max() >= n_vertices:     # before the cast could wrap it
            raise SceneError(path, "face indices out of range")
        faces[first:first + CHUNK] = chunk
    del rows, records
    return vertices, faces


def merge_vertices(vertices, faces):
    """(vertices, faces) with the referenced vertices at the same position (to MERGE_DIGITS
    decimals) made one, in the order of their first occurrence, and the non-finite ones
    dropped with the faces that use them (counted: the third value): what trimesh's
    processing does to a mesh of positions alone."""
    from trimesh.grouping import unique_rows
    finite = np.isfinite(vertices).all(axis=1)
    dropped = 0
    if not finite.all():
        keep = finite[faces].all(axis=1)
        dropped = int((~keep).sum())
        faces = faces[keep]
    referenced = np.zeros(len(vertices), bool)
    referenced[faces] = True
    referenced &= finite
    chosen = np.flatnonzero(referenced)
    with np.errstate(all="ignore"):
        stacked = np.round(vertices[chosen] * 10.0 ** MERGE_DIGITS).astype(np.int64)
    unique, inverse = unique_rows(stacked, keep_order=True)
    del stacked
    remap = np.zeros(len(vertices), faces.dtype)
    remap[chosen] = inverse
    del inverse
    vertices = vertices[chosen[unique]]
    for first in range(0, len(faces), CHUNK):
        faces[first:first + CHUNK] = remap[faces[first:first + CHUNK]]
    return vertices, faces, dropped
