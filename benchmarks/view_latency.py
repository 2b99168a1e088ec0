"""How long from a camera drag to the first refreshed image in `ptrace view`.

    python -m benchmarks.view_latency [--quick] [--drags N] [--screenshot docs/view.png]
    python -m benchmarks.view_latency --only-screenshot docs/view.png

Serves each scene with ptrace.app.view.ViewServer (in this process, on its own loop), opens the
page in headless chromium (Debian's chromium and chromedriver, through Selenium), lets the
render start, and then, N times, while a pass is under way: sends the page's own drag message
(an orbit step, `moving`, through the page's socket, as its mouse handler does once per frame)
and takes the time until the first frame of the moved camera is pushed by the server and until
it is drawn on the page's canvas (both from the message's sending, by the page's clock), then
the release (`still`) and the time to its first frame. Medians over the drags. Scenes:
scenes/cornell.dae and $PTRACE_SCENES/sky/CBbunny.dae at ptrace view's defaults (800x600,
-s 1024, -m 1) and at -m 5. Writes benchmarks/results/view_latency.md; with --screenshot, also
a screenshot of the page (Cornell box, 320x240, -m 5) for the README; --only-screenshot makes
the screenshot alone (no measurement, the results file untouched). The screenshot is cropped
to the page's content and written as a 256-colour palette PNG (Pillow's octree, dithered), to
keep it small.
"""
import argparse
import os
import shutil
import statistics
import tempfile

from . import report
from .rays import scenes_dir

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORNELL = os.path.join(HERE, "scenes", "cornell.dae")


def bunny():
    return os.path.join(scenes_dir(), "sky", "CBbunny.dae")


def chromium(width=1000, height=1000):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu",
                     "--disable-dev-shm-usage", f"--window-size={width},{height}",
                     "--force-device-scale-factor=1"):
        options.add_argument(argument)
    return webdriver.Chrome(service=Service(shutil.which("chromedriver")
                                            or "/usr/bin/chromedriver"), options=options)


def serve(scene, settings, camera):
    """A ViewServer in a background thread, writing its saves to a scratch directory."""
    from ptrace.app.view import ViewServer
    directory = tempfile.mkdtemp(prefix="ptrace-view-bench-")
    return ViewServer(scene, settings, camera,
                      outputs=(os.path.join(directory, "v.png"),
                               os.path.join(directory, "v.exr"))).start_in_background()


def wait(driver, condition, timeout=600):
    from selenium.webdriver.support.ui import WebDriverWait
    return WebDriverWait(driver, timeout, poll_frequency=0.01).until(lambda d: condition())


# The page's clock: the drag message's sending, its first frame pushed (the server's latency
# is measured from its arrival; the socket's way in is added by taking the page's receipt of
# the frame's stats) and drawn.
_DRAG = """
const view = window.ptraceView, id = arguments[0], op = arguments[1];
view.timing = {sent: performance.now(), received: null, drawn: null, server: null};
const listen = (event) => {
  if (typeof event.data === "string") {
    const m = JSON.parse(event.data);
    if (m.type === "frame" && m.request === id && view.timing.received === null) {
      view.timing.received = performance.now(); view.timing.server = m.latency_ms; }
  }
};
view.listen = listen;
view.socket.addEventListener("message", listen);
view.onDraw = (stats) => {
  if (stats && stats.request === id && view.timing.drawn === null)
    view.timing.drawn = performance.now();
};
if (op === "still") view.send({type: "camera", op: "still", moving: false, id});
else view.send({type: "camera", op: "orbit", dx: 12, dy: 0, moving: true, id});
"""


def measure(driver, served, drags):
    """[(moving push ms, moving drawn ms, server ms, still push ms, still drawn ms)] per drag."""
    driver.get(served.url)
    stats = lambda: driver.execute_script("return window.ptraceView.stats") or {}  # noqa: E731
    wait(driver, lambda: stats().get("kind") in ("progress", "pass"))
    rows = []
    for k in range(drags):
        row = []
        for op, id_ in (("orbit", 2 * k + 1), ("still", 2 * k + 2)):
            driver.execute_script(_DRAG, id_, op)
            wait(driver, lambda: driver.execute_script("return window.ptraceView.timing.drawn"))
            t = driver.execute_script("const t = window.ptraceView.timing;"
                                      "window.ptraceView.socket.removeEventListener("
                                      "'message', window.ptraceView.listen); return t")
            row += [t["received"] - t["sent"], t["drawn"] - t["sent"], t["server"]]
        rows.append(row)
        # the next drag comes while a pass of the new camera is under way
        wait(driver, lambda: stats().get("kind") in ("progress", "pass")
             and stats().get("request") == 2 * k + 2)
    return rows


