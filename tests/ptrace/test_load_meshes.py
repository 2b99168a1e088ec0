"""Plain mesh files load through trimesh with a default material, light and camera."""
import numpy as np
import pytest
import trimesh

import ptrace
from ptrace.scene import AMBIENT, DIFFUSE

MESH_FORMATS = ["obj", "ply", "stl", "glb"]


def box_mesh():
    """A 2 x 1 x 0.5 box centred at (1, 2, 3): 12 triangles."""
    box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    box.apply_translation((1.0, 2.0, 3.0))
    return box


@pytest.mark.parametrize("extension", MESH_FORMATS)
def test_mesh_file_loads_with_defaults(tmp_path, extension):
    """The README's promise for mesh files: one diffuse material of albedo 0.5, one ambient
    light of radiance 1, and the course's orbit camera on the +Z side (49.1 x 37.8 degrees)."""
    path = tmp_path / f"box.{extension}"
    box_mesh().export(path)
    scene = ptrace.load(path)
    assert scene.triangle_count == 12
    assert scene.sphere_count == 0
    lower, upper = scene.bounds()
    np.testing.assert_allclose(lower, [0, 1.5, 2.75], atol=1e-6)
    np.testing.assert_allclose(upper, [2, 2.5, 3.25], atol=1e-6)
    assert list(scene.lights.kind) == [AMBIENT]
    np.testing.assert_allclose(scene.lights.radiance[0], [1, 1, 1])
    assert list(scene.materials.kind) == [DIFFUSE]
    np.testing.assert_allclose(scene.materials.albedo[0], [0.5, 0.5, 0.5])
    assert (scene.material_index == 0).all() and len(scene.material_index) == 12
    assert scene.camera is not None
    np.testing.assert_allclose(scene.camera.view_point, [0, 0, 1])
    assert scene.camera.vfov == pytest.approx(37.849, abs=1e-3)
    lengths = np.linalg.norm(scene.vertex_normals[np.unique(scene.geometry.faces)], axis=1)
    np.testing.assert_allclose(lengths, 1.0)
    assert scene.notes


def test_gltf_scene_with_two_placed_meshes(tmp_path):
    first = trimesh.creation.box(extents=(1, 1, 1))
    second = trimesh.creation.box(extents=(1, 1, 1))
    gltf_scene = trimesh.Scene()
    move = trimesh.transformations.translation_matrix
    gltf_scene.add_geometry(first, node_name="a", transform=move((5, 0, 0)))
    gltf_scene.add_geometry(second, node_name="b", transform=move((-5, 0, 0)))
    path = tmp_path / "two.glb"
    gltf_scene.export(path)
    scene = ptrace.load(path)
    assert scene.triangle_count == 24
    lower, upper = scene.bounds()
    np.testing.assert_allclose(lower, [-5.5, -0.5, -0.5], atol=1e-6)
    np.testing.assert_allclose(upper, [5.5, 0.5, 0.5], atol=1e-6)


def test_missing_mesh_file(tmp_path):
    with pytest.raises(ptrace.SceneError, match="missing.obj"):
        ptrace.load(tmp_path / "missing.obj")


@pytest.mark.parametrize("extension, content", [
    ("obj", b"# only a comment, no faces\nv 0 0 0\nv 1 0 0\n"),
    ("stl", b"\x00\x01garbage that is no stl"),
    ("ply", b"ply\nformat nonsense\n"),
    ("glb", b"glTF not really"),
    ("obj", b""),
])
def test_bad_mesh_files(tmp_path, extension, content):
    path = tmp_path / f"bad.{extension}"
    path.write_bytes(content)
    with pytest.raises(ptrace.SceneError, match=f"bad.{extension}"):
        ptrace.load(path)


def test_nan_vertex(tmp_path):
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    with pytest.raises(ptrace.SceneError, match="nan.obj"):
        ptrace.load(path)
