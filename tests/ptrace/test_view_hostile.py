"""`ptrace view` under hostile or careless input: every socket message checked (an error reply,
the socket and the session going on), a camera no message can break, a closed page that stops
within one kernel call, a session cap that counts sessions still stopping, no token in any log
line, and the bounds on resolution, samples and the rays of one path."""
import asyncio
import json
import logging
import threading
import time

import numpy as np
import pytest
import tornado.httpclient
import tornado.websocket
from test_view import SHIPPED, Frames, H, W, next_frame, preview, socket_url

import ptrace
from ptrace.app import cli, view, view_messages, view_render
from ptrace.app.options import EXIT_USAGE
from ptrace.camera import course_camera
from ptrace.image import read_image
from ptrace.rendering import tiles
from ptrace.rendering.settings import Settings

EXPENSIVE = dict(light_samples=1024, max_depth=8)   # a few ms a path: a TileWork block of 4096
                                                    # paths would take seconds


@pytest.fixture(scope="module")
def cornell():
    return ptrace.load(SHIPPED)


def serve(scene, test, settings, tmp_path, **keywords):
    """Run the coroutine test(server, url) against a ViewServer of a small Cornell box."""
    async def main():
        server = view.ViewServer(scene, settings, course_camera(scene, W, H),
                                 outputs=(str(tmp_path / "v.png"), str(tmp_path / "v.exr")),
                                 **keywords)
        url = server.start()
        try:
            return await asyncio.wait_for(test(server, url), 120)
        finally:
            server.stop()
    return asyncio.run(main())


async def reply(connection):
    """The next message that is not a frame (frames' PNGs skipped)."""
    while True:
        text = await connection.read_message()
        assert text is not None, f"the socket closed ({connection.close_code})"
        if isinstance(text, str) and json.loads(text)["type"] == "frame":
            await connection.read_message()
        elif isinstance(text, str) and json.loads(text)["type"] not in ("hello", "notice"):
            return json.loads(text)


HOSTILE = [   # (text, what the error reply says)
    ('{"type": "settings", "spp": 1e999}', "1e999 is not a finite number"),
    ("[" * 30000 + "]" * 30000, "more than 4096"),
    ("[" * 2000 + "]" * 2000, "nested more than 1 deep"),
    ('{"type": "probe", "x": {"y": [1]}, "y": 0}', "nested"),
    (json.dumps({"type": "settings", "spp": 2 ** 64}), "beyond 2^63 - 1"),
    (json.dumps({"type": "settings", "spp": 2 ** 40}), "from 1 to 4294967296"),
    (json.dumps({"type": "settings", "light_samples": 10 ** 9}),
     "light samples (-l) must be an integer from 1 to 65536"),
    (json.dumps({"type": "settings", "light_samples": 65536, "max_depth": 100}),
     "one path may trace"),
    (json.dumps({"type": "settings", "max_depth": -1}), "max depth (-m) must be an integer from 0"),
    (json.dumps({"type": "settings", "spp": 1.5}), "spp must be an integer"),
    ('{"type": "camera", "op": "zoom", "factor": NaN, "moving": false}', "NaN is not a number"),
    ('{"type": "camera", "op": "orbit", "dx": Infinity, "dy": 0}', "Infinity is not a number"),
    ('{"type": "camera", "op": "pan", "dx": 1e300, "dy": 0}', "camera pan refused"),
    ('{"type": "camera", "op": "zoom"}', "factor missing"),
    ('{"type": "exposure", "stops": -Infinity}', "-Infinity is not a number"),
    ('{"type": "probe", "x": 1e999, "y": 0}', "not a finite number"),
    ('{"type": "probe", "x": 99999, "y": 0}', "not in the image"),
    ('{"type": "cell", "x": 0, "y": 0, "dx": 99999999999, "dy": 1}', "not inside the image"),
    ('{"type": "pause", "paused": "yes"}', "paused must be true or false"),
    ('{"type": "save", "path": "/etc/passwd"}', "unknown field 'path'"),
    ('{"type": "nonsense"}', "unknown message type"),
    ('"just a string"', "not a JSON object"),
    ("{", "not JSON"),
    (b"\x00\x01", "not binary"),
]


