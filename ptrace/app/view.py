"""`ptrace view SCENE [render flags]`: a local browser preview that refines pass by pass.

A tornado server (HTTP and WebSocket in one well-kept library, already in the tree through
dask.distributed) bound to 127.0.0.1 on a free port serves one page (view_page.html) and one
socket, both only with the unguessable token of the printed URL, which no log line shows
(_Redact). Each socket is its own session (ptrace.app.view_session.Preview): its own camera,
settings and render thread over the shared scene and backends (ptrace.app.view_render.Backends);
every message is checked (ptrace.app.view_messages) and answered, an error with an error reply;
closing the socket stops its render within one kernel call (ptrace.app.view_render.Blocks), and a
session counts against the cap until its render thread has ended.
"""
import asyncio
import hmac
import json
import logging
import os
import re
import secrets
import sys
import threading
from importlib import resources

import numba

import accel

from ..errors import PtraceError
from . import options, view_messages, view_render
from .cli_camera import check_pointing
from .view_render import Backends, denoiser_missing, page_settings
from .view_session import Preview

VIEW_SPP = 1024                 # -s without a value: a preview has something to refine
MAX_SESSIONS = 4                # more sessions than this (open, or closed and still stopping)
                                # are refused; fewer when their buffers would not fit memory
LOGGERS = ("tornado.access", "tornado.application", "tornado.general", "asyncio")


class _Redact(logging.Filter):
    """Takes every viewer's token out of the log records of tornado and asyncio (tornado logs
    a request's URL, which carries the token, in its access log and beside any uncaught error,
    with the request's repr and the traceback)."""
    QUERY = re.compile(r"(token=)[^&\s'\"]*")
    tokens = set()

    def _clean(self, text):
        for token in self.tokens:
            text = text.replace(token, "[token]")
        return self.QUERY.sub(r"\1[token]", text)

    def filter(self, record):
        try:
            text = record.getMessage()
        except Exception:   # noqa: BLE001 - a record logging cannot format is still redacted
            text = f"{record.msg} {record.args!r}"
        record.msg, record.args = self._clean(text), ()
        if record.exc_info:
            record.exc_text = logging.Formatter().formatException(record.exc_info)
            record.exc_info = None
        if record.exc_text:
            record.exc_text = self._clean(record.exc_text)
        if record.stack_info:
            record.stack_info = self._clean(record.stack_info)
        return True


_redact = _Redact()


# --- the server -------------------------------------------------------------------------

def page():
    return resources.files("ptrace.app").joinpath("view_page.html").read_text(encoding="utf-8")


class ViewServer:
    """The HTTP and WebSocket server of one scene: start() binds 127.0.0.1 on a free port and
    returns the URL with its token; stop() closes every socket and stops every render."""

    def __init__(self, scene, settings, camera, *, threads=None, crop=None,
                 outputs=("view.png", "view.exr"), notice=None, denoise=False):
        self.scene, self.settings, self.camera = scene, settings, camera
        self.threads, self.crop, self.outputs = threads, crop, outputs
        self.denoise = denoise          # the page's denoised toggle starts on (--denoise)
        self.notice = notice or (lambda text: None)
        view_render.check_settings(scene, settings, view_render.FLAG_NAMES)
        self.max_sessions = view_render.sessions_that_fit(camera.width, camera.height,
                                                          MAX_SESSIONS, "resolution")
        self.backends = Backends(scene, self._notice)
        self.token = secrets.token_urlsafe(32)
        self.sockets = set()
        self.sessions = []              # every Preview whose render thread may still run
        self.server = None
        self.port = None

    def _notice(self, text):
        self.notice(text)
        for socket in list(self.sockets):
            socket.publish({"type": "notice", "message": text}, None)

    def authorised(self, token):
        return hmac.compare_digest(token.encode(), self.token.encode())

    def start(self):
        import tornado.httpserver
        import tornado.netutil
        import tornado.web
        _redact.tokens.add(self.token)
        for name in LOGGERS:
            if _redact not in logging.getLogger(name).filters:
                logging.getLogger(name).addFilter(_redact)
        handlers = _handlers(self)
        app = tornado.web.Application(handlers, websocket_max_message_size=1 << 16)
        sockets = tornado.netutil.bind_sockets(0, address="127.0.0.1")
        self.server = tornado.httpserver.HTTPServer(app, xheaders=False)
        self.server.add_sockets(sockets)
        self.port = sockets[0].getsockname()[1]
        return f"http://127.0.0.1:{self.port}/?token={self.token}"

    def stop(self):
        sessions = list(self.sessions)
        for socket in list(self.sockets):
            socket.close(1001, "the server is stopping")
        for session in sessions:
            session.stop()
        for session in sessions:
            session.join(timeout=10)
        if self.server is not None:
            self.server.stop()

    def start_in_background(self):
        """Run this server on its own asyncio loop in a daemon thread (for Python callers: a
        notebook, the browser tests, the latency benchmark); returns a Background whose url is
        the page's and whose stop() stops the server and the thread."""
        return Background(self)

    def new_session(self, publish):
        return Preview(self.scene, self.settings, self.camera, self.backends, publish,
                       threads=self.threads, crop=self.crop, outputs=self.outputs,
                       denoise=self.denoise)


