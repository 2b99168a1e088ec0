"""Distributed rendering on a local Dask cluster: bit-identical to in-process, robust to a lost
worker, clear errors, and dask never imported unless asked for."""
import os
import re
import signal
import subprocess
import sys
import threading
import time
import uuid

import cloudpickle  # comes with dask[distributed], which the test extra installs
import dask.distributed as dd
import numpy as np
import pytest

import ptrace
from ptrace.app import cli
from ptrace.errors import PtraceError
from ptrace.image import read_image
from ptrace.rendering import distributed, tiles

from console import (
    INTERRUPTED_SPP,
    SHIPPED,
    check_interrupted_render,
    interrupt_once_rendering,
    run,
)

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
    """The README's promise: a Dask render is bit-identical to an in-process one with the same
    seed."""
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
    alone = ptrace.render(scene, spp=32, adaptive=(4, 0.1), max_depth=2, resolution=(32, 24),
                          stats=stats_alone)
    spread = ptrace.render(scene, spp=32, adaptive=(4, 0.1), max_depth=2, resolution=(32, 24),
                           stats=stats_spread, client=client)
    samples = stats_alone["samples"]
    assert samples.min() < 32 and samples.max() == 32   # adaptive stopped some pixels, not all
    assert np.array_equal(samples, stats_spread["samples"])
    assert np.array_equal(alone, spread)


def test_each_worker_builds_once_per_scene(client, monkeypatch):
    """The README's promise: each worker builds its BVH once per scene."""
    monkeypatch.setattr(distributed, "TASK_RAYS", 2000)   # many small tasks
    scene = ptrace.load(SHIPPED)
    before = client.run(lambda: distributed.builds)
    stats = {}
    ptrace.render(scene, client=client, spp=32, resolution=(32, 24), stats=stats)
    after = client.run(lambda: distributed.builds)
    assert stats["tasks"] >= 8
    assert sum(after[w] - before[w] for w in after) <= len(after)
    assert all(after[w] - before[w] <= 1 for w in after)


def break_builds_on_the_workers(client, error):
    """Every worker's next accelerator build raises `error`; returns the repair to run."""
    def break_builds():
        import accel

        def broken(kind, geometry, **options):
            raise error
        tiles.accel = type("Broken", (), {"build": staticmethod(broken)})
        return accel is not None

    def repair():
        import accel
        tiles.accel = accel

    client.run(break_builds)
    return lambda: client.run(repair)


def test_a_user_error_in_a_task_names_the_tile_and_pass(client):
    """The README's promise: an error inside a task names the tile and pass.
    A PtraceError on a worker (the user's: here, a backend the worker cannot build) comes
    back as a PtraceError, one line naming the tile and the pass."""
    repair = break_builds_on_the_workers(client, PtraceError("no accelerator today"))
    try:
        with pytest.raises(PtraceError, match=r"^tile \d+ .* of pass 0 .*: no accelerator today$"):
            ptrace.render(ptrace.load(SHIPPED), client=client, spp=1, resolution=(8, 6))
    finally:
        repair()
    # the workers are fine again
    assert ptrace.render(ptrace.load(SHIPPED), client=client, spp=1, resolution=(8, 6)).max() > 0


def test_a_bug_in_a_task_is_not_a_user_error_and_keeps_its_cause(client):
    """Anything else raised on a worker is a bug: not a PtraceError (which the CLI would show as
    the user's fault, without a traceback), but a TileTaskError naming the tile and the pass,
    chained to the worker's exception with the worker's traceback."""
    import traceback
    repair = break_builds_on_the_workers(client, ZeroDivisionError("planted bug"))
    try:
        with pytest.raises(distributed.TileTaskError) as caught:
            ptrace.render(ptrace.load(SHIPPED), client=client, spp=1, resolution=(8, 6))
    finally:
        repair()
    error = caught.value
    assert not isinstance(error, PtraceError)
    assert re.search(r"^tile \d+ .* of pass 0 .* failed: ZeroDivisionError: planted bug$",
                     str(error)), str(error)
    assert isinstance(error.__cause__, ZeroDivisionError)
    text = "".join(traceback.format_exception(error))
    assert "in broken" in text and "in tile_task" in text   # the worker's frames came back
    assert "The above exception was the direct cause" in text


