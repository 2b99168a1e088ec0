"""load_mesh: triangle meshes (.obj .ply .glb .gltf .stl) with the materials, textures and
lights the file carries, and defaults for what it lacks, so that they render like a course
scene.

OBJ is read by ptrace.io.obj; the other formats by trimesh, after a check of what trimesh
would read wrongly or silently (ptrace.io.gltf for glTF's JSON and references, ptrace.io.ply
for a PLY's header). Every failure inside a reader becomes one line naming the file and what
is wrong in words (ptrace.io.files.describe_failure).
"""
import io
import logging
import math
import os

import numpy as np

import accel
from accel.types import MAX_VERTICES

from .. import budget
from ..budget import BudgetError
from ..errors import SceneError
from ..scene import (
    DIFFUSE,
    CameraSpec,
    Lights,
    Materials,
    Scene,
    Textures,
    area_weighted_normals,
)
from . import files, gltf, gltf_cameras, gltf_materials, gltf_scene, obj, ply
from .default_light import default_lights
from .limits import LIMIT, LIMIT_WORDS, UV_LIMIT, UV_WORDS, first_outside
from .materials import DEFAULT_ALBEDO, TexturePool, linear_rgb

MESH_EXTENSIONS = (".obj", ".ply", ".glb", ".gltf", ".stl")
FORMAT_NAMES = {".ply": "PLY", ".glb": "binary glTF", ".gltf": "glTF", ".stl": "STL"}
TEXTURES = ("albedo_texture", "emission_texture", "roughness_texture", "alpha_texture",
            "normal_texture")
# The course's CB camera: 49.13434 degrees across a 4:3 frame.
DEFAULT_HFOV = 49.13434
DEFAULT_VFOV = math.degrees(2 * math.atan(math.tan(math.radians(DEFAULT_HFOV) / 2) * 3 / 4))
DEFAULT_ZNEAR, DEFAULT_ZFAR = 0.001, 1e6


def load_mesh(path, default_light=True):
    """Read a mesh file into a Scene. Any problem raises SceneError.

    Each geometry keeps the material its file gives it (an OBJ's .mtl, a glTF's materials, a
    PLY's vertex colours; their textures and texture coordinates); a geometry without one gets
    the default diffuse material. glTF files' KHR_lights_punctual lights and cameras are read
    (Scene.file_cameras). A file without lights gets the default ambient light unless its
    emissive surfaces light it (ptrace.io.default_light says when) or default_light is
    False.

    Every number is checked where it enters (ptrace.io.limits); an overflow the checks did not
    foresee is still one line (a SceneError), never numpy's warnings."""
    path = str(path)
    try:
        with np.errstate(over="raise"):
            return _load_mesh(path, default_light)
    except FloatingPointError as error:
        raise SceneError(path, f"its numbers overflow while it is read ({error}; ptrace "
                               f"takes magnitudes up to {LIMIT:g})") from None


