"""load_mesh: triangle meshes (.obj .ply .glb .gltf .stl) via trimesh, with the materials,
textures and lights the file carries (ptrace.io.materials) and defaults for what it lacks, so
that they render like a course scene."""
import math
import os

import numpy as np

import accel

from ..errors import SceneError
from ..scene import (
    AMBIENT,
    DIFFUSE,
    EMISSION,
    CameraSpec,
    Lights,
    Materials,
    Scene,
    Textures,
    area_weighted_normals,
)
from . import materials

MESH_EXTENSIONS = (".obj", ".ply", ".glb", ".gltf", ".stl")
DEFAULT_ALBEDO = 0.5
AMBIENT_RADIANCE = 1.0
# The course's CB camera: 49.13434 degrees across a 4:3 frame.
DEFAULT_HFOV = 49.13434
DEFAULT_VFOV = math.degrees(2 * math.atan(math.tan(math.radians(DEFAULT_HFOV) / 2) * 3 / 4))
DEFAULT_ZNEAR, DEFAULT_ZFAR = 0.001, 1e6


def load_mesh(path):
    """Read a mesh file into a Scene. Any problem raises SceneError.

    Each geometry keeps the material its file gives it (ptrace.io.materials: an OBJ's .mtl, a
    glTF's materials, a PLY's vertex colours; their textures and texture coordinates); a
    geometry without one gets the default diffuse material. glTF files' KHR_lights_punctual
    lights are read; a file with neither a light nor an emissive material gets the default
    ambient light."""
    path = str(path)
    if not os.path.exists(path):
        raise SceneError(path, "no such file")
    if os.path.isdir(path):
        raise SceneError(path, "is a directory, not a scene file")
    parts = _read_parts(path)
    vertices, faces, non_finite = parts["vertices"], parts["faces"], parts["non_finite"]
    if non_finite and len(faces) == 0:
        raise SceneError(path, f"every face ({non_finite}) has NaN or infinite vertex "
                               f"coordinates")
    if len(faces) == 0:
        raise SceneError(path, "the file contains no triangles")
    if not np.isfinite(vertices).all():
        raise SceneError(path, "NaN or infinite vertex coordinates")
    notes = [f"mesh file: dropped {non_finite} face(s) with NaN or infinite vertex coordinates"] \
        if non_finite else []
    notes += parts["notes"]
    records, light_records = parts["materials"], parts["lights"]
    if parts["defaulted"]:
        notes.append(f"mesh file: {parts['defaulted']} geometry(s) without a material: one "
                     f"diffuse material, albedo {DEFAULT_ALBEDO}")
    emitters = any(r["kind"] == EMISSION for r in records)
    if not light_records and not emitters:
        light_records = [{"kind": AMBIENT, "radiance": (AMBIENT_RADIANCE,) * 3}]
        notes.append(f"mesh file: no light and no emissive material: one ambient light, "
                     f"radiance {AMBIENT_RADIANCE}")
    notes += [
        "mesh file: default camera on the +Z side looking toward -Z, +Y up, framing the bounds "
        f"at any -r, its longer image side spanning {DEFAULT_HFOV} degrees (--up, --eye: others)",
        "mesh file: coordinates taken as they are (Y-up unless --up); file normals ignored",
    ]
    materials = Materials.from_records(records)
    lights = Lights.from_records(light_records)
    camera = CameraSpec(view_point=np.array([0.0, 0.0, 1.0]), position=np.zeros(3),
                        hfov=DEFAULT_HFOV, vfov=DEFAULT_VFOV,
                        znear=DEFAULT_ZNEAR, zfar=DEFAULT_ZFAR)
    try:
        geometry = accel.Geometry(vertices=vertices, faces=faces)
    except ValueError as error:
        raise SceneError(path, f"invalid mesh: {error}") from error
    pool = parts["textures"]
    return Scene(path=path, geometry=geometry,
                 vertex_normals=area_weighted_normals(geometry.vertices, geometry.faces),
                 material_index=parts["material_index"], materials=materials, lights=lights,
                 camera=camera, notes=notes, uv=parts["uv"],
                 vertex_colours=parts["vertex_colours"],
                 textures=Textures.from_images(pool.images, pool.wraps, pool.names))


