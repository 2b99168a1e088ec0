"""`ptrace view`: the preview's renders (bit for bit ptrace.render's), its camera moves, and
the server's safety (loopback, the token, one session per socket, Ctrl-C), without a browser
(tests/ptrace/test_view_browser.py drives the page in chromium)."""
import asyncio
import json
import os
import pathlib
import queue
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import tornado.httpclient
import tornado.websocket

import ptrace
from ptrace.app import cli, view, view_render, view_session
from ptrace.app.options import EXIT_USAGE
from ptrace.camera import course_camera
from ptrace.features import denoise
from ptrace.image import course_8bit, read_image
from ptrace.rendering.settings import Settings

from console import ptrace_command

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"
W, H = 40, 30


@pytest.fixture(scope="module")
def cornell():
    return ptrace.load(SHIPPED)


class Frames:
    """A Preview's publish(): every frame's stats with a copy of the radiance it showed (and
    in self.shown, by the frame's seq, the whole Shown: its AOVs and denoised image).

    The Preview starts rendering in its constructor, so its first frame can be published before
    preview() has stored it here: publish waits for that (`attached`)."""

    def __init__(self):
        self.queue = queue.Queue()
        self.preview = None
        self.attached = threading.Event()
        self.shown = {}

    def __call__(self, message, png):
        if not self.attached.wait(60):
            raise RuntimeError("no Preview was attached to these Frames")
        shown = None if png is None else self.preview.shown[0].copy()
        if png is not None:
            self.shown[message["seq"]] = self.preview.shown
        self.queue.put((message, png, shown))

    def until(self, test, timeout=120):
        """Frames up to and including the first for which test(stats) is true."""
        seen = []
        deadline = time.monotonic() + timeout
        while True:
            message, png, shown = self.queue.get(timeout=max(0.1, deadline - time.monotonic()))
            assert message["type"] != "error", message
            seen.append((message, shown))
            if message["type"] == "frame" and test(message):
                return seen


def preview(scene, settings, frames, **keywords):
    camera = course_camera(scene, W, H)
    backends = view_render.Backends(scene, lambda text: None)
    frames.preview = view_session.Preview(scene, settings, camera, backends, frames, **keywords)
    frames.attached.set()
    return frames.preview


@pytest.mark.parametrize("options", [dict(spp=40, max_depth=3),
                                     dict(spp=48, max_depth=2, adaptive=(8, 0.05)),
                                     dict(spp=20, integrator="normals")])
def test_preview_is_bit_for_bit_the_render(cornell, options):
    """N samples pass by pass in the viewer are ptrace.render's N samples, bit for bit (the
    passes are traced into fresh sums and added, as render adds them); the spp counter grows
    pass by pass and the image changes as passes arrive."""
    frames = Frames()
    session = preview(cornell, Settings(**options), frames)
    try:
        seen = frames.until(lambda m: m["state"] == "done")
    finally:
        session.stop()
        session.join()
    stats = {}
    expected = ptrace.render(cornell, resolution=(W, H), stats=stats, **options)
    np.testing.assert_array_equal(seen[-1][1], expected)
    np.testing.assert_array_equal(session.shown[1], stats["samples"])
    passes = [(m["spp"], shown) for m, shown in seen if m.get("kind") == "pass"]
    assert len(passes) >= 2
    counts = [spp for spp, _ in passes]
    assert counts == sorted(counts) and counts[0] < counts[-1]
    if options.get("integrator") != "normals":
        assert not np.array_equal(passes[0][1], passes[-1][1])


