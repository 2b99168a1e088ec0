"""The package layout: the commands in ptrace.app, the render job in ptrace.rendering, and the
modules' old names (ptrace.cli, ptrace.settings, ...) still importable, as the same module
objects, with one DeprecationWarning each that names the new path."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

import ptrace
from ptrace import _moved, jit

ROOT = Path(__file__).resolve().parents[2]

# Run in a fresh process: an old name warns only the first time it is imported in a process.
PROBE = r"""
import importlib, json, pickle, sys, warnings
import ptrace
from ptrace import _moved
out = {}
for old, new in sorted(_moved.MOVED.items()):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        module = importlib.import_module(old)
        again = importlib.import_module(old)
    out[old] = {"same": module is importlib.import_module(new) and again is module,
                "name": module.__name__,
                "warnings": [(w.category.__name__, str(w.message)) for w in caught]}
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    sys.modules.pop("ptrace.settings"); del ptrace.settings
    from ptrace.settings import Settings        # this line is the one the warning names
out["from"] = {"same": Settings is ptrace.Settings,
               "where": [(w.filename, w.lineno) for w in caught]}
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    sys.modules.pop("ptrace.renderer"); del ptrace.renderer
    attribute = ptrace.renderer
out["attribute"] = {"same": attribute is sys.modules["ptrace.rendering.renderer"],
                    "warnings": len(caught)}
out["pickle"] = pickle.loads(pickle.dumps(ptrace.Settings(spp=3))) == ptrace.Settings(spp=3)
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def probed():
    run = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout.strip().splitlines()[-1])


def test_every_moved_module_lives_at_its_new_path_only():
    assert len(_moved.MOVED) == 13
    for old, new in _moved.MOVED.items():
        assert (ROOT / (new.replace(".", "/") + ".py")).is_file(), new
        assert not (ROOT / (old.replace(".", "/") + ".py")).exists(), old
    assert (ROOT / "ptrace" / "app" / "view_page.html").is_file()


def test_an_old_name_is_the_new_module_and_warns_once(probed):
    for old, new in _moved.MOVED.items():
        seen = probed[old]
        assert seen["same"] and seen["name"] == new, (old, seen)
        assert seen["warnings"] == [["DeprecationWarning",
                                     f"{old} has moved to {new}; import it from there (the old "
                                     f"name is deprecated)"]], (old, seen)


def test_the_warning_names_the_line_that_used_the_old_name(probed):
    assert probed["from"]["same"]
    assert probed["from"]["where"] == [["<string>", PROBE.splitlines().index(
        "    from ptrace.settings import Settings        # this line is the one the warning "
        "names") + 1]]


def test_an_old_name_as_an_attribute_of_the_package(probed):
    assert probed["attribute"] == {"same": True, "warnings": 1}
    with pytest.raises(AttributeError, match="has no attribute 'no_such_module'"):
        ptrace.no_such_module   # only moved names answer


def test_the_public_api_is_unchanged(probed):
    for name in ptrace.__all__:
        assert getattr(ptrace, name) is not None, name
    assert callable(ptrace.render) and ptrace.render.__module__ == "ptrace.rendering.renderer"
    assert ptrace.Settings.__module__ == "ptrace.rendering.settings"
    assert probed["pickle"]


def test_a_name_that_never_existed_is_not_found():
    with pytest.raises(ModuleNotFoundError):
        __import__("ptrace.no_such_module")


def test_the_viewer_page_is_package_data():
    from ptrace.app import view
    assert "ptraceView" in view.page()


def test_the_console_script_and_python_m_call_the_same_main():
    text = (ROOT / "pyproject.toml").read_text()
    assert 'ptrace = "ptrace.app.cli:main"' in text
    run = subprocess.run([sys.executable, "-m", "ptrace", "--help"], capture_output=True,
                         text=True, timeout=300, cwd=ROOT)
    assert run.returncode == 0 and run.stdout.startswith("usage: ptrace"), run.stderr


def test_the_kernel_cache_key_covers_the_subpackages(tmp_path):
    """jit keys cached kernels on every source under ptrace/: an edit in a subfolder (as
    ptrace/rendering/) changes the key too."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub" / "b.py").write_text("y = 1\n")
    before = jit._folders_digest([str(tmp_path)])
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    assert jit._folders_digest([str(tmp_path)]) != before
