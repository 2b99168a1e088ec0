"""The package layout: the commands in ptrace.app, the render job in ptrace.rendering, and the
modules' old names (ptrace.cli, ptrace.settings, ...) still importable, as the same module
objects, with one DeprecationWarning each that names the new path."""
import ast
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
    """jit keys cached kernels on every source under a kernels' folder: an edit in a subfolder
    (as ptrace/kernel/) changes the key too."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub" / "b.py").write_text("y = 1\n")
    before = jit._folders_digest([str(tmp_path)])
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    assert jit._folders_digest([str(tmp_path)]) != before


COMPILERS = {"njit", "jit", "cfunc", "vectorize", "guvectorize", "generated_jit"}


def compiled(function):
    """Whether an ast function definition carries a numba decorator (njit, numba.njit(...))."""
    for decorator in function.decorator_list:
        target = decorator.func if isinstance(decorator, ast.Call) else decorator
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name in COMPILERS:
            return True
    return False


def test_an_edit_where_no_kernel_lives_recompiles_nothing(tmp_path):
    """jit.KERNEL_FREE (ptrace/io, app, rendering) stays out of the cache key, so an edit to a
    loader or the command line loads the cached kernels: right only while no compiled function
    is defined there and no compiled function elsewhere reads a name imported from there."""
    package = ROOT / "ptrace"
    free = [package / name for name in jit.KERNEL_FREE]
    for folder in free:
        for path in folder.rglob("*.py"):
            defined = [node.name for node in ast.walk(ast.parse(path.read_text()))
                       if isinstance(node, ast.FunctionDef) and compiled(node)]
            assert not defined, f"{path} defines compiled {defined}"
    kernel_sources = [path for folder in (package, ROOT / "accel") for path in folder.rglob("*.py")
                      if not any(folder in path.parents for folder in free)]
    read = 0
    for path in kernel_sources:
        tree = ast.parse(path.read_text())
        imported = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                parts = node.module.split(".")
                inside = parts[0] in jit.KERNEL_FREE if node.level else (
                    parts[0] == "ptrace" and len(parts) > 1 and parts[1] in jit.KERNEL_FREE)
                if inside:
                    imported |= {alias.asname or alias.name for alias in node.names}
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef) and compiled(node):
                used = {name.id for name in ast.walk(node) if isinstance(name, ast.Name)}
                assert not used & imported, f"{path}: {node.name} reads {used & imported}"
                read += 1
    assert read > 100     # the compiled functions were found
    for name in jit.KERNEL_FREE + ("kernel",):
        (tmp_path / name).mkdir()
        (tmp_path / name / "a.py").write_text("x = 1\n")
    before = jit._folders_digest([str(tmp_path)])
    for name in jit.KERNEL_FREE:
        (tmp_path / name / "a.py").write_text("x = 2\n")
    assert jit._folders_digest([str(tmp_path)]) == before
    (tmp_path / "kernel" / "a.py").write_text("x = 2\n")
    assert jit._folders_digest([str(tmp_path)]) != before
