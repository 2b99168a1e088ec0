"""PLY files: the header read before trimesh reads the data, and vertex colours under the
names writers use.

trimesh reads a PLY of points or of triangle strips into nothing, which ptrace would report
as "no triangles" without saying why, and it reads vertex colours only as `red green blue`:
float `r g b` (and `diffuse_red ...`) it drops without a word. So the header is read here
first: a file with no faces is refused with the reason, and the colour properties are found
by any of their common names and read from trimesh's raw element data.
"""
import numpy as np

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
