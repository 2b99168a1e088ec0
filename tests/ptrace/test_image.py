"""Output files are written whole or not at all (the README's promise): a write that fails
leaves the previous file byte-identical and no temporary behind; one that succeeds replaces it."""
import numpy as np
import OpenImageIO as oiio
import pytest

from ptrace.errors import PtraceError
from ptrace.image import read_image, write_image


class FailingOutput:
    """An OpenImageIO output that opens its file (creating or truncating it, as a real write
    does) and then fails while writing the pixels, as a full disk would."""

    def __init__(self, real, failure):
        self.real, self.failure = real, failure

    def open(self, name, spec):
        return self.real.open(name, spec)

    def write_image(self, pixels):
        if self.failure == "raises":
            raise KeyboardInterrupt   # Ctrl-C in the middle of the write
        return False

    def close(self):
        return self.real.close()

    def geterror(self):
        return "no space left on device (simulated)"


@pytest.mark.parametrize("extension", [".png", ".exr"])
@pytest.mark.parametrize("failure", ["returns false", "raises"])
def test_a_failed_write_leaves_the_previous_file_byte_identical(tmp_path, monkeypatch, extension,
                                                               failure):
    target = tmp_path / f"out{extension}"
    write_image(target, np.full((4, 5, 3), 0.25))
    before = target.read_bytes()
    create = oiio.ImageOutput.create
    monkeypatch.setattr(oiio.ImageOutput, "create",
                        staticmethod(lambda name: FailingOutput(create(name), failure)))
    expected = KeyboardInterrupt if failure == "raises" else PtraceError
    with pytest.raises(expected):
        write_image(target, np.full((4, 5, 3), 0.75))
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [target.name]


@pytest.mark.parametrize("extension", [".png", ".exr"])
def test_a_successful_write_replaces_the_file_whole(tmp_path, extension):
    target = tmp_path / f"out{extension}"
    write_image(target, np.full((4, 5, 3), 0.25))
    write_image(target, np.full((6, 7, 3), 0.75))
    image = read_image(target)
    assert image.shape == (6, 7, 3)
    assert [p.name for p in tmp_path.iterdir()] == [target.name]
