"""Hostile paths and numbers at the edge (the README's promise: an error a user can cause is one
line and exit code 2): a FIFO, a device or a directory as the scene, -e or -c file is refused
before anything opens it (a FIFO would block the reader for ever); numbers beyond what the
kernels' int64 and the machine's memory allow are refused with the flag and its range, in the
CLI and in the Python API alike; a camera file whose rotation is degenerate is refused naming the
file."""
import os
import subprocess
import sys

import numpy as np
import pytest

import ptrace
from ptrace.app import cli
from ptrace.camera import load_camera_settings
from ptrace.rendering.renderer import MAX_SIDE
from ptrace.rendering.settings import RANGES, Settings

from console import SHIPPED, ptrace_command


def one_line(capsys, *args):
    """(exit code, the one stderr line) of the CLI run in this process; fails on more lines."""
    code = cli.main([str(a) for a in args])
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return code, lines[0]


@pytest.fixture
def fifo(tmp_path):
    path = tmp_path / "pipe.dae"
    os.mkfifo(path)
    return path


@pytest.mark.parametrize("place", ["scene", "-e", "-c"])
def test_a_fifo_is_refused_without_opening_it(tmp_path, fifo, place):
    """In a subprocess with a timeout: opening a FIFO with no writer blocks, so a regression
    shows as a timeout, not as a hung test run."""
    args = [fifo] if place == "scene" else [place, fifo, SHIPPED]
    result = subprocess.run(ptrace_command() + ["-q", "-f", str(tmp_path / "x.png")]
                            + [str(a) for a in args], capture_output=True, text=True,
                            timeout=120, stdin=subprocess.DEVNULL)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert str(fifo) in lines[0] and "FIFO" in lines[0] and "regular file" in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe.dae"]


@pytest.mark.parametrize("place", ["scene", "-e", "-c"])
@pytest.mark.parametrize("path, kind", [("/dev/null", "device"), ("/", "directory")])
def test_a_device_or_directory_is_refused(tmp_path, capsys, place, path, kind):
    args = [path] if place == "scene" else [place, path, SHIPPED]
    code, line = one_line(capsys, "-q", "-f", tmp_path / "x.png", *args)
    assert code == 2 and line.startswith(f"ptrace: error: {path}:") and kind in line, line


