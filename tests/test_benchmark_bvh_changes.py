"""Smoke test of benchmarks.bvh_changes with two processes per revision, on a small batch:
every cell of its table is filled, and the report says how far apart the processes were."""
import re

import pytest

from benchmarks import bvh_changes


@pytest.mark.slow
def test_two_processes_per_revision(tmp_path, monkeypatch, scenes_dir):
    monkeypatch.setenv("PTRACE_SCENES", str(scenes_dir))
    started = []

    class Counted(bvh_changes.Revision):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            started.append(self.process.pid)

    monkeypatch.setattr(bvh_changes, "Revision", Counted)
    output = tmp_path / "bvh_changes.md"
    bvh_changes.main(["--revisions", "tree=this tree", "--processes", "2", "--rays", "4000",
                      "--repeats", "2", "--meshes", "meshedit/cow.dae", "--splits", "mean",
                      "--leaf-sizes", "--renders", "0", "--output", str(output)])
    assert len(set(started)) == 2
    text = output.read_text()
    spread = re.search(r"Each revision ran in 2 processes; .* median (\d+\.\d+)x, largest "
                       r"(\d+\.\d+)x \(meshedit/cow\.dae, \w+, mean split, this tree\)", text)
    assert spread, text
    assert 1.0 <= float(spread.group(1)) <= float(spread.group(2))
    rows = [line for line in text.splitlines() if line.startswith("| meshedit/cow.dae |")]
    assert [row.split(" | ")[1] for row in rows] == ["random", "camera", "secondary",
                                                    "shadow (any hit)"]
    for row in rows:   # this tree's rate, Embree's, and their ratio: positive numbers
        cells = row.strip("| ").split(" | ")[2:]
        assert len(cells) == 3 and all(float(c.replace(",", "")) > 0 for c in cells), row
    assert not list(tmp_path.glob("*.tmp"))