def test_a_cell_renders_only_its_pixels(cornell):
    """The course's C: a cell (y from the bottom) is traced again from its first sample;
    every other pixel keeps its bits, and the cell ends as render(crop=cell) does."""
    frames = Frames()
    settings = Settings(spp=48, max_depth=2)
    session = preview(cornell, settings, frames)
    try:
        before = frames.until(lambda m: m["state"] == "done")[-1][1]
        cell = (5, 4, 12, 9)
        session.handle({"type": "cell", "x": 5, "y": 4, "dx": 12, "dy": 9})
        seen = frames.until(lambda m: m["state"] == "done")
        with pytest.raises(ptrace.PtraceError, match="not inside"):
            session.handle({"type": "cell", "x": 35, "y": 4, "dx": 12, "dy": 9})
    finally:
        session.stop()
        session.join()
    inside = np.zeros((H, W), bool)
    inside[H - 4 - 9:H - 4, 5:17] = True
    first = next(shown for m, shown in seen if m.get("kind") == "pass")
    np.testing.assert_array_equal(first[~inside], before[~inside])
    assert not np.array_equal(first[inside], before[inside])    # 16 samples, not 48
    crop = ptrace.render(cornell, spp=48, max_depth=2, resolution=(W, H), crop=cell)
    np.testing.assert_array_equal(seen[-1][1][inside].reshape(crop.shape), crop)
    np.testing.assert_array_equal(seen[-1][1], before)


def test_camera_moves_are_quick_frames_then_a_restart(cornell):
    """While the camera moves the screen gets throwaway frames of 1 sample (the passes stop);
    when it is still, the render restarts from sample 0 with the new camera."""
    frames = Frames()
    session = preview(cornell, Settings(spp=32, max_depth=2), frames)
    try:
        frames.until(lambda m: m["kind"] == "pass")
        start = session.camera
        session.handle({"type": "camera", "op": "orbit", "dx": 8, "dy": 2, "moving": True,
                        "id": 1})
        moving = frames.until(lambda m: m["request"] == 1)[-1][0]
        assert moving["state"] == "moving" and moving["kind"] == "quick"
        assert moving["latency_ms"] is not None
        session.handle({"type": "camera", "op": "still", "moving": False, "id": 2})
        seen = frames.until(lambda m: m["state"] == "done" and m["request"] == 2)
    finally:
        session.stop()
        session.join()
    assert not np.allclose(session.camera.position, start.position)
    expected = ptrace.render(cornell, spp=32, max_depth=2, resolution=(W, H),
                             camera=session.camera)
    np.testing.assert_array_equal(seen[-1][1], expected)


def test_save_while_moving_writes_the_accumulated_render(cornell, tmp_path):
    """Save during a move writes the last full-resolution render (here ptrace.render's 16
    samples of the camera before the move, exposure applied), not the quick 1-sample frame of
    the moved camera on screen, and the reply says so; when still, it writes what is shown."""
    frames = Frames()
    outputs = (str(tmp_path / "v.png"), str(tmp_path / "v.exr"))
    session = preview(cornell, Settings(spp=16, max_depth=2), frames, outputs=outputs)
    try:
        frames.until(lambda m: m["state"] == "done")
        session.handle({"type": "exposure", "stops": 1.0})
        frames.until(lambda m: m["exposure"] == 1.0)
        still = session.save()
        assert "note" not in still
        session.handle({"type": "camera", "op": "orbit", "dx": 8, "dy": 2, "moving": True,
                        "id": 1})
        quick = frames.until(lambda m: m["request"] == 1)[-1]
        assert quick[0]["kind"] == "quick" and session.shown[0] is not session.accumulated[0]
        saved = session.save()
    finally:
        session.stop()
        session.join()
    assert "quick frame" in saved["note"] and saved["exr"] == os.path.abspath(outputs[1])
    expected = ptrace.render(cornell, spp=16, max_depth=2, resolution=(W, H)) * np.float32(2)
    np.testing.assert_array_equal(read_image(outputs[1]), expected)
    png = np.round(read_image(outputs[0]) * 255).astype(np.uint8)
    np.testing.assert_array_equal(png, course_8bit(expected))
    assert not np.array_equal(quick[1], expected / 2)


