"""load_collada: the course's COLLADA dialect (docs/course.md#dialect) into a flat Scene."""
import numpy as np

import accel

from .. import budget
from ..errors import SceneError
from ..scene import Lights, Materials, Scene, area_weighted_normals
from .collada_dialect import check_dialect
from .collada_document import ColladaDocument
from .collada_geometry import read_mesh, sphere_radius
from .collada_shading import MaterialTable, apply, placed, read_camera, read_light

# Pre-multiplied onto the whole scene so that the renderer works Y-up (docs/course.md#up-axis).
UP_AXIS_MATRICES = {
    "Y_UP": np.eye(4),
    "Z_UP": np.array([[-1, 0, 0, 0], [0, 0, 1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], dtype=float),
    "X_UP": np.array([[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]], dtype=float),
}
# Transform elements the course parses into an all-zero matrix (or ignores): the node would be
# silently mis-placed, so they are refused.
UNSUPPORTED_TRANSFORMS = ("translate", "rotate", "scale", "lookat", "skew")
# Course files nest nodes at most 2 deep; a file nesting hundreds deep is refused rather than
# walked (it is either broken or built to exhaust the reader).
MAX_NODE_DEPTH = 256


def load_collada(path):
    """Read a .dae file in the course dialect. Any problem raises SceneError."""
    try:
        with np.errstate(over="ignore", invalid="ignore"):    # results are checked instead
            return _load(path)
    except SceneError:
        raise
    except Exception as error:      # a case the explicit checks missed: still a SceneError
        raise SceneError(path, f"could not read the scene ({type(error).__name__}: {error})") \
            from error


def _load(path):
    document = ColladaDocument(path)
    check_dialect(document)
    up_axis = read_up_axis(document)
    visual_scene = select_visual_scene(document)
    builder = SceneBuilder(document)
    placed = list(walk_nodes_post_order(document, visual_scene, up_axis))
    builder.charge(node for node, _ in placed)    # before any instance is expanded
    for node, world in placed:
        builder.add_node(node, world)
    return builder.finish()


def read_up_axis(document):
    element = document.find_path(document.root, "asset", "up_axis")
    if element is None:
        document.fail("<asset><up_axis> is missing (required: one of "
                      f"{', '.join(UP_AXIS_MATRICES)})")
    name = (element.text or "").strip()
    if name not in UP_AXIS_MATRICES:
        document.fail(f'<up_axis> "{name[:40]}" is not one of {", ".join(UP_AXIS_MATRICES)}')
    return UP_AXIS_MATRICES[name]


def select_visual_scene(document):
    """<scene><instance_visual_scene url>, else the only <visual_scene> in the file."""
    instance = document.find_path(document.root, "scene", "instance_visual_scene")
    if instance is not None:
        return document.resolve(instance, "url", ("visual_scene",))
    candidates = list(document.root.iter("visual_scene"))
    if len(candidates) != 1:
        document.fail(f"no <scene><instance_visual_scene> and {len(candidates)} "
                      f"<visual_scene> elements (need exactly one)")
    document.notes.append("no <scene><instance_visual_scene>; using the only <visual_scene>")
    return candidates[0]


def node_matrix(document, node):
    """The node's first <matrix>: 16 numbers row-major; missing trailing ones read as 0."""
    for child in node:
        if child.tag in UNSUPPORTED_TRANSFORMS:
            document.fail(f"{document.describe(node)} uses <{child.tag}>: the course's reader "
                          f"does not support it (only <matrix>), the node would be mis-placed")
        if child.tag == "instance_node":
            document.fail(f"{document.describe(node)} uses <instance_node>, which the course's "
                          f"reader does not support")
    matrix_element = document.child(node, "matrix")
    if matrix_element is None:
        return np.eye(4)
    numbers = document.floats(matrix_element, "matrix entries")[:16]
    if numbers.size < 16:
        document.notes.append(f"{document.describe(matrix_element)}: {numbers.size} numbers; "
                              f"the missing {16 - numbers.size} read as 0 like the course")
        numbers = np.concatenate([numbers, np.zeros(16 - numbers.size)])
    return numbers.reshape(4, 4)


def walk_nodes_post_order(document, visual_scene, up_axis):
    """(node, world matrix) for every <node>, children before their parent, in file order."""
    stack = [(node, up_axis, False, 1)
             for node in reversed(document.children(visual_scene, "node"))]
    while stack:
        node, matrix, expanded, depth = stack.pop()
        if expanded:
            yield node, matrix
            continue
        if depth > MAX_NODE_DEPTH:
            document.fail(f"{document.describe(node)} is nested more than {MAX_NODE_DEPTH} "
                          f"nodes deep")
        world = matrix @ node_matrix(document, node)
        if not np.isfinite(world).all():
            document.fail(f"{document.describe(node)}: world matrix overflows to infinity")
        stack.append((node, world, True, depth))
        stack.extend((child, world, False, depth + 1)
                     for child in reversed(document.children(node, "node")))


class SceneBuilder:
    """Collects the instances of the visual scene into flat arrays."""

    def __init__(self, document):
        self.document = document
        self.materials = MaterialTable(document)
        self.vertex_blocks, self.face_blocks, self.normal_blocks = [], [], []
        self.triangle_materials = []
        self.vertex_count = 0
        self.centers, self.radii, self.sphere_materials = [], [], []
        self.light_records = []
        self.camera = None
        self.camera_count = 0
        self._meshes = {}        # <geometry> element -> (local positions, faces)

    def add_node(self, node, world):
        """The node's first instance_camera, else instance_light, else instance_geometry."""
        tag, instance = self._instance(node)
        if instance is not None:
            {"instance_camera": self._add_camera, "instance_light": self._add_light,
             "instance_geometry": self._add_geometry}[tag](node, instance, world)

    def _instance(self, node):
        for tag in ("instance_camera", "instance_light", "instance_geometry"):
            instance = self.document.child(node, tag)
            if instance is not None:
                return tag, instance
        return None, None

    def charge(self, nodes):
        """Charge the memory budget (ptrace.budget) for the triangles the nodes place, each
        instance of a mesh counting its own, before they are expanded."""
        document, triangles, instances = self.document, 0, 0
        for node in nodes:
            tag, instance = self._instance(node)
            if tag != "instance_geometry":
                continue
            geometry = document.resolve(instance, "url", ("geometry",))
            mesh = document.child(geometry, "mesh")
            if mesh is not None:
                if geometry not in self._meshes:
                    self._meshes[geometry] = read_mesh(document, mesh)
                triangles += len(self._meshes[geometry][1])
                instances += 1
        budget.current().triangles(
            document.path, triangles, f"the {triangles:,} triangles its nodes place "
                                      f"({instances:,} instances of {len(self._meshes):,} "
                                      f"mesh{'es' if len(self._meshes) != 1 else ''})")

    def _add_camera(self, node, instance, world):
        camera = self.document.resolve(instance, "url", ("camera",))
        self.camera = read_camera(self.document, camera, world)    # the last camera wins
        self.camera_count += 1

    def _add_light(self, node, instance, world):
        light = self.document.resolve(instance, "url", ("light",))
        self.light_records.append(read_light(self.document, light, node, world))

    def _add_geometry(self, node, instance, world):
        document = self.document
        geometry = document.resolve(instance, "url", ("geometry",))
        material = self.materials.index_for(instance)
        mesh = document.child(geometry, "mesh")
        if mesh is not None:
            if geometry not in self._meshes:
                self._meshes[geometry] = read_mesh(document, mesh)
            positions, faces = self._meshes[geometry]
            world_positions = positions @ world[:3, :3].T + world[:3, 3]
            placed(document, document.describe(node), world_positions,
                   f"the transformed positions of {document.describe(geometry)}")
            self.vertex_blocks.append(world_positions)
            self.face_blocks.append(faces + self.vertex_count)
            self.normal_blocks.append(area_weighted_normals(world_positions, faces))
            self.triangle_materials.append(np.full(len(faces), material, dtype=np.int32))
            self.vertex_count += len(world_positions)
            return
        radius = sphere_radius(document, geometry)
        if radius is None:
            document.fail(f"{document.describe(geometry)} has neither a <mesh> nor a CGL <sphere>")
        scale = float(np.linalg.norm(world[:3, :3] @ np.array([1.0, 0.0, 0.0])))
        center = apply(world, (0, 0, 0))
        placed(document, document.describe(node), np.append(center, radius * scale),
               f"the placement of the sphere {document.describe(geometry)}")
        self.centers.append(center)
        self.radii.append(radius * scale)
        self.sphere_materials.append(material)

    def finish(self):
        document = self.document
        vertices = np.concatenate(self.vertex_blocks) if self.vertex_blocks else np.empty((0, 3))
        faces = (np.concatenate(self.face_blocks) if self.face_blocks
                 else np.empty((0, 3), dtype=np.int64))
        normals = np.concatenate(self.normal_blocks) if self.normal_blocks else np.empty((0, 3))
        centers = np.array(self.centers, dtype=np.float64).reshape(-1, 3)
        radii = np.array(self.radii, dtype=np.float64)
        material_index = np.concatenate(
            self.triangle_materials + [np.array(self.sphere_materials, dtype=np.int32)])
        notes = document.notes
        if self.camera is None:
            notes.append("no camera in the scene")
        elif self.camera_count > 1:
            notes.append(f"{self.camera_count} cameras; the last one parsed is used")
        if not self.light_records:
            notes.append("no lights in the scene")
        if len(faces) + len(radii) == 0:
            notes.append("no geometry in the scene")
        return Scene(path=document.path,
                     geometry=accel.Geometry(vertices=vertices, faces=faces,
                                             centers=centers, radii=radii),
                     vertex_normals=normals,
                     material_index=material_index.astype(np.int32),
                     materials=Materials.from_records(self.materials.records),
                     lights=Lights.from_records(self.light_records),
                     camera=self.camera,
                     notes=notes)
