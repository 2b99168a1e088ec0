"""Faces are int32 in every scene (accel.Geometry): one dtype whatever the loader, so that no
kernel is compiled a second time for another, and Embree indexes the same array. A mesh with
more vertices than int32 indexes is refused in one line naming the file."""
from pathlib import Path

import numpy as np
import pytest
import trimesh

import accel
import ptrace
from ptrace.app import cli

REPO = Path(__file__).resolve().parents[2]
TINY = ["-r", 8, 6, "-s", 1, "-m", 1, "-t", 1]


def box():
    """A 2 x 1 x 0.5 box: 12 triangles over 8 corners."""
    return trimesh.creation.box(extents=(2.0, 1.0, 0.5))


def binary_ply(path, vertex_count, vertices, faces):
    """A binary PLY of positions and triangles (the loader's own reader); vertex_count is what
    the header says."""
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {vertex_count}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(faces)}\nproperty list uchar uint vertex_indices\nend_header\n")
    records = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<u4", 3)])
    records["n"], records["i"] = 3, faces
    path.write_bytes(head.encode() + np.asarray(vertices, "<f4").tobytes() + records.tobytes())
    return path


def write_each_format(folder):
    """The same box in every format a loader reads: {name: path}."""
    mesh = box()
    paths = {}
    for extension in ("obj", "stl", "glb", "gltf"):
        paths[extension] = folder / f"box.{extension}"
        mesh.export(paths[extension])
    paths["ply (binary, read by ptrace)"] = binary_ply(folder / "plain.ply", len(mesh.vertices),
                                                       mesh.vertices, mesh.faces)
    coloured = mesh.copy()
    coloured.visual.vertex_colors = np.tile([200, 100, 50, 255], (len(mesh.vertices), 1))
    paths["ply (colours, read by trimesh)"] = folder / "coloured.ply"
    coloured.export(paths["ply (colours, read by trimesh)"], encoding="ascii")
    paths["dae"] = REPO / "scenes" / "cornell.dae"
    paths["xml"] = REPO / "scenes" / "guiding_door.xml"
    return paths


def test_every_loader_gives_int32_faces_with_the_file_s_triangles(tmp_path):
    paths = write_each_format(tmp_path)
    corners = np.sort(box().vertices[box().faces].reshape(-1, 9), axis=0)
    for name, path in paths.items():
        geometry = ptrace.load(path).geometry
        assert geometry.faces.dtype == np.int32, name
        assert geometry.faces.flags.c_contiguous, name
        if name in ("dae", "xml"):
            continue
        # the triangles are the file's (the indices' values survive the narrower type)
        found = np.sort(geometry.vertices[geometry.faces].reshape(-1, 9), axis=0)
        np.testing.assert_allclose(found, corners, atol=1e-6, err_msg=name)


def test_indices_a_cast_to_int32_would_wrap_are_refused():
    """2**32 + 1 would become 1 in int32: refused as out of range, not wrapped."""
    corners = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    for faces in (np.array([[0, 1, 2 ** 32 + 1]]), np.array([[0, 1, 2 ** 31]]),
                  np.array([[0, -1, 2]])):
        with pytest.raises(ValueError, match="outside 0..2"):
            accel.Geometry(corners, faces)
    faces = accel.Geometry(corners, np.array([[2, 0, 1]], np.uint64)).faces
    assert faces.dtype == np.int32 and faces.tolist() == [[2, 0, 1]]


def test_more_vertices_than_int32_indexes_are_refused():
    """A (2**31, 3) view that takes no memory: refused before any copy."""
    many = np.broadcast_to(np.zeros(3), (2 ** 31, 3))
    with pytest.raises(ValueError, match="2,147,483,648 vertices, more than the 2,147,483,647"):
        accel.Geometry(many, [[0, 1, 2]])


def test_a_ply_with_more_vertices_than_int32_indexes_is_one_line(tmp_path, capsys):
    """The header's count is refused before the data is read (the file is short of it)."""
    path = binary_ply(tmp_path / "huge.ply", 2 ** 31, [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                      [[0, 1, 2]])
    code = cli.main([str(a) for a in TINY + ["-f", tmp_path / "out.png", path]])
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(lines) == 1, lines
    assert "huge.ply" in lines[0] and "2,147,483,648 vertices" in lines[0], lines


def test_a_binary_ply_whose_index_would_wrap_is_refused(tmp_path):
    """An index of 2**32 - 1 (uint) in a 3-vertex file: out of range, not -1 after a cast."""
    path = binary_ply(tmp_path / "wrap.ply", 3, [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                      [[0, 1, 2 ** 32 - 1]])
    with pytest.raises(ptrace.SceneError, match="face indices out of range") as caught:
        ptrace.load(path)
    assert "wrap.ply" in str(caught.value)