def main(argv=None):
    import ptrace
    from ptrace.app.view import VIEW_SPP
    from ptrace.camera import course_camera
    from ptrace.rendering.settings import Settings
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 drags, 320x240")
    parser.add_argument("--drags", type=int, default=None)
    parser.add_argument("--screenshot", default=None, metavar="PNG",
                        help="also save a screenshot of the page here")
    parser.add_argument("--only-screenshot", default=None, metavar="PNG",
                        help="only save the screenshot here (no measurement)")
    args = report.quick_defaults(parser.parse_args(argv), drags=(2, 9))
    if args.only_screenshot:
        screenshot(args.only_screenshot)
        return 0
    resolution = (320, 240) if args.quick else (800, 600)
    cases = [("cornell.dae", CORNELL, 1), ("cornell.dae", CORNELL, 5),
             ("CBbunny.dae", bunny(), 1), ("CBbunny.dae", bunny(), 5)]
    driver = chromium()
    lines = [report.header("ptrace view: camera drag to refreshed image"),
             f"Median of {args.drags} drags per row, each sent while a pass is under way "
             f"(so the pass is abandoned first), {resolution[0]}x{resolution[1]}, -s "
             f"{VIEW_SPP}, -l 1, bvh, headless chromium on this machine. *Drag*: an orbit "
             "step (`moving`) to the first frame of the moved camera (a throwaway 1-sample "
             "frame, at the resolution the last measured speed renders in about "
             "60 ms); *release*: `still` to the first frame of the restarted render (the same "
             "kind of frame, then the passes). *pushed*: the page has the frame's stats; "
             "*drawn*: on the canvas; *server*: from the message's arrival to the frame handed "
             "to the socket. All in milliseconds.", "",
             "| scene | -m | drag pushed | drag drawn | drag server | release pushed | "
             "release drawn | release server |", "|---|---|---|---|---|---|---|---|"]
    try:
        for name, path, depth in cases:
            scene = ptrace.load(path)
            served = serve(scene, Settings(spp=VIEW_SPP, max_depth=depth),
                            course_camera(scene, *resolution))
            try:
                rows = measure(driver, served, args.drags)
            finally:
                served.stop()
            medians = [statistics.median(column) for column in zip(*rows)]
            lines.append(f"| {name} | {depth} | " + " | ".join(f"{m:.0f}" for m in medians)
                         + " |")
            print(lines[-1], flush=True)
        if args.screenshot:
            screenshot(args.screenshot)
    finally:
        driver.quit()
    lines += ["", "The drag's frame is the first image; the passes (16 samples per pixel "
              "each, the schedule of ptrace.render) refine it after the release."]
    path = report.write("view_latency.md", "\n".join(lines) + "\n")
    print(f"wrote {path}")
    return 0


def screenshot(path, spp_shown=24):
    """The page on the Cornell box (320x240, -m 5) once it shows spp_shown samples per pixel,
    cropped below the page's last line and quantised to a 256-colour palette (dithered)."""
    import io

    import PIL.Image

    import ptrace
    from ptrace.camera import course_camera
    from ptrace.rendering.settings import Settings
    scene = ptrace.load(CORNELL)
    driver = chromium(720, 800)
    served = serve(scene, Settings(spp=1024, max_depth=5), course_camera(scene, 320, 240))
    try:
        driver.get(served.url)
        wait(driver, lambda: (driver.execute_script("return window.ptraceView.stats")
                              or {}).get("spp", 0) >= spp_shown)
        bottom = driver.execute_script(
            "return Math.ceil(document.getElementById('message').getBoundingClientRect()"
            ".bottom)")
        shot = PIL.Image.open(io.BytesIO(driver.get_screenshot_as_png())).convert("RGB")
    finally:
        served.stop()
        driver.quit()
    shot = shot.crop((0, 0, shot.width, min(shot.height, bottom + 8)))
    shot.quantize(256, method=PIL.Image.Quantize.FASTOCTREE,
                  dither=PIL.Image.Dither.FLOYDSTEINBERG).save(os.path.abspath(path),
                                                               optimize=True)
    print(f"wrote {path} ({os.path.getsize(path) // 1024} KB)")


if __name__ == "__main__":
    raise SystemExit(main())