def _handlers(view):
    import tornado.ioloop
    import tornado.web
    import tornado.websocket

    class Guarded:
        def prepare(self):
            host = self.request.host
            token = self.get_query_argument("token", "")
            if host not in (f"127.0.0.1:{view.port}", f"localhost:{view.port}") \
                    or not view.authorised(token):
                raise tornado.web.HTTPError(403)

    class Page(Guarded, tornado.web.RequestHandler):
        def get(self):
            self.set_header("Content-Type", "text/html; charset=utf-8")
            self.set_header("Cache-Control", "no-store")
            self.set_header("Referrer-Policy", "no-referrer")
            self.set_header("Content-Security-Policy",
                            "default-src 'none'; script-src 'unsafe-inline'; style-src "
                            "'unsafe-inline'; img-src blob: data:; connect-src "
                            f"ws://127.0.0.1:{view.port} ws://localhost:{view.port}")
            self.write(page())

    class Socket(Guarded, tornado.websocket.WebSocketHandler):
        session = None

        def open(self):
            view.sessions = [session for session in view.sessions if session.running()]
            if len(view.sessions) >= view.max_sessions:
                self.close(4003, f"{view.max_sessions} viewers are open (or still stopping) "
                                 f"already")
                return
            self.loop = tornado.ioloop.IOLoop.current()
            view.sockets.add(self)
            width, height = view.camera.width, view.camera.height
            mode = "normals" if view.settings.integrator == "normals" else "image"
            self.send({"type": "hello", "scene": os.path.basename(view.scene.path),
                       "width": width, "height": height, "accels": list(accel.KINDS),
                       **page_settings(view.settings, mode, view.denoise),
                       "denoiser_missing": denoiser_missing(),
                       "outputs": [os.path.abspath(p) for p in view.outputs]}, None)
            self.session = view.new_session(self.publish)
            view.sessions.append(self.session)

        def publish(self, message, png):   # from any thread
            self.loop.add_callback(self.send, message, png)

        def send(self, message, png):
            if self.ws_connection is None or self.ws_connection.is_closing():
                return
            try:
                self.write_message(json.dumps(message))
                if png is not None:
                    self.write_message(png, binary=True)
            except tornado.websocket.WebSocketClosedError:
                pass

        def on_message(self, text):
            """Every message gets its reply, or an error reply, and the socket stays open."""
            if self.session is None:
                return
            try:
                reply = self.session.handle(view_messages.parse(text))
            except PtraceError as error:    # with the settings kept, for the page's fields
                session = self.session
                reply = {"type": "error", "message": str(error), "settings": page_settings(
                    session.settings, session.mode, session.denoise)}
            except OSError as error:            # Save's files
                reply = {"type": "error", "message": f"cannot write: {error}"}
            except Exception as error:   # noqa: BLE001 - a bug, told as one; the session goes on
                reply = {"type": "error",
                         "message": f"internal error: {type(error).__name__}: {error}"}
                print(f"ptrace: {reply['message']}", file=sys.stderr, flush=True)
            if reply is not None:
                self.send(reply, None)

        def on_close(self):
            view.sockets.discard(self)
            if self.session is not None:    # its render thread ends after its kernel calls
                self.session.stop()         # under way, and removes its files

    return [(r"/", Page), (r"/socket", Socket)]


