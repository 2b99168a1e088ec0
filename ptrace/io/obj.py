"""read_obj: a Wavefront OBJ file's triangles, texture coordinates, vertex colours and
materials (through ptrace.io.mtl), read here rather than by trimesh.

Why a reader of our own (chosen by trying each on hand-written and exported files):
- trimesh 5's OBJ reader resolves negative (relative) indices against the end of the file,
  not against the vertices read so far as the OBJ specification says, so every file written
  with them (hand-written and exported Cornell boxes) collapses; it skips vertex lines written
  `v<TAB>x y z`; it reads `map_Kd` silently or not at all (a backslash path, a missing file)
  and gives a mesh with texture coordinates but no material a 2 x 2 placeholder texture as
  its colour. A text pre-pass could fix the first two, but not the material handling.
- The assimp bindings on PyPI read such geometry right, but impasse needs a system libassimp
  and assimp-py bundles a large native library; both flatten the MTL to assimp's keys (no
  `illum`, no map options), and assimp-py returns an empty scene for random bytes.
OBJ is a line format; reading it whole here is short, and every statement it does not read
is a note. Statements are read in order, so relative indices count the vertices read so far;
the parsing of the (usually millions of) numbers is vectorised with numpy.
"""
import os
import re

import numpy as np

from accel.types import MAX_VERTICES

from ..errors import SceneError
from . import files, mtl
from .limits import LIMIT, LIMIT_WORDS

IGNORED = {"o", "g", "mg", "vp", "lod", "shadow_obj", "trace_obj", "maplib",
           "usemap", "bevel", "c_interp", "d_interp", "call", "csh"}
FREE_FORM = {"cstype", "deg", "bmat", "step", "curv", "curv2", "surf", "parm", "trim", "hole",
             "scrv", "sp", "end", "con"}
# the four forms of a face's corner: v, v/vt, v//vn, v/vt/vn (an index may be negative)
CORNER_FORMS = {0: r"-?\d+", 1: r"-?\d+/-?\d+", 2: r"-?\d+//-?\d+", 3: r"-?\d+/-?\d+/-?\d+"}


def read_obj(path):
    """The parts of a scene (as ptrace.io.meshes assembles them) that an OBJ file gives."""
    text = _text(path)
    state = _read_statements(path, text)
    del text      # read again for the line number of an error (_line_number)
    notes = state["notes"]
    if not state["face_count"]:
        if state["vertex_count"]:
            lines = " and lines" if state["skipped"].get("l") else ""
            raise SceneError(path, f"contains no faces, only points (vertices{lines}): "
                                   f"ptrace renders surfaces")
        if state["unknown"]:
            word, number = state["first_unknown"], _line_number(state, None, 0)
            what = repr(word) if word.isascii() and word.isprintable() else "bytes that are " \
                "not text"
            raise SceneError(path, f"is not an OBJ file: line {number} starts with {what}, "
                                   f"which is no OBJ statement, and there are no vertices")
        raise SceneError(path, "the file contains no triangles (no face statements)")
    vertices, colours = _joined_vertices(state)
    _check_magnitudes(path, state, vertices)
    uv_rows = np.concatenate(state["vt"]) if state["vt"] else np.zeros((0, 2))
    del state["vt"]
    corner_v, corner_vt, corner_vn, counts = _corners(path, state, len(vertices),
                                                      len(uv_rows))
    triangles, face_of_triangle = _fan(counts, notes)
    if len(triangles) == 0:
        raise SceneError(path, "the file contains no triangles (every face has fewer than "
                               "three corners)")
    tri_v = corner_v[triangles]                   # (T, 3) vertex index of each corner
    del corner_v
    tri_vt = corner_vt[triangles]                 # (T, 3), -1 where a corner has none
    del corner_vt
    has_uv = (tri_vt >= 0).all(axis=1)
    if len(uv_rows):
        uv = np.zeros((len(triangles), 3, 2))
        uv[has_uv] = uv_rows[tri_vt[has_uv]]
    else:       # no face has texture coordinates: zeros that take no memory
        uv = np.broadcast_to(np.zeros((1, 1, 1)), (len(triangles), 3, 2))
    del tri_vt, uv_rows
    # Which faces share a vertex, so that the area-weighted normals ptrace computes are smooth
    # only where the file's are (the normals' values are not read): a corner with a normal (vn)
    # is the pair (v, vn), so a position given several normals (a cube's corner) splits; one
    # without is (v, smoothing group), and under `s off` it is the face's own (flat), as the
    # OBJ specification says. A file with neither vn nor `s` is smooth, the course's rule.
    # Unreferenced vertices are dropped.
    count, groups = len(counts), len(state["groups"])
    if state["vn"] == 0 and not state["smoothing"]:     # every corner shares by position
        del corner_vn, triangles
        used, faces = np.unique(tri_v, return_inverse=True)
    else:
        group = _per_face(state["smoothing"], count, -1)[face_of_triangle][:, None]
        normal = corner_vn[triangles]
        del corner_vn, triangles
        base = state["vn"] + 1
        share = np.where(normal >= 0, normal, np.where(
            group == 0, base + face_of_triangle[:, None], base + count + 1 + group))
        del normal, group
        span = base + count + groups + 2
        tri_v *= span
        tri_v += share
        del share
        keys, faces = np.unique(tri_v, return_inverse=True)
        used = keys // span
        del keys
    del tri_v
    if len(used) > MAX_VERTICES:
        raise SceneError(path, f"{len(used):,} vertices, more than the {MAX_VERTICES:,} that "
                               f"ptrace's int32 faces can index")
    faces = faces.reshape(-1, 3).astype(np.int32)
    material_of_face = _per_face(state["materials"], len(counts), -1)[face_of_triangle]
    for word, count in sorted(state["skipped"].items()):
        notes.append(f"OBJ: {count} {SKIPPED_NAMES.get(word, word)} statement(s) ignored "
                     f"(ptrace renders surfaces)")
    if state["unknown"]:
        word, number = state["first_unknown"], _line_number(state, None, 0)
        notes.append(f"OBJ: {state['unknown']} line(s) with unknown statements ignored (the "
                     f"first, line {number}: {word!r})")
    directory = os.path.dirname(os.path.abspath(path))
    library = mtl.read_libraries(path, directory, state["mtllib"], notes)
    return mtl.assemble(path, directory, library, state["material_names"], material_of_face,
                        has_uv, uv, vertices[used], faces,
                        colours[used] if colours is not None else None, notes)