def test_every_hostile_message_gets_an_error_reply_and_the_session_goes_on(cornell, tmp_path):
    """Each message is refused with an error reply naming what is wrong; the socket stays
    open, the camera and settings are unchanged, and Save then writes the render (not an
    all-zero image from a broken camera)."""
    async def test(server, url):
        connection = await tornado.websocket.websocket_connect(socket_url(url))
        await next_frame(connection)
        session = next(iter(server.sockets)).session
        camera, settings = session.camera, session.settings
        for text, expected in HOSTILE:
            connection.write_message(text, binary=isinstance(text, bytes))
            answer = await reply(connection)
            assert answer["type"] == "error" and expected in answer["message"], (text[:40],
                                                                                answer)
            if isinstance(text, str) and "settings" in text[:30]:   # the page's fields get
                assert answer["settings"]["spp"] == settings.spp    # the values kept
        assert session.camera is camera and session.settings == settings
        connection.write_message(json.dumps({"type": "exposure", "stops": 0}))
        while (await next_frame(connection))["state"] != "done":    # it still renders
            pass
        connection.write_message(json.dumps({"type": "save"}))
        assert (await reply(connection))["type"] == "saved"
        assert connection.close_code is None

    serve(cornell, test, Settings(spp=8, max_depth=2), tmp_path)
    saved = read_image(tmp_path / "v.exr")
    assert np.isfinite(saved).all() and saved.max() > 0.1


def test_messages_are_refused_before_parsing_when_long_or_deep():
    """The size and depth checks come before json.loads: a 4,000-deep array under the size cap
    (json would raise RecursionError) is refused by a linear scan, and brackets inside strings
    do not count."""
    with pytest.raises(view_messages.MessageError, match="nested"):
        view_messages.parse("[" * 2040 + "]" * 2040)
    with pytest.raises(view_messages.MessageError, match="more than 4096"):
        view_messages.parse('{"type": "save"}' + " " * 5000)
    assert view_messages.parse('{"type": "camera", "op": "still", "id": 3}') == {
        "type": "camera", "op": "still", "id": 3}
    with pytest.raises(view_messages.MessageError, match="unknown field"):
        view_messages.parse('{"type": "save", "[[[[": 1}')   # depth 1: only the field refused
    message = view_messages.check({"type": "settings", "spp": 16.0, "max_depth": np.int64(3)})
    assert message["spp"] == 16 and isinstance(message["spp"], int) and message["max_depth"] == 3
    for bad in (float("nan"), float("inf"), 2 ** 63, True):
        with pytest.raises(view_messages.MessageError):
            view_messages.check({"type": "exposure", "stops": bad})


def test_no_camera_move_breaks_the_camera(cornell):
    """Moves whose result would not be finite, or would leave the scene far behind, are refused
    (the session keeps its camera); zooming in or out without end stops at ZOOM_RANGE."""
    home = course_camera(cornell, W, H)
    distance = np.linalg.norm(home.position - home.target)
    for op, keywords in (("zoom", dict(factor=float("nan"))), ("orbit", dict(dx=float("inf"))),
                         ("orbit", dict(dx=1e308, dy=1e308)), ("pan", dict(dx=1e300)),
                         ("pan", dict(dy=-1e9))):
        with pytest.raises(ptrace.PtraceError, match=f"camera {op} refused"):
            view_render.moved(home, home, op, **keywords)
    camera = home
    for _ in range(100):
        camera = view_render.moved(camera, home, "zoom", factor=0.1)
    near = np.linalg.norm(camera.position - camera.target)
    assert near == pytest.approx(view_render.ZOOM_RANGE[0] * distance)
    for _ in range(100):
        camera = view_render.moved(camera, home, "zoom", factor=1e300)
    assert np.linalg.norm(camera.position - camera.target) == pytest.approx(
        view_render.ZOOM_RANGE[1] * distance)
    camera = view_render.moved(camera, home, "orbit", dx=5, dy=3)
    assert np.isfinite(camera.camera_to_world).all()


