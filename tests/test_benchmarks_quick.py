"""Smoke test of the intersection benchmark in its smallest mode, through `python -m benchmarks`.

The report and chart go to a temporary directory, never into benchmarks/results/.
"""
import argparse
import contextlib
import dataclasses
import importlib
import io
import json
import pkgutil
import struct

import numba
import pytest

import benchmarks
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
    import numpy as np

    import ptrace
    from accel import raygen

    def table_rows(text, heading):
        """The data rows ("| ..." lines after the separator) of the first table under `heading`,
        each as a list of stripped cells."""
        lines = text.splitlines()
        at = next(i for i, line in enumerate(lines) if line.startswith(heading))
        rows, started = [], False
        for line in lines[at + 1:]:
            if line.startswith("#"):
                break
            if line.startswith("|---"):
                started = True
            elif started and line.startswith("| "):
                rows.append([c.strip() for c in line.strip().strip("|").split("|")])
            elif started:
                break
        return rows

    def is_number(cell):
        digits = cell.replace(",", "")
        return digits.replace(".", "", 1).isdigit() and float(digits) > 0

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
    for title in ("## Targets, 2 threads", "## bvh / embree rays/s ratio",
                  "## Rays per second (2 threads)", "## Rays per second at 1 thread",
                  "## Builds", "## Traversal work per ray"):
        assert title in text
    assert accel_rays.RAY_KINDS == ("random", "camera", "secondary", "shadow")
    backends = ("naive", "bvh mean", "bvh sah", "bvh mean mt", "bvh sah mt", "embree")
    assert accel_rays.BACKENDS == backends
    meshes = (("meshedit/teapot.dae", "2,464"), ("torus-1k", "1,024"))
    for mesh, triangles in meshes:
        # one table per mesh at 2 threads: a row per ray kind, every backend's rays/s and the
        # three ratios positive numbers (the Möller–Trumbore variants run on the tori too)
        assert f"{triangles} triangles; shadow rays go to the synthetic square." in text
        header = next(line for line in text.split(f"### {mesh}\n", 1)[1].splitlines()
                      if line.startswith("| kind |"))
        assert header == ("| kind | query | rays | naive rays | " + " | ".join(backends)
                          + " | mean/embree | sah/embree | wt/MT mean |")
        rows = table_rows(text, f"### {mesh}")
        assert [r[0] for r in rows] == list(accel_rays.RAY_KINDS)
        for row in rows:
            assert row[1] == ("any hit" if row[0] == "shadow" else "closest")
            assert len(row) == 4 + len(backends) + 3 and all(is_number(c) for c in row[2:]), row
        # the other thread count: the same cells, one row per kind
        rows = [r for r in table_rows(text, "## Rays per second at 1 thread") if r[0] == mesh]
        assert [(r[1], r[2]) for r in rows] == [(k, "1") for k in accel_rays.RAY_KINDS]
        assert all(len(r) == 3 + len(backends) + 3 and all(is_number(c) for c in r[3:])
                   for r in rows)
        [summary] = [r for r in table_rows(text, "## bvh / embree rays/s ratio") if r[0] == mesh]
        assert len(summary) == 2 + 2 * 4 + 2 and all(is_number(c) for c in summary[2:])
        builds = [r for r in table_rows(text, "## Builds") if r[0] == mesh]
        assert [r[2] for r in builds] == ["bvh mean", "bvh sah", "embree"]
        work = [r for r in table_rows(text, "## Traversal work per ray") if r[0] == mesh]
        assert [r[1] for r in work] == list(accel_rays.RAY_KINDS)
        assert all(r[-1] == "0/0" for r in work)          # bvh agrees with naive on every ray
        assert 0 < float(work[-1][2]) < 1                  # some shadow rays blocked, not all
    # the targets, none of whose meshes ran here
    targets = table_rows(text, "## Targets,")
    four = ["meshedit/cow.dae", "sky/CBbunny.dae", "keenan/building.dae", "meshedit/maxplanck.dae"]
    expected = ([("bvh / embree, closest hit", "random", m, "0.80x") for m in four]
                + [("bvh / embree, closest hit", "secondary", m, "0.60x") for m in four]
                + [("bvh / embree, any hit", "shadow", "sky/CBbunny.dae", "0.80x")]
                + [("watertight / Möller–Trumbore", k, m, "0.90x")
                   for k in ("random", "secondary") for m in four])
    assert [tuple(r[:4]) for r in targets] == expected
    assert all(r[4:] == ["–", "not run", "–", "not run"] for r in targets)
    # the verdicts follow the numbers: pass at the threshold, FAIL below it, mean decides
    rates = {}
    for kind in accel_rays.RAY_KINDS:
        rates.update({(kind, 2, "embree"): 100.0, (kind, 2, "bvh mean"): 80.0,
                      (kind, 2, "bvh sah"): 59.0, (kind, 2, "bvh mean mt"): 90.0,
                      (kind, 2, "bvh sah mt"): 50.0})
    fake = [{"label": m, "rates": rates} for m in four]
    verdicts = [[c.strip() for c in line.strip("|").split("|")]
                for line in accel_rays.targets_table(fake, argparse.Namespace(threads=[1, 2]))
                if line.startswith("| bvh") or line.startswith("| watertight")]
    assert [v[4:] for v in verdicts] == (
        [["0.80x", "pass", "0.59x", "FAIL"]] * 4 + [["0.80x", "pass", "0.59x", "FAIL"]] * 4
        + [["0.80x", "pass", "0.59x", "FAIL"]] + [["0.89x", "FAIL", "1.18x", "pass"]] * 8)
    # the shadow batch: surface_rays' origins, segments ending 1e-4 short of the light
    scene = ptrace.load(scenes_dir / "sky" / "CBbunny.dae")
    light = accel_rays.scene_light(scene)
    rays = raygen.shadow_rays(scene.geometry, 500, seed=3, light=light)
    assert (rays.origins == raygen.surface_rays(scene.geometry, 500, seed=3).origins).all()
    assert (rays.tmin == 1e-4).all() and (rays.tmax == 1 - 1e-4).all()
    ends = rays.origins + rays.directions - light[0]     # on the light, within half its edges
    for edge in light[1:]:
        assert (np.abs(ends @ edge) <= 0.5 * (edge @ edge) + 1e-9).all()
    centre, edge_x, edge_y = raygen.light_square(scene.geometry)
    assert centre[1] > scene.geometry.bounds()[1][1] and edge_x @ edge_y == 0
    chart = output.with_suffix(".png").read_bytes()
    assert chart[:8] == b"\x89PNG\r\n\x1a\n" and chart[12:16] == b"IHDR"
    width, height = struct.unpack(">II", chart[16:24])
    assert width > 200 and height > 200
    assert not list(output.parent.glob("*.tmp*"))


