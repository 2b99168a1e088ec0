"""Distributed rendering on a local Dask cluster: bit-identical to in-process, robust to a lost
worker, clear errors, and dask never imported unless asked for."""
import os
import signal
import subprocess
import sys
import threading
import time

import cloudpickle   # comes with dask[distributed], which the test extra installs
import numpy as np
import pytest

import ptrace
from ptrace import distributed
from ptrace.errors import PtraceError
from ptrace.image import read_image

from test_cli import SHIPPED, ptrace_command, run

pytestmark = pytest.mark.slow
# functions below run on workers and the scheduler: send them by value (tests/ is not a package
# the workers can import)
cloudpickle.register_pickle_by_value(sys.modules[__name__])


@pytest.fixture(scope="module")
def client():
    client, cluster = distributed.local_client(2)
    yield client
    client.close()
    cluster.close()


def both(scene, client, **options):
    """(in-process image, distributed image, distributed stats)."""
    alone = ptrace.render(scene, **options)
    stats = {}
    spread = ptrace.render(scene, client=client, stats=stats, **options)
    return alone, spread, stats


def test_path_render_is_bit_identical(client, course_scene):
    scene = ptrace.load(course_scene("sky/CBspheres_lambertian.dae"))
    alone, spread, stats = both(scene, client, spp=4, light_samples=2, max_depth=5,
                                resolution=(48, 36), seed=7)
    assert stats["workers"] == 2 and stats["tasks"] >= 4
    assert alone.max() > 0
    assert np.array_equal(alone, spread)


@pytest.mark.parametrize("option", [dict(roulette=False), dict(hemisphere=True),
                                    dict(rr_cap=0.3)])
def test_light_transport_options_reach_the_workers(client, course_scene, option):
    """Every setting travels to the workers whole: until the settings became one value, the
    workers' whitelist dropped `roulette`, so roulette=False ran roulette on the cluster."""
    scene = ptrace.load(course_scene("sky/CBspheres_lambertian.dae"))
    kwargs = dict(spp=2, light_samples=2, max_depth=6, resolution=(24, 18), seed=5)
    alone, spread, _ = both(scene, client, **kwargs, **option)
    assert np.array_equal(alone, spread)
    assert not np.array_equal(alone, ptrace.render(scene, **kwargs))   # the option matters


def test_normals_and_adaptive_renders_are_bit_identical(client, course_scene):
    cow = ptrace.load(course_scene("meshedit/cow.dae"))
    alone, spread, _ = both(cow, client, integrator="normals", resolution=(64, 48))
    assert np.array_equal(alone, spread)
    scene = ptrace.load(course_scene("sky/CBspheres_lambertian.dae"))
    stats_alone, stats_spread = {}, {}
    alone = ptrace.render(scene, spp=32, adaptive=(4, 0.2), max_depth=2, resolution=(32, 24),
                          stats=stats_alone)
    spread = ptrace.render(scene, spp=32, adaptive=(4, 0.2), max_depth=2, resolution=(32, 24),
                           stats=stats_spread, client=client)
    samples = stats_alone["samples"]
    assert samples.min() < 32 and samples.max() == 32   # adaptive stopped some pixels, not all
    assert np.array_equal(samples, stats_spread["samples"])
    assert np.array_equal(alone, spread)


def test_each_worker_builds_once_per_scene(client, monkeypatch):
    monkeypatch.setattr(distributed, "TASK_RAYS", 2000)   # many small tasks
    scene = ptrace.load(SHIPPED)
    before = client.run(lambda: distributed.builds)
    stats = {}
    ptrace.render(scene, client=client, spp=32, resolution=(32, 24), stats=stats)
    after = client.run(lambda: distributed.builds)
    assert stats["tasks"] >= 8
    assert sum(after[w] - before[w] for w in after) <= len(after)
    assert all(after[w] - before[w] <= 1 for w in after)


def test_an_error_in_a_task_names_the_tile_and_pass(client):
    def break_builds():
        import accel

        def broken(kind, geometry, **options):
            raise RuntimeError("no accelerator today")
        distributed.accel = type("Broken", (), {"build": staticmethod(broken)})
        return accel is not None

    def repair():
        import accel
        distributed.accel = accel

    client.run(break_builds)
    try:
        with pytest.raises(PtraceError, match=r"tile \d+ .* of pass 0 .*no accelerator today"):
            ptrace.render(ptrace.load(SHIPPED), client=client, spp=1, resolution=(8, 6))
    finally:
        client.run(repair)
    # the workers are fine again
    assert ptrace.render(ptrace.load(SHIPPED), client=client, spp=1, resolution=(8, 6)).max() > 0


def test_the_bvh_split_reaches_the_workers(client):
    scene = ptrace.load(SHIPPED)
    image = ptrace.render(scene, client=client, spp=1, resolution=(8, 6), bvh_split="sah")
    np.testing.assert_array_equal(image, ptrace.render(scene, spp=1, resolution=(8, 6)))

    def splits():
        return sorted({(key[1], key[2], backend.split) for key, backend in
                       distributed._built.items() if key[1] == "bvh"})
    built = set().union(*client.run(splits).values())
    assert ("bvh", "sah", "sah") in built


