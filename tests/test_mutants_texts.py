"""tests/mutants.py plants each bug by replacing a text that must occur exactly once in its file:
an edit of the code can silently move a mutant's text away (it happened to no-tmax-shrink when the
BVH's pop compare was renamed), and the mutation check then stops before planting anything."""
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_every_mutant_text_is_found_once():
    result = subprocess.run([sys.executable, str(ROOT / "tests" / "mutants.py"), "--check"],
                            cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "every text found exactly once" in result.stdout