def test_the_cli_reports_a_bug_in_a_task_as_an_internal_error(client, monkeypatch, capsys,
                                                               tmp_path):
    """Through ptrace.app.cli.main, on this module's cluster (its connect patched to return it):
    exit 1, the tile and pass in the first line, the worker's cause in the traceback."""
    monkeypatch.setattr(distributed, "connect", lambda address: client)
    monkeypatch.setattr(distributed, "shutdown", lambda client, cluster=None: None)
    repair = break_builds_on_the_workers(client, ZeroDivisionError("planted bug"))
    try:
        code = cli.main(["--scheduler", "tcp://unused:1", "-q", "-r", "8", "6", "-f",
                         str(tmp_path / "x.png"), str(SHIPPED)])
    finally:
        repair()
    err = capsys.readouterr().err
    assert code == 1, err
    first = [line for line in err.splitlines() if line.startswith("ptrace: internal error")]
    assert len(first) == 1 and re.search(r"TileTaskError: tile \d+ .* of pass 0 .* failed: "
                                         r"ZeroDivisionError: planted bug", first[0]), err
    assert "ZeroDivisionError: planted bug\n" in err and "in broken" in err
    assert not (tmp_path / "x.png").exists()


def test_the_bvh_split_reaches_the_workers(client):
    scene = ptrace.load(SHIPPED)
    image = ptrace.render(scene, client=client, spp=1, resolution=(8, 6), bvh_split="sah")
    np.testing.assert_array_equal(image, ptrace.render(scene, spp=1, resolution=(8, 6)))

    def splits():
        return sorted({(key[1], key[2], job.backend.split) for key, (_, job) in
                       distributed._jobs.items() if key[1] == "bvh"})
    built = set().union(*client.run(splits).values())
    assert ("bvh", "sah", "sah") in built


def test_a_killed_worker_still_gives_the_identical_image(course_scene, monkeypatch):
    """The README's promise: a worker that dies mid-render costs only time.
    A worker killed (SIGKILL) while it holds a task, after it has finished one: the render
    recovers (Dask reruns the lost tasks) and gives the in-process image. Each worker, after
    its first tile, holds its next task until the test says go, so the kill lands in the
    middle of the render whatever the speed; the waits are on Dask events, not on time."""
    monkeypatch.setattr(distributed, "TASK_RAYS", 20000)
    scene = ptrace.load(course_scene("sky/CBspheres_lambertian.dae"))
    options = dict(spp=16, light_samples=2, max_depth=3, resolution=(64, 48), seed=3)
    alone = ptrace.render(scene, **options)
    client, cluster = distributed.local_client(2)
    go = dd.Event(f"ptrace-test-go-{uuid.uuid4().hex}", client=client)
    try:
        pids = client.run(os.getpid)
        holding = {address: dd.Event(f"ptrace-test-holding-{pid}", client=client)
                   for address, pid in pids.items()}

        def hold_after_the_first_tile(go_name):
            from ptrace.rendering import tiles
            trace = tiles.TileWork.trace
            state = {"finished": 0}

            def held(*args, **kwargs):
                if state["finished"] >= 1:
                    dd.Event(f"ptrace-test-holding-{os.getpid()}").set()
                    if not dd.Event(go_name).wait(timeout=600):
                        raise RuntimeError("the test never said go")
                counts = trace(*args, **kwargs)
                state["finished"] += 1
                return counts
            tiles.TileWork.trace = held
        client.run(hold_after_the_first_tile, go.name)
        result = {}

        def render():
            try:
                result["image"] = ptrace.render(scene, client=client, stats=result, **options)
            except BaseException as error:   # surfaced in the main thread below
                result["error"] = error
        renderer = threading.Thread(target=render)
        renderer.start()
        for address, event in holding.items():   # both workers finished a tile and hold one
            assert event.wait(timeout=300), f"{address} never finished its first tile"
        assert renderer.is_alive() and "error" not in result, result.get("error")
        os.kill(next(iter(pids.values())), signal.SIGKILL)
        go.set()
        renderer.join(timeout=300)
        assert not renderer.is_alive(), "the render did not recover from the lost worker"
        assert "error" not in result, result.get("error")
        assert np.array_equal(alone, result["image"])
    finally:
        go.set()
        client.close()
        cluster.close()


def test_unreachable_scheduler_is_one_line_and_exit_2(tmp_path):
    start = time.monotonic()
    result = run("--scheduler", "tcp://127.0.0.1:9", "-f", tmp_path / "x.png", SHIPPED)
    assert time.monotonic() - start < 60
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in lines[0]
    assert "connection refused" in lines[0]     # said at once, not after Dask's retries
    assert not (tmp_path / "x.png").exists()


def test_an_unknown_scheduler_host_is_said_at_once():
    with pytest.raises(PtraceError, match="unknown host 'no-such-host.invalid'"):
        distributed.connect("tcp://no-such-host.invalid:8786")


