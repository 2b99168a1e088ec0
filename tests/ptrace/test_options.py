"""ptrace and ptrace view read their flags through one module (ptrace.app.options): the same bad
flag gets the same one line and exit code 2 from both, before any scene is read, and a good set
of flags gives both commands the same Settings."""
import pathlib

import pytest

from ptrace.app import cli, options, view

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"


@pytest.mark.parametrize("flags", [
    ["-a", "0", "0.1"], ["-a", "4", "nan"], ["-a", str(2 ** 40), "0.1"],
    ["-f", "{tmp}/missing/x.png"], ["-f", "{tmp}/x.jpg"], ["-s", "0"],
    ["--bvh-split", "sah", "--accel", "naive"], ["-s", str(2 ** 20), "-l", str(2 ** 13)],
    ["-p", "0", "0", "900", "1"], ["--look-at", "0,1,0"], ["--max-memory", "lots"],
])
def test_the_same_bad_flag_is_the_same_line_from_both_commands(flags, tmp_path, capsys):
    flags = [flag.replace("{tmp}", str(tmp_path)) for flag in flags]
    if "-f" not in flags:
        flags += ["-f", str(tmp_path / "x.png")]
    lines = []
    for argv in ([str(SHIPPED)] + flags, ["view", str(SHIPPED), "--no-browser"] + flags):
        assert cli.main(argv) == options.EXIT_USAGE == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("ptrace: error: "), err
        lines.append(err)
    assert lines[0] == lines[1]
    assert list(tmp_path.iterdir()) == []


def test_both_commands_read_the_same_settings(tmp_path):
    flags = ["-s", "8", "-l", "2", "-m", "3", "-a", "4", "0.05", "--seed", "7", "--direct",
             "light", "--sampler", "independent", "--light-sampler", "power", "--bvh-split",
             "sah", "-f", str(tmp_path / "x.exr"), str(SHIPPED)]
    args = options.parse(options.build_parser(), flags)
    job = options.plan(args, lambda output: [output])
    _, settings, _, outputs = view.prepare(view.parse(flags))
    assert settings == job.settings
    assert (settings.spp, settings.adaptive, settings.sampler) == (8, (4, 0.05), "independent")
    assert outputs == (str(tmp_path / "x.png"), str(tmp_path / "x.exr"))
    assert job.output == str(tmp_path / "x.exr") and job.files == [job.output]


def test_a_usage_error_is_one_line_and_a_bug_is_an_internal_error(capsys):
    def bad_flag():
        raise options.UsageError("argument -s: bad")

    def bug():
        raise KeyError("planted")
    assert options.guarded(bad_flag) == 2
    assert capsys.readouterr().err == "ptrace: error: argument -s: bad\n"
    assert options.guarded(bug) == options.EXIT_INTERNAL == 1
    err = capsys.readouterr().err
    assert err.startswith("ptrace: internal error: KeyError: 'planted'\n")
    assert "Traceback (most recent call last):" in err and "bug in ptrace" in err