def test_a_closed_page_stops_within_one_kernel_call(cornell):
    """With paths of thousands of rays (one of TileWork's 4096-path blocks would take seconds),
    a stop ends the render thread within one of the viewer's kernel calls, and no call takes
    more than BLOCK_RAYS rays."""
    frames = Frames()
    settings = Settings(spp=64, **EXPENSIVE)
    rays = view_render.path_rays(cornell, settings)
    assert tiles.BLOCK_PATHS * rays > 16 * view_render.BLOCK_RAYS >= 16 * rays
    session = preview(cornell, settings, frames)
    try:
        frames.until(lambda m: m["kind"] == "quick")
        time.sleep(0.5)                           # passes under way
        assert session.running() and session.job.samples == 0
        start = time.perf_counter()
        session.stop()
        session.join(30)
        stopped = time.perf_counter() - start
    finally:
        session.stop()
        session.join(30)
    assert not session.running()
    assert stopped < 1.0, stopped
    assert session.blocks.paths_per_call(rays) * rays <= view_render.BLOCK_RAYS


def test_a_pass_cut_into_one_sample_calls_is_bit_for_bit_the_render(cornell, monkeypatch):
    """When a pass of a pixel does not fit one call, it is traced one sample per call, and the
    image is still ptrace.render's, bit for bit (adaptive sampling's decisions included)."""
    calls = []
    trace = tiles.TileWork.trace

    def counted(work, pixel_x, pixel_y, first, n, *rest):
        calls.append((len(pixel_x), n, first))
        return trace(work, pixel_x, pixel_y, first, n, *rest)
    monkeypatch.setattr(tiles.TileWork, "trace", counted)
    monkeypatch.setattr(view_render, "BLOCK_RAYS", 30)
    options = dict(spp=24, max_depth=2, adaptive=(8, 0.05))
    frames = Frames()
    session = preview(cornell, Settings(**options), frames)
    try:
        last = frames.until(lambda m: m["state"] == "done")[-1][1]
    finally:
        session.stop()
        session.join(30)
    paths = 30 // view_render.path_rays(cornell, Settings(**options))
    assert paths < 8 and calls and all(pixels * n <= paths for pixels, n, _ in calls)
    assert any(n == 1 and first > 0 for _, n, first in calls)     # a pass cut by sample
    np.testing.assert_array_equal(last, ptrace.render(cornell, resolution=(W, H), **options))


