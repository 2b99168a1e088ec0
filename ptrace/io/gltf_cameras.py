"""The cameras a glTF file carries: each node of the file's scene that names a camera becomes a
ptrace.scene.FileCamera (ptrace.pointing.file_camera turns one into the Camera it renders).

glTF's camera axes are ptrace's: a camera looks down its node's -Z with +Y up, and
ptrace's camera_to_world columns are right (+X), up (+Y) and backward (+Z). A camera's
numbers are checked as the specification bounds them (yfov in (0, pi), znear > 0, zfar >
znear, aspectRatio > 0, xmag and ymag not zero) and a file breaking them is refused naming
the camera, as for its lights and materials.
"""
import math

import numpy as np

from ..errors import SceneError
from ..scene import FileCamera
from .gltf_scene import unit_or_zero
from .limits import problem
from .materials import check_numbers

PERSPECTIVE, ORTHOGRAPHIC = "perspective", "orthographic"


def gltf_cameras(path, document, matrices, notes):
    """FileCamera records of the file's camera nodes, in the order of its `nodes` array
    (matrices: {node index: world matrix} of the nodes in its scene). A node naming a camera
    that does not exist, one outside the scene, and one of zero scale (no direction) are
    left out with a note; numbers the specification forbids raise SceneError."""
    cameras = _list(document.get("cameras"))
    records = []
    for i, node in enumerate(_list(document.get("nodes"))):
        node = _dict(node)
        if "camera" not in node:
            continue
        where = f"glTF node {str(node.get('name', i))[:60]!r}"
        index = node["camera"]
        if not (isinstance(index, int) and 0 <= index < len(cameras)):
            notes.append(f"<{where}>: its camera {str(index)[:20]} does not exist: ignored")
            continue
        if i not in matrices:
            notes.append(f"<{where}>: a camera outside the file's scene: ignored")
            continue
        camera = _dict(cameras[index])
        label = f"camera {index} ({str(camera.get('name', camera.get('type')))[:60]!r})"
        words = problem(matrices[i][:3, 3])
        if words is not None:    # each node's numbers are in range, their product is not
            named = f" ({str(node['name'])[:60]!r})" if "name" in node else ""
            raise SceneError(path, f"{label} on node {i}{named}: its position, where the node "
                                   f"and its ancestors place it, {words}")
        axes = _axes(matrices[i][:3, :3])
        if axes is None:
            notes.append(f"<{where}>: a camera on a node of zero or degenerate scale has no "
                         f"direction: ignored")
            continue
        kind = camera.get("type")
        if kind not in (PERSPECTIVE, ORTHOGRAPHIC):
            notes.append(f"<{where}>: camera type {str(kind)[:40]!r} unknown: ignored")
            continue
        values = _dict(camera.get(kind))
        fields = dict(name=str(camera.get("name", node.get("name", f"camera {index}")))[:80],
                      node=i, kind=kind, position=np.array(matrices[i][:3, 3], dtype=float),
                      camera_to_world=axes)
        if kind == PERSPECTIVE:
            yfov = _number(path, values, "yfov", label, required=True)
            if not 0 < yfov < math.pi:
                raise SceneError(path, f"{label}: yfov {yfov:g} is out of range (must be "
                                       f"greater than 0 and less than pi radians)")
            aspect = _number(path, values, "aspectRatio", label)
            if aspect is not None and not aspect > 0:
                raise SceneError(path, f"{label}: aspectRatio {aspect:g} must be positive")
            znear = _number(path, values, "znear", label, required=True)
            if not znear > 0:
                raise SceneError(path, f"{label}: znear {znear:g} must be positive")
            fields.update(yfov=math.degrees(yfov), aspect=aspect)
        else:
            xmag = _number(path, values, "xmag", label, required=True)
            ymag = _number(path, values, "ymag", label, required=True)
            if xmag == 0 or ymag == 0:
                raise SceneError(path, f"{label}: xmag and ymag must not be zero, got "
                                       f"{xmag:g}, {ymag:g}")
            znear = _number(path, values, "znear", label, required=True)
            if not znear >= 0:
                raise SceneError(path, f"{label}: znear {znear:g} must not be negative")
            fields.update(xmag=abs(xmag), ymag=abs(ymag))
        zfar = _number(path, values, "zfar", label, required=kind == ORTHOGRAPHIC)
        if zfar is not None and not zfar > znear:
            raise SceneError(path, f"{label}: zfar {zfar:g} must be greater than znear "
                                   f"{znear:g}")
        records.append(FileCamera(znear=znear, zfar=zfar, **fields))
    return tuple(records)


def camera_note(cameras):
    """The loader's one line about the default camera of a file with these cameras."""
    listed = ", ".join(f"{i} {c.name!r} {c.kind}" for i, c in enumerate(cameras[:8]))
    more = f", ... ({len(cameras)} in all)" if len(cameras) > 8 else ""
    first = next((i for i, c in enumerate(cameras) if c.kind == PERSPECTIVE), None)
    if first is None:
        return (f"glTF: its camera{'s' if len(cameras) > 1 else ''} ({listed}{more}) "
                f"orthographic, which ptrace cannot render (it has pinhole and thin-lens "
                f"cameras): the default camera frames the bounds instead")
    return (f"glTF: the default camera is the file's camera {first} ({cameras[first].name!r}, "
            f"its vertical field of view {cameras[first].yfov:.6g} degrees at any -r); "
            f"--camera-index N picks another of its cameras ({listed}{more}); --eye, --up, "
            f"--fov: others")


def _axes(linear):
    """camera_to_world (columns right, up, backward) of a node's 3x3 world matrix: its Z
    column (backward) and Y column (up) made unit and at right angles; None if degenerate
    (lengths taken without overflow: a product of large scales still has its axes)."""
    if not np.isfinite(linear).all():
        return None
    backward, up = unit_or_zero(linear[:, 2]), unit_or_zero(linear[:, 1])
    if backward is None or up is None:
        return None
    right = np.cross(up, backward)
    if not np.linalg.norm(right) > 1e-12:
        return None
    right = right / np.linalg.norm(right)
    return np.stack([right, np.cross(backward, right), backward], axis=1)


def _number(path, values, key, label, required=False):
    if key not in values:
        if required:
            raise SceneError(path, f"{label}: {key} is missing (the glTF specification "
                                   f"requires it)")
        return None
    checked = check_numbers([values[key]], f"{label}: {key}")
    if isinstance(checked, str):
        raise SceneError(path, checked)
    return checked[0]


def _list(value):
    return value if isinstance(value, list) else []


def _dict(value):
    return value if isinstance(value, dict) else {}
