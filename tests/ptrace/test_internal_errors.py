"""The README's promise that bugs are told apart from user errors: a PtraceError
(the user's input or flags) is one line on stderr and exit code 2; anything else escaping the CLI is
`ptrace: internal error: ...` with its traceback and exit code 1. (A Dask tile task's side of this
is in test_distributed.py.)"""
import os
import pathlib
import subprocess
import sys

import pytest

from ptrace.app import cli
from ptrace.app.options import EXIT_INTERNAL, EXIT_USAGE
from ptrace.errors import PtraceError
from ptrace.rendering import tiles

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"


def planted_bug(*args, **kwargs):
    raise RuntimeError("planted bug in the tile work")


def test_a_bug_in_the_render_is_an_internal_error_with_its_traceback(tmp_path, monkeypatch,
                                                                     capsys):
    monkeypatch.setattr(tiles.TileWork, "trace", planted_bug)
    output = tmp_path / "out.png"
    code = cli.main(["-q", "-r", "8", "6", "-f", str(output), str(SHIPPED)])
    err = capsys.readouterr().err
    assert code == EXIT_INTERNAL == 1, err
    lines = err.strip().splitlines()
    assert lines[0] == "ptrace: internal error: RuntimeError: planted bug in the tile work"
    assert "Traceback (most recent call last):" in err
    assert "in planted_bug" in err and f'{os.path.join("ptrace", "app", "cli.py")}", line' in err
    assert "bug in ptrace" in lines[-1] and "report" in lines[-1]
    assert "ptrace: error:" not in err
    assert list(tmp_path.iterdir()) == []   # nothing written


def test_a_user_error_from_the_same_place_stays_one_line(tmp_path, monkeypatch, capsys):
    def refuse(*args, **kwargs):
        raise PtraceError("something the user can fix")
    monkeypatch.setattr(tiles.TileWork, "trace", refuse)
    code = cli.main(["-q", "-r", "8", "6", "-f", str(tmp_path / "out.png"), str(SHIPPED)])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE == 2
    assert err.strip().splitlines() == ["ptrace: error: something the user can fix"]


@pytest.mark.parametrize("error", [KeyError("geometry"), AttributeError("no attribute 'x'"),
                                   ZeroDivisionError("division by zero"),
                                   MemoryError("out of memory")])
def test_any_other_exception_is_internal(tmp_path, monkeypatch, capsys, error):
    def fail(*args, **kwargs):
        raise error
    monkeypatch.setattr(tiles.TileWork, "trace", fail)
    code = cli.main(["-q", "-r", "8", "6", "-f", str(tmp_path / "out.png"), str(SHIPPED)])
    err = capsys.readouterr().err
    assert code == 1, err
    assert err.startswith(f"ptrace: internal error: {type(error).__name__}: ")
    assert "Traceback (most recent call last):" in err


def test_the_console_entry_exits_1_with_the_traceback(tmp_path):
    """The real entry point (python -m ptrace, as the console script calls cli.main) in a fresh
    process, with a bug planted before it runs."""
    code = ("import runpy, sys; from ptrace.rendering import tiles\n"
            "def planted_bug(*args, **kwargs):\n"
            "    raise RuntimeError('planted bug in the tile work')\n"
            "tiles.TileWork.trace = planted_bug\n"
            f"sys.argv = ['ptrace', '-q', '-r', '8', '6', '-f', {str(tmp_path / 'x.png')!r}, "
            f"{str(SHIPPED)!r}]\n"
            "runpy.run_module('ptrace', run_name='__main__')\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=600)
    assert result.returncode == 1, result.stderr
    lines = result.stderr.strip().splitlines()
    assert lines[0] == "ptrace: internal error: RuntimeError: planted bug in the tile work"
    assert "Traceback (most recent call last):" in result.stderr
    assert 'line 3, in planted_bug' in result.stderr
    assert not (tmp_path / "x.png").exists()