def _load_mesh(path, default_light):
    files.require_regular_file(path)
    if os.path.getsize(path) == 0:
        raise SceneError(path, "is empty (0 bytes)")
    extension = os.path.splitext(path)[1].lower()
    parts = obj.read_obj(path) if extension == ".obj" else _read_with_trimesh(path, extension)
    parts = _drop_non_finite(path, parts)
    vertices, faces = parts["vertices"], parts["faces"]
    _check_magnitudes(path, vertices)
    _check_texture_coordinates(path, parts["uv"])
    if len(faces) == 0:
        why = parts.get("why_empty")
        raise SceneError(path, "the file contains no triangles" + (f": {why}" if why else ""))
    notes = parts["notes"]
    if parts["non_finite"]:
        notes.insert(0, f"mesh file: dropped {parts['non_finite']} face(s) with NaN or "
                        f"infinite vertex coordinates")
    if parts["defaulted"]:
        notes.append(f"mesh file: {parts['defaulted']} triangle(s) without a material: one "
                     f"diffuse material, albedo {DEFAULT_ALBEDO}")
    pool = parts["textures"]
    materials = Materials.from_records(parts["materials"])
    textures = Textures.from_images(pool.images, pool.wraps, pool.names)
    uv = parts["uv"] if parts["uv"] is not None else np.zeros((0, 3, 2))
    light_records = parts["lights"]
    if not light_records:
        light_records, note = default_lights(vertices, faces, parts["material_index"],
                                             materials, uv, textures, on=default_light)
        notes.append(note)
    cameras = parts.get("cameras", ())
    notes += [
        gltf_cameras.camera_note(cameras) if cameras else
        "mesh file: default camera on the +Z side looking toward -Z, +Y up, framing the bounds "
        f"at any -r, its longer image side spanning {DEFAULT_HFOV} degrees (--up, --eye: others)",
        "mesh file: coordinates taken as they are (Y-up unless --up); file normals ignored",
    ]
    camera = CameraSpec(view_point=np.array([0.0, 0.0, 1.0]), position=np.zeros(3),
                        hfov=DEFAULT_HFOV, vfov=DEFAULT_VFOV,
                        znear=DEFAULT_ZNEAR, zfar=DEFAULT_ZFAR)
    try:
        geometry = accel.Geometry(vertices=vertices, faces=faces)
    except ValueError as error:
        raise SceneError(path, f"invalid mesh: {error}") from error
    framed = not any(c.kind == gltf_cameras.PERSPECTIVE for c in cameras)
    if framed and not _facing_view(geometry.vertices, geometry.faces):
        notes.append("mesh file: every face is edge-on to the default view along the Z axis "
                     "(a flat model in a plane that holds it): the default camera looks at it "
                     "from the plane's normal instead")
    return Scene(path=path, geometry=geometry,
                 vertex_normals=area_weighted_normals(geometry.vertices, geometry.faces),
                 material_index=parts["material_index"], materials=materials,
                 lights=Lights.from_records(light_records), camera=camera, notes=notes,
                 uv=parts["uv"], vertex_colours=parts["vertex_colours"], textures=textures,
                 file_cameras=cameras)


def _drop_non_finite(path, parts):
    """The parts without the faces that have a NaN or infinite vertex coordinate (counted in
    parts["non_finite"]), and without the vertices no face uses."""
    vertices, faces = parts["vertices"], parts["faces"]
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise SceneError(path, "face indices out of range")
    finite = np.isfinite(vertices).all(axis=1)
    keep = finite[faces].all(axis=1) if faces.size else np.zeros(0, bool)
    dropped = int((~keep).sum()) + parts.get("non_finite", 0)
    if dropped and not keep.any():
        raise SceneError(path, f"every face ({dropped}) has NaN or infinite vertex coordinates")
    parts["non_finite"] = dropped
    if keep.all() and finite.all():
        return parts
    used, remap = np.unique(faces[keep], return_inverse=True)
    parts.update(vertices=vertices[used], faces=remap.reshape(-1, 3),
                 material_index=parts["material_index"][keep],
                 uv=parts["uv"][keep] if parts["uv"] is not None else None,
                 vertex_colours=(parts["vertex_colours"][used]
                                 if parts["vertex_colours"] is not None else None))
    return parts


def _check_magnitudes(path, vertices):
    """Refuse vertices (as placed by the file's transforms) with a coordinate of magnitude
    above ptrace.io.limits.LIMIT: finite, but the default camera's distance, the bounds' area
    and the emitters' power would overflow (the OBJ reader names the line itself)."""
    with np.errstate(invalid="ignore"):
        big = ~(np.abs(vertices) <= LIMIT)
    if big.any():
        k, axis = np.argwhere(big)[0]
        placed = " (where its node places it)" if path.lower().endswith((".gltf", ".glb")) \
            else ""
        raise SceneError(path, f"vertex {k + 1}{placed}: its {'xyz'[axis]} "
                               f"{vertices[k, axis]:g} is {LIMIT_WORDS}")


def texture_coordinate_problem(uv):
    """What is wrong with texture coordinates (F, 3, 2) (as the file's texture transforms leave
    them) that are NaN, infinite or beyond ptrace.io.limits.UV_LIMIT, in words naming the
    first such triangle; None if nothing (or no uv). A texture lookup there reads an arbitrary
    texel (or none), and the surface renders black where it should show its texture."""
    if uv is None or first_outside(uv, UV_LIMIT) is None:
        return None
    with np.errstate(invalid="ignore"):
        k, corner, axis = np.argwhere(~(np.abs(uv) <= UV_LIMIT))[0]
    value = float(uv[k, corner, axis])
    words = f"{value:g} is not a finite number" if not math.isfinite(value) else \
        f"{value:g} is {UV_WORDS}"
    return (f"triangle {k + 1}: its texture coordinate {'uv'[axis]} at corner {corner + 1} "
            f"(after the file's texture transforms): {words}")