# --- the command ------------------------------------------------------------------------

def _open_browser(url):
    """The default browser, where there is a graphical one (never a text browser in the
    terminal the server prints to)."""
    if sys.platform in ("darwin", "win32") or os.environ.get("DISPLAY") \
            or os.environ.get("WAYLAND_DISPLAY"):
        import webbrowser
        webbrowser.open(url)


def parse(argv):
    """The arguments of `ptrace view`: ptrace's flags (ptrace.app.options) and --no-browser, -s
    defaulting to VIEW_SPP; the flags of what the viewer does not do are refused."""
    parser = options.build_parser(
        prog="ptrace view",
        description="Preview a scene in the browser, refining pass by pass: a server on "
                    "127.0.0.1 prints a URL with a token (and opens it when there is a "
                    "browser); Ctrl-C stops it.")
    parser.add_argument("--no-browser", action="store_true",
                        help="only print the URL, do not open a browser")
    parser.set_defaults(spp=VIEW_SPP)
    args = options.parse(parser, argv)
    check_pointing(args)
    for flag, given in (("--info", args.info), ("--aov", args.aov is not None),
                        ("--workers", args.workers is not None),
                        ("--scheduler", args.scheduler is not None),
                        ("--dashboard", args.dashboard),
                        ("--guiding", args.guiding != "off")):
        if given:
            raise PtraceError(f"ptrace view renders in this process and has no {flag}")
    return args


def prepare(args):
    """(scene, settings, camera, outputs) of the view's flags, checked as ptrace checks them
    (ptrace.app.options), and against what a viewer holds: its threads, its sessions' buffers."""
    from ..budget import check_render
    job = options.plan(args, lambda output: [os.path.splitext(output)[0] + extension
                                             for extension in (".png", ".exr")])
    if args.threads is not None and args.threads > numba.config.NUMBA_NUM_THREADS:
        raise PtraceError(f"threads must be between 1 and {numba.config.NUMBA_NUM_THREADS}, "
                          f"got {args.threads}")
    width, height = args.resolution
    view_render.sessions_that_fit(width, height, MAX_SESSIONS, "-r")
    scene, camera = options.scene_and_camera(args, job.budget, job)   # -e, -c, --eye ..., -b, -d
    view_render.sessions_that_fit(*args.resolution, MAX_SESSIONS, "-r")   # a file's film
    check_render(scene, job.settings.accel, job.buffers, job.budget)
    return scene, job.settings, camera, tuple(job.files)


async def _serve(args, scene, settings, camera, outputs):
    def notice(text):
        if not args.quiet:
            print(f"ptrace: {text}", file=sys.stderr, flush=True)

    import logging
    logging.getLogger("tornado.access").setLevel(logging.ERROR)   # refusals are not news
    view = ViewServer(scene, settings, camera, threads=args.threads, crop=args.crop,
                      outputs=outputs, notice=notice, denoise=args.denoise)
    url = view.start()
    print(f"ptrace: viewing {args.scene} at {url} (Ctrl-C stops)", flush=True)
    if not args.no_browser:
        _open_browser(url)
    try:
        await asyncio.Event().wait()
    finally:
        view.stop()


def main(argv):
    """`ptrace view ...`: exit 0 never (it serves until Ctrl-C: 130), 2 for a user's error."""
    def command():
        args = parse(argv)
        scene, settings, camera, outputs = prepare(args)
        asyncio.run(_serve(args, scene, settings, camera, outputs))
        return 0
    return options.guarded(command, interrupted="interrupted: the viewer stopped")


class Background:
    """A ViewServer on its own asyncio loop in a background thread
    (ViewServer.start_in_background)."""

    def __init__(self, server):
        self.server, self.url = server, None
        self.ready = threading.Event()
        self.thread = threading.Thread(target=asyncio.run, args=(self._main(),), daemon=True)
        self.thread.start()
        if not self.ready.wait(60):
            raise RuntimeError("the view server did not start")

    async def _main(self):
        self.loop = asyncio.get_running_loop()
        self.stopping = asyncio.Event()
        self.url = self.server.start()
        self.ready.set()
        try:
            await self.stopping.wait()
        finally:
            self.server.stop()

    def stop(self):
        self.loop.call_soon_threadsafe(self.stopping.set)
        self.thread.join(60)