def test_cli_workers_writes_the_in_process_image(tmp_path):
    args = ["-s", "2", "-m", "2", "-r", "32", "24", SHIPPED]
    alone = run(*args[:-1], "-f", tmp_path / "alone.exr", SHIPPED)
    spread = run("--workers", "2", *args[:-1], "-f", tmp_path / "spread.exr", SHIPPED)
    assert alone.returncode == 0 and spread.returncode == 0, spread.stderr
    assert "workers 2" in spread.stdout
    assert np.array_equal(read_image(tmp_path / "alone.exr"), read_image(tmp_path / "spread.exr"))


def test_cli_ctrl_c_cancels_and_writes_what_was_merged(tmp_path):
    """The README's promise (Ctrl-C cancels what is outstanding and writes what has been
    merged).
    Ctrl-C once the progress bar shows merged samples: the tasks are cancelled, exit 130,
    and the image is the same-seed in-process render of exactly the samples merged (tiles are
    merged in order, so a prefix of the pixels has one pass more than the rest)."""
    output = tmp_path / "box.exr"
    resolution = (64, 48)
    code, stdout, stderr = interrupt_once_rendering(
        ["--workers", 2, "-s", INTERRUPTED_SPP, "-m", 3, "-r", *resolution, "-f", output,
         SHIPPED])
    assert code == 130, stderr
    assert "rendering on 2 Dask workers" in stderr and "workers 2" in stdout
    check_interrupted_render(output, INTERRUPTED_SPP, resolution, 3, stdout, stderr)


def test_default_mode_never_imports_dask():
    """The README's promise: without the dask flags ptrace never imports dask."""
    code = ("import sys, ptrace; from ptrace.app import cli; "
            f"ptrace.render(ptrace.load({str(SHIPPED)!r}), spp=1, resolution=(8, 6)); "
            f"cli.main(['--info', {str(SHIPPED)!r}]); "
            "loaded = [m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')]; "
            "assert not loaded, loaded")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr


def test_missing_dask_says_how_to_install(tmp_path):
    code = ("import sys; sys.modules['dask'] = None; sys.modules['dask.distributed'] = None; "
            "from ptrace.app import cli; "
            f"sys.exit(cli.main(['--workers', '2', '-f', {str(tmp_path / 'x.png')!r}, "
            f"{str(SHIPPED)!r}]))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 2
    assert result.stderr.strip() == ('ptrace: error: distributed rendering needs Dask: '
                                     'pip install "ptrace[dist]"')


def test_local_cluster_listens_on_loopback_only(client):
    """The README's promise: --workers binds everything to 127.0.0.1."""
    import psutil  # comes with dask[distributed]
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
    its coroutine assigned `future` is not shown while a render (or the CLI) asks for it;
    other tornado errors still are, and outside that scope nothing is dropped."""
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
    before = list(logger.filters)
    assert logger.filter(race)   # importing ptrace.rendering.distributed installed nothing
    with distributed.dropping_the_sync_cancel_race():
        assert not logger.filter(race)
        assert logger.filter(other) and logger.filter(record(RuntimeError("boom")))
    assert logger.filter(race) and logger.filters == before


def test_a_distributed_render_scopes_its_log_filter_to_itself(client, monkeypatch):
    """The filter is on the tornado logger while render_passes runs and gone after: a library
    call leaves the process's logging as it found it."""
    import logging
    loggers = [logging.getLogger(name) for name in
               ("", "tornado", "tornado.application", "distributed", "dask")]

    def configuration():
        return [(lg.level, list(lg.filters), list(lg.handlers), lg.propagate) for lg in loggers]
    before = configuration()
    seen = []
    inner = distributed._render_passes

    def watched(*args, **kwargs):
        seen.append([type(f).__name__ for f in logging.getLogger("tornado.application").filters])
        return inner(*args, **kwargs)
    monkeypatch.setattr(distributed, "_render_passes", watched)
    assert ptrace.render(ptrace.load(SHIPPED), client=client, spp=1, resolution=(8, 6)).max() > 0
    assert seen == [["_DropSyncCancelRace"]]
    assert configuration() == before


def test_aovs_are_refused_on_a_cluster(client):
    """AOVs are rendered in-process only: asking for them with a client is a one-line
    PtraceError before any task runs, not a silently empty dict."""
    scene = ptrace.load(os.path.join(os.path.dirname(__file__), "..", "..", "scenes",
                                     "cornell.dae"))
    with pytest.raises(ptrace.PtraceError, match="in-process only"):
        ptrace.render(scene, client=client, resolution=(8, 6), aovs={})