def _check_texture_coordinates(path, uv):
    """Refuse the file's texture coordinates if texture_coordinate_problem finds one."""
    wrong = texture_coordinate_problem(uv)
    if wrong is not None:
        raise SceneError(path, wrong)


def _read_with_trimesh(path, extension):
    """The parts of a PLY, STL or glTF file, read by trimesh: each node's geometry with its
    transform baked in, concatenated, each processed as trimesh's loader would (merged
    vertices, seams of texture coordinates kept, non-finite faces removed and counted)."""
    import trimesh  # imported here: only these files need it

    directory = os.path.dirname(os.path.abspath(path))
    document, missing, notes, elements = None, {}, [], None
    if extension in (".gltf", ".glb"):
        (data, file_type, resolver), (document, notes, missing) = gltf.prepare(path)
    else:
        data, file_type = files.read_bytes(path), extension[1:]
        resolver = files.trimesh_resolver(directory)
        if extension == ".ply":
            elements = ply.read_header(path, data)
            notes += elements.pop("notes", [])
            faces = elements.get("face", (0,))[0]
            budget.current().triangles(path, faces, f"its {faces:,} faces")
            plain = ply.read_plain_binary(path, data)
            if plain is not None:      # positions and triangles alone: read without trimesh
                del data
                return _plain_parts(path, *plain, notes)
        if extension == ".stl":
            _check_stl(path, data)
    quiet = logging.getLogger("trimesh")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)    # its warnings would print bare; ours are notes
    import PIL.Image
    bomb = PIL.Image.MAX_IMAGE_PIXELS
    # Pillow's own size limit would raise inside trimesh, which drops the image without a
    # word: the memory budget (ptrace.budget) decides instead, before an image is decoded
    PIL.Image.MAX_IMAGE_PIXELS = None
    try:
        with np.errstate(all="ignore"):
            scene = trimesh.load_scene(io.BytesIO(data), file_type=file_type,
                                       resolver=resolver, process=False)
            non_finite = 0
            for geometry in scene.geometry.values():   # each geometry as the file holds it
                if not isinstance(geometry, trimesh.Trimesh):    # points, lines: noted later
                    continue
                raw_faces = np.asarray(geometry.faces, dtype=np.int64).reshape(-1, 3)
                raw_vertices = np.asarray(geometry.vertices, dtype=np.float64).reshape(-1, 3)
                if raw_faces.size and raw_faces.min() >= 0 and \
                        raw_faces.max() < len(raw_vertices):
                    non_finite += int((~np.isfinite(raw_vertices[raw_faces])
                                       .all(axis=(1, 2))).sum())
                if elements is not None:
                    colours = ply.vertex_colours(path, elements,
                                                 geometry.metadata.get("_ply_raw", {}), notes)
                    if colours is not None and len(colours) == len(raw_vertices):
                        geometry.visual = trimesh.visual.ColorVisuals(geometry,
                                                                      vertex_colors=colours)
                geometry.process()
            # texture coordinates without a texture file: trimesh gives them a placeholder
            untextured = elements is not None and not elements["texture"]
            parts = _assemble(path, scene, document, missing, notes, untextured)
    except SceneError:
        raise
    except Exception as error:     # trimesh raises many kinds for a bad file
        raise SceneError(path, f"could not be read as {FORMAT_NAMES[extension]}: "
                               f"{files.describe_failure(error)}") from None
    finally:
        quiet.setLevel(level)
        PIL.Image.MAX_IMAGE_PIXELS = bomb
    parts["non_finite"] = non_finite
    if document is not None and len(parts["faces"]) == 0:
        parts["why_empty"] = gltf.why_empty(document)
    return parts


def _plain_parts(path, vertices, faces, notes):
    """The parts of a mesh of positions and triangles alone (ptrace.io.ply.read_plain_binary):
    its vertices merged as trimesh's processing merges them, one default diffuse material."""
    vertices, faces, dropped = ply.merge_vertices(vertices, faces)
    record = {"kind": DIFFUSE, "albedo": (DEFAULT_ALBEDO,) * 3, "name": "default"}
    return {"vertices": vertices, "faces": faces,
            "material_index": np.zeros(len(faces), np.int32), "materials": [record],
            "uv": None, "vertex_colours": None, "textures": TexturePool(path), "notes": notes,
            "lights": [], "cameras": (), "defaulted": len(faces), "non_finite": dropped}


