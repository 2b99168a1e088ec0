"""Every relative link in the README and docs/ points at a file that exists, and the README
keeps its two set-up-and-go commands (the render and the tests) and stays short."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\]\(([^)#\s]+)(#[^)]*)?\)")


def documents():
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def test_every_relative_link_resolves():
    missing = []
    for path in documents():
        for match in LINK.finditer(path.read_text()):
            target = match.group(1)
            if target.startswith(("http://", "https://", "mailto:")):
                continue
            if not (path.parent / target).exists():
                missing.append(f"{path.relative_to(ROOT)}: {target}")
    assert not missing, missing


def test_the_readme_has_its_two_commands_and_fits_on_two_screens():
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```sh\n(.*?)```", text, re.S)
    assert "pip install -e . && ptrace " in blocks[0] and "scenes/cornell.dae" in blocks[0]
    assert blocks[1].strip() == ('python3 -m venv .venv && . .venv/bin/activate && pip install '
                                 '-q -e ".[test]" && python -m pytest -q')
    assert len(text.splitlines()) <= 160