SKIPPED_NAMES = {"p": "point", "l": "line", "free-form": "free-form (curve or surface)"}


def _text(path):
    """The file's text (UTF-8, UTF-16 with its byte order mark, or Latin-1); SceneError for a
    file that is not text."""
    data = files.read_bytes(path)
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):     # UTF-16 text, with its byte order mark
        try:
            data = data.decode("utf-16").encode("utf-8")
        except UnicodeError:
            raise SceneError(path, "is not an OBJ file: it starts as UTF-16 text but is not "
                                   "UTF-16") from None
    if b"\x00" in data:
        raise SceneError(path, "is not an OBJ file: it holds binary data (NUL bytes), and OBJ "
                               "is text")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")     # names in a legacy encoding; the numbers are ASCII
    return text


CHUNK_ROWS = 1 << 16        # statements of a kind turned into arrays at a time
BLOCK_CHARACTERS = 1 << 20  # text split into lines a block at a time


def _blocks(text):
    """The text in blocks that each end just after a newline (or at the text's end), so that
    their lines are the text's lines, without a list of every line at once."""
    start = 0
    while start < len(text):
        end = text.find("\n", start + BLOCK_CHARACTERS)
        end = len(text) if end < 0 else end + 1
        yield text[start:end]
        start = end


def _uncommented(rows):
    return [row.split("#", 1)[0] for row in rows] if "#" in "".join(rows) else rows


