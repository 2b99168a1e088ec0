"""The user hears what the loader ignored, changed or assumed:
`ptrace: note: ...` on stderr once per kind after the summary, in --info, silenced by -q; a face
with NaN coordinates is dropped with a note that says NaN, never silently."""
import json
import subprocess
import sys

import pytest

import ptrace
from ptrace.app.cli import grouped_notes

from console import SHIPPED

PLY = """ply
format ascii 1.0
element vertex 6
property float x
property float y
property float z
element face {faces}
property list uchar int vertex_indices
end_header
0 0 0
1 0 0
0 1 0
nan 0 0
1 1 0
0 1 1
{face_lines}"""


def ply(tmp_path, faces):
    path = tmp_path / "nan.ply"
    path.write_text(PLY.format(faces=len(faces), face_lines="".join(f"3 {f}\n" for f in faces)))
    return path


def test_a_face_with_nan_is_dropped_with_a_note_that_says_nan(tmp_path):
    scene = ptrace.load(ply(tmp_path, ["0 1 2", "3 4 5"]))
    assert scene.triangle_count == 1
    assert any("dropped 1 face(s) with NaN" in note for note in scene.notes), scene.notes


def test_a_file_whose_only_face_has_nan_says_nan(tmp_path):
    with pytest.raises(ptrace.SceneError, match="NaN") as caught:
        ptrace.load(ply(tmp_path, ["3 4 5"]))
    assert "nan.ply" in str(caught.value) and "no triangles" not in str(caught.value)


def test_notes_of_one_kind_become_one_line_with_a_count():
    notes = ['<polylist> in <geometry id="a">: fan-triangulated 2 polygon(s)',
             '<polylist> in <geometry id="b">: fan-triangulated 2 polygon(s)',
             "no lights in the scene"]
    assert grouped_notes(notes) == [
        'fan-triangulated 2 polygon(s) (2 places, the first <polylist> in <geometry id="a">)',
        "no lights in the scene"]
    assert grouped_notes(notes[:1]) == [notes[0]]


def test_notes_of_one_kind_with_other_numbers_are_one_line_too():
    """Only the numbers differ (1 polygon in five places, 6 in another): still one kind, and
    the line sums them; notes of another kind stay apart."""
    notes = [f'<polylist> in <geometry id="{name}">: fan-triangulated 1 polygon(s) with more '
             f'than 3 corners' for name in "abcde"]
    notes += ['<polylist> in <geometry id="block">: fan-triangulated 6 polygon(s) with more '
              'than 3 corners', '<p> in <geometry id="f">: skipped 2 polygon(s) with fewer than '
              '3 corners']
    assert grouped_notes(notes) == [
        'fan-triangulated 11 polygon(s) with more than 3 corners (6 places, the first '
        '<polylist> in <geometry id="a">)',
        '<p> in <geometry id="f">: skipped 2 polygon(s) with fewer than 3 corners']


def test_the_shipped_cornell_box_loads_without_a_note():
    """A user's first render prints nothing but its summary."""
    assert ptrace.load(SHIPPED).notes == []


def run(*args):
    return subprocess.run([sys.executable, "-m", "ptrace", *map(str, args)], capture_output=True,
                          text=True, timeout=300)


def test_the_command_line_prints_the_notes_and_quiet_silences_them(tmp_path):
    mesh = ply(tmp_path, ["0 1 2", "3 4 5"])
    out = tmp_path / "out.png"
    loud = run("-s", "1", "-r", "8", "6", "-f", out, mesh)
    assert loud.returncode == 0, loud.stderr
    lines = [line for line in loud.stderr.splitlines() if line.startswith("ptrace: note: ")]
    assert any("NaN" in line for line in lines), loud.stderr
    assert any("one diffuse material" in line for line in lines), loud.stderr
    assert len(lines) == len(set(lines))
    # a note on the file as a whole names it (the loader's own "mesh file:" does not)
    assert any(line.startswith(f"ptrace: note: {mesh.name}: default camera") for line in lines)
    assert not any("mesh file:" in line for line in lines), loud.stderr
    quiet = run("-q", "-s", "1", "-r", "8", "6", "-f", out, mesh)
    assert quiet.returncode == 0 and "note" not in quiet.stderr, quiet.stderr
    info = json.loads(run("--info", mesh).stdout)
    assert any("NaN" in note for note in info["notes"])
    assert any(note.startswith(f"{mesh.name}: default camera") for note in info["notes"])
