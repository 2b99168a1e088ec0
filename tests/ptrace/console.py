"""Running the real console script in tests: the command, a run, and Ctrl-C on a render in
progress (a readiness signal, not a sleep) with the check of what it wrote. Shared by
test_cli.py and test_distributed.py."""
import fcntl
import os
import pathlib
import pty
import re
import select
import shutil
import signal
import struct
import subprocess
import sys
import termios
import time

import numpy as np
import pytest

import ptrace
from ptrace.image import rate_colours, read_image
from ptrace.rendering.tiles import PASS_SAMPLES

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"


def ptrace_command():
    script = shutil.which("ptrace", path=os.path.dirname(sys.executable))
    return [script] if script else [sys.executable, "-m", "ptrace"]


def run(*args, cwd=None):
    return subprocess.run(ptrace_command() + [str(a) for a in args], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


# tqdm's counter of samples done, e.g. "| 4.10k/12.5M [" (unit_scale: k, M, ... suffixes)
_PROGRESS = re.compile(r"\| *([0-9.]+)[kMGTPEZY]?/[0-9.]+[kMGTPEZY]?")


def interrupt_once_rendering(args, timeout=600):
    """Run the console script with stderr on a pseudo-terminal, so it draws its progress bar as
    at a user's terminal; once the bar shows samples done (the readiness signal: the render
    loop is running and has summed a block), send SIGINT, as Ctrl-C does. Returns
    (exit code, stdout, everything written on the terminal). No sleeping: every wait is on
    the child's output, bounded by `timeout` seconds in all."""
    master, slave = pty.openpty()
    # a terminal of 0 columns (a fresh pty's size) makes tqdm draw nothing
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    # SIGINT back to its default in the child: a process started in the background (`cmd &`)
    # ignores SIGINT and its children inherit that, and Python does not turn an ignored SIGINT
    # into KeyboardInterrupt, so Ctrl-C would be lost and the render run to its end
    process = subprocess.Popen(ptrace_command() + [str(a) for a in args],
                               stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    os.close(slave)
    deadline = time.monotonic() + timeout
    terminal = b""

    def read():
        """One chunk of the terminal's output (b"" once the child and its children closed it)."""
        while time.monotonic() < deadline:
            if select.select([master], [], [], 1.0)[0]:
                try:
                    return os.read(master, 1 << 16)
                except OSError:   # EIO: every writer has closed the terminal
                    return b""
        pytest.fail(f"no end within {timeout} s; the terminal showed: {terminal[-2000:]!r}")

    try:
        while not any(float(n) > 0 for n in _PROGRESS.findall(terminal.decode(errors="replace"))):
            chunk = read()
            assert chunk, f"the render ended before it showed progress: {terminal!r}"
            terminal += chunk
        process.send_signal(signal.SIGINT)
        while chunk := read():
            terminal += chunk
        stdout = process.stdout.read().decode()
        code = process.wait(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        os.close(master)
        if process.poll() is None:
            process.kill()
            process.wait()
        process.stdout.close()
    return code, stdout, terminal.decode(errors="replace")


# 255 passes of PASS_SAMPLES: the 8-bit rate image (samples / spp on the course's ramp, two
# levels a pass) then tells apart every whole number of passes in the first half of the render
# (where Ctrl-C comes: about a second into a render of half a minute)
INTERRUPTED_SPP = 255 * PASS_SAMPLES


def check_interrupted_render(output, spp, resolution, max_depth, stdout, stderr):
    """The image an interrupted render wrote (EXR) is, pixel for pixel and bit for bit, the
    same-seed render of exactly the samples that pixel got: counts read from the rate image,
    in whole passes (Ctrl-C acts between kernel calls, which take whole pixels), and in the
    order the work was handed out (bottom row first: a prefix of the pixels has one pass more
    than the rest)."""
    assert "non-finite samples dropped 0" in stdout, stdout   # so counts are samples taken
    assert "interrupted" in stderr and "Traceback" not in stderr, stderr
    image = read_image(output)
    width, height = resolution
    assert image.shape == (height, width, 3)
    counts = np.arange(0, spp // 2, PASS_SAMPLES)
    ramp = rate_colours(counts / spp)
    assert len(np.unique(ramp, axis=0)) == len(counts)   # the rate image can tell them apart
    rate = np.round(read_image(rate_path_of(output)) * 255).astype(np.uint8)
    match = np.all(rate[:, :, None, :] == ramp[None, None, :, :], axis=-1)
    assert match.any(axis=-1).all(), \
        "a pixel's count is not a whole number of passes in the first half of the render"
    samples = counts[match.argmax(axis=-1)]
    in_order = samples[::-1].reshape(-1)   # the order the pixels were handed out
    assert np.all(np.diff(in_order) <= 0) and in_order[0] - in_order[-1] <= PASS_SAMPLES
    assert 0 < in_order[0] and in_order[-1] < spp, "not a partial render"
    scene = ptrace.load(SHIPPED)
    expected = np.zeros_like(image)
    for n in np.unique(samples[samples > 0]):
        whole = ptrace.render(scene, spp=int(n), max_depth=max_depth, resolution=resolution)
        expected[samples == n] = whole[samples == n]
    np.testing.assert_array_equal(image, expected)
    return samples


def rate_path_of(output):
    return output.with_name(output.stem + "_rate.png")
