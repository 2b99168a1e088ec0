"""numba's cache handled (ptrace.jit): a cache file with garbage in it is recompiled with a note,
not an unpickling traceback; with no writable cache folder anywhere numba looks, ptrace still
imports and caches in a private per-user folder (or a fresh temporary one) with a note. Every
test runs in a subprocess on its own cache folder or a copy of the sources, so the suite's cache
is never touched, and compiles only a one-line function (or nothing)."""
import os
import pathlib
import shutil
import subprocess
import sys

import pytest

from ptrace import jit
from ptrace.app import cli

from console import SHIPPED

REPO = pathlib.Path(__file__).resolve().parents[2]
TINY = ("from numba import njit\n\n\n@njit(cache=True)\ndef add_one(x):\n    return x + 1\n\n\n"
        "@njit(cache=True)\ndef add_two(x):\n    return add_one(x) + 1\n")


def python(code, env, cwd):
    return subprocess.run([sys.executable, "-c", code], env=env, cwd=cwd, capture_output=True,
                          text=True, timeout=300)


@pytest.fixture
def tiny(tmp_path):
    """A module with one cached kernel, compiled once into its own cache folder."""
    (tmp_path / "mod").mkdir()
    (tmp_path / "mod" / "tiny.py").write_text(TINY)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path / "mod"), str(REPO)]))
    first = python("import tiny; print(tiny.add_two(0))", env, tmp_path)
    assert first.stdout.strip() == "2", first.stderr
    return env, tmp_path


WITH_PTRACE = ("import ptrace, tiny; print(tiny.add_two(0)); "
               "print('\\n'.join(ptrace.jit.cache_notes()))")


@pytest.mark.parametrize("pattern, garbage", [("*.nbi", b"\x80\x04\x95garbage"),
                                              ("*.nbc", b"garbage\n")])
def test_a_corrupt_cache_file_is_recompiled_with_a_note(tiny, pattern, garbage):
    env, folder = tiny
    files = list((folder / "cache").rglob(pattern))
    assert len(files) == 2     # add_one's and add_two's
    for path in files:
        path.write_bytes(garbage)
    plain = python("import tiny; print(tiny.add_two(0))", env, folder)
    assert plain.returncode != 0 and "Traceback" in plain.stderr   # numba alone: a traceback
    for path in files:
        path.write_bytes(garbage)   # (in case numba alone rewrote one)
    guarded = python(WITH_PTRACE, env, folder)
    assert guarded.returncode == 0 and "Traceback" not in guarded.stderr, guarded.stderr
    out = guarded.stdout.strip().splitlines()
    assert out[0] == "2"
    # one line for the kind, however many files
    assert len(out) == 2 and out[1].startswith("numba's cache: ") and "recompiling" in out[1]
    assert out[1].endswith("(and 1 more files like it)"), out[1]
    again = python("import tiny; print(tiny.add_two(0))", env, folder)   # rewritten whole
    assert again.returncode == 0 and again.stdout.strip() == "2", again.stderr


def unwritable_copy(tmp_path):
    """ptrace and accel copied where numba finds no cache folder: each package's __pycache__
    is a file (so it cannot be made, even by root), HOME's .cache is a file, no NUMBA_CACHE_DIR,
    and TMPDIR a folder of the test's own."""
    copy = tmp_path / "copy"
    for package in ("ptrace", "accel"):
        shutil.copytree(REPO / package, copy / package,
                        ignore=shutil.ignore_patterns("__pycache__"))
    for folder in [p for p in copy.rglob("*") if p.is_dir()] + [copy]:
        (folder / "__pycache__").write_text("not a folder")
    (tmp_path / "home").mkdir()
    (tmp_path / "home" / ".cache").write_text("not a folder")
    (tmp_path / "tmp").mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME")}
    env.update(HOME=str(tmp_path / "home"), PYTHONPATH=str(copy), PYTHONDONTWRITEBYTECODE="1",
               TMPDIR=str(tmp_path / "tmp"))
    return copy, env


IMPORT_AND_RUN = ("import ptrace, ptrace.sampling as s; print(ptrace.__file__); "
                  "print(s.uniform(1, 2, 3, 4)); print('\\n'.join(ptrace.jit.cache_notes()))")


