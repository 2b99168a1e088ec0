"""The render profile benchmark: the render's own phases that it reads (stats["phases"] and
stats["counts"], ptrace.rendering.timing.Phases), its helpers on tiny renders (the wall-time
phases add up, the wrappers are put back, the stage clock times every stage, counts every ray
and changes no pixel, the differencing rows add up), and a tiny quick run's report, with a
failing embree backend skipped.

Reports go to a temporary directory, never into benchmarks/results/.
"""
import pathlib
import re
import time

import numba
import numpy as np
import pytest

import accel
import ptrace
import ptrace.rendering.tiles
import ptrace.rendering.timing
from benchmarks import profile_render as pr
from benchmarks import report
from ptrace.kernel import wavefront

TINY = dict(spp=2, light_samples=2, max_depth=4, integrator="path", resolution=(24, 18))
PIXELS = 24 * 18
REPO = pathlib.Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cow(course_scene):
    return ptrace.load(course_scene("meshedit/cow.dae"))


def test_the_render_reports_its_phases(cow):
    ptrace.render(cow, threads=2, accel="bvh", **TINY)    # compiled (or loaded) already
    stats = {}
    start = time.perf_counter()
    ptrace.render(cow, threads=2, accel="bvh", stats=stats, **dict(TINY, spp=20))
    wall = time.perf_counter() - start
    phases = stats["phases"]
    assert list(phases) == list(ptrace.rendering.timing.IN_PROCESS_PHASES)
    assert min(phases.values()) >= 0 and phases["render"] > 0, phases
    assert sum(phases.values()) <= wall, (phases, wall)
    assert phases["build"] <= stats["build_seconds"] + 1e-3
    assert phases["records"] + phases["render"] <= stats["render_seconds"] + 1e-3
    # passes of 16 and 4 samples (2 + 1 kernel calls at 24x18); nothing left to compile
    assert stats["counts"] == {"compiled": 0, "passes": 2, "kernel_calls": 3}
    assert pr.planned_blocks(PIXELS, 20) == 3
    assert phases["compile"] < 0.05 * wall, phases


def test_compiling_goes_to_the_compile_phase(cow, monkeypatch):
    """numba compiling inside a phase (here a fresh, uncached function in accel.build) is
    counted in "compile", not in the phase; the compiler events are listened to only during
    the call, a failing one included."""
    from numba import njit
    from numba.core import event
    build, listening = accel.build, []

    def compiling_build(*args, **kwargs):
        njit(lambda x: x + 1)(1)    # a new function each time: compiled, never cached
        return build(*args, **kwargs)

    for name, step in (("register", 1), ("unregister", -1)):
        def counted(kind, listener, original=getattr(event, name), step=step):
            listening.append(step)
            return original(kind, listener)
        monkeypatch.setattr(event, name, counted)
    monkeypatch.setattr(accel, "build", compiling_build)
    stats = {}
    start = time.perf_counter()
    ptrace.render(cow, threads=2, accel="bvh", stats=stats, **TINY)
    wall = time.perf_counter() - start
    phases = stats["phases"]
    assert stats["counts"]["compiled"] >= 1
    assert phases["compile"] > phases["build"] and phases["compile"] > 0.01, phases
    assert phases["compile"] + phases["build"] <= stats["build_seconds"] + 1e-3
    assert sum(phases.values()) <= wall and min(phases.values()) >= 0
    assert listening and sum(listening) == 0
    stats = {}
    with pytest.raises(ptrace.PtraceError):
        ptrace.render(cow, threads=0, stats=stats, **TINY)
    assert sum(listening) == 0 and stats["phases"]["render"] == 0


def test_union_seconds():
    assert pr.union_seconds([]) == 0
    assert pr.union_seconds([(2.0, 3.0), (0.0, 1.0)]) == pytest.approx(2.0)
    assert pr.union_seconds([(0.0, 1.0), (0.5, 2.0), (3.0, 4.0), (3.5, 3.6)]) == \
        pytest.approx(3.0)
    assert pr.union_seconds([(0.0, 5.0), (1.0, 2.0), (2.0, 6.0)]) == pytest.approx(6.0)