def _facing_view(vertices, faces, chunk=1 << 16):
    """Whether any face turns toward the default view along Z: the faces' normals' |z| summed
    is more than 1e-9 of their lengths summed (a chunk of faces at a time)."""
    along, length = 0.0, 0.0
    for first in range(0, len(faces), chunk):
        corners = vertices[faces[first:first + chunk]]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        along += float(np.abs(normals[:, 2]).sum())
        length += float(np.linalg.norm(normals, axis=1).sum())
    return along > 1e-9 * length


def _assemble(path, scene, document, missing, notes, untextured):
    pool = TexturePool(path)
    records, by_key, built = [], {}, {}
    vertices, faces, material_index, uvs, colours, vertex_sets = [], [], [], [], [], []
    defaulted, offset, skipped = 0, 0, 0
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        geometry = scene.geometry[name]
        if not hasattr(geometry, "faces"):
            skipped += 1
            continue
        if len(geometry.faces) == 0:
            continue
        v = np.asarray(geometry.vertices, dtype=np.float64).reshape(-1, 3)
        f = np.asarray(geometry.faces, dtype=np.int64).reshape(-1, 3)
        v = v @ transform[:3, :3].T + transform[:3, 3]
        visual = getattr(geometry, "visual", None)
        material = getattr(visual, "material", None) if visual is not None else None
        if untextured:      # a PLY with texture coordinates but no texture file
            material = None
        kind = getattr(visual, "kind", None) if visual is not None else None
        uv = getattr(visual, "uv", None) if material is not None else None
        has_uv = uv is not None and len(uv) == len(v)
        where = f"geometry {name!r}"
        record, key, transform_uv = None, None, None
        if material is None and kind == "vertex":   # the colours are the albedo
            key = "vertex colours"
            record = {"kind": DIFFUSE, "albedo": (1.0, 1.0, 1.0), "name": key}
        elif material is None:
            key = "default"
            record = {"kind": DIFFUSE, "albedo": (DEFAULT_ALBEDO,) * 3, "name": key}
            defaulted += len(f)
        elif document is not None:
            index = _material_index(getattr(material, "name", None))
            if index not in built:
                built[index] = gltf_materials.material_record(index, material, document,
                                                              missing, pool, notes, path)
            record, transform_uv = built[index]
            key = ("gltf", index)
        else:     # a PLY's texture (its TextureFile comment): the albedo of a diffuse material
            key = ("image", id(material))
            record = _image_material(material, pool, notes, where)
        if any(t in record for t in TEXTURES) and not has_uv:
            record = {k: value for k, value in record.items() if k not in TEXTURES}
            key = (key, "without texture coordinates")
            notes.append(f"<{where}>: no texture coordinates: its material's textures are "
                         f"not applied to it")
        if key not in by_key:
            by_key[key] = len(records)
            records.append(record)
        vertex_colours = None
        if material is None and kind == "vertex":
            vertex_colours = linear_rgb(np.asarray(visual.vertex_colors)[None, :, :3],
                                        srgb=document is None)[0]
        elif material is not None and "color" in getattr(visual, "vertex_attributes", {}):
            vertex_colours = _attribute_colours(visual.vertex_attributes["color"], len(v))
            if record.get("cutoff", 0.0) != 0.0 and \
                    np.shape(visual.vertex_attributes["color"])[-1:] == (4,):
                notes.append(f"<{where}>: COLOR_0's alpha not read (its alphaMode takes the "
                             f"base colour's alpha alone)")
        elif material is None and kind == "face":
            notes.append(f"<{where}>: per-face colours ignored")
        corner_uv = np.zeros((len(f), 3, 2))
        if has_uv:
            corner_uv = np.asarray(uv, dtype=np.float64)[f]
            if transform_uv is not None:
                corner_uv = gltf_materials.apply_transform(corner_uv, transform_uv)
        vertices.append(v)
        faces.append(f + offset)
        material_index.append(np.full(len(f), by_key[key], dtype=np.int32))
        uvs.append(corner_uv)
        colours.append(vertex_colours if vertex_colours is not None else np.ones((len(v), 3)))
        vertex_sets.append(vertex_colours)
        offset += len(v)
    if skipped and document is None:
        notes.append(f"mesh file: {skipped} geometry(s) of points or lines skipped (ptrace "
                     f"renders surfaces)")
    textured = any(any(r.get(t, -1) >= 0 for t in TEXTURES) for r in records)
    coloured = any(c is not None for c in vertex_sets)
    if coloured:
        notes.append("mesh file: vertex colours " + ("(COLOR_0, linear) multiply the base "
                     "colour" if document is not None else "(read as sRGB) are the albedo of "
                     "a diffuse material"))
    lights, cameras = [], ()
    if document is not None:
        lights = gltf_scene.gltf_lights(path, document, notes)
        matrices = gltf_scene.node_matrices(path, document)
        cameras = gltf_cameras.gltf_cameras(path, document, matrices, notes)
    if not vertices:
        return {"vertices": np.zeros((0, 3)), "faces": np.zeros((0, 3), np.int32),
                "material_index": np.zeros(0, np.int32), "materials": [],
                "uv": None, "vertex_colours": None, "textures": pool, "notes": notes,
                "lights": lights, "cameras": cameras, "defaulted": 0}
    if offset > MAX_VERTICES:
        raise SceneError(path, f"{offset:,} vertices, more than the {MAX_VERTICES:,} that "
                               f"ptrace's int32 faces can index")
    return {"vertices": np.concatenate(vertices),
            "faces": np.concatenate(faces, dtype=np.int32, casting="unsafe"),
            "material_index": np.concatenate(material_index), "materials": records,
            "uv": np.concatenate(uvs) if textured else None,
            "vertex_colours": np.concatenate(colours) if coloured else None,
            "textures": pool, "notes": notes, "lights": lights, "cameras": cameras,
            "defaulted": defaulted}