def test_the_registry_names_every_module_and_its_quick_mode():
    """Every module of the package is a registered benchmark or a helper; `all` runs them in
    the registry's order; a module registered with --quick has it on its command line (its
    --help lists it; every module in `all` parses its arguments before doing anything) and one
    registered otherwise does not."""
    modules = {m.name for m in pkgutil.iter_modules(benchmarks.__path__)}
    assert modules == set(benchmarks.BENCHMARKS) | set(benchmarks.HELPERS)
    assert runner.names() == ["accel_rays", "first_images", "mitsuba_reference", "distributed",
                              "error_vs_time", "paths_per_second", "profile_render"]
    for name in runner.names():
        entry = benchmarks.BENCHMARKS[name]
        assert entry.description and (entry.quick is not None or entry.quick_skip), name
        module = importlib.import_module(f"benchmarks.{name}")
        out = io.StringIO()
        with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as exit_:
            module.main(["--help"])
        assert exit_.value.code == 0, name
        assert ("--quick" in out.getvalue()) == (entry.quick == ("--quick",)), name
    assert runner.quick_args("first_images", None) == ["--repeats", "1"]


def test_runner_skips_what_the_registry_says(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(runner, "names", lambda: ["accel_rays"])
    monkeypatch.setattr(accel_rays, "main", calls.append)
    entry = benchmarks.BENCHMARKS["accel_rays"]
    for changed, argv, line in (
            (dict(quick=None, quick_skip="a reason"), ["--quick"], "skipped in --quick (a reason)"),
            (dict(requires="no_such_module_here"), [], "skipped (no_such_module_here is not "
                                                       "installed)")):
        monkeypatch.setitem(benchmarks.BENCHMARKS, "accel_rays",
                            dataclasses.replace(entry, **changed))
        assert runner.main(["all", *argv, "--output-dir", str(tmp_path)]) == 0
        assert f"--- accel_rays: {line}" in capsys.readouterr().out
    assert calls == []
    monkeypatch.setitem(benchmarks.BENCHMARKS, "accel_rays", entry)
    assert runner.main(["all", "--quick", "--output-dir", str(tmp_path)]) == 0
    assert calls == [["--quick"]]
    mitsuba = benchmarks.BENCHMARKS["mitsuba_reference"]
    assert mitsuba.quick is None and mitsuba.requires == "mitsuba"


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



def test_mitsuba_scenes_z_test_tells_agreeing_images_from_differing_ones():
    """Batches drawn from one distribution agree; a 5 % brighter one in a quarter of the
    pixels differs; a pixel with no spread agrees only with a mean within float32 rounding."""
    pytest.importorskip("scipy")
    import numpy as np

    from benchmarks.mitsuba_scenes import z_test
    rng = np.random.default_rng(7)
    truth = rng.uniform(0.2, 1.0, (1, 20, 30, 3))
    ours = truth + rng.normal(0, 0.05, (8, 20, 30, 3))
    theirs = truth + rng.normal(0, 0.05, (8, 20, 30, 3))
    share, agrees = z_test(ours, theirs)
    assert agrees and share < 0.03
    brighter = theirs.copy()
    brighter[:, :5] *= 1.05
    assert not z_test(ours, brighter)[1]
    flat = np.ones((4, 1, 1, 3))
    assert z_test(flat, flat.copy()) == (0.0, True)
    assert z_test(flat, 2 * flat) == (1.0, False)
    assert z_test(0 * flat, 0 * flat) == (0.0, True)
    # float32 sums a few ulps apart with no spread (Mitsuba's film) agree; 0.1 % apart differ
    ulps = np.float32(0.12) * (1 + 4e-7 * np.arange(4))[:, None, None, None] * flat
    assert z_test(0.12 * flat, ulps) == (0.0, True)
    assert z_test(0.12 * flat, 0.12012 * flat) == (1.0, False)


def test_mitsuba_scenes_quick(tmp_path):
    """The quick run renders its two scenes with both renderers and reports each: every number
    finite, the means within 10 % at 8 spp, and ptrace's notes of each scene."""
    pytest.importorskip("mitsuba")
    from benchmarks import mitsuba_scenes
    output = tmp_path / "mitsuba_scenes.md"
    threads = numba.get_num_threads()
    try:
        assert mitsuba_scenes.main(["--quick", "--output", str(output)]) == 0
    finally:
        numba.set_num_threads(threads)
    text = output.read_text()
    scenes, loading = text.split("## Loading a large mesh")
    loading, history = loading.split("## Earlier changes measured")   # (a fixed record)
    loading, survey = loading.split("## Public Mitsuba scenes")        # (a fixed record)
    assert "| before (commit" in history and "| outcome | files |" in survey
    rows = [line.split("|")[1:-1] for line in scenes.splitlines()
            if line.startswith("| ") and not line.startswith("| scene")]
    assert [r[0].strip() for r in rows] == list(mitsuba_scenes.QUICK_SCENES)
    loads = [line.split("|")[1:-1] for line in loading.splitlines()
             if line.startswith("| ") and not line.startswith("| form")]
    assert [r[0].strip() for r in loads] == ["ply", "serialized"]
    assert all(float(cell.strip().rstrip("x").replace(",", "")) > 0 for r in loads
               for cell in r[1:])
    for row in rows:
        numbers = [float(cell.strip().rstrip("%")) for cell in row[2:9]]
        assert all(value >= 0 for value in numbers), row
        assert abs(numbers[4] - 1) < 0.1, row           # the timing run's mean ratio
        assert row[9].strip() in ("agrees", "differs")
    for name in mitsuba_scenes.QUICK_SCENES:
        assert f"### {name}\n\n- " in text
    assert "the file's sensor and integrator render with -r 24 18, -s 8" in text
