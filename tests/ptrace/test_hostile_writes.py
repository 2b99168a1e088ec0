"""Writes that cannot lose data (the README's promise: output files are written whole or not at
all). A full disk is simulated by patching the writer as OpenImageIO behaves on one (its write and
close report success while the file stays short), by an fsync that fails with ENOSPC, and, where
the tests run as root and can mount, by a real tmpfs of 64 KiB. Every failed write must leave the
old file byte-identical, no temporary file behind, and one line naming the file."""
import errno
import os
import subprocess

import numpy as np
import OpenImageIO as oiio
import pytest

from ptrace.app import cli
from ptrace.errors import PtraceError
from ptrace.image import write_image, write_images

from console import SHIPPED

OLD = np.full((4, 5, 3), 0.25)
NEW = np.random.default_rng(1).random((60, 80, 3))


class SilentlyShortOutput:
    """OpenImageIO's output on a full disk: open, write_image and close all return True, but the
    pixels never reach the file (here: not written at all) and the error state says so only if
    `records` is set (OpenImageIO 3.2's PNG writer records it; assume nothing else does)."""

    def __init__(self, real, records):
        self.real, self.records = real, records

    def open(self, name, spec):
        return self.real.open(name, spec)

    def write_image(self, pixels):
        return True

    @property
    def has_error(self):
        return self.records

    def geterror(self):
        return "Write error at position 161, could only write 0/8192 bytes\nmore\n"

    def close(self):
        return self.real.close()


def old_file(tmp_path, extension):
    target = tmp_path / f"out{extension}"
    write_image(target, OLD)
    return target, target.read_bytes()


def assert_untouched(tmp_path, target, before, error):
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]
    message = str(error.value)
    assert "\n" not in message and f"cannot write {target}" in message, message


@pytest.mark.parametrize("extension", [".png", ".exr"])
@pytest.mark.parametrize("records", [True, False])
def test_a_write_that_reports_success_but_writes_nothing_keeps_the_old_file(
        tmp_path, monkeypatch, extension, records):
    target, before = old_file(tmp_path, extension)
    create = oiio.ImageOutput.create
    monkeypatch.setattr(oiio.ImageOutput, "create",
                        staticmethod(lambda name: SilentlyShortOutput(create(name), records)))
    with pytest.raises(PtraceError) as error:
        write_image(target, NEW)
    assert_untouched(tmp_path, target, before, error)


@pytest.mark.parametrize("extension", [".png", ".exr"])
def test_a_lost_write_found_at_fsync_keeps_the_old_file_and_says_no_space(
        tmp_path, monkeypatch, extension):
    """A filesystem with delayed allocation reports ENOSPC only at fsync."""
    target, before = old_file(tmp_path, extension)

    def fsync(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(os, "fsync", fsync)
    with pytest.raises(PtraceError) as error:
        write_image(target, NEW)
    assert_untouched(tmp_path, target, before, error)
    assert str(error.value).endswith("no space left on device")


def test_several_images_are_written_all_or_none(tmp_path, monkeypatch):
    """The CLI writes the image and its rate image together: when the second fails, the first
    is not replaced either."""
    first, second = tmp_path / "out.png", tmp_path / "out_rate.png"
    write_images([dict(path=first, radiance=OLD), dict(path=second, radiance=OLD)])
    before = first.read_bytes(), second.read_bytes()
    create = oiio.ImageOutput.create
    calls = []

    def failing_second(name):
        calls.append(name)
        return create(name) if len(calls) == 1 else SilentlyShortOutput(create(name), True)
    monkeypatch.setattr(oiio.ImageOutput, "create", staticmethod(failing_second))
    with pytest.raises(PtraceError, match="out_rate.png"):
        write_images([dict(path=first, radiance=NEW), dict(path=second, radiance=NEW)])
    assert (first.read_bytes(), second.read_bytes()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png", "out_rate.png"]


@pytest.fixture
def tiny_tmpfs(tmp_path):
    """A 64 KiB tmpfs (root only), unmounted after the test."""
    mount = tmp_path / "tiny"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount)],
                          capture_output=True, text=True) if os.geteuid() == 0 else None
    if made is None or made.returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root and mount); the patched-writer "
                    "tests above cover the same promise")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=True)


def fill(folder):
    """Write zeros into folder/filler until the filesystem is full."""
    with open(folder / "filler", "wb", buffering=0) as handle:
        with pytest.raises(OSError) as error:
            while True:
                handle.write(b"\0" * 4096)
    assert error.value.errno == errno.ENOSPC


@pytest.mark.parametrize("extension", [".png", ".exr"])
def test_a_real_full_disk_keeps_the_old_file(tiny_tmpfs, extension):
    target, before = old_file(tiny_tmpfs, extension)
    fill(tiny_tmpfs)
    with pytest.raises(PtraceError, match="no space left on device") as error:
        write_image(target, NEW)
    assert target.read_bytes() == before
    assert sorted(os.listdir(tiny_tmpfs)) == ["filler", target.name]
    assert "\n" not in str(error.value)


def run_cli(capsys, *args):
    code = cli.main([str(a) for a in args])
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


def test_the_rate_image_path_being_a_directory_is_refused_before_anything_is_written(
        tmp_path, capsys):
    (tmp_path / "X_rate.png").mkdir()
    code, err = run_cli(capsys, "-q", "--integrator", "normals", "-r", 4, 3, "-f",
                        tmp_path / "X.png", SHIPPED)
    assert code == 2 and len(err) == 1 and "X_rate.png" in err[0] and "directory" in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["X_rate.png"]


def test_an_output_path_that_is_a_directory_is_refused(tmp_path, capsys):
    (tmp_path / "Y.png").mkdir()
    code, err = run_cli(capsys, "-q", "-f", tmp_path / "Y.png", SHIPPED)
    assert code == 2 and len(err) == 1 and "is a directory" in err[0], err


def test_a_folder_where_no_file_can_be_made_is_refused(capsys):
    """/proc exists everywhere Linux does and takes no new files, root or not."""
    code, err = run_cli(capsys, "-q", "-f", "/proc/ptrace-out.png", SHIPPED)
    assert code == 2 and len(err) == 1 and "cannot write /proc/ptrace-out.png" in err[0], err