def _check_stl(path, data):
    """Refuse bytes that are neither binary STL (an 80-byte header, a triangle count n, then
    exactly 50 bytes per triangle) nor ASCII STL (text starting with 'solid')."""
    if len(data) >= 84 and len(data) == 84 + 50 * int.from_bytes(data[80:84], "little"):
        return
    head = data[:512].lstrip()
    if head[:5].lower() == b"solid" and b"\x00" not in head:
        return
    raise SceneError(path, "is not an STL file: not binary STL (its size is not 84 bytes plus "
                           "50 per triangle) and not ASCII STL (it does not start with 'solid')")


def _material_index(name):
    """The JSON index of a material trimesh read from ptrace.io.gltf's renamed copy."""
    if isinstance(name, str) and name.startswith(gltf.TAG):
        try:
            return int(name[len(gltf.TAG):])
        except ValueError:
            pass
    return -1


def _image_material(material, pool, notes, where):
    image = getattr(material, "image", None)
    record = {"kind": DIFFUSE, "albedo": (1.0, 1.0, 1.0), "name": "texture"}
    if image is None:
        record["albedo"] = (DEFAULT_ALBEDO,) * 3
        notes.append(f"<{where}>: its texture could not be read: the default diffuse "
                     f"material (albedo {DEFAULT_ALBEDO})")
        return record
    try:
        record["albedo_texture"] = pool.add(image, srgb=True, name="texture")
        notes.append(f"<{where}>: its texture is the albedo of a diffuse material")
    except BudgetError:
        raise
    except Exception as error:     # Pillow decodes lazily: any decoder error lands here
        record["albedo"] = (DEFAULT_ALBEDO,) * 3
        notes.append(f"<{where}>: its texture could not be decoded ({str(error)[:80]}): the "
                     f"default diffuse material (albedo {DEFAULT_ALBEDO})")
    return record


def _attribute_colours(values, count):
    """(V, 3) linear colours of a glTF COLOR_0 attribute (float, or normalized integers)."""
    array = np.asarray(values)
    if array.ndim != 2 or len(array) != count or array.shape[1] < 3:
        return None
    if array.dtype.kind in "ui":
        array = array / float(np.iinfo(array.dtype).max)
    return np.clip(np.asarray(array[:, :3], dtype=np.float64), 0.0, None)
