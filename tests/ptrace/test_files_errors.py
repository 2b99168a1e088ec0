"""Every reader failure is one line naming the file and what is wrong in words, never a bare
Python exception ("AssertionError: ", "FileNotFoundError: model.gltf"); COLLADA files not in
the course's dialect are refused saying so and what was found."""
import struct
import subprocess
import sys

import numpy as np
import pytest
from files_by_hand import gltf, quad

import ptrace

EXCEPTION_NAMES = ("Error", "Exception", "Traceback")


def glb_truncated(path):
    gltf(path, [quad()])
    path.write_bytes(path.read_bytes()[:40])


def glb_wrong_chunk(path):
    path.write_bytes(b"glTF" + struct.pack("<IIII", 2, 40, 8, 0x12345678) + b"\x00" * 20)


def gltf_accessor_overrun(path):
    document = gltf(path, [quad()])
    document["accessors"][0]["count"] = 1000     # more vertices than its view holds
    import json
    path.write_text(json.dumps(document))


CASES = {
    "random.obj": lambda p: p.write_bytes(np.random.default_rng(3).bytes(4000)),
    "random.ply": lambda p: p.write_bytes(np.random.default_rng(4).bytes(4000)),
    "random.stl": lambda p: p.write_bytes(np.random.default_rng(5).bytes(4000)),
    "random.glb": lambda p: p.write_bytes(np.random.default_rng(6).bytes(4000)),
    "random.gltf": lambda p: p.write_bytes(np.random.default_rng(7).bytes(4000)),
    "truncated.glb": glb_truncated,
    "chunk.glb": glb_wrong_chunk,
    "overrun.gltf": gltf_accessor_overrun,
    "empty.ply": lambda p: p.write_bytes(b""),
    "header.ply": lambda p: p.write_text("ply\nformat ascii 1.0\nelement vertex 3\n"
                                         "property float x\n"),
    "binary.ply": lambda p: p.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement "
                                          b"vertex 3\nproperty float x\nproperty float y\n"
                                          b"property float z\nelement face 1\nproperty list "
                                          b"uchar int vertex_indices\nend_header\n\x00\x01"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_broken_file_is_one_line_in_words(tmp_path, name):
    path = tmp_path / name
    CASES[name](path)
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    message = str(caught.value)
    assert name in message and "\n" not in message, message
    words = message.split(": ", 1)[1]
    assert not any(bad in words for bad in EXCEPTION_NAMES), message
    assert len(words) > 15, message


def test_the_command_line_gives_one_line_and_exit_code_2(tmp_path):
    path = tmp_path / "model.gltf"
    path.write_text("{ broken")
    run = subprocess.run([sys.executable, "-m", "ptrace", "--info", str(path)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "model.gltf" in lines[0] and "JSON is malformed" in lines[0]


COLLADA = """<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><up_axis>Z_UP</up_axis></asset>
  <library_lights><light id="sun"><technique_common><directional><color>1 1 1</color>
  </directional></technique_common></light></library_lights>
  <library_visual_scenes><visual_scene id="scene">
    <node id="lamp">{transform}<instance_light url="#sun"/></node>
  </visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#scene"/></scene>
</COLLADA>
"""


@pytest.mark.parametrize("transform, words", [
    ("", ["it has no camera"]),
    ("<translate>0 0 1</translate><rotate>0 0 1 90</rotate>",
     ['<node id="lamp"> uses <translate>', "also uses <rotate>", "has no camera"]),
    ('<instance_node url="#lamp"/>', ["uses <instance_node>"])])
def test_collada_outside_the_course_dialect_says_so(tmp_path, transform, words):
    """A generic COLLADA file with lights and no camera said only "the scene has no
    camera"."""
    path = tmp_path / "lights.dae"
    path.write_text(COLLADA.format(transform=transform))
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    message = str(caught.value)
    assert "not in the course's dialect" in message and "lights.dae" in message, message
    for fragment in words:
        assert fragment in message, message