def test_the_denoised_toggle_shows_ptrace_denoise_of_the_render(cornell, tmp_path):
    """With the toggle on, the passes also sum the AOVs from sample 0 (turning it on restarts
    the render) and each full-resolution frame is ptrace.features.denoise of the merged
    passes: at the end the radiance and the AOVs are ptrace.render(..., aovs=)'s bit for bit
    and the denoised image is denoise() of them (equal within float tolerance; OIDN gave the
    same bits on every call here, but is not promised to). Turning it off and on again
    redraws without a restart; Save writes NAME_denoised.png/.exr beside the noisy ones."""
    options = dict(spp=24, max_depth=3)
    frames = Frames()
    outputs = (str(tmp_path / "v.png"), str(tmp_path / "v.exr"))
    session = preview(cornell, Settings(**options), frames, outputs=outputs)
    try:
        frames.until(lambda m: m["state"] == "done")
        assert session.features is None                 # not summed while the toggle is off
        session.handle({"type": "settings", "denoise": True})
        seen = frames.until(lambda m: m["state"] == "done" and m["denoised"])
        done = frames.shown[seen[-1][0]["seq"]]
        session.handle({"type": "settings", "denoise": False})
        off = frames.until(lambda m: not m["denoised"])[-1][0]
        session.handle({"type": "settings", "denoise": True})
        on = frames.until(lambda m: m["denoised"])[-1][0]
        saved = session.save()
    finally:
        session.stop()
        session.join()
    assert seen[0][0]["kind"] == "quick" and not seen[0][0]["denoised"]   # the restart
    assert all(m["denoised"] for m, _ in seen if m["kind"] in ("pass", "progress"))
    assert off["kind"] == on["kind"] == "redraw" and on["state"] == "done"
    aovs = {}
    expected = ptrace.render(cornell, resolution=(W, H), aovs=aovs, **options)
    np.testing.assert_array_equal(done.radiance, expected)
    for name in ("albedo", "normal", "depth"):
        np.testing.assert_array_equal(done.aovs[name], aovs[name])
    denoised = denoise(expected, aovs["albedo"], aovs["normal"])
    np.testing.assert_allclose(done.denoised, denoised, rtol=1e-5, atol=1e-6)
    assert not np.allclose(done.denoised, expected, atol=1e-3)
    np.testing.assert_array_equal(frames.shown[on["seq"]].denoised, done.denoised)   # reused
    assert saved["denoised"] == [str(tmp_path / "v_denoised.png"), str(tmp_path / "v_denoised.exr")]
    np.testing.assert_array_equal(read_image(outputs[1]), expected)
    np.testing.assert_array_equal(read_image(tmp_path / "v_denoised.exr"), done.denoised)
    png = np.round(read_image(tmp_path / "v_denoised.png") * 255).astype(np.uint8)
    np.testing.assert_array_equal(png, course_8bit(done.denoised))


def test_without_pyoidn_the_toggle_is_refused_with_the_reason(cornell, monkeypatch):
    """No pyoidn: the page's hello carries the one-line reason (the page disables the toggle
    and shows it) and a session refuses the toggle with it; the render goes on."""
    monkeypatch.setitem(sys.modules, "pyoidn", None)     # import pyoidn raises ImportError

    async def test(server, url):
        connection = await tornado.websocket.websocket_connect(socket_url(url))
        hello = json.loads(await connection.read_message())
        await next_frame(connection)
        session = next(iter(server.sockets)).session
        with pytest.raises(ptrace.PtraceError, match="ptrace.denoise"):
            session.handle({"type": "settings", "denoise": True})
        connection.close()
        return hello, session.denoise
    hello, on = serve(cornell, test)
    assert hello["denoise"] is False and not on
    reason = hello["denoiser_missing"]
    assert "\n" not in reason and 'pip install "ptrace[denoise]"' in reason


