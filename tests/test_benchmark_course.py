"""The course comparison benchmark in its quick mode: every table and target row is there, every
timing is a positive number, the growth fit and its chart are sound, and nothing is written into
benchmarks/results/ (the report goes to a temporary directory).
"""
import re
import struct

import numba
import numpy as np
import pytest

from benchmarks import course_comparison, report

NUMBER = re.compile(r"^[0-9][0-9,]*(\.[0-9]+)?x?$")


def number(cell):
    cell = cell.strip()
    assert NUMBER.match(cell), cell
    return float(cell.rstrip("x").replace(",", ""))


def cells(row):
    return [c.strip() for c in row.strip().strip("|").split("|")]


def snapshot(directory):
    if not directory.exists():
        return {}
    return {p.name: (p.stat().st_mtime_ns, p.stat().st_size) for p in directory.iterdir()}


def test_fit_recovers_n_over_log_n():
    n = np.array([1024, 4096, 16384, 65536])
    rows = [{"n": int(k), "speedup": 0.7 * k / np.log2(k)} for k in n]
    f = course_comparison.fit(rows)
    assert f["c"] == pytest.approx(0.7)
    assert np.allclose(f["nlogn"], f["s"])
    passed, worst, sentence = course_comparison.growth_verdict(f)
    assert passed and worst == pytest.approx(1.0) and "grows like n / log n" in sentence
    rows[1]["speedup"] *= 3                           # one point far off the model
    passed, worst, sentence = course_comparison.growth_verdict(course_comparison.fit(rows))
    assert not passed and worst > 1.5 and "torus-4k" in sentence


@pytest.mark.slow
def test_course_comparison_quick(tmp_path, monkeypatch, scenes_dir):
    monkeypatch.setenv("PTRACE_SCENES", str(scenes_dir))
    committed = report.RESULTS
    before = snapshot(committed)
    monkeypatch.setattr(report, "RESULTS", tmp_path)
    threads = numba.get_num_threads()
    try:
        path = course_comparison.main(["--quick"])
    finally:
        numba.set_num_threads(threads)
    assert path == tmp_path / "course_comparison.md"
    text = path.read_text()
    for title in ("## Targets (issue 5)", "## 1. Normal shading", "## 2. The seed's full commands",
                  "## 3. Growth of the speedup", "How naive's rows were estimated"):
        assert title in text, title
    rows = [line for line in text.splitlines() if line.startswith("| ")]

    # 1. normal shading: build >= 0, render and wall seconds > 0, speedups positive
    for scene in course_comparison.NORMALS:
        for kind in course_comparison.BACKENDS:
            row = [cells(r) for r in rows if r.startswith(f"| {scene} | ")
                   and cells(r)[2] == kind]
            assert len(row) == 1, (scene, kind)
            build, render, wall, rate, speedup, speedup_render = map(number, row[0][3:9])
            assert build >= 0 and render > 0 and wall > 0 and rate > 0
            assert speedup > 0 and speedup_render > 0

    # 2. the quick commands: naive, bvh and embree seconds positive; the target row
    for name in course_comparison.QUICK:
        row = [cells(r) for r in rows if r.startswith(f"| {name} | ")]
        assert len(row) == 1, name
        naive, bvh, embree = number(row[0][3]), number(row[0][5]), number(row[0][6])
        assert naive > 0 and bvh > 0 and embree > 0
        assert number(row[0][7]) > 0 and number(row[0][8]) > 0
        if name.startswith("CBspheres"):                 # 12 triangles: naive runs in full
            assert row[0][4] == "run"
    assert "est. from" in [cells(r) for r in rows if r.startswith("| cow -s 64")][0][4]
    target = [cells(r) for r in rows if r.startswith("| target: cow -s 64 -l 16 -m 6")]
    assert len(target) == 1 and number(target[0][5]) > 0
    assert re.search(r"<= 6 s: (PASS|FAIL)", target[0][-1])

    # targets table: three rows, each judged
    judged = [cells(r) for r in rows if r.endswith("indicative only |")]
    assert len(judged) == 3
    assert all(re.match(r"(PASS|FAIL)", r[-1]) for r in judged)
    assert any(r[0].startswith("cow normal shading") for r in judged)
    assert any(r[0].startswith("cow `-t 2 -s 64") for r in judged)
    assert any("n / log n" in r[0] for r in judged)

    # 3. growth: the three quick tori, positive rates, bvh agrees with naive, c > 0
    for name in ("torus-1k", "torus-4k", "torus-16k"):
        row = [cells(r) for r in rows if r.startswith(f"| {name} | ")]
        assert len(row) == 1, name
        assert all(number(c) > 0 for c in row[0][5:13])
        assert row[0][13] == "0"
    c = float(re.search(r"S = c \* n / log2\(n\), c = ([0-9.e+-]+);", text).group(1))
    assert c > 0
    assert "is within a factor" in text

    chart = path.with_suffix(".png").read_bytes()
    assert chart[:8] == b"\x89PNG\r\n\x1a\n" and chart[12:16] == b"IHDR"
    width, height = struct.unpack(">II", chart[16:24])
    assert width > 200 and height > 200
    assert f"]({path.with_suffix('.png').name})" in text
    assert not list(tmp_path.glob("*.tmp*"))
    assert snapshot(committed) == before              # nothing written into benchmarks/results
