"""Notebook display: ptrace.show(image) shows itself through IPython's
_repr_png_ with the course's curve; ptrace.render still returns a plain numpy array."""
import io

import numpy as np

import ptrace
from ptrace.image import course_8bit, read_image

from scenes_by_hand import floor_plane, looking_down, make_scene, point_light


def test_show_is_the_course_curve_as_png(tmp_path):
    radiance = np.random.default_rng(0).random((5, 7, 3)).astype(np.float32) * 2
    shown = ptrace.show(radiance)
    data = shown._repr_png_()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    path = tmp_path / "shown.png"
    path.write_bytes(data)
    pixels = np.round(read_image(path) * 255).astype(np.uint8)
    np.testing.assert_array_equal(pixels, course_8bit(radiance))
    brighter = tmp_path / "brighter.png"
    brighter.write_bytes(ptrace.show(radiance, exposure=1).png())
    np.testing.assert_array_equal(np.round(read_image(brighter) * 255).astype(np.uint8),
                                  course_8bit(radiance * 2))
    assert not list(tmp_path.glob(".ptrace-*"))   # nothing left beside


def test_render_returns_a_plain_array():
    scene = make_scene(**floor_plane(0.5), lights=[point_light((0, 1, 0), 1.0)])
    image = ptrace.render(scene, camera=looking_down(3.0), resolution=(8, 8))
    assert type(image) is np.ndarray and image.dtype == np.float32
    assert io.BytesIO(ptrace.show(image).png()).getbuffer().nbytes > 0