def test_no_writable_cache_folder_falls_back_to_a_private_one(tmp_path):
    copy, env = unwritable_copy(tmp_path)
    result = python(IMPORT_AND_RUN, env, tmp_path)
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    path, number, note = result.stdout.strip().splitlines()
    assert path.startswith(str(copy))
    assert 0.0 <= float(number) < 1.0
    folder = tmp_path / "tmp" / f"ptrace-numba-{os.getuid()}"
    assert note.startswith("numba's cache: no writable folder") and str(folder) in note
    assert "this run only" not in note
    assert list(folder.rglob("*.nbi"))   # the kernel was cached there
    assert folder.stat().st_mode & 0o777 == 0o700


def test_a_private_folder_that_is_not_ours_is_not_used(tmp_path):
    """A file (or another user's folder) at the private folder's name: a fresh temporary
    folder is used instead, for this run only."""
    copy, env = unwritable_copy(tmp_path)
    (tmp_path / "tmp" / f"ptrace-numba-{os.getuid()}").write_text("planted")
    result = python(IMPORT_AND_RUN, env, tmp_path)
    assert result.returncode == 0, result.stderr
    note = result.stdout.strip().splitlines()[-1]
    assert "for this run only" in note and str(tmp_path / "tmp" / "ptrace-numba-") in note


def test_the_cli_says_a_cache_note_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(jit, "_NOTES", {})
    jit._note("numba's cache: a test note")
    code = cli.main(["--integrator", "normals", "-r", "4", "3", "-f", str(tmp_path / "x.png"),
                     str(SHIPPED)])
    err = capsys.readouterr().err
    assert code == 0
    assert err.count("numba's cache: a test note") == 1
    assert "ptrace: warning: numba's cache: a test note" in err.splitlines()
    assert jit.cache_notes() == []   # told once


CALLEE = ("from numba import njit\n\nSCALE = {scale}\n\n\n@njit(cache=True)\ndef scale(x):\n"
          "    return SCALE * x\n")
CALLER = ("from numba import njit\n\nfrom kernels.callee import scale\n\n\n@njit(cache=True)\n"
          "def twice_scaled(x):\n    return 2 * scale(x)\n")
RUN_CALLER = ("import ptrace.jit, os; ptrace.jit.depend_on_folders([os.path.abspath('kernels')]); "
              "import kernels.caller as c; print(c.twice_scaled(1))")


def test_an_edit_to_a_called_module_recompiles_its_callers(tmp_path):
    """numba's cache checks a kernel's own file only: after an edit to a module it calls, the
    caller's old compiled code (with the callee inlined) would be loaded. Under
    depend_on_folders (ptrace's and accel's folders on import) every source file counts."""
    package = tmp_path / "kernels"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "callee.py").write_text(CALLEE.format(scale=3))
    (package / "caller.py").write_text(CALLER)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(REPO)]))
    plain = "import kernels.caller as c; print(c.twice_scaled(1))"
    assert python(plain, env, tmp_path).stdout.strip() == "6"
    (package / "callee.py").write_text(CALLEE.format(scale=5))
    stale = python(plain, env, tmp_path)
    assert stale.stdout.strip() == "6", stale.stderr   # numba alone: the stale kernel
    first = python(RUN_CALLER, env, tmp_path)
    assert first.stdout.strip() == "10", first.stderr
    (package / "callee.py").write_text(CALLEE.format(scale=7))
    again = python(RUN_CALLER, env, tmp_path)
    assert again.stdout.strip() == "14", again.stderr
    assert python(RUN_CALLER, env, tmp_path).stdout.strip() == "14"   # and cached so


OTHER = ("from numba import njit\n\n\n@njit(cache=True)\ndef plus_one(x):\n"
         "    return x + 1{comment}\n")
RUN_BY_IMPORTS = ("import ptrace.jit, os; "
                  "ptrace.jit.depend_on_folders([], by_imports=[os.path.abspath('kernels')]); "
                  "import kernels.caller as c, kernels.other as o; "
                  "print(c.twice_scaled(1), o.plus_one(1), "
                  "sum(c.twice_scaled.stats.cache_hits.values()), "
                  "sum(o.plus_one.stats.cache_hits.values()))")


