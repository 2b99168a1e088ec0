"""load_mesh: plain triangle meshes (.obj .ply .glb .gltf .stl) via trimesh, with default
material, light and camera so that they render like a course scene."""
import math
import os

import numpy as np

import accel

from ..errors import SceneError
from ..scene import AMBIENT, DIFFUSE, CameraSpec, Lights, Materials, Scene, area_weighted_normals

MESH_EXTENSIONS = (".obj", ".ply", ".glb", ".gltf", ".stl")
DEFAULT_ALBEDO = 0.5
AMBIENT_RADIANCE = 1.0
# The course's CB camera: 49.13434 degrees across a 4:3 frame.
DEFAULT_HFOV = 49.13434
DEFAULT_VFOV = math.degrees(2 * math.atan(math.tan(math.radians(DEFAULT_HFOV) / 2) * 3 / 4))
DEFAULT_ZNEAR, DEFAULT_ZFAR = 0.001, 1e6


def load_mesh(path):
    """Read a mesh file into a Scene. Any problem raises SceneError."""
    path = str(path)
    if not os.path.exists(path):
        raise SceneError(path, "no such file")
    if os.path.isdir(path):
        raise SceneError(path, "is a directory, not a scene file")
    vertices, faces, non_finite = _read_triangles(path)
    if non_finite and len(faces) == 0:
        raise SceneError(path, f"every face ({non_finite}) has NaN or infinite vertex "
                               f"coordinates")
    if len(faces) == 0:
        raise SceneError(path, "the file contains no triangles")
    if not np.isfinite(vertices).all():
        raise SceneError(path, "NaN or infinite vertex coordinates")
    notes = [f"mesh file: dropped {non_finite} face(s) with NaN or infinite vertex coordinates"] \
        if non_finite else []
    notes += [
        f"mesh file: one diffuse material, albedo {DEFAULT_ALBEDO}",
        f"mesh file: one ambient light, radiance {AMBIENT_RADIANCE}",
        "mesh file: camera on +Z looking toward -Z (view_point (0, 0, 1)), "
        f"hfov {DEFAULT_HFOV}, vfov {DEFAULT_VFOV:.3f}, znear {DEFAULT_ZNEAR}, zfar {DEFAULT_ZFAR}",
        "mesh file: coordinates used as they are (taken to be Y-up); file normals ignored",
    ]
    materials = Materials.from_records([{"kind": DIFFUSE, "albedo": (DEFAULT_ALBEDO,) * 3,
                                         "name": "default"}])
    lights = Lights.from_records([{"kind": AMBIENT, "radiance": (AMBIENT_RADIANCE,) * 3}])
    camera = CameraSpec(view_point=np.array([0.0, 0.0, 1.0]), position=np.zeros(3),
                        hfov=DEFAULT_HFOV, vfov=DEFAULT_VFOV,
                        znear=DEFAULT_ZNEAR, zfar=DEFAULT_ZFAR)
    try:
        geometry = accel.Geometry(vertices=vertices, faces=faces)
    except ValueError as error:
        raise SceneError(path, f"invalid mesh: {error}") from error
    return Scene(path=path, geometry=geometry,
                 vertex_normals=area_weighted_normals(geometry.vertices, geometry.faces),
                 material_index=np.zeros(len(faces), dtype=np.int32),
                 materials=materials, lights=lights, camera=camera, notes=notes)


def _read_triangles(path):
    """(vertices (V, 3) float64, faces (F, 3) int64, faces dropped for NaN or infinite
    coordinates); every geometry of a file's scene concatenated with its node transform baked
    in. The file is read unprocessed first, to count the faces trimesh's processing would drop
    without a word, then each geometry is processed as trimesh's loader would (merged vertices,
    non-finite faces removed)."""
    import trimesh  # imported here: only mesh files need it

    try:
        scene = trimesh.load_scene(path, process=False)
        non_finite = 0
        for geometry in scene.geometry.values():   # each geometry as the file holds it
            if not hasattr(geometry, "process"):
                continue
            raw_faces = np.asarray(geometry.faces, dtype=np.int64).reshape(-1, 3)
            raw_vertices = np.asarray(geometry.vertices, dtype=np.float64).reshape(-1, 3)
            if raw_faces.size and raw_faces.min() >= 0 and raw_faces.max() < len(raw_vertices):
                non_finite += int((~np.isfinite(raw_vertices[raw_faces]).all(axis=(1, 2))).sum())
            geometry.process()
        mesh = scene.to_mesh()
        vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
        faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    except SceneError:
        raise
    except Exception as error:     # trimesh raises many kinds for a bad file
        raise SceneError(path, f"could not read the mesh ({type(error).__name__}: {error})") \
            from error
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise SceneError(path, "face indices out of range")
    return vertices, faces, non_finite