def test_orbit_pan_and_zoom(cornell):
    camera = course_camera(cornell, W, H)
    distance = np.linalg.norm(camera.position - camera.target)
    turned = view_render.orbit(camera, 0.3, -0.2)
    np.testing.assert_array_equal(turned.target, camera.target)
    assert np.linalg.norm(turned.position - turned.target) == pytest.approx(distance)
    assert not np.allclose(turned.position, camera.position)
    np.testing.assert_allclose(view_render.orbit(camera, 0.0, 0.0).position, camera.position,
                               atol=1e-12)
    np.testing.assert_allclose(view_render.orbit(camera, 0.0, 0.0).camera_to_world,
                               camera.camera_to_world, atol=1e-12)
    moved = view_render.pan(camera, 10, -4)
    shift = moved.position - camera.position
    np.testing.assert_allclose(moved.target - camera.target, shift, atol=1e-12)
    assert abs(shift @ camera.camera_to_world[:, 2]) < 1e-12 and np.linalg.norm(shift) > 0
    near = view_render.zoom(camera, 0.5)
    assert np.linalg.norm(near.position - near.target) == pytest.approx(distance / 2)
    small = view_render.scaled(camera, 4)
    assert (small.width, small.height) == (W // 4, H // 4)
    assert small.hfov == pytest.approx(camera.hfov, rel=0.05)


def test_errors_of_the_view_command_are_one_line(tmp_path, capsys):
    for argv, text in ((["view", str(tmp_path / "missing.dae"), "--no-browser"], "missing.dae"),
                       (["view", str(SHIPPED), "--workers", "2"], "no --workers"),
                       (["view", str(SHIPPED), "--aov", "albedo"], "no --aov"),
                       (["view", str(SHIPPED), "-f", str(tmp_path / "a.jpg")], "must end in"),
                       (["view", str(SHIPPED), "-s", "0"], "samples per pixel")):
        assert cli.main(argv) == EXIT_USAGE
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("ptrace: error: ") and text in err, err


# --- the server ---------------------------------------------------------------------------

def serve(scene, test, **keywords):
    """Run the coroutine test(server, url) against a ViewServer of a small Cornell box."""
    camera = course_camera(scene, W, H)

    async def main():
        server = view.ViewServer(scene, Settings(spp=4096, max_depth=2), camera, **keywords)
        url = server.start()
        try:
            return await asyncio.wait_for(test(server, url), 120)
        finally:
            server.stop()
    return asyncio.run(main())


def socket_url(url, token=True):
    base, _, query = url.partition("?")
    return base.replace("http://", "ws://") + "socket" + ("?" + query if token else "")


async def next_frame(connection):
    """The next frame's stats (and its PNG read), skipping other messages."""
    while True:
        text = await connection.read_message()
        assert text is not None, "the socket closed"
        message = json.loads(text)
        if message["type"] == "frame":
            png = await connection.read_message()
            assert png[:8] == b"\x89PNG\r\n\x1a\n"
            return message


def test_the_token_is_required_and_nothing_else_is_served(cornell):
    async def test(server, url):
        client = tornado.httpclient.AsyncHTTPClient()

        async def status(address, **keywords):
            response = await client.fetch(address, raise_error=False, **keywords)
            return response.code

        base = url.partition("?")[0]
        assert await status(url) == 200
        assert "ptraceView" in (await client.fetch(url)).body.decode()
        assert await status(base) == 403
        assert await status(url + "x") == 403
        assert await status(base + "?token=") == 403
        assert await status(base + "view_page.html?" + url.partition("?")[2]) == 404
        assert await status(base + "../app/view.py?" + url.partition("?")[2]) == 404
        assert await status(url, headers={"Host": f"evil.example:{server.port}"}) == 403
        for address in (socket_url(url, token=False), socket_url(url) + "x"):
            with pytest.raises(tornado.httpclient.HTTPClientError) as refused:
                await tornado.websocket.websocket_connect(address)
            assert refused.value.code == 403
        foreign = tornado.httpclient.HTTPRequest(socket_url(url),
                                                 headers={"Origin": "http://evil.example"})
        with pytest.raises(tornado.httpclient.HTTPClientError) as refused:
            await tornado.websocket.websocket_connect(foreign)
        assert refused.value.code == 403
        return server.port

    port = serve(cornell, test)
    with pytest.raises(ConnectionRefusedError):   # stop() closed it
        socket.create_connection(("127.0.0.1", port), timeout=5)


def listening_addresses(port):
    """Local addresses (hex, as /proc/net/tcp* gives them) listening on this TCP port."""
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if os.path.exists(table):
            for line in pathlib.Path(table).read_text().splitlines()[1:]:
                local, state = line.split()[1], line.split()[3]
                address, _, hex_port = local.partition(":")
                if int(hex_port, 16) == port and state == "0A":   # LISTEN
                    found.append(address)
    return found


def test_bound_to_loopback_only(cornell):
    async def test(server, url):
        return listening_addresses(server.port)
    assert serve(cornell, test) == ["0100007F"]   # 127.0.0.1, and nothing on IPv6


def test_each_socket_is_its_own_session_and_closing_stops_its_render(cornell):
    async def test(server, url):
        first = await tornado.websocket.websocket_connect(socket_url(url))
        second = await tornado.websocket.websocket_connect(socket_url(url))
        await next_frame(first)
        await next_frame(second)
        sessions = [s.session for s in server.sockets]
        assert len(sessions) == 2 and sessions[0] is not sessions[1]
        first.write_message(json.dumps({"type": "camera", "op": "zoom", "factor": 0.5,
                                        "moving": False, "id": 7}))
        while (await next_frame(first))["request"] != 7:
            pass
        assert (await next_frame(second))["request"] == 0   # the other did not move
        closed = next(s for s in sessions if s.request == 7)
        first.close()
        # the IOLoop runs on while this waits for the closed socket's render thread to end
        await asyncio.get_running_loop().run_in_executor(None, closed.thread.join, 30)
        assert not closed.thread.is_alive()
        assert [s.session for s in server.sockets] == [x for x in sessions if x is not closed]
        for _ in range(2):
            await next_frame(second)          # the other session still renders
        extra = [await tornado.websocket.websocket_connect(socket_url(url))
                 for _ in range(view.MAX_SESSIONS)]
        assert await extra[-1].read_message() is None    # one more than MAX_SESSIONS: refused
        assert extra[-1].close_code == 4003
        second.close()
        for connection in extra:
            connection.close()
        for session in sessions + [s.session for s in server.sockets]:
            await asyncio.get_running_loop().run_in_executor(None, session.thread.join, 30)
            assert not session.thread.is_alive()
        assert not server.sockets

    serve(cornell, test)


def session_processes(sid):
    """Processes whose session id is sid (from /proc/*/stat)."""
    found = []
    for entry in pathlib.Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            fields = stat.rpartition(")")[2].split()
            if int(fields[3]) == sid:
                found.append(int(entry.name))
    return found


def test_ctrl_c_stops_the_server_and_leaves_no_process(tmp_path):
    """The command prints its URL; with a page's socket rendering, SIGINT (Ctrl-C) ends it with
    exit code 130, one line, no traceback, nothing left in its session, the port closed."""
    process = subprocess.Popen(
        ptrace_command() + ["view", str(SHIPPED), "-r", "64", "48", "-m", "2", "--no-browser"],
        cwd=tmp_path, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        line = process.stdout.readline()
        assert "http://127.0.0.1:" in line, line + process.stderr.read()
        url = line.split(" at ")[1].split()[0]

        async def rendering():
            connection = await tornado.websocket.websocket_connect(socket_url(url))
            while (await next_frame(connection))["kind"] != "pass":
                pass
            process.send_signal(signal.SIGINT)
            return await connection.read_message()   # None: the server closed the socket
        assert asyncio.run(asyncio.wait_for(rendering(), 300)) is None
        code = process.wait(timeout=60)
        stderr = process.stderr.read()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        process.stdout.close()
        process.stderr.close()
    assert code == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr, stderr
    assert session_processes(process.pid) == []
    port = int(url.split(":")[2].split("/")[0])
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection(("127.0.0.1", port), timeout=5)