def test_a_kernel_depends_on_the_modules_it_imports_and_on_no_other(tmp_path):
    """Under depend_on_folders' by_imports (ptrace's folder on import), an edit recompiles the
    kernels of the edited module and of those importing it, directly or not, and loads every
    other kernel from the cache."""
    package = tmp_path / "kernels"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "callee.py").write_text(CALLEE.format(scale=3))
    (package / "caller.py").write_text(CALLER)
    (package / "other.py").write_text(OTHER.format(comment=""))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(REPO)]))

    def run():
        result = python(RUN_BY_IMPORTS, env, tmp_path)
        assert result.returncode == 0, result.stderr
        return result.stdout.split()

    assert run() == ["6", "2", "0", "0"]          # both compiled
    assert run() == ["6", "2", "1", "1"]          # both from the cache
    (package / "callee.py").write_text(CALLEE.format(scale=5))
    assert run() == ["10", "2", "0", "1"]         # the caller recompiled, the other cached
    (package / "other.py").write_text(OTHER.format(comment="  # edited"))
    assert run() == ["10", "2", "1", "0"]         # the other recompiled, the caller cached
    (package / "__init__.py").write_text("# a package edit imports nothing into its modules\n")
    assert run() == ["10", "2", "1", "1"]


STATEMENTS = ("import a.b as c, d  # a comment\nfrom .e import (f,\n    g as h,  # why\n    i)\n"
              "def j():\n    from ..k import l; import m\nfrom n import \\\n    o\n"
              "from p import q\tas\tr, s\n")


def test_the_import_scan_finds_every_import_the_parser_finds():
    """A kernel's dependencies are read from its modules' import statements by a regular
    expression (ptrace.jit._import_statements), not by parsing them: on a sample of every form
    (aliases, tabs among them, parentheses over lines with comments, imports inside functions
    and after a `;`, a continued line) and on every module of ptrace, accel, the tests and the
    benchmarks, it finds every (module, name) that Python's own parser finds (at most a few
    more, from strings that read as imports)."""
    import ast

    def parsed(text):
        found = set()
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.Import):
                found.update((None, alias.name) for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                found.update(("." * node.level + (node.module or ""), alias.name)
                             for alias in node.names)
        return found

    def scanned(text):
        return {(base, name) for base, names in jit._import_statements(text) for name in names}

    assert scanned(STATEMENTS) == parsed(STATEMENTS) == {
        (None, "a.b"), (None, "d"), (".e", "f"), (".e", "g"), (".e", "i"), ("..k", "l"),
        (None, "m"), ("n", "o"), ("p", "q"), ("p", "s")}
    sources = [path for folder in ("ptrace", "accel", "tests", "benchmarks")
               for path in (REPO / folder).rglob("*.py")]
    assert len(sources) > 100
    for path in sources:
        text = path.read_text()
        assert parsed(text) <= scanned(text), path


def test_a_cache_entry_is_saved_whole_while_another_process_reads_the_index(tmp_path):
    """numba saves an entry as an index and a data file, each replaced on its own; ptrace holds
    a lock on the index across both (and across a load's two reads), so a save waits while a
    load holds it and a load never sees an index naming data not yet written."""
    import fcntl
    import threading

    from numba.core.caching import IndexDataCacheFile
    cache_file = IndexDataCacheFile(str(tmp_path), "kernel-1.py311", ("stamp", 1))
    saved = threading.Event()

    def save():
        cache_file.save(("signature",), ("compiled", 1))
        saved.set()

    with open(cache_file._index_path + ".lock", "ab") as reader:
        fcntl.flock(reader, fcntl.LOCK_SH)      # another process loading
        thread = threading.Thread(target=save)
        thread.start()
        assert not saved.wait(0.5), "the save did not wait for the load's lock"
        assert not os.path.exists(cache_file._index_path)
    thread.join(10)
    assert saved.is_set()
    assert cache_file.load(("signature",)) == ("compiled", 1)


CLOSURES = ("from numba import njit\n\n\n@njit(cache=True)\ndef double(x):\n    return 2 * x\n\n\n"
            "@njit(cache=True)\ndef triple(x):\n    return 3 * x\n\n\ndef applying(f):\n"
            "    @njit(cache=True)\n    def apply(x):\n        return f(x) + 1\n    return apply\n")
RUN_CLOSURES = ("{imports}; a, b = m.applying(m.double), m.applying(m.triple); "
                "print(a(1), b(1), sum(a.stats.cache_hits.values()), "
                "sum(b.stats.cache_hits.values()))")


def test_a_closure_of_a_numba_function_is_found_in_the_cache_by_the_next_process(tmp_path):
    """A kernel made by a factory that captures numba functions (as the shading and hit stages
    capture their kind's BSDF and their light sampler's functions) is loaded from the cache by
    the next process, not compiled again in every one (numba alone keys it by a per-process id:
    issue 6264); closures of different functions stay different kernels."""
    (tmp_path / "mod").mkdir()
    (tmp_path / "mod" / "m.py").write_text(CLOSURES)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path / "mod"), str(REPO)]))
    plain = RUN_CLOSURES.format(imports="import m")
    assert python(plain, env, tmp_path).stdout.split() == ["3", "4", "0", "0"]
    numba_alone = python(plain, env, tmp_path)
    assert numba_alone.stdout.split() == ["3", "4", "0", "0"], numba_alone.stderr  # compiled
    with_ptrace = RUN_CLOSURES.format(imports="import ptrace, m")
    first = python(with_ptrace, env, tmp_path)
    assert first.stdout.split() == ["3", "4", "0", "0"], first.stderr
    again = python(with_ptrace, env, tmp_path)
    assert again.stdout.split() == ["3", "4", "1", "1"], again.stderr   # both from the cache


