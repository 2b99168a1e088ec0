"""Over 200 generated malformed scene files: each ends in one line, exit code 2, within 2 s and
bounded memory, and leaves no output file. In-process through ptrace.cli.main for the corpus,
and through the real console script for a sample of it."""
import pathlib
import subprocess
import sys
import time
import tracemalloc

import pytest

from ptrace.cli import main

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
def test_every_malformed_file_fails_cleanly(tmp_path, cases, capsys):
    assert len(cases) >= 200
    slowest = (0.0, "")
    for name, text in cases:
        scene = tmp_path / f"{name}.dae"
        scene.write_text(text)
        output = tmp_path / "out.png"
        arguments = ["-q", "--integrator", "normals", "-r", "8", "6", "-f", str(output), str(scene)]
        start = time.perf_counter()
        code = main(arguments)
        seconds = time.perf_counter() - start
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        tracemalloc.start()     # a second run for memory: tracemalloc slows what it watches
        main(arguments)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        capsys.readouterr()
        assert code == 2, f"{name}: exit {code}, stderr {captured.err!r}"
        assert len(lines) == 1 and lines[0].startswith("ptrace: error: "), f"{name}: {lines}"
        assert "Traceback" not in captured.err
        assert seconds < 2.0, f"{name}: {seconds:.2f} s"
        assert peak < MEMORY_LIMIT, f"{name}: {peak / 2 ** 20:.0f} MiB"
        assert not output.exists() and not list(tmp_path.glob("*.png")), name
        slowest = max(slowest, (seconds, name))
        scene.unlink()
    print(f"{len(cases)} malformed files, slowest {slowest[1]} in {slowest[0]:.3f} s")


@pytest.mark.slow
def test_a_sample_through_the_console_script(tmp_path, cases):
    names = {"entity-bomb", "external-entity"}
    sample = [c for c in cases if c[0] in names or c[0].startswith(("truncated-0", "deeply_nested-0",
                                                                     "huge_count-0"))]
    assert len(sample) == 5
    for name, text in sample:
        scene = tmp_path / f"{name}.dae"
        scene.write_text(text)
        start = time.perf_counter()
        result = subprocess.run([sys.executable, "-m", "ptrace", "--info", str(scene)],
                                capture_output=True, text=True, timeout=60)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1, (name, result.stderr)
        assert time.perf_counter() - start < 10   # process start-up included