def test_blocks_shrink_to_the_time_measured():
    blocks = view_render.Blocks(1)
    assert blocks.paths_per_call(10) == tiles.BLOCK_PATHS
    assert blocks.paths_per_call(view_render.BLOCK_RAYS // 7) == 7
    blocks.seconds_per_ray = 1e-4             # a slow scene: 0.1 s is 1000 rays
    assert blocks.paths_per_call(10) == 100
    assert blocks.paths_per_call(10 ** 6) == 1


class Stuck:
    """A session whose render thread has not ended yet."""
    def __init__(self):
        self.alive = True

    def running(self):
        return self.alive

    def stop(self):
        pass

    def join(self, timeout=None):
        pass


def test_the_session_cap_counts_closed_pages_still_stopping(cornell, tmp_path):
    """Open and close six pages rendering expensive paths: each session's thread ends within
    a second of its close and nothing is left running; sessions whose threads still run count
    against the cap, so a fifth page is refused until they stop."""
    async def test(server, url):
        for _ in range(6):
            connection = await tornado.websocket.websocket_connect(socket_url(url))
            await next_frame(connection)
            session = server.sessions[-1]
            connection.write_message(json.dumps({"type": "settings", **EXPENSIVE}))
            await asyncio.sleep(0.3)
            connection.close()
            start = time.perf_counter()
            while session.running() and time.perf_counter() - start < 10:
                await asyncio.sleep(0.02)
            assert time.perf_counter() - start < 1.0
        assert not any(s.running() for s in server.sessions)
        assert not [t for t in threading.enumerate() if t.name.startswith("ptrace-view")]
        stuck = [Stuck() for _ in range(view.MAX_SESSIONS)]
        server.sessions.extend(stuck)
        refused = await tornado.websocket.websocket_connect(socket_url(url))
        assert await refused.read_message() is None and refused.close_code == 4003
        stuck[0].alive = False
        accepted = await tornado.websocket.websocket_connect(socket_url(url))
        await next_frame(accepted)
        accepted.close()

    serve(cornell, test, Settings(spp=4096, max_depth=2), tmp_path)


def test_no_token_in_any_log_line(cornell, tmp_path, caplog, monkeypatch):
    """tornado logs the URL of each request (access log) and of an uncaught error, with the
    request's repr and a traceback: every record comes out with the token replaced."""
    def broken():
        raise RuntimeError("a bug in the page")
    monkeypatch.setattr(view, "page", broken)

    async def test(server, url):
        client = tornado.httpclient.AsyncHTTPClient()
        assert (await client.fetch(url, raise_error=False)).code == 500
        assert (await client.fetch(url + "x", raise_error=False)).code == 403
        connection = await tornado.websocket.websocket_connect(socket_url(url))
        await next_frame(connection)
        connection.close()
        return server.token

    caplog.set_level(logging.INFO, logger="tornado")
    caplog.set_level(logging.INFO, logger="tornado.access")
    token = serve(cornell, test, Settings(spp=16, max_depth=1), tmp_path)
    formatter = logging.Formatter()
    lines = [formatter.format(record) for record in caplog.records]
    text = "\n".join(lines)
    assert "Uncaught exception GET /?token=[token]" in text
    assert "a bug in the page" in text and "Traceback" in text
    assert "GET /socket?token=[token]" in text            # the access log's line
    assert token not in text and token[:12] not in text


def test_resolution_samples_and_path_rays_are_bounded_at_start(tmp_path, capsys, monkeypatch):
    """ptrace view refuses, with one line naming the flag and exit 2, a resolution whose
    buffers pass half the memory, samples beyond the sampler's, a seed beyond 64 bits and
    paths of more rays than one kernel call may trace; a resolution of which fewer than
    MAX_SESSIONS sessions fit in memory lowers the cap."""
    for argv, text in ((["-r", "100000", "100000"], "buffers would need 1.5 TiB"),
                       (["-r", "9223372036854775807", "1"], "from 1 to 1048576"),
                       (["-s", str(2 ** 64)], "from 1 to 4294967296"),
                       (["--seed", str(10 ** 20)], "seed (--seed) must be an integer from 0 to"),
                       (["-l", "1000000000"], "from 1 to 65536, got 1000000000"),
                       (["-l", "65536", "-m", "100"], "-l 65,536 and -m 100: one path may trace")):
        assert cli.main(["view", str(SHIPPED), "--no-browser"] + argv) == EXIT_USAGE
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("ptrace: error: ") and text in err, err
    scene = ptrace.load(SHIPPED)
    pixels = 640 * 480
    monkeypatch.setattr(view_render, "physical_memory",
                        lambda: 5 * pixels * view_render.VIEW_BYTES_PER_PIXEL)
    assert view_render.sessions_that_fit(640, 480, view.MAX_SESSIONS, "-r") == 2
    server = view.ViewServer(scene, Settings(), course_camera(scene, 640, 480))
    assert server.max_sessions == 2
    with pytest.raises(ptrace.PtraceError, match="resolution 1280 960"):
        view.ViewServer(scene, Settings(), course_camera(scene, 1280, 960))


def test_a_naive_ray_costs_its_primitives(tmp_path):
    """With the naive backend a path's rays count NAIVE_PRIMITIVES_PER_RAY primitives each, so
    a big mesh gets smaller blocks (and a refusal sooner) than with an accelerator."""
    lines = [f"v {i} {j} 0" for i in range(21) for j in range(21)]
    lines += [f"f {i * 21 + j + 1} {(i + 1) * 21 + j + 1} {i * 21 + j + 2}"
              for i in range(20) for j in range(20)]            # 400 triangles
    (tmp_path / "grid.obj").write_text("\n".join(lines) + "\n")
    scene = ptrace.load(tmp_path / "grid.obj")
    bvh = view_render.path_rays(scene, Settings(max_depth=3))
    naive = view_render.path_rays(scene, Settings(max_depth=3, accel="naive"))
    assert naive == bvh * 7                                     # ceil(400 / 64)