def _read_statements(path, text):
    """One pass over the lines, in order, turning the payloads of v, vt and f statements into
    arrays a chunk of statements at a time (state["v"], ["v_colours"], ["vt"], ["faces"]:
    lists of chunks): where each run of faces starts (with the counts of v and vt read before
    it, for relative indices), and each usemtl's face. The common lines (`v `, `vt `, `f ` at
    the line's start) take a short path; the rest (tabs, indentation, other statements) are
    split into words."""
    text = text.replace("\\\r\n", " ").replace("\\\n", " ")
    state = {"v": [], "v_colours": [], "vt": [], "faces": [], "runs": [], "materials": [],
             "mtllib": [], "vn": 0, "smoothing": [], "groups": {},
             "material_names": {}, "skipped": {}, "unknown": 0, "first_unknown": None,
             "notes": [], "path": path, "vertex_count": 0, "uv_count": 0, "face_count": 0}
    runs, names, skipped = state["runs"], state["material_names"], state["skipped"]
    v_rows, vt_rows, faces = [], [], []
    counted = {"v": 0, "vt": 0, "f": 0}      # rows flushed into arrays already

    def flush(force=False):
        if v_rows and (force or len(v_rows) >= CHUNK_ROWS):
            positions, colours = _vertex_rows(path, _uncommented(v_rows), counted["v"])
            state["v"].append(positions)
            state["v_colours"].append(colours)
            counted["v"] += len(v_rows)
            v_rows.clear()
        if vt_rows and (force or len(vt_rows) >= CHUNK_ROWS):
            state["vt"].append(_uv_rows(path, _uncommented(vt_rows)))
            counted["vt"] += len(vt_rows)
            vt_rows.clear()
        if faces and (force or len(faces) >= CHUNK_ROWS):
            state["faces"].append(_raw_corners(path, _uncommented(faces)))
            counted["f"] += len(faces)
            faces.clear()

    in_faces, normals = False, 0
    for block in _blocks(text):
        for line in block.splitlines():
            head = line[:2]
            if head == "v ":
                v_rows.append(line[2:])
                in_faces = False
                continue
            if head == "f ":
                if not in_faces:
                    runs.append((counted["f"] + len(faces), counted["v"] + len(v_rows),
                                 counted["vt"] + len(vt_rows), normals))
                    in_faces = True
                faces.append(line[2:])
                continue
            if head == "vt" and line[2:3] == " ":
                vt_rows.append(line[3:])
                in_faces = False
                continue
            if head == "vn" and line[2:3] == " ":
                normals += 1
                in_faces = False
                continue
            words = line.split(None, 1)
            if not words or words[0][0] == "#":
                continue
            key, rest = words[0], (words[1] if len(words) > 1 else "")
            if key == "v":
                v_rows.append(rest)
                in_faces = False
            elif key == "vt":
                vt_rows.append(rest)
                in_faces = False
            elif key == "vn":
                normals += 1
                in_faces = False
            elif key == "f":
                if not in_faces:
                    runs.append((counted["f"] + len(faces), counted["v"] + len(v_rows),
                                 counted["vt"] + len(vt_rows), normals))
                    in_faces = True
                faces.append(rest)
            elif key == "s":      # smoothing group: off (or 0), or a name
                group = rest.strip().lower()
                group = 0 if group in ("off", "0", "") else \
                    state["groups"].setdefault(group, len(state["groups"]) + 1)
                state["smoothing"].append((counted["f"] + len(faces), group))
            elif key == "usemtl":
                state["materials"].append((counted["f"] + len(faces),
                                           names.setdefault(rest.strip(), len(names))))
            elif key == "mtllib":
                state["mtllib"].append(rest.strip())
            elif key in IGNORED:
                continue
            elif key in ("p", "l"):
                skipped[key] = skipped.get(key, 0) + 1
            elif key in FREE_FORM:
                skipped["free-form"] = skipped.get("free-form", 0) + 1
            else:
                state["unknown"] += 1
                if state["first_unknown"] is None:
                    state["first_unknown"] = key[:40]
        flush()
    flush(force=True)
    state["vn"] = normals
    state["vertex_count"], state["uv_count"], state["face_count"] = \
        counted["v"], counted["vt"], counted["f"]
    return state


def _joined_vertices(state):
    """(V, 3) positions and (V, 3) colours or None of the chunks read (a vertex without a
    colour, where others have one, is white)."""
    if not state["v"]:
        return np.zeros((0, 3)), None
    positions = np.concatenate(state["v"]) if len(state["v"]) > 1 else state["v"][0]
    colours = None
    if any(c is not None for c in state["v_colours"]):
        colours = np.concatenate([np.ones((len(p), 3)) if c is None else c
                                  for p, c in zip(state["v"], state["v_colours"])])
    del state["v"], state["v_colours"]
    return positions, colours


def _line_number(state, key, index):
    """The line number of the index-th statement of kind key ("f", or the first unknown)."""
    seen = 0
    text = _text(state["path"]).replace("\\\r\n", " ").replace("\\\n", " ")
    for number, line in enumerate(text.splitlines(), 1):
        words = line.split(None, 1)
        if words and (words[0] == key or key is None and words[0] == state["first_unknown"]):
            if seen == index:
                return number
            seen += 1
    return 0


def _per_face(changes, count, default):
    """Per face, the value of the last (face index, value) change at or before it."""
    values = np.full(count, default, dtype=np.int64)
    if not changes:
        return values
    starts = np.array([c[0] for c in changes], dtype=np.int64)
    given = np.array([c[1] for c in changes], dtype=np.int64)
    last = np.append(starts[1:] != starts[:-1], True)       # of changes at one face, the last
    starts, given = starts[last], given[last]
    values[starts[0]:] = np.repeat(given, np.diff(np.append(starts, count)))
    return values


