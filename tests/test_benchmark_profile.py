"""The render profile benchmark in its quick mode: a table per command whose shares add up, the
phases it names really reached, the wrapped functions put back, and images unchanged by it.

The report goes to a temporary directory, never into benchmarks/results/.
"""
import importlib

import numba
import numpy as np
import pytest

import accel
import ptrace
import ptrace.camera
import ptrace.integrator
import ptrace.paths
from benchmarks import profile_render, report

render_module = importlib.import_module("ptrace.render")   # ptrace.render is the function


def patched_attributes():
    """Every attribute the profiler replaces, with its current value."""
    names = [(ptrace.integrator, n) for n in profile_render.integrator_kernels()]
    names += [(ptrace.paths, "shading_normals"), (ptrace.paths, "normal_colours"),
              (render_module, "camera_samples"), (render_module, "make_tracer"),
              (accel, "build"), (ptrace.camera.Camera, "directions")]
    return {(owner.__name__, name): getattr(owner, name) for owner, name in names}


def tables(text):
    """{command: [(phase, calls, seconds, share)]} from the report's per-command sections."""
    out = {}
    for section in text.split("\n## ")[1:]:
        title, _, body = section.partition("\n")
        rows = [line.strip("|").split("|") for line in body.splitlines()
                if line.startswith("| ") and not line.startswith("| phase")]
        if body.count("| phase | calls | seconds | share of wall % |") == 1:
            out[title] = [(p.strip(), c.strip(), float(s), float(sh)) for p, c, s, sh in rows]
    return out


@pytest.mark.slow   # about 5 s on an idle machine; 40-70 s with the 2 cores shared or a cold cache
def test_quick_profile_report(tmp_path, monkeypatch, scenes_dir):
    monkeypatch.setenv("PTRACE_SCENES", str(scenes_dir))
    monkeypatch.setattr(report, "RESULTS", tmp_path)
    before = patched_attributes()
    light_samples = ptrace.integrator.light_samples
    threads = numba.get_num_threads()
    try:
        profile_render.main(["--quick", "--output", str(tmp_path / "p.md")])
    finally:
        numba.set_num_threads(threads)
    assert ptrace.integrator.light_samples is light_samples
    after = patched_attributes()
    assert all(after[key] is value for key, value in before.items())
    assert "light_samples" in profile_render.integrator_kernels()

    text = (tmp_path / "p.md").read_text()
    assert text.startswith("# ") and "- command: `" in text and "Method:" in text
    by_command = tables(text)
    assert set(by_command) == set(profile_render.COMMANDS)
    for command, rows in by_command.items():
        phases = {phase: (calls, seconds, share) for phase, calls, seconds, share in rows}
        named = [share for phase, _, _, share in rows if phase != profile_render.GLUE]
        assert profile_render.GLUE in phases and len(named) == len(rows) - 1, command
        assert sum(named) <= 100 + 0.05 * len(named), command        # shares printed to 0.1
        assert abs(sum(named) + phases[profile_render.GLUE][2] - 100) <= 1, command
        assert [r[2] for r in rows] == sorted((r[2] for r in rows), reverse=True), command
        # one camera intersect per chunk of camera rays, i.e. per camera_samples call
        assert phases[profile_render.CAMERA_HIT][0] == phases["camera_samples kernel"][0]
        assert phases[profile_render.BUILD][0] == "1"
        section = text.split(f"## {command}\n", 1)[1].split("\n## ", 1)[0]
        assert "profiled and un-profiled images identical" in section, command
        assert "Three slowest parts:" in section
        slowest = [line for line in section.splitlines() if line[:3] in ("1. ", "2. ", "3. ")]
        assert len(slowest) == 3
        assert all(line[3:].startswith(f"{r[0]}: ") for line, r in zip(slowest, rows)), command
    for backend in ("bvh", "embree"):
        cow = {phase: (seconds, share) for phase, _, seconds, share
               in by_command[f"cow -s 64 -l 16 -m 6 ({backend})"]}
        assert cow[profile_render.SHADOW_HIT][0] > 0 and cow[profile_render.SHADOW_HIT][1] > 0
        assert cow[profile_render.BOUNCE_HIT][0] > 0
    normals = {row[0] for row in by_command["cow normals -s 1 (bvh)"]}
    assert "shading_normals kernel (normal shading)" in normals
    assert profile_render.SHADOW_HIT not in normals and profile_render.BOUNCE_HIT not in normals
    assert "## Traversal share by backend" in text


def test_profiled_render_gives_the_same_image(course_scene):
    scene = ptrace.load(course_scene("meshedit/cow.dae"))
    options = dict(spp=2, light_samples=2, max_depth=3, resolution=(40, 30), threads=2)
    for kind in ("bvh", "embree"):
        plain = ptrace.render(scene, accel=kind, **options)
        image, wall, profile = profile_render.profiled_render(scene, accel=kind, **options)
        assert image.shape == (30, 40, 3) and np.abs(image).sum() > 0
        assert np.array_equal(image, plain), kind
        assert 0 < sum(profile.seconds.values()) <= wall
        assert profile.calls[profile_render.SHADOW_HIT] > 0


def test_wrappers_are_removed_when_the_render_fails(course_scene):
    scene = ptrace.load(course_scene("meshedit/cow.dae"))
    before = patched_attributes()

    def failing_kernel(*args):
        raise RuntimeError("kernel failed")

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(ptrace.integrator, "bounce", failing_kernel)
        before["ptrace.integrator", "bounce"] = failing_kernel
        with pytest.raises(RuntimeError, match="kernel failed"):
            profile_render.profiled_render(scene, spp=1, max_depth=2, resolution=(8, 6))
        after = patched_attributes()
        assert all(after[key] is value for key, value in before.items())
