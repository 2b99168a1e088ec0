"""ptrace against an independent renderer: Mitsuba 3's render of the quad-free
CBspheres_lambertian at ptrace's -m 5 (benchmarks/mitsuba_reference.py made the EXR, which is
committed; Mitsuba itself is not needed here)."""
import pathlib

import numpy as np
import pytest

import ptrace
from ptrace.image import read_image

REFERENCE = (pathlib.Path(__file__).resolve().parents[1] / "references"
             / "CBspheres_lambertian_m5_mitsuba.exr")
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def relative_mse(image, reference):
    return float(np.mean((image - reference) ** 2 / (reference ** 2 + 1e-2)))


@pytest.mark.slow
def test_cbspheres_lambertian_matches_mitsuba(scenes_dir):
    reference = read_image(REFERENCE)[..., :3]
    scene = ptrace.load(scenes_dir / "variants_sp23/sky/CBspheres_lambertian.dae")
    kwargs = dict(resolution=(480, 360), light_samples=1, max_depth=5, seed=1)
    low = ptrace.render(scene, spp=2, **kwargs)
    high = ptrace.render(scene, spp=8, **kwargs)
    ours, theirs = float((high @ LUMINANCE).mean()), float((reference @ LUMINANCE).mean())
    error_low, error_high = relative_mse(low, reference), relative_mse(high, reference)
    print(f"mean luminance ptrace {ours:.4f}, mitsuba {theirs:.4f} ({ours / theirs - 1:+.2%}); "
          f"relative MSE at 2 spp {error_low:.4f}, at 8 spp {error_high:.4f}")
    assert ours == pytest.approx(theirs, rel=0.01)
    # noise, not bias: four times the samples cut the error about four times
    assert error_high < error_low / 3
    # the red wall is on the left and the blue on the right in both
    for image in (high, reference):
        left = image[150:250, 5:25].mean(axis=(0, 1))
        right = image[150:250, 455:475].mean(axis=(0, 1))
        assert left[0] > 2 * left[2] and right[2] > 2 * right[0]