def _numbers(path, rows, what):
    """The numbers of some statements' payloads, one flat float array."""
    tokens = " ".join(rows).split()
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not _is_number(t))
        raise SceneError(path, f"a {what} has {bad[:40]!r} where a number belongs") from None


def _is_number(token):
    try:
        float(token)
        return True
    except ValueError:
        return False


def _vertex_rows(path, rows, first=0):
    """(V, 3) positions, and (V, 3) colours or None: `v x y z`, `v x y z w` (w ignored) and
    `v x y z r g b` (vertex colours, as MeshLab writes them). first: the number of vertices
    read before these rows (an error names the vertex by its number in the file)."""
    flat = _numbers(path, rows, "vertex (v)")
    if len(flat) == 3 * len(rows):
        positions, colours = flat.reshape(-1, 3), None
    else:
        counts = np.array([len(row.split()) for row in rows])
        if counts.min() < 3:
            line = int(np.argmin(counts))
            raise SceneError(path, f"vertex {first + line + 1} has {counts[line]} "
                                   f"coordinate(s); a "
                                   f"vertex needs three")
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        positions = flat[starts[:, None] + np.arange(3)]
        coloured = counts >= 6
        colours = None
        if coloured.any():
            colours = np.ones((len(rows), 3))
            colours[coloured] = flat[starts[coloured, None] + np.arange(3, 6)]
    return positions, colours


def _check_magnitudes(path, state, positions):
    """Refuse a vertex coordinate that is finite but of magnitude above ptrace.io.limits.LIMIT,
    naming its line (a NaN or infinite one is dropped with its faces and noted instead)."""
    with np.errstate(invalid="ignore"):
        big = np.isfinite(positions) & ~(np.abs(positions) <= LIMIT)
    if big.any():
        k, axis = np.argwhere(big)[0]
        raise SceneError(path, f"vertex {k + 1} (line {_line_number(state, 'v', k)}): its "
                               f"{'xyz'[axis]} {positions[k, axis]:g} is {LIMIT_WORDS}")


def _uv_rows(path, rows):
    """(N, 2) texture coordinates (u, v) of `vt u [v [w]]` statements (a missing v is 0)."""
    if not rows:
        return np.zeros((0, 2))
    flat = _numbers(path, rows, "texture coordinate (vt)")
    if len(flat) == 2 * len(rows):
        return flat.reshape(-1, 2)
    counts = np.array([len(row.split()) for row in rows])
    if counts.min() < 1:
        raise SceneError(path, "a texture coordinate (vt) statement has no numbers")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    uv = np.zeros((len(rows), 2))
    uv[:, 0] = flat[starts]
    two = counts >= 2
    uv[two, 1] = flat[starts[two] + 1]
    return uv


def _raw_corners(path, rows):
    """(v, vt, vn, counts) of some face statements' payloads: per corner its three indices as
    the file writes them (0 where one is absent), and the number of corners of each face."""
    text = "\n".join(rows)
    if any(c in text for c in ("\t", "\r", "\f", "\v", "  ", " \n", "\n ")) or \
            text[:1] == " " or text[-1:] == " ":      # whitespace other than single spaces
        text = re.sub(r"[ \t\r\f\v]+", " ", text)
        text = re.sub(r" ?\n ?", "\n", text).strip(" ")
    counts = np.fromiter((row.count(" ") + 1 if row else 0 for row in text.split("\n")),
                         dtype=np.int64, count=len(rows))
    corners = text.replace("\n", " ") if counts.all() else " ".join(text.split())
    del text
    if not corners:
        none = np.zeros(0, np.int64)
        return none, none, none, counts
    first = corners.split(" ", 1)[0]
    form = first.count("/") + (first.count("//") > 0)
    pattern = CORNER_FORMS.get(form)
    if pattern is not None and re.fullmatch(rf"{pattern}(?: {pattern})*", corners):
        width = (1, 2, 2, 3)[form]
        numbers = np.fromstring(corners.replace("//", " ").replace("/", " "), dtype=np.int64,
                                sep=" ").reshape(-1, width)
        raw_v = numbers[:, 0]
        raw_vt = numbers[:, 1] if form in (1, 3) else np.zeros(len(numbers), np.int64)
        raw_vn = numbers[:, width - 1] if form in (2, 3) else np.zeros(len(numbers), np.int64)
    else:     # corners of mixed forms: one at a time
        raw_v, raw_vt, raw_vn = _mixed_corners(path, corners.split(" "))
    return (np.ascontiguousarray(raw_v), np.ascontiguousarray(raw_vt),
            np.ascontiguousarray(raw_vn), counts)