class _Index:
    """A stand-in for a numba dispatcher, as ptrace.jit reads one: its cache's index (keys whose
    first item is a signature) and its cache folder."""

    def __init__(self, signatures, folder=".", broken=False):
        self._cache = self
        self._cache_file = self
        self._cache_path = str(folder)
        self.signatures, self.broken = signatures, broken

    def _load_index(self):
        if self.broken:
            raise OSError("unreadable")
        return {(signature, "target", "key"): "entry" for signature in self.signatures}


def test_cold_tells_a_first_compile_from_another_backends():
    from collections import namedtuple

    from numba import typeof

    from ptrace.jit import cold
    first, other = namedtuple("First", ["a"]), namedtuple("Other", ["a"])
    cached = _Index([(typeof(first(1.0)), typeof(1.0))])
    assert cold(first, cached) is None                   # this backend's kernel is cached
    assert cold(other, cached) == "backend"              # another backend's is
    assert cold(other, _Index([])) == "first"            # none is
    assert cold(other, _Index([], broken=True)) is None  # no message rather than a wrong one


def test_the_cold_notice_quotes_the_compile_measured_here(tmp_path):
    from ptrace.jit import COLD_COMPILE_SECONDS, compile_estimate, remember_compile
    stage = _Index([], tmp_path)
    assert compile_estimate("first", stage) == COLD_COMPILE_SECONDS["first"]   # none measured
    remember_compile("backend", 4.26, stage)
    remember_compile("first", 17.04, stage)
    assert (compile_estimate("backend", stage), compile_estimate("first", stage)) == (4.3, 17.0)
    (tmp_path / "ptrace-compile-seconds.json").write_text("{not json")
    assert compile_estimate("backend", stage) == COLD_COMPILE_SECONDS["backend"]
    remember_compile("first", 9.5, stage)   # an unreadable file is started again
    assert compile_estimate("first", stage) == 9.5
    assert [p.name for p in tmp_path.iterdir()] == ["ptrace-compile-seconds.json"]
    remember_compile("first", 1.0, _Index([], tmp_path / "missing"))   # nowhere to keep it


def test_a_kernel_defined_before_ptrace_is_imported_is_saved_and_loaded(tiny):
    """A module whose kernels were defined before ptrace was imported (numba set their stamps,
    before ptrace.jit made stamps wait until first used) still saves and loads them, with no
    note (a test worker that imported accel first said "could not be saved ...
    ('_ptrace_source_stamp')" and compiled the kernel again in every run)."""
    env, cwd = tiny
    code = ("import tiny, ptrace; tiny.add_one(1.5); print(tiny.add_one.stats.cache_hits and 1 "
            "or 0); print('\\n'.join(ptrace.jit.cache_notes()))")
    first = python(code, env, cwd)      # compiled (a float signature the fixture did not save)
    assert first.returncode == 0 and first.stdout.split() == ["0"], first.stdout + first.stderr
    again = python(code, env, cwd)
    assert again.returncode == 0 and again.stdout.split() == ["1"], again.stdout + again.stderr
