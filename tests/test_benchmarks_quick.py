"""Smoke test of the intersection benchmark in its smallest mode, through `python -m benchmarks`.

The report and chart go to a temporary directory, never into benchmarks/results/.
"""
import json
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


def test_error_vs_time_targets_and_report_follow_the_numbers(tmp_path, monkeypatch):
    """The report is written from measured data only: a synthetic measurement gives the target
    rows, the roulette verdict and the JSON beside the Markdown that its numbers imply."""
    from benchmarks import error_vs_time as evt
    from benchmarks import report
    monkeypatch.setattr(report, "RESULTS", tmp_path)

    def curve(seconds, error):
        return [{"spp": s, "seconds": seconds * s, "rel_mse": error / s, "luminance": 0.3}
                for s in (1, 2, 4, 8, 16)]

    curves = {label: curve(1.0, 0.5) for label in evt.PTRACE_METHODS}
    curves[evt.DEFAULT] = curve(1.0, 0.2)
    curves["roulette from vertex 2 (ptrace's rule before)"] = curve(1.0, 0.1)
    curves["roulette off"] = curve(2.0, 0.2)
    curves[f"Mitsuba {evt.MITSUBA_VARIANT} independent"] = curve(0.5, 0.4)
    curves[f"Mitsuba {evt.MITSUBA_VARIANT} multijitter"] = curve(0.5, 0.1)
    data = {"resolution": [480, 360], "max_depth": 5, "threads": 2, "spp": [1, 2, 4, 8, 16],
            "repeats": 1, "mitsuba": "3.x", "reference_spp": 4096,
            "scenes": {"CBbunny": {"scene": "sky/CBbunny.dae", "curves": curves, "reference": {
                "file": "x.exr", "spp": 4096, "variant": "llvm_ad_rgb", "luminance": 0.25,
                "masked_fraction": 0.01}}}}
    [row] = evt.targets(data)
    assert row["ptrace_mse"] == pytest.approx(0.2 / 16)
    assert row["mitsuba_multijitter_mse"] == pytest.approx(0.1 / 16)
    assert row["ptrace_efficiency"] == pytest.approx(0.2)
    assert row["mitsuba_independent_efficiency"] == pytest.approx(0.2)
    assert row["luminance_ratio"] == pytest.approx(1.2)
    rules = evt.roulette_rules(data)["CBbunny"]
    assert rules["roulette off"] == pytest.approx(0.4)
    path = evt.write_report(data, "evt.md")
    text = path.read_text()
    assert "Most efficient: roulette from vertex 2 (ptrace's rule before)." in text
    assert "| CBbunny | 0.0125 | 0.0063 |" in text
    assert (tmp_path / "error_vs_time_CBbunny.png").exists()
    assert json.loads((tmp_path / "evt.json").read_text()) == data