def _take_joined(chunks, k):
    """The k-th arrays of the chunks joined into one, each chunk's freed as it is taken."""
    joined = np.concatenate([chunk[k] for chunk in chunks]) if len(chunks) != 1 \
        else chunks[0][k]
    for chunk in chunks:
        chunk[k] = None
    return joined


def _corners(path, state, vertex_count, uv_count):
    """Per corner of every face: its vertex index and its texture coordinate index (-1 for
    none), 0-based, relative indices resolved against the statements read before the face;
    and the number of corners of each face."""
    chunks = [list(chunk) for chunk in state.pop("faces")]
    raw_v, raw_vt, raw_vn, counts = [_take_joined(chunks, k) for k in range(4)]
    n_faces = len(counts)
    runs = state["runs"]
    face = np.repeat(np.arange(n_faces), counts)
    read = np.repeat(_per_face([(r[0], r[1]) for r in runs], n_faces, 0), counts)
    v = _resolve(path, state, raw_v, read, vertex_count, "vertex", face)
    del raw_v
    read = np.repeat(_per_face([(r[0], r[2]) for r in runs], n_faces, 0), counts)
    vt = _resolve(path, state, raw_vt, read, uv_count, "texture coordinate", face,
                  optional=True)
    del raw_vt
    read = np.repeat(_per_face([(r[0], r[3]) for r in runs], n_faces, 0), counts)
    vn = _resolve(path, state, raw_vn, read, state["vn"], "normal", face, optional=True)
    return v, vt, vn, counts


def _mixed_corners(path, corners):
    raw_v = np.zeros(len(corners), np.int64)
    raw_vt = np.zeros(len(corners), np.int64)
    raw_vn = np.zeros(len(corners), np.int64)
    for i, corner in enumerate(corners):
        parts = corner.split("/")
        try:
            raw_v[i] = int(parts[0])
            if len(parts) > 1 and parts[1]:
                raw_vt[i] = int(parts[1])
            if len(parts) > 2 and parts[2]:
                raw_vn[i] = int(parts[2])
        except (ValueError, OverflowError):
            raise SceneError(path, f"a face corner {corner[:40]!r} is not of the form v, "
                                   f"v/vt, v//vn or v/vt/vn (whole numbers)") from None
        if len(parts) > 3:
            raise SceneError(path, f"a face corner {corner[:40]!r} has more than three "
                                   f"indices")
    return raw_v, raw_vt, raw_vn


def _resolve(path, state, raw, read_so_far, total, what, faces, optional=False):
    """0-based indices of OBJ indices: positive ones count from 1 at the file's first
    statement of their kind; negative ones count back from the last one read before the face
    (-1 is the latest). 0 means none for an optional index (a missing vt) and is an error
    otherwise. An index past what the file holds is an error naming the face's line."""
    index = np.where(raw > 0, raw - 1, read_so_far + raw)
    missing = raw == 0
    if optional:
        index[missing] = -1
    elif missing.any():
        line = _line_number(state, "f", int(faces[np.argmax(missing)]))
        raise SceneError(path, f"the face on line {line} has {what} index 0 (OBJ counts from 1)")
    bad = ~missing & ((index < 0) | (index >= total))
    if bad.any():
        i = int(np.argmax(bad))
        line = _line_number(state, "f", int(faces[i]))
        raise SceneError(path, f"the face on line {line} refers to {what} {int(raw[i])}, "
                               f"but {_count(total, what)} "
                               + ("are read before it" if raw[i] < 0 else "are in the file"))
    return index


def _count(n, what):
    plural = {"vertex": "vertices"}.get(what, what + "s")
    return f"only {n} {what if n == 1 else plural}" if n else f"no {plural}"


def _fan(counts, notes):
    """Triangles (T, 3) as indices of corners, each face fanned from its first corner, and the
    face each triangle came from. Faces with fewer than three corners are dropped (noted)."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    per_face = np.maximum(counts - 2, 0)
    short = int((counts < 3).sum())
    if short:
        notes.append(f"OBJ: {short} face(s) with fewer than three corners dropped")
    large = int((counts > 4).sum())
    if large:
        notes.append(f"OBJ: {large} polygon(s) with more than four corners fan-triangulated "
                     f"from their first corner (right for convex polygons)")
    face = np.repeat(np.arange(len(counts)), per_face)
    step = np.arange(len(face)) - np.repeat(np.cumsum(per_face) - per_face, per_face) + 1
    first = starts[face]
    triangles = np.stack([first, first + step, first + step + 1], axis=1)
    return triangles, face