def test_dev_stdin_is_refused(tmp_path):
    result = subprocess.run(ptrace_command() + ["-q", "-f", str(tmp_path / "x.png"),
                                                "/dev/stdin"], stdin=subprocess.PIPE,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "/dev/stdin" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


BIG = 99999999999999999999
INT64_PAST = 2 ** 63


@pytest.mark.parametrize("args, flag, high", [
    (["--seed", BIG], "--seed", RANGES["seed"][1]),
    (["-s", BIG, "-p", 0, 0, 1, 1], "-s", RANGES["spp"][1]),
    (["-l", INT64_PAST], "-l", RANGES["light_samples"][1]),
    (["-m", INT64_PAST], "-m", RANGES["max_depth"][1]),
    (["-r", 2 ** 63 - 1, 1], "-r", MAX_SIDE),
    (["-a", BIG, 0.1], "-a", RANGES["spp"][1]),
])
def test_numbers_beyond_their_range_name_the_flag_and_the_range(tmp_path, capsys, args, flag,
                                                                high):
    code, line = one_line(capsys, "-q", "-f", tmp_path / "x.png", *args, SHIPPED)
    assert code == 2 and f"({flag})" in line and f"to {high}," in line, line
    assert list(tmp_path.iterdir()) == []


def test_a_resolution_beyond_memory_says_how_much_it_would_need(tmp_path, capsys):
    code, line = one_line(capsys, "-q", "-f", tmp_path / "x.png", "-r", 100000, 100000,
                          SHIPPED)
    assert code == 2 and "image buffers would need" in line and "GiB" in line, line
    assert list(tmp_path.iterdir()) == []


def test_a_tiny_memory_budget_says_the_buffers_in_a_unit_that_shows_them(tmp_path, capsys):
    """--max-memory 1: the buffers of a 48-pixel image are a few KiB, not "0.0 GiB"."""
    code, line = one_line(capsys, "-q", "-f", tmp_path / "x.png", "-r", 8, 6, "--max-memory", 1,
                          SHIPPED)
    assert code == 2 and "48-pixel" in line and "KiB" in line and "0.0 " not in line, line
    assert list(tmp_path.iterdir()) == []


def test_the_range_is_in_the_help():
    text = cli.build_parser().format_help()
    for low, high in (RANGES["seed"], RANGES["max_depth"], RANGES["light_samples"]):
        assert f"{low} to {high:_}" in text or f"{low} to {high}" in text


@pytest.mark.parametrize("keywords", [
    dict(seed=2 ** 64), dict(seed=-1), dict(spp=BIG), dict(spp=0), dict(spp=2.0),
    dict(light_samples=INT64_PAST), dict(max_depth=INT64_PAST), dict(max_depth=True),
    dict(spp=2 ** 20, light_samples=2 ** 13), dict(adaptive=(BIG, 0.1)),
    dict(adaptive=(4, float("nan"))), dict(rr_cap=float("nan")),
])
def test_the_python_api_refuses_the_same_numbers(keywords):
    with pytest.raises(ptrace.PtraceError):
        Settings.from_options(**keywords)


def test_render_refuses_a_resolution_past_the_side_limit_or_memory():
    scene = ptrace.load(SHIPPED)
    for resolution in ((MAX_SIDE + 1, 1), (2 ** 63 - 1, 1), (100000, 100000), (4.5, 3)):
        with pytest.raises(ptrace.PtraceError, match="resolution|GiB"):
            ptrace.render(scene, resolution=resolution)


def test_settings_at_the_ends_of_their_ranges_are_accepted():
    settings = Settings(seed=RANGES["seed"][1], spp=RANGES["spp"][1], light_samples=1,
                        max_depth=RANGES["max_depth"][1])
    assert settings.kernel_options().seed == 2 ** 63 - 1


def camera_file(path, rotation):
    numbers = [73.7, 60, 4 / 3, 0.01, 100, 5, 0, 0, 0, 0, 0, 1.5708, 1.5708, 5, 1, 50,
               *rotation, 800, 600, 519.6, 5, 0]
    path.write_text(" ".join(str(x) for x in numbers))
    return path


@pytest.mark.parametrize("rotation", [[0] * 9, [1, 0, 0, 1, 0, 0, 0, 0, 1],
                                      [2, 0, 0, 0, 2, 0, 0, 0, 2], [-1, 0, 0, 0, 1, 0, 0, 0, 1]])
def test_a_camera_file_with_a_degenerate_rotation_names_the_file(tmp_path, capsys, rotation):
    path = camera_file(tmp_path / "cam.txt", rotation)
    with pytest.raises(ptrace.PtraceError, match="cam.txt: .*rotation"):
        load_camera_settings(path, 800, 600)
    code, line = one_line(capsys, "-q", "-r", 8, 6, "-f", tmp_path / "x.png", "-c", path,
                          SHIPPED)
    assert code == 2 and "cam.txt" in line and "rotation" in line, line


def test_a_camera_file_with_a_rounded_rotation_is_accepted(tmp_path):
    """A rotation by 1 radian about +Y, written to six decimals as the course's dump does."""
    c, s = np.cos(1.0), np.sin(1.0)
    rotation = np.round([c, 0, s, 0, 1, 0, -s, 0, c], 6)
    camera = load_camera_settings(camera_file(tmp_path / "cam.txt", rotation), 800, 600)
    np.testing.assert_allclose(camera.camera_to_world.reshape(-1), rotation)


def test_the_cli_end_to_end_in_a_process(tmp_path):
    """One of the above through the console script (no traceback, exit 2)."""
    result = subprocess.run(ptrace_command() + ["--seed", str(BIG), str(SHIPPED)],
                            capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.count("\n") == 1 and "seed" in result.stderr
    assert sys.executable   # the console script ran beside this interpreter