def test_wall_phases_add_up_to_the_wall_time(cow):
    original = wavefront.Wavefront.trace
    plain = ptrace.render(cow, threads=2, accel="bvh", **TINY)
    run = pr.timed_render(cow, 2, accel="bvh", **TINY)
    assert wavefront.Wavefront.trace is original
    assert np.array_equal(run.image, plain)
    phases = run.phases()
    assert list(phases) == list(pr.WALL_PHASES)
    assert sum(phases.values()) == pytest.approx(run.wall, rel=1e-9)
    assert min(phases.values()) >= -1e-6, phases     # the calls lie inside the passes
    assert run.calls == pr.planned_blocks(PIXELS, TINY["spp"]) == 1
    assert run.calls == run.stats["counts"]["kernel_calls"]
    assert 0 < run.thread_seconds <= 2 * run.span + 1e-6
    assert run.rays > PIXELS * TINY["spp"]


def test_planned_blocks_match_the_calls_of_a_render(cow):
    options = dict(TINY, spp=20, max_depth=1, resolution=(40, 30))   # passes of 16 and 4
    run = pr.timed_render(cow, 2, accel="bvh", **options)
    from ptrace.rendering.tiles import BLOCK_PATHS
    by_hand = -(-1200 // (BLOCK_PATHS // 16)) + -(-1200 // (BLOCK_PATHS // 4))   # 5 + 2 today
    assert run.calls == pr.planned_blocks(1200, 20) == by_hand
    assert 0 < run.busy <= 1 + 1e-6


def test_the_wrapper_is_put_back_when_the_render_fails(cow, monkeypatch):
    def failing(*args):
        raise RuntimeError("kernel failed")

    monkeypatch.setattr(wavefront.Wavefront, "trace", failing)
    closest = wavefront.closest_stage
    with pytest.raises(RuntimeError, match="kernel failed"):
        pr.timed_render(cow, 2, stages=pr.StageClock(), accel="bvh", **TINY)
    assert wavefront.Wavefront.trace is failing and wavefront.closest_stage is closest


def test_the_stage_clock_times_every_stage_counts_every_ray_and_changes_no_pixel(cow):
    stats = {}
    options = dict(TINY, accel="bvh")
    plain = ptrace.render(cow, threads=2, stats=stats, **options)
    factories = pr.STAGES + ("hit_stage", "light_stage", "shading_stage")
    saved = [getattr(wavefront, name) for name in factories]
    run = pr.timed_render(cow, 2, stages=pr.StageClock(), **options)
    assert [getattr(wavefront, name) for name in factories] == saved
    assert np.array_equal(run.image, plain)
    clock = run.stages
    assert {"camera_stage", "closest_stage", "hit_stage", "light_stage", "shading: diffuse",
            "any_stage", "shadow_stage", "fold_stage", "add_stage"} <= set(clock.seconds)
    assert clock.items["camera_stage"] == PIXELS * TINY["spp"]
    # every ray traced went through a trace stage: camera and bounce rays the closest hit's,
    # shadow rays the any hit's
    traced = sum(clock.items.get(name, 0) for name in pr.TRACE_STAGES)
    assert traced == stats["rays"] == run.rays
    assert clock.items["closest_stage"] > PIXELS * TINY["spp"] and clock.items["any_stage"] > 0
    rows = pr.stage_rows(run)
    assert rows[-1][3] == pytest.approx(run.thread_seconds)
    assert sum(row[3] for row in rows[:-1]) == pytest.approx(run.thread_seconds)
    assert all(row[3] > 0 for row in rows[:-2])
    assert 0 < pr.accelerator_seconds(run) < run.thread_seconds


def test_the_differencing_rows_add_up():
    loop = {"normals": 1.0, "m0": 1.5, "m1": 3.0, "full": 7.0}
    rays = {"normals": 100, "m0": 100, "m1": 250, "full": 600}
    rows = pr.ladder_rows(loop, rays)
    assert [r[1] for r in rows] == [100, 0, 150, 350, 600]
    assert [r[2] for r in rows] == pytest.approx([1.0, 0.5, 1.5, 4.0, 7.0])


def table(section, first_header_cell):
    """The rows (lists of cells) of the table whose header starts with first_header_cell."""
    lines = section.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"| {first_header_cell}"))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def number(cell):
    assert re.fullmatch(r"-?[0-9][0-9,]*(\.[0-9]+)?", cell), cell
    return float(cell.replace(",", ""))