def test_a_killed_worker_still_gives_the_identical_image(course_scene, monkeypatch):
    monkeypatch.setattr(distributed, "TASK_RAYS", 20000)
    scene = ptrace.load(course_scene("sky/CBspheres_lambertian.dae"))
    options = dict(spp=16, light_samples=2, max_depth=3, resolution=(64, 48), seed=3)
    alone = ptrace.render(scene, **options)
    client, cluster = distributed.local_client(2)
    try:
        pids = client.run(os.getpid)

        def slow_tasks():
            # every task waits 0.5 s first and counts itself when done, so the render outlasts
            # the kill however fast the tracing gets (it ended before the kill once renders
            # became 2x faster); finished tiles are merged and released at once, so the
            # scheduler cannot be asked how many finished
            from ptrace import tiles
            trace = tiles.TileWork.trace

            def slow(*args, **kwargs):
                time.sleep(0.5)
                counts = trace(*args, **kwargs)
                tiles.finished_tiles = getattr(tiles, "finished_tiles", 0) + 1
                return counts
            tiles.TileWork.trace = slow
        client.run(slow_tasks)
        result = {}

        def render():
            try:
                result["image"] = ptrace.render(scene, client=client, stats=result, **options)
            except BaseException as error:   # surfaced in the main thread below
                result["error"] = error
        worker = threading.Thread(target=render)
        worker.start()

        def finished_tiles():
            from ptrace import tiles
            return getattr(tiles, "finished_tiles", 0)
        deadline = time.monotonic() + 120
        while sum(client.run(finished_tiles).values()) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert worker.is_alive(), "the render ended before a worker could be killed"
        os.kill(next(iter(pids.values())), signal.SIGKILL)
        worker.join(timeout=300)
        assert "error" not in result, result.get("error")
        assert np.array_equal(alone, result["image"])
    finally:
        client.close()
        cluster.close()


def test_unreachable_scheduler_is_one_line_and_exit_2(tmp_path):
    start = time.monotonic()
    result = run("--scheduler", "tcp://127.0.0.1:9", "-f", tmp_path / "x.png", SHIPPED)
    assert time.monotonic() - start < 60
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in lines[0]
    assert not (tmp_path / "x.png").exists()


def test_cli_workers_writes_the_in_process_image(tmp_path):
    args = ["-s", "2", "-m", "2", "-r", "32", "24", SHIPPED]
    alone = run(*args[:-1], "-f", tmp_path / "alone.exr", SHIPPED)
    spread = run("--workers", "2", *args[:-1], "-f", tmp_path / "spread.exr", SHIPPED)
    assert alone.returncode == 0 and spread.returncode == 0, spread.stderr
    assert "workers 2" in spread.stdout
    assert np.array_equal(read_image(tmp_path / "alone.exr"), read_image(tmp_path / "spread.exr"))


def test_cli_ctrl_c_cancels_and_writes_what_was_merged(tmp_path):
    output = tmp_path / "box.png"
    process = subprocess.Popen(ptrace_command() + ["--workers", "2", "-s", "1000000", "-m", "3",
                                                   "-r", "32", "24", "-f", str(output),
                                                   str(SHIPPED)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen = []   # the CLI says when the cluster is up and the render starts
    while not any("rendering on 2 Dask workers" in line for line in seen) and len(seen) < 50:
        line = process.stderr.readline()
        assert line, "".join(seen)
        seen.append(line)
    time.sleep(8)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    assert read_image(output).max() > 0


def test_default_mode_never_imports_dask():
    code = ("import sys, ptrace; from ptrace import cli; "
            f"ptrace.render(ptrace.load({str(SHIPPED)!r}), spp=1, resolution=(8, 6)); "
            f"cli.main(['--info', {str(SHIPPED)!r}]); "
            "loaded = [m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')]; "
            "assert not loaded, loaded")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr


def test_missing_dask_says_how_to_install(tmp_path):
    code = ("import sys; sys.modules['dask'] = None; sys.modules['dask.distributed'] = None; "
            "from ptrace import cli; "
            f"sys.exit(cli.main(['--workers', '2', '-f', {str(tmp_path / 'x.png')!r}, "
            f"{str(SHIPPED)!r}]))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 2
    assert result.stderr.strip() == ('ptrace: error: distributed rendering needs Dask: '
                                     'pip install "ptrace[dist]"')


def test_local_cluster_listens_on_loopback_only(client):
    import psutil   # comes with dask[distributed]
    me = psutil.Process()
    listening = [c.laddr for p in [me] + me.children(recursive=True)
                 for c in p.net_connections(kind="inet") if c.status == psutil.CONN_LISTEN]
    assert len(listening) >= 3   # scheduler, its HTTP server, the workers and nannies
    assert all(address.ip == "127.0.0.1" for address in listening), listening


def test_tile_pixels_targets_work_per_task():
    assert distributed.tile_pixels(480 * 360, 17, 16, 2) == -(-distributed.TASK_RAYS // (17 * 16))
    assert distributed.tile_pixels(100, 17, 16, 2) == 25            # two tiles per worker
    assert distributed.tile_pixels(1, 17, 16, 8) == 1



def test_only_the_sync_cancel_race_is_dropped_from_tornado_logs():
    """The NameError distributed.utils.sync's cancel callback raises when Ctrl-C comes before
    its coroutine assigned `future` is not shown; other tornado errors still are."""
    import logging

    def record(error):
        try:
            raise error
        except Exception:
            return logging.LogRecord("tornado.application", logging.ERROR, __file__, 1,
                                     "Exception in callback", None, sys.exc_info())

    logger = logging.getLogger("tornado.application")
    race = record(NameError("cannot access free variable 'future' where it is not associated "
                            "with a value in enclosing scope"))
    other = record(NameError("name 'x' is not defined"))
    assert not logger.filter(race)
    assert logger.filter(other) and logger.filter(record(RuntimeError("boom")))