def _read_parts(path):
    """Everything load_mesh takes from the file, through trimesh: each node's geometry with its
    transform baked in, concatenated (vertices (V, 3), faces (F, 3)), the faces dropped for NaN
    or infinite coordinates, and per face its material (records deduplicated by trimesh's
    material object), per corner texture coordinates if any material has a texture, per vertex
    colours if any geometry has them, the textures and the glTF lights. Each geometry is read
    unprocessed first, to count the faces trimesh's processing would drop without a word, then
    processed as trimesh's loader would (merged vertices, seams of texture coordinates kept,
    non-finite faces removed)."""
    import trimesh  # imported here: only mesh files need it

    try:
        scene = trimesh.load_scene(path, process=False)
        document = None
        if path.lower().endswith((".gltf", ".glb")):
            document = materials.gltf_json(path)
        non_finite = 0
        for geometry in scene.geometry.values():   # each geometry as the file holds it
            if not hasattr(geometry, "process"):
                continue
            raw_faces = np.asarray(geometry.faces, dtype=np.int64).reshape(-1, 3)
            raw_vertices = np.asarray(geometry.vertices, dtype=np.float64).reshape(-1, 3)
            if raw_faces.size and raw_faces.min() >= 0 and raw_faces.max() < len(raw_vertices):
                non_finite += int((~np.isfinite(raw_vertices[raw_faces]).all(axis=(1, 2))).sum())
            geometry.process()
        parts = _assemble(scene, document, os.path.dirname(os.path.abspath(path)))
    except SceneError:
        raise
    except Exception as error:     # trimesh raises many kinds for a bad file
        raise SceneError(path, f"could not read the mesh ({type(error).__name__}: {error})") \
            from error
    faces = parts["faces"]
    if faces.size and (faces.min() < 0 or faces.max() >= len(parts["vertices"])):
        raise SceneError(path, "face indices out of range")
    parts["non_finite"] = non_finite
    return parts


def _assemble(scene, document, directory):
    pool = materials.TexturePool()
    notes, records, by_material = [], [], {}
    vertices, faces, material_index, uvs, colours, vertex_sets = [], [], [], [], [], []
    defaulted = 0
    offset = 0
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        geometry = scene.geometry[name]
        if not hasattr(geometry, "faces") or len(geometry.faces) == 0:
            continue
        v = np.asarray(geometry.vertices, dtype=np.float64).reshape(-1, 3)
        f = np.asarray(geometry.faces, dtype=np.int64).reshape(-1, 3)
        v = v @ transform[:3, :3].T + transform[:3, 3]
        visual = getattr(geometry, "visual", None)
        material = getattr(visual, "material", None) if visual is not None else None
        uv = getattr(visual, "uv", None) if material is not None else None
        where = f"geometry {name!r}"
        kind = getattr(visual, "kind", None) if visual is not None else None
        if material is None and kind == "vertex":   # the colours are the albedo
            key = "vertex colours"
            if key not in by_material:
                by_material[key] = len(records)
                records.append({"kind": DIFFUSE, "albedo": (1.0, 1.0, 1.0),
                                "name": "vertex colours"})
        elif material is None:
            key = "default"
            if key not in by_material:
                by_material[key] = len(records)
                records.append({"kind": DIFFUSE, "albedo": (DEFAULT_ALBEDO,) * 3,
                                "name": "default"})
            defaulted += 1
        else:
            key = id(material)
            if key not in by_material:
                by_material[key] = len(records)
                if document is not None:
                    records.append(materials.gltf_material(material, document, pool, notes,
                                                           where))
                else:
                    records.append(materials.obj_material(material, directory, pool, notes,
                                                          where))
        m = by_material[key]
        vertex_colours = None
        if material is None and kind == "vertex":
            vertex_colours = materials.linear_rgb(
                np.asarray(visual.vertex_colors)[None, :, :3], srgb=True)[0]
        elif material is None and kind == "face":
            notes.append(f"{where}: per-face colours ignored")
        corner_uv = None
        if uv is not None and len(uv) == len(v):
            corner_uv = np.asarray(uv, dtype=np.float64)[f]
        vertices.append(v)
        faces.append(f + offset)
        material_index.append(np.full(len(f), m, dtype=np.int32))
        uvs.append(corner_uv if corner_uv is not None else np.zeros((len(f), 3, 2)))
        colours.append(vertex_colours if vertex_colours is not None else np.ones((len(v), 3)))
        vertex_sets.append(vertex_colours)
        offset += len(v)
    textured = any(r.get("albedo_texture", -1) >= 0 or r.get("emission_texture", -1) >= 0
                   or r.get("roughness_texture", -1) >= 0 for r in records)
    coloured = any(c is not None for c in vertex_sets)
    if coloured:
        notes.append("mesh file: vertex colours (read as sRGB) are the albedo of a diffuse "
                     "material")
    lights = []
    if document is not None:
        names = {}
        for i, node in enumerate(document.get("nodes", [])):
            names[i] = node.get("name", str(i))

        def node_transform(i):
            try:
                return np.asarray(scene.graph.get(names[i])[0], dtype=np.float64)
            except (KeyError, TypeError, ValueError):
                return None
        lights = materials.gltf_lights(document, node_transform, notes)
    if not vertices:
        return {"vertices": np.zeros((0, 3)), "faces": np.zeros((0, 3), np.int64),
                "material_index": np.zeros(0, np.int32), "materials": records or
                [{"kind": DIFFUSE, "albedo": (DEFAULT_ALBEDO,) * 3, "name": "default"}],
                "uv": None, "vertex_colours": None, "textures": pool, "notes": notes,
                "lights": lights, "defaulted": 0}
    return {"vertices": np.concatenate(vertices), "faces": np.concatenate(faces),
            "material_index": np.concatenate(material_index), "materials": records,
            "uv": np.concatenate(uvs) if textured else None,
            "vertex_colours": np.concatenate(colours) if coloured else None,
            "textures": pool, "notes": notes, "lights": lights, "defaulted": defaulted}