@pytest.mark.slow   # a few seconds
def test_quick_report(tmp_path, monkeypatch, scenes_dir):
    monkeypatch.setenv("PTRACE_SCENES", str(scenes_dir))
    monkeypatch.setattr(report, "RESULTS", tmp_path)
    build = accel.build

    def embree_fails(kind, geometry, **options):
        if kind == "embree":
            raise RuntimeError("embree is being rewritten")
        return build(kind, geometry, **options)

    monkeypatch.setattr(accel, "build", embree_fails)
    names = ["cow -s 64 -l 16 -m 6 (bvh)", "cow -s 64 -l 16 -m 6 (embree)",
             "cow normals -s 1 (bvh)"]
    threads = numba.get_num_threads()
    original = wavefront.Wavefront.trace
    path = pr.main(["--quick", "--resolution", "32x24", "--only", *names, "--output", "p.md"])
    assert numba.get_num_threads() == threads and wavefront.Wavefront.trace is original
    assert accel.build is embree_fails
    assert path == tmp_path / "p.md"
    text = path.read_text()
    assert text.startswith("# ") and "- command: `" in text and "Method." in text

    summary = table(text.split("## Summary", 1)[1], "command")
    assert [(row[0], row[1]) for row in summary] == [
        ("cow -s 64 -l 16 -m 6", "bvh"), ("cow -s 64 -l 16 -m 6", "embree"),
        ("cow normals -s 1", "bvh")]
    assert summary[1][2] == "skipped"
    embree = text.split("## cow -s 64 -l 16 -m 6 (embree)\n", 1)[1].split("\n## ", 1)[0]
    assert 'Skipped: `accel="embree"` failed (RuntimeError: embree is being rewritten).' in embree

    for name in (names[0], names[2]):
        section = text.split(f"## {name}\n", 1)[1].split("\n## ", 1)[0]
        assert "32x24" in section and "profiled and un-profiled images identical" in section
        wall = table(section, "phase")
        assert [row[0] for row in wall] == list(pr.WALL_PHASES) + [
            "total: wall time of ptrace.render"]
        seconds = [number(row[1]) for row in wall]
        assert abs(sum(seconds[:-1]) - seconds[-1]) <= 0.0005 * len(seconds), name
        assert abs(sum(number(row[2]) for row in wall[:-1]) - 100) <= 0.05 * len(wall), name
        stages = table(section, "stage")
        assert stages[-2][0] == pr.BETWEEN and stages[-1][0] == "total: the loop"
        seconds = [number(row[3]) for row in stages]
        assert abs(sum(seconds[:-1]) - seconds[-1]) <= 0.0005 * len(seconds), name
        traced = re.search(r"their rays ([0-9,]+) = rays traced ([0-9,]+)\.", section)
        assert traced and number(traced[1]) == number(traced[2]), name
        slowest = [line for line in section.splitlines() if line[:3] in ("1. ", "2. ", "3. ")]
        assert len(slowest) == 3 and all(re.search(r"\(measured\)$", line)
                                         for line in slowest), name
        shares = [float(re.search(r", ([0-9.]+)% of wall", line)[1]) for line in slowest]
        assert shares == sorted(shares, reverse=True)

    full = text.split(f"## {names[0]}\n", 1)[1].split("\n## ", 1)[0]
    loop = table(full, "part of the path loop")
    assert len(loop) == len(pr.LADDER) + 1
    assert [row[0] for row in loop[:-1]] == [label for _, label in pr.LADDER]
    parts = [number(row[2]) for row in loop]
    assert abs(sum(parts[:-1]) - parts[-1]) <= 0.0005 * len(parts)
    assert number(loop[1][1]) == 0 and number(loop[0][1]) == 32 * 24 * 4   # -s 64 / 16
    assert sum(number(row[1]) for row in loop[:-1]) == number(loop[-1][1])
    stages = {row[0]: row for row in table(full, "stage")}
    assert number(stages["camera_stage"][2]) == 32 * 24 * 4
    assert number(stages["closest_stage"][2]) + number(stages["any_stage"][2]) == \
        number(loop[-1][1])
    normals = text.split(f"## {names[2]}\n", 1)[1].split("\n## ", 1)[0]
    assert "part of the path loop" not in normals
    stages = {row[0]: row for row in table(normals, "stage")}
    assert number(stages["closest_stage"][2]) == 32 * 24
    assert "any_stage" not in stages and "hit_stage" not in stages
