"""The README's loader departures from the course ("How ptrace departs from the course"), one
test each: polygons are fan-triangulated; node transforms other than <matrix> and
<instance_node> are refused with an error naming the element; glTF loads as .gltf as well as
.glb. (The mesh camera's field of view is pinned by tests/ptrace/test_load_meshes.py.)"""
import numpy as np
import pytest
import trimesh

import ptrace

PLANE = "simple/plane.dae"
TRIANGLES = ('<polylist material="backWall_002-material" count="2">',
             "<vcount>3 3 </vcount>", "<p>0 0 0 1 0 1 2 0 2 3 1 3 0 1 4 2 1 5</p>")
QUAD = ('<polylist material="backWall_002-material" count="1">',
        "<vcount>4 </vcount>", "<p>0 0 0 1 0 1 2 0 2 3 0 3</p>")
NODE = '<node id="backWall" name="backWall" type="NODE">'


def edited(course_scene, tmp_path, replacements, name="edited.dae"):
    text = course_scene(PLANE).read_text(encoding="utf-8")
    for old, new in replacements:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def area(geometry):
    p = geometry.vertices[geometry.faces]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()


def test_a_quad_is_fan_triangulated_not_cut_to_its_first_three_corners(course_scene, tmp_path):
    """The plane's two triangles written as one 4-corner polygon load as the fan (0 1 2),
    (0 2 3): the same two triangles' area, where the course would keep only (0 1 2)."""
    two = ptrace.load(course_scene(PLANE))
    quad = ptrace.load(edited(course_scene, tmp_path, zip(TRIANGLES, QUAD)))
    assert quad.triangle_count == 2
    assert area(quad.geometry) == pytest.approx(area(two.geometry), rel=1e-12)
    corners = quad.geometry.vertices[quad.geometry.faces]
    np.testing.assert_array_equal(corners[0, 0], corners[1, 0])          # a fan: shared first
    np.testing.assert_array_equal(corners[0, 2], corners[1, 1])          # corner and diagonal


@pytest.mark.parametrize("element", [
    "<translate>0 1 0</translate>", "<rotate>0 0 1 90</rotate>", "<scale>2 2 2</scale>",
    "<lookat>0 0 5 0 0 0 0 1 0</lookat>", "<skew>45 1 0 0 0 1 0</skew>",
    '<instance_node url="#Area"/>'])
def test_a_node_transform_other_than_matrix_is_refused(course_scene, tmp_path, element):
    path = edited(course_scene, tmp_path, [(NODE, NODE + element)])
    tag = element[1:].split(">")[0].split()[0].rstrip("/")
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    message = str(caught.value)
    assert path.name in message and tag in message, message
    assert "\n" not in message


@pytest.mark.parametrize("extension", [".glb", ".gltf"])
def test_gltf_loads_from_either_extension(tmp_path, extension):
    box = trimesh.creation.box(extents=(1, 2, 3))
    path = tmp_path / f"box{extension}"
    trimesh.Scene([box]).export(path)
    scene = ptrace.load(path)
    assert scene.triangle_count == 12
    lower, upper = scene.bounds()
    np.testing.assert_allclose(upper - lower, [1, 2, 3], atol=1e-6)
