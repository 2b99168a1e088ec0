"""Smoke test of benchmarks.paths_per_second on tiny frames: ptrace's rates and image means are
sound, the report and its JSON are written (to a temporary directory), libLLVM is found, and,
where mitsuba is importable, the Mitsuba rows agree with ptrace's image (skipped cleanly
otherwise).
"""
import importlib.util
import json
import math
import os

import numba
import numpy as np
import pytest

from benchmarks import paths_per_second as pps

SCENE = "sky/CBspheres_lambertian.dae"
THREADS = min(2, numba.config.NUMBA_NUM_THREADS)


@pytest.fixture(scope="module")
def spheres(course_scene):
    import ptrace
    scene = ptrace.load(str(course_scene(SCENE)))
    pps.warm_up(scene, ("bvh",))
    return scene


def test_find_libllvm_prefers_the_environment_then_the_newest(tmp_path):
    for name in ("libLLVM-14.so.1", "libLLVM.so.19.1", "libLLVM-15.so", "libLLVMSupport.a"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "libLLVM-19.so").symlink_to(tmp_path / "libLLVM.so.19.1")
    patterns = [str(tmp_path / "libLLVM*")]
    found = pps.find_libllvm(patterns, environ={})
    assert pps.libllvm_version(found) == 19 and os.path.realpath(found).endswith("so.19.1")
    assert pps.find_libllvm(patterns, environ={"DRJIT_LIBLLVM_PATH": "/x/libLLVM.so"}) \
        == "/x/libLLVM.so"
    assert pps.find_libllvm([str(tmp_path / "nothing*")], environ={}) is None
    assert [pps.libllvm_version(p) for p in ("/usr/lib/llvm-18/lib/libLLVM.so",
                                             "libLLVM-14.0.6.so.1", "libLLVM.so")] == [18, 14, 0]


def test_ptrace_rates_and_means_on_a_tiny_frame(spheres):
    row = pps.measure_ptrace(spheres, SCENE, "bvh", 1, (16, 12), THREADS, 2)
    assert row["renderer"] == "ptrace bvh" and row["paths"] == 16 * 12
    assert len(row["seconds"]) == 2 and all(s > 0 for s in row["seconds"])
    assert row["paths_per_second"] == pytest.approx(192 / row["median_seconds"])
    assert 0 < row["mean"] < 10 and math.isfinite(row["mean_sd"])
    assert row["mean_off_lamp"] == row["mean"]            # no mask given
    assert 1 <= row["rays_per_path"] <= 2 * pps.DEPTH     # camera ray, bounces, shadow rays
    assert len(row["build_seconds"]) == 2 and len(row["mean_rgb"]) == 3


def test_lamp_mask_covers_the_lamp_only(spheres):
    mask = pps.lamp_mask(spheres, (480, 360), 1)
    assert mask.shape == (360, 480)
    assert 0 < mask.sum() < 0.05 * mask.size               # the ceiling lamp, near the top
    assert np.nonzero(mask)[0].max() < 120
    assert not pps.lamp_mask(spheres, (16, 12), 1).any()  # the central crop does not see it
    image = np.ones((360, 480, 3))
    image[mask] = 10.0
    whole, off = pps.image_means(image, mask)
    assert off == 1.0 and whole > 1.0


def test_report_and_json_ptrace_only(tmp_path, monkeypatch, scenes_dir):
    monkeypatch.setenv("PTRACE_SCENES", str(scenes_dir))
    output = tmp_path / "pps.md"
    assert pps.main(["--spp", "1", "--resolution", "16", "12", "--repeats", "1",
                     "--threads", str(THREADS), "--scenes", SCENE, "--no-mitsuba",
                     "--output", str(output)]) == 0
    text = output.read_text()
    assert text.startswith("# Camera paths per second") and "- command: `" in text
    rows = [line for line in text.splitlines() if line.startswith(f"| {SCENE} |")]
    assert [r.split("|")[2].strip() for r in rows] == ["ptrace naive", "ptrace bvh",
                                                       "ptrace embree"]
    assert all("| n/a |" in r for r in rows)               # no Mitsuba anchor
    assert "Mitsuba rows skipped: --no-mitsuba." in text
    raw = json.loads(output.with_suffix(".json").read_text())
    assert raw["settings"]["resolution"] == [16, 12] and raw["settings"]["threads"] == THREADS
    assert [r["renderer"] for r in raw["rows"]] == ["ptrace naive", "ptrace bvh", "ptrace embree"]
    means = [r["mean"] for r in raw["rows"]]
    assert max(means) - min(means) < 1e-6                  # the backends render the same image
    assert not list(tmp_path.glob("*.tmp"))


@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="mitsuba not installed")
def test_mitsuba_rows_agree_with_ptrace(tmp_path, monkeypatch, scenes_dir):
    monkeypatch.setenv("PTRACE_SCENES", str(scenes_dir))
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "")          # restored after; main finds libLLVM
    output = tmp_path / "pps.md"
    assert pps.main(["--spp", "2", "--resolution", "32", "24", "--repeats", "1",
                     "--threads", str(THREADS), "--scenes", SCENE, "--output",
                     str(output)]) == 0
    raw = json.loads(output.with_suffix(".json").read_text())
    rows = {r["renderer"]: r for r in raw["rows"]}
    assert "Mitsuba scalar_rgb" in rows
    llvm = rows.get("Mitsuba llvm_ad_rgb")
    if llvm is None:
        assert any(n.startswith("Mitsuba llvm_ad_rgb rows skipped") for n in raw["notes"])
    else:
        assert llvm["first_render_seconds"] > 0 and "| 1.00x |" in output.read_text()
    reference = rows["ptrace bvh"]["mean"]
    for name, row in rows.items():
        assert row["paths"] == 32 * 24 * 2
        assert abs(row["mean"] - reference) < 0.1 * reference, name
    assert "black twosided diffuse" in rows["Mitsuba scalar_rgb"]["mapping"]


@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="mitsuba not installed")
def test_emissive_quad_maps_to_a_black_non_emitter(tmp_path, spheres):
    import mitsuba as mi

    from ptrace.camera import course_camera
    from ptrace.scene import EMISSION
    mi.set_variant("scalar_rgb")
    description, mapping = pps.mitsuba_description(spheres, course_camera(spheres, 16, 12), 1,
                                                   0, str(tmp_path))
    assert mapping.startswith("mitsuba_reference refuses it")
    emissive = [m for m in np.unique(spheres.material_index)
                if spheres.materials.kind[m] == EMISSION]
    assert emissive
    for m in emissive:
        entry = description[f"mesh_{m}"]
        assert "emitter" not in entry
        assert entry["bsdf"]["bsdf"]["reflectance"]["value"] == [0.0, 0.0, 0.0]
    emitters = [k for k, v in description.items() if isinstance(v, dict) and "emitter" in v]
    assert emitters == ["light_0"]
    assert spheres.materials.kind[emissive[0]] == EMISSION   # the loaded scene is untouched
