"""Shared test set-up: where the CS184 course scenes are, two numba threads at least, and cold
renders compiled in their own process.

PTRACE_SCENES (if set) or <repo>/../shared/scenes/cs184. Tests that need the scenes fail (not
skip) when neither exists: CI always has ../shared.
"""
import os
import pathlib

# Before numba is imported anywhere: at least two threads, even on a one-core machine, so the
# tests that compare one thread with two really run two (numba allows more threads than cores).
os.environ.setdefault("NUMBA_NUM_THREADS", str(max(2, os.cpu_count() or 1)))
# A cold render compiles its kernels in its own process alone (ptrace.kernel.ahead would start
# one worker process a core): the suite's workers keep every core busy already, and each started
# process would cost its start-up. tests/ptrace/test_compile_ahead.py runs the workers itself.
os.environ.setdefault("PTRACE_COMPILE_PROCESSES", "1")

import pytest  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[1]
DEFAULT_SCENES = REPO.parent / "shared" / "scenes" / "cs184"


def scenes_root():
    """The course scenes directory; fails the calling test with a clear message if missing."""
    configured = os.environ.get("PTRACE_SCENES")
    root = pathlib.Path(configured) if configured else DEFAULT_SCENES
    if not root.is_dir():
        origin = "PTRACE_SCENES" if configured else "the default location"
        pytest.fail(f"course scenes not found at {root} ({origin}); set PTRACE_SCENES to the "
                    f"directory holding sky/, meshedit/, keenan/, simple/, variants_sp23/",
                    pytrace=False)
    return root


def course_scene(relpath):
    """Path of a course scene file, e.g. course_scene("sky/CBspheres.dae")."""
    path = scenes_root() / relpath
    if not path.exists():
        pytest.fail(f"course scene {relpath} missing from {scenes_root()}", pytrace=False)
    return path


@pytest.fixture(scope="session")
def scenes_dir():
    return scenes_root()


@pytest.fixture(name="course_scene", scope="session")
def course_scene_fixture():
    """The course_scene(relpath) function, for tests that cannot import this module."""
    return course_scene
