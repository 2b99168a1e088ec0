"""Feature buffers (--aov) and the opt-in denoiser (--denoise)."""
import builtins
import math
import pathlib
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest

import ptrace
from ptrace.app import cli

from scenes_by_hand import floor_plane, looking_down, make_scene, pixel_hits_on_floor, point_light

ROOT = pathlib.Path(__file__).resolve().parents[2]
CORNELL = ROOT / "scenes" / "cornell.dae"


def test_aovs_of_a_diffuse_plane_are_its_albedo_normal_and_distance():
    """At spp 1 (pixel centres) the albedo AOV is the floor's albedo, the normal +Y and the
    depth the distance from the camera to where each pixel's ray meets the floor."""
    scene = make_scene(**floor_plane(0.6), lights=[point_light((0, 1, 0), 2.0)])
    camera = looking_down(3.0)
    aovs = {}
    ptrace.render(scene, camera=camera, resolution=(32, 32), max_depth=1, aovs=aovs)
    np.testing.assert_allclose(aovs["albedo"], 0.6, rtol=1e-6)
    np.testing.assert_allclose(aovs["normal"], np.broadcast_to([0, 1, 0], (32, 32, 3)),
                               atol=1e-12)
    expected = np.linalg.norm(pixel_hits_on_floor(camera) - camera.position, axis=-1)
    np.testing.assert_allclose(aovs["depth"], expected, rtol=1e-5)


def test_the_image_is_the_same_bits_with_or_without_aovs():
    scene = ptrace.load(CORNELL)
    options = dict(resolution=(40, 30), spp=8, light_samples=2, max_depth=4, seed=5)
    plain = ptrace.render(scene, **options)
    aovs = {}
    featured = ptrace.render(scene, aovs=aovs, **options)
    assert np.array_equal(plain, featured)
    # the Cornell box: every camera ray hits; normals are unit vectors averaged over the pixel
    assert np.isfinite(aovs["depth"]).all()
    lengths = np.linalg.norm(aovs["normal"], axis=-1)
    assert (lengths <= 1 + 1e-6).all() and np.median(lengths) > 0.99


def test_aov_of_a_miss_is_zero_and_depth_infinite():
    scene = make_scene(**floor_plane(0.5, half=0.5), lights=[point_light((0, 1, 0), 1.0)])
    aovs = {}
    ptrace.render(scene, camera=looking_down(3.0), resolution=(32, 32), aovs=aovs)
    corner = (0, 0)    # outside the small floor
    assert aovs["albedo"][corner].tolist() == [0, 0, 0]
    assert math.isinf(aovs["depth"][corner])
    assert np.isfinite(aovs["depth"][16, 16])


def exr_channels(path):
    buffer = oiio.ImageBuf(str(path))
    return list(buffer.spec().channelnames), buffer.get_pixels(oiio.FLOAT)


def test_cli_writes_the_aovs_as_exr_channels(tmp_path):
    out = tmp_path / "box.exr"
    run = subprocess.run([sys.executable, "-m", "ptrace", "-s", "2", "-r", "32", "24", "--aov",
                          "albedo,normal,depth", "-f", str(out), str(CORNELL)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    names, pixels = exr_channels(out)
    # OpenEXR keeps channels sorted by layer; look them up by name
    assert sorted(names) == sorted(["R", "G", "B", "albedo.R", "albedo.G", "albedo.B",
                                    "normal.X", "normal.Y", "normal.Z", "depth.Z"])
    channel = lambda *wanted: pixels[..., [names.index(n) for n in wanted]]  # noqa: E731
    aovs = {}
    image = ptrace.render(ptrace.load(CORNELL), spp=2, resolution=(32, 24), aovs=aovs)
    np.testing.assert_array_equal(channel("R", "G", "B"), image)
    np.testing.assert_array_equal(channel("albedo.R", "albedo.G", "albedo.B"), aovs["albedo"])
    np.testing.assert_array_equal(channel("normal.X", "normal.Y", "normal.Z"), aovs["normal"])
    np.testing.assert_array_equal(channel("depth.Z")[..., 0], aovs["depth"])


@pytest.mark.parametrize("flags, message", [
    (["--aov", "albedo"], "--aov adds channels to an .exr output"),
    (["--aov", "albedo,shadow", "-f", "x.exr"], "--aov takes a comma-separated list"),
])
def test_cli_aov_errors_are_one_line(tmp_path, flags, message):
    run = subprocess.run([sys.executable, "-m", "ptrace", *flags, str(CORNELL)],
                         capture_output=True, text=True, cwd=tmp_path)
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and message in run.stderr, run.stderr


def relative_mse(image, reference):
    return float(np.mean((image - reference) ** 2 / (reference ** 2 + 1e-2)))


def test_denoise_writes_a_second_image_nearer_the_converged_one(tmp_path):
    """--denoise keeps the noisy image and writes NAME_denoised beside it; at 4 spp on the
    Cornell box the denoised image is much nearer a 256-spp render than the noisy one."""
    out = tmp_path / "box.exr"
    run = subprocess.run([sys.executable, "-m", "ptrace", "-s", "4", "-l", "1", "-m", "3", "-r",
                          "80", "60", "--denoise", "-f", str(out), str(CORNELL)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "denoised by Open Image Denoise (biased)" in run.stdout
    noisy = exr_channels(out)[1][..., :3]        # R, G, B only: no --aov
    denoised = exr_channels(tmp_path / "box_denoised.exr")[1]
    reference = ptrace.render(ptrace.load(CORNELL), spp=256, light_samples=1, max_depth=3,
                              resolution=(80, 60), seed=99)
    noisy_error, denoised_error = relative_mse(noisy, reference), relative_mse(denoised,
                                                                                reference)
    assert denoised_error < 0.5 * noisy_error, (noisy_error, denoised_error)


def test_denoise_without_pyoidn_names_the_extra(tmp_path, monkeypatch, capsys):
    real_import = builtins.__import__

    def no_pyoidn(name, *args, **kwargs):
        if name == "pyoidn":
            raise ImportError("no pyoidn here")
        return real_import(name, *args, **kwargs)
    monkeypatch.setattr(builtins, "__import__", no_pyoidn)
    monkeypatch.delitem(sys.modules, "pyoidn", raising=False)
    code = cli.main(["--denoise", "-f", str(tmp_path / "x.png"), str(CORNELL)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert 'pip install "ptrace[denoise]"' in err
    assert not (tmp_path / "x.png").exists()     # refused before rendering


def test_ptrace_does_not_import_the_denoiser_unless_asked():
    code = ("import sys, ptrace; s = ptrace.load(sys.argv[1]); "
            "ptrace.render(s, resolution=(8, 6), aovs={}); print('pyoidn' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code, str(CORNELL)], capture_output=True,
                         text=True, check=True).stdout
    assert out.strip() == "False"
