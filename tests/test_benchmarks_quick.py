"""Smoke test of the intersection benchmark in its smallest mode, through `python -m benchmarks`.

The report and chart go to a temporary directory, never into benchmarks/results/.
"""
import struct

import numba
import pytest

from benchmarks import __main__ as runner
from benchmarks import accel_rays, report, synthetic


def test_synthetic_series_is_exact_and_deterministic():
    for triangles in (1024, 4096):
        vertices, faces = synthetic.displaced_torus(triangles)
        assert faces.shape == (triangles, 3)
        again = synthetic.displaced_torus(triangles)
        assert (again[0] == vertices).all() and (again[1] == faces).all()
        corners = vertices[faces]
        areas = 0.5 * ((corners[:, 1] - corners[:, 0]) ** 2).sum(axis=1)   # no degenerate edge
        assert areas.min() > 0
    with pytest.raises(ValueError):
        synthetic.displaced_torus(1000)
    assert [synthetic.name(n) for n in (1024, 65536, 1048576)] == ["torus-1k", "torus-64k",
                                                                   "torus-1M"]


def test_accel_rays_smallest_mode(tmp_path, monkeypatch, scenes_dir):
    monkeypatch.setenv("PTRACE_SCENES", str(scenes_dir))
    output = tmp_path / "out" / "accel_rays.md"
    threads = numba.get_num_threads()
    try:
        code = runner.main(["accel_rays", "--quick", "--meshes", "meshedit/teapot.dae",
                            "--synthetic", "1024", "--rays", "1000", "--threads", "1", "2",
                            "--output", str(output)])
    finally:
        numba.set_num_threads(threads)
    assert code == 0
    text = output.read_text()
    for title in ("## Builds", "## Closest-hit rays per second", "## bvh / embree rays/s ratio",
                  "## Traversal work per ray", "## Targets (issue 5)"):
        assert title in text
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    for mesh, triangles in (("meshedit/teapot.dae", "2,464"), ("torus-1k", "1,024")):
        for backend in ("bvh mean", "bvh sah", "embree"):
            assert any(r.startswith(f"| {mesh} | {triangles} | {backend} |") for r in rows)
        for kind in accel_rays.RAY_KINDS:
            for t in (1, 2):
                matching = [r for r in rows if r.startswith(f"| {mesh} | {triangles} | ")
                            and f"| {kind} | {t} |" in r]
                assert len(matching) == 1, (mesh, kind, t)
                cells = [c.strip() for c in matching[0].strip("|").split("|")]
                assert len(cells) == 12 and all(c.replace(",", "").replace(".", "").isdigit()
                                                for c in cells[5:])
            assert any(r.startswith(f"| {mesh} | {kind} | ") and r.endswith("| 0/0 |")
                       for r in rows)                   # bvh agrees with naive on every ray
    targets = [r for r in rows if "| >= 0." in r]
    assert len(targets) == 8 and all(r.endswith("| not run |") for r in targets)
    chart = output.with_suffix(".png").read_bytes()
    assert chart[:8] == b"\x89PNG\r\n\x1a\n" and chart[12:16] == b"IHDR"
    width, height = struct.unpack(">II", chart[16:24])
    assert width > 200 and height > 200
    assert not list(output.parent.glob("*.tmp*"))


def test_runner_rejects_unknown_names(capsys):
    assert runner.main(["no_such_benchmark"]) == 2
    assert runner.main(["report"]) == 2
    assert runner.main([]) == 0
    assert "accel_rays" in capsys.readouterr().out


def test_runner_all_passes_quick_and_output(tmp_path, monkeypatch, capsys):
    calls = []
    results = report.RESULTS
    monkeypatch.setattr(runner, "names", lambda: ["accel_rays", "no_such_module", "report"])
    monkeypatch.setattr(accel_rays, "main", lambda argv: calls.append((argv, report.RESULTS)))
    assert runner.main(["all", "--quick", "--output-dir", str(tmp_path)]) == 0
    assert calls == [(["--quick"], tmp_path.resolve())]     # every report goes to the directory
    assert report.RESULTS == results
    out = capsys.readouterr().out
    assert "no_such_module: skipped" in out and "report: skipped (no main(argv))" in out


def test_error_vs_time_verdicts_follow_the_numbers():
    from benchmarks import error_vs_time
    point = lambda spp, seconds, error: (spp, seconds, error, float(spp))   # noqa: E731
    curves = {
        "light -l 1": [point(1, 1.0, 0.01)], "light -l 4": [point(1, 2.0, 0.01)],
        "light -l 16": [point(1, 8.0, 0.01)], "hemisphere -H -l 4": [point(1, 1.0, 1.0)],
        "adaptive -a 8 0.05 -l 4": [point(8, 1.0, 0.01)],
        "roulette off -l 4": [point(1, 4.0, 0.01)],
        "naive -l 4": [point(1, 20.0, 0.01)], "embree -l 4": [point(1, 3.0, 0.0101)],
        "Mitsuba 3 scalar_rgb": [point(1, 0.5, 0.01)]}
    best = {k: min(p[1] * p[2] for p in v) for k, v in curves.items()}
    text = "\n".join(error_vs_time.verdict_lines(curves, best))
    assert "light -l 1 is 100x more efficient than hemisphere" in text
    assert "best first light -l 1 (0.0100), light -l 4 (0.0200), light -l 16" in text
    assert "adaptive is more efficient (0.0100 against 0.0200, 2.00x)" in text
    assert "roulette is more efficient (0.0200 against 0.0400, 2.00x)" in text
    assert "naive: relative MSE within 0.00% of bvh's at every -s, median time 10.00x" in text
    assert "embree: relative MSE within 1.00%" in text
    assert "needs 2.00x the wall time" in text
