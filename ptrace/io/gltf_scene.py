"""A glTF file's scene graph and what is placed on it: each node's world matrix (node_matrices,
local_matrix) and the KHR_lights_punctual lights on those nodes (gltf_lights), with the two
guards (_list, _dict) by which the glTF readers take a JSON value of the wrong type as empty.

Separate from ptrace.io.gltf, which checks the document and its references before trimesh reads
the meshes; this reads the nodes and lights from that checked document, and ptrace.io.gltf
re-exports its names.
"""
import math

import numpy as np

from ..errors import SceneError
from ..scene import DIRECTIONAL, PHYSICAL, POINT, SPOT
from .limits import problem
from .materials import check_numbers


def _list(value):
    return value if isinstance(value, list) else []


def _dict(value):
    return value if isinstance(value, dict) else {}


def node_matrices(path, document):
    """{node index: world matrix} of the nodes of the file's scene (its `scene`, else the
    first): a node's `matrix`, or its translation, rotation (a unit quaternion x, y, z, w)
    and scale, times its parents'."""
    nodes = _list(document.get("nodes"))
    scenes = _list(document.get("scenes"))
    index = document.get("scene", 0)
    if scenes and isinstance(index, int) and 0 <= index < len(scenes):
        roots = _list(_dict(scenes[index]).get("nodes"))
    else:
        children = {c for n in nodes for c in _list(_dict(n).get("children"))}
        roots = [i for i in range(len(nodes)) if i not in children]
    world, stack = {}, [(r, np.eye(4)) for r in roots]
    while stack:
        i, parent = stack.pop()
        if not isinstance(i, int) or not 0 <= i < len(nodes) or i in world:
            continue
        node = _dict(nodes[i])
        local = local_matrix(path, node, i)
        with np.errstate(over="ignore", invalid="ignore"):    # checked here instead
            world[i] = parent @ local
        if not np.isfinite(world[i]).all():
            raise SceneError(path, f"node {i}: its world matrix (its ancestors' matrices "
                                   f"times its own) overflows to infinity")
        stack.extend((c, world[i]) for c in _list(node.get("children")))
    return world


def local_matrix(path, node, i):
    """A node's matrix relative to its parent (SceneError naming the node if not finite)."""
    if "matrix" in node:
        values = check_numbers(_list(node["matrix"]), f"node {i} matrix")
        if isinstance(values, str) or len(values) != 16:
            raise SceneError(path, values if isinstance(values, str) else
                             f"node {i}'s matrix has {len(values)} numbers, not 16")
        return np.array(values, dtype=np.float64).reshape(4, 4).T    # column-major
    parts = []
    for key, default in (("translation", [0, 0, 0]), ("rotation", [0, 0, 0, 1]),
                         ("scale", [1, 1, 1])):
        values = check_numbers(_list(node.get(key, default)), f"node {i} {key}")
        if isinstance(values, str) or len(values) != len(default):
            raise SceneError(path, values if isinstance(values, str) else
                             f"node {i}'s {key} has {len(values)} numbers, not {len(default)}")
        parts.append(values)
    (tx, ty, tz), (x, y, z, w), scale = parts
    norm = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    matrix = np.eye(4)
    matrix[:3, :3] = rotation * np.asarray(scale)
    matrix[:3, 3] = (tx, ty, tz)
    return matrix


def unit_or_zero(vector):
    """The vector made unit length, or None when it is (numerically) zero: a node of zero
    scale. Its length is taken after dividing by its largest component, so that a product of
    large scales (finite, each in range) gives a direction, not an overflowed length of inf
    and a direction of zeros."""
    vector = np.asarray(vector, dtype=np.float64)
    largest = float(np.abs(vector).max())
    if not (math.isfinite(largest) and largest > 0):
        return None
    scaled = vector / largest
    length = float(np.linalg.norm(scaled))
    if not largest * length > 1e-12:
        return None
    return scaled / length


