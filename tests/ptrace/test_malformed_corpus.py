"""Over 200 generated malformed scene files: each ends in one line, exit code 2, with bounded
memory and before any rendering starts (work counts, not wall-clock limits: speed lives in
benchmarks/), and leaves no output file. In-process through ptrace.app.cli.main for the corpus, and
through the real console script for a sample of it."""
import pathlib
import subprocess
import sys
import tracemalloc

import pytest

import ptrace
from ptrace.app.cli import main

from malformed_corpus import corpus

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"
MEMORY_LIMIT = 256 * 2 ** 20


@pytest.fixture(scope="module")
def cases(scenes_dir):
    bases = [("cornell", SHIPPED.read_text()),
             ("cube", (scenes_dir / "simple/cube.dae").read_text()),
             ("CBspheres", (scenes_dir / "sky/CBspheres_lambertian.dae").read_text())]
    return corpus(bases, seed=184)


@pytest.mark.slow
def test_every_malformed_file_fails_cleanly(tmp_path, cases, capsys, monkeypatch):
    assert len(cases) >= 200
    loads, renders = [], []
    load = ptrace.load

    def counted_load(path, *args, **kwargs):
        loads.append(path)
        return load(path, *args, **kwargs)

    def no_render(scene, **options):   # a malformed file must be refused before this
        renders.append(scene.path)
        raise RuntimeError("a malformed scene reached the renderer")
    monkeypatch.setattr(ptrace, "load", counted_load)   # what ptrace.app.cli.run calls
    monkeypatch.setattr(ptrace, "render", no_render)
    largest = (0, "")
    for name, text in cases:
        scene = tmp_path / f"{name}.dae"
        scene.write_text(text)
        output = tmp_path / "out.png"
        arguments = ["-q", "--integrator", "normals", "-r", "8", "6", "-f", str(output), str(scene)]
        del loads[:]
        tracemalloc.start()
        try:
            code = main(arguments)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        captured = capsys.readouterr()
        assert len(loads) == 1 and renders == [], (name, loads, renders, captured.err)
        lines = captured.err.strip().splitlines()
        assert code == 2, f"{name}: exit {code}, stderr {captured.err!r}"
        assert len(lines) == 1 and lines[0].startswith("ptrace: error: "), f"{name}: {lines}"
        assert "Traceback" not in captured.err
        assert peak < MEMORY_LIMIT, f"{name}: {peak / 2 ** 20:.0f} MiB"
        assert not output.exists() and not list(tmp_path.glob("*.png")), name
        largest = max(largest, (peak, name))
        scene.unlink()
    print(f"{len(cases)} malformed files, largest peak {largest[1]} at "
          f"{largest[0] / 2 ** 20:.1f} MiB")


@pytest.mark.slow
def test_a_sample_through_the_console_script(tmp_path, cases):
    names = {"entity-bomb", "external-entity"}
    prefixes = ("truncated-0", "deeply_nested-0", "huge_count-0")
    sample = [c for c in cases if c[0] in names or c[0].startswith(prefixes)]
    assert len(sample) == 5
    for name, text in sample:
        scene = tmp_path / f"{name}.dae"
        scene.write_text(text)
        result = subprocess.run([sys.executable, "-m", "ptrace", "--info", str(scene)],
                                capture_output=True, text=True, timeout=300)   # a hang guard
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1, (name, result.stderr)
        assert lines[0].startswith("ptrace: error: ") and result.stdout == "", (name, result)
