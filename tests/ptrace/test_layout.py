"""The package layout: the commands in ptrace.app, the render job in ptrace.rendering (at those
paths only), the public API, the console script, and what the kernel cache's key covers."""
import ast
import subprocess
import sys
from pathlib import Path

import pytest

import ptrace
from ptrace import jit

ROOT = Path(__file__).resolve().parents[2]

# the modules that moved into ptrace.app and ptrace.rendering, now at their new paths only
MOVED = {f"ptrace.{name}": f"ptrace.app.{name}" for name in (
    "cli", "cli_camera", "options", "view", "view_messages", "view_render", "view_session")}
MOVED.update({f"ptrace.{name}": f"ptrace.rendering.{name}" for name in (
    "distributed", "executors", "renderer", "settings", "tiles", "timing")})


def test_every_moved_module_lives_at_its_new_path_only():
    for old, new in MOVED.items():
        assert (ROOT / (new.replace(".", "/") + ".py")).is_file(), new
        assert not (ROOT / (old.replace(".", "/") + ".py")).exists(), old
        with pytest.raises(ModuleNotFoundError):
            __import__(old)
    assert (ROOT / "ptrace" / "app" / "view_page.html").is_file()


def test_the_public_api_and_a_pickled_settings():
    import pickle
    for name in ptrace.__all__:
        assert getattr(ptrace, name) is not None, name
    assert callable(ptrace.render) and ptrace.render.__module__ == "ptrace.rendering.renderer"
    assert ptrace.Settings.__module__ == "ptrace.rendering.settings"
    assert pickle.loads(pickle.dumps(ptrace.Settings(spp=3))) == ptrace.Settings(spp=3)


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