def gltf_lights(path, document, notes):
    """ptrace light records of glTF's KHR_lights_punctual (point, spot and directional lights,
    all of the PHYSICAL model: intensity times colour as the radiance numerator, inverse-square
    falloff, cones as the extension defines them), placed by their nodes.

    A light whose numbers the extension forbids (a negative or non-finite intensity or colour,
    cone angles outside 0 <= inner < outer <= pi/2, a range that is not positive) is refused
    with the light named: the file is invalid and any light we made of it would be a guess.
    A spot or directional light on a node of zero scale has no direction; such a node is how
    glTF files hide things, so the light is dropped with a note."""
    lights = _list(_dict(_dict(document.get("extensions")).get("KHR_lights_punctual"))
                   .get("lights"))
    matrices = node_matrices(path, document)
    records = []
    for i, node in enumerate(_list(document.get("nodes"))):
        ref = _dict(_dict(node).get("extensions")).get("KHR_lights_punctual")
        if ref is None:
            continue
        where = f"glTF node {_dict(node).get('name', i)!r}"
        try:
            light = _dict(lights[ref["light"]])
        except (KeyError, IndexError, TypeError):
            notes.append(f"<{where}>: its KHR_lights_punctual light does not exist: ignored")
            continue
        label = f"light {ref['light']} ({light.get('name', light.get('type'))!r})"
        colour = check_numbers(_list(light.get("color", [1.0, 1.0, 1.0])), f"{label}: color",
                               low=0.0)
        intensity = check_numbers([light.get("intensity", 1.0)], f"{label}: intensity",
                                  low=0.0)
        for checked in (colour, intensity):
            if isinstance(checked, str):
                raise SceneError(path, checked)
        if len(colour) != 3:
            raise SceneError(path, f"{label}: color has {len(colour)} numbers, not 3")
        if i not in matrices:
            notes.append(f"<{where}>: a light outside the file's scene: ignored")
            continue
        matrix = matrices[i]
        radiance = tuple(np.asarray(colour, dtype=np.float64) * intensity[0])
        words = problem(radiance)
        if words is not None:    # each factor is in range, their product need not be
            raise SceneError(path, f"{label}: its color times its intensity {words}")
        kind = light.get("type")
        position = tuple(matrix[:3, 3])
        words = problem(position) if kind in ("point", "spot") else None
        if words is not None:    # each node's numbers are in range, their product is not
            named = f" ({str(_dict(node)['name'])[:60]!r})" if "name" in _dict(node) else ""
            raise SceneError(path, f"{label} on node {i}{named}: its position, where the node "
                                   f"and its ancestors place it, {words}")
        axis = unit_or_zero(matrix[:3, :3] @ np.array([0.0, 0.0, -1.0]))   # down its -Z
        if light.get("range") is not None:
            span = check_numbers([light["range"]], f"{label}: range", low=0.0)
            if isinstance(span, str) or span[0] == 0.0:
                raise SceneError(path, span if isinstance(span, str) else
                                 f"{label}: range 0 (must be positive)")
            notes.append(f"<{where}>: light range ignored (no cut-off)")
        if kind in ("spot", "directional") and axis is None:
            notes.append(f"<{where}>: a {kind} light on a node of zero scale has no "
                         f"direction: dropped")
            continue
        if kind == "point":
            records.append({"kind": POINT, "radiance": radiance, "position": position,
                            "model": PHYSICAL})
        elif kind == "spot":
            spot = _dict(light.get("spot"))
            angles = check_numbers([spot.get("innerConeAngle", 0.0),
                                    spot.get("outerConeAngle", math.pi / 4)],
                                   f"{label}: innerConeAngle, outerConeAngle", low=0.0,
                                   high=math.pi / 2)
            if isinstance(angles, str) or not angles[0] < angles[1]:
                raise SceneError(path, angles if isinstance(angles, str) else
                                 f"{label}: innerConeAngle {angles[0]:g} is not less than "
                                 f"outerConeAngle {angles[1]:g}")
            inner, outer = angles
            records.append({"kind": SPOT, "radiance": radiance, "position": position,
                            "direction": tuple(axis), "model": PHYSICAL,
                            "cos_inner": math.cos(inner), "cos_outer": math.cos(outer)})
        elif kind == "directional":
            # toward the light, as the course's directional lights
            records.append({"kind": DIRECTIONAL, "radiance": radiance,
                            "direction": tuple(-axis), "model": PHYSICAL})
        else:
            notes.append(f"<{where}>: light type {str(kind)[:40]!r} unknown: ignored")
    if records:
        notes.append(f"glTF: {len(records)} KHR_lights_punctual light(s), intensity taken as "
                     f"radiometric (no lumen-to-watt factor), inverse-square falloff")
    return records
