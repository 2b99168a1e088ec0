"""The real console script, run in a subprocess: help, --info, renders, and every error case."""
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import ptrace
from ptrace.image import course_8bit, read_image

from console import (
    INTERRUPTED_SPP,
    SHIPPED,
    check_interrupted_render,
    interrupt_once_rendering,
    run,
)


def test_help():
    result = run("--help")
    assert result.returncode == 0
    for flag in ("--spp", "--light-samples", "--max-depth", "--adaptive", "--hemisphere",
                 "--resolution", "--output", "--crop", "--camera", "--accel", "--seed",
                 "--integrator", "--info", "--threads"):
        assert flag in result.stdout


def test_info_on_every_course_scene(scenes_dir, capsys):
    """In this process (the console script's own start-up is tested on the shipped scene)."""
    from ptrace.app.cli import main
    files = sorted(scenes_dir.rglob("*.dae"))
    assert len(files) == 25
    for path in files:
        assert main(["--info", str(path)]) == 0
        info = json.loads(capsys.readouterr().out)
        assert set(info) >= {"file", "triangles", "spheres", "lights", "bsdfs", "camera", "bounds"}
        assert set(info["camera"]) >= {"position", "target", "hfov", "vfov", "screen_dist"}
        assert info["triangles"] > 0 and all("type" in light for light in info["lights"])


def test_info_on_the_shipped_scene():
    info = json.loads(run("--info", SHIPPED).stdout)
    assert (info["triangles"], info["spheres"]) == (24, 1)
    assert info["lights"][0]["type"] == "area" and info["lights"][0]["area"] == pytest.approx(0.48)
    assert info["bsdfs"] == ["diffuse", "emission"]
    assert info["camera"]["screen_dist"] == pytest.approx(875.0, abs=0.1)


@pytest.mark.parametrize("extension", ["png", "exr"])
def test_normals_render_written_and_read_back(tmp_path, scenes_dir, extension):
    output = tmp_path / f"cow.{extension}"
    result = run("--integrator", "normals", "-r", 120, 90, "-f", output, "--accel", "embree",
                 scenes_dir / "meshedit/cow.dae")
    assert result.returncode == 0, result.stderr
    assert "120x90" in result.stdout and "rays/s" in result.stdout and "embree" in result.stdout
    pixels = read_image(output)
    assert pixels.shape == (90, 120, 3)
    expected = ptrace.render(ptrace.load(scenes_dir / "meshedit/cow.dae"), integrator="normals",
                             resolution=(120, 90), accel="embree")
    if extension == "png":
        np.testing.assert_array_equal(np.round(pixels * 255).astype(np.uint8),
                                      course_8bit(expected))
    else:
        np.testing.assert_array_equal(pixels, expected)
    # the image and the course's rate image, and no temporary left behind
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([output.name, "cow_rate.png"])


def test_default_output_is_scene_name_in_current_directory(tmp_path):
    result = run("--integrator", "normals", "-r", 16, 12, "-q", SHIPPED, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "cornell.png").exists()
    assert str(tmp_path / "cornell.png") in result.stdout


def test_path_render_summary_and_rate_image(tmp_path):
    output = tmp_path / "box.png"
    result = run("-s", 8, "-l", 2, "-m", 3, "-a", 4, 0.2, "-r", 40, 30, "-f", output, SHIPPED)
    assert result.returncode == 0, result.stderr
    assert "non-finite samples dropped 0" in result.stdout and "40x30" in result.stdout
    rate = read_image(tmp_path / "box_rate.png")
    assert rate.shape == (30, 40, 3)
    # adaptive sampling stopped some pixels early (not pure red) and not all (some red)
    red = (rate[..., 0] > 0.99) & (rate[..., 1] < 0.01)
    assert 0 < red.sum() < red.size


def test_direct_and_sampler_flags_reach_the_render(tmp_path):
    """--direct light --sampler independent is the course's estimator on independent numbers:
    its image differs from the default's (MIS, Sobol'), and each flag alone changes it too."""
    images = {}
    for name, flags in (("default", []), ("light", ["--direct", "light"]),
                        ("independent", ["--sampler", "independent"])):
        output = tmp_path / f"{name}.exr"
        result = run("-s", 4, "-m", 2, "-r", 24, 18, "-q", *flags, "-f", output, SHIPPED)
        assert result.returncode == 0, result.stderr
        images[name] = read_image(output)
    assert not np.array_equal(images["default"], images["light"])
    assert not np.array_equal(images["default"], images["independent"])


def test_bvh_split_reaches_the_build_and_leaves_the_image_alone(tmp_path):
    """--bvh-split sah builds the SAH tree (the summary says so) and, the BVH's answers being
    exact whatever the tree, renders the mean split's image bit for bit."""
    images, summaries = {}, {}
    for split in ("mean", "sah"):
        output = tmp_path / f"{split}.exr"
        result = run("-s", 2, "-m", 2, "-r", 24, 18, "-q", "--bvh-split", split, "-f", output,
                     SHIPPED)
        assert result.returncode == 0, result.stderr
        images[split], summaries[split] = read_image(output), result.stdout + result.stderr
    np.testing.assert_array_equal(images["mean"], images["sah"])
    assert "accel bvh split sah build" in summaries["sah"]
    assert "accel bvh build" in summaries["mean"]


def test_hemisphere_on_a_scene_without_emitters_warns_once(tmp_path, scenes_dir):
    result = run("-H", "-r", 16, 12, "-f", tmp_path / "cow.png", scenes_dir / "meshedit/cow.dae")
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "emissive" in warnings[0]


def test_8bit_curve_matches_the_course():
    values = np.array([0.0, 0.1, 0.5, 1 / np.sqrt(2), 10.0, np.nan])
    expected = [0, int(np.floor(255 * (np.sqrt(2) * 0.1) ** (1 / 2.2))),
                int(np.floor(255 * (np.sqrt(2) * 0.5) ** (1 / 2.2))), 255, 255, 255]
    np.testing.assert_array_equal(course_8bit(values), expected)


BAD_CALLS = {
    "zero spp": (["-s", "0"], "at least 1"),
    "zero width": (["-r", "0", "10"], "at least 1"),
    "unknown accel": (["--accel", "foo"], "invalid choice"),
    "crop outside": (["-p", "700", "500", "200", "200", "--integrator", "normals"], "not inside"),
    "bad adaptive": (["-a", "32", "-1"], "positive"),
    "bad output extension": (["-f", "out.jpg"], "must end in"),
    "missing output dir": (["-f", "/nonexistent-dir/x.png"], "cannot write"),
    "missing camera file": (["-c", "/nonexistent-cam.txt", "--integrator", "normals"], "camera"),
    "zero light samples": (["-l", "0"], "at least 1"),
    "negative depth": (["-m", "-1"], "negative"),
    "unknown estimator": (["--direct", "bdpt"], "invalid choice"),
    "unknown sampler": (["--sampler", "halton"], "invalid choice"),
    "unknown split": (["--bvh-split", "median"], "invalid choice"),
    "split without bvh": (["--bvh-split", "sah", "--accel", "embree"], "only to the bvh"),
}


@pytest.mark.parametrize("name", list(BAD_CALLS))
def test_errors_are_one_line_and_exit_2(tmp_path, name):
    """The README's promise: any error a user can cause prints one line and exits with code 2."""
    args, fragment = BAD_CALLS[name]
    result = run(*args, SHIPPED, cwd=tmp_path)
    assert result.returncode == 2, (result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0], result.stderr
    assert "Traceback" not in result.stderr
    assert list(tmp_path.iterdir()) == []   # nothing written


def test_scene_errors_are_one_line_and_exit_2(tmp_path):
    """The README's promise: a bad scene file is one line naming the file, exit 2."""
    for content, fragment in [(None, "bad.dae"), ("<COLLADA><asset/>", "bad.dae"),
                              ("<notcollada/>", "COLLADA")]:
        path = tmp_path / "bad.dae"
        if content is not None:
            path.write_text(content)
        result = run("--info", path)
        assert result.returncode == 2
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and fragment in lines[0] and "Traceback" not in result.stderr
        path.unlink(missing_ok=True)


def test_ctrl_c_writes_what_was_rendered(tmp_path):
    """The README's promise (Ctrl-C, exit 130).
    Ctrl-C (once the progress bar shows samples done) writes the samples summed so far and
    exits 130: the image is the same-seed render of exactly those samples."""
    output = tmp_path / "box.exr"
    resolution = (64, 48)
    code, stdout, stderr = interrupt_once_rendering(
        ["-s", INTERRUPTED_SPP, "-m", 3, "-r", *resolution, "-f", output, SHIPPED])
    assert code == 130, stderr
    check_interrupted_render(output, INTERRUPTED_SPP, resolution, 3, stdout, stderr)


def _cache_without_the_render_kernel(cache_dir):
    """A numba cache folder (laid out as NUMBA_CACHE_DIR lays it out) holding this process's
    cached kernels of ptrace and accel except the wavefront's closest-hit stage: that stage is
    what ptrace's cold check looks for (the default loop's kernel compiled once per backend), so
    a render without it prints the cold notice and compiles only that stage (its callees load
    from the cache), not every kernel again. Returns that stage's folder in the cache."""
    import shutil

    from numba.core.caching import UserProvidedCacheLocator

    import accel.bvh
    import ptrace.integrator
    import ptrace.kernel.trace
    for module, dispatcher in ((ptrace.integrator, ptrace.integrator.surface),
                               (ptrace.kernel.trace, ptrace.kernel.trace.closest_stage),
                               (accel.bvh, accel.bvh._primitive_boxes)):
        source = dispatcher._cache._cache_path
        target = cache_dir / UserProvidedCacheLocator.get_suitable_cache_subpath(module.__file__)
        target.mkdir(parents=True, exist_ok=True)
        if os.path.isdir(source):
            for name in os.listdir(source):
                if name.endswith((".nbi", ".nbc")) and not name.startswith(
                        "trace.closest_stage-"):
                    shutil.copy2(os.path.join(source, name), target / name)
        if module is ptrace.kernel.trace:
            stage_folder = target
    return stage_folder


@pytest.mark.slow
def test_a_cold_cache_says_it_is_compiling_and_a_warm_one_does_not(tmp_path):
    """The README's promise (the first run says it compiles).
    With no render kernel in numba's cache the first render prints one line saying that it
    compiles (the first run used to sit at 0% for half a minute without a word), then how long
    compiling took, left out of the summary's seconds; the next run loads the cache and says
    nothing. (The cache starts as the session's own without the render kernel, so the test
    compiles one kernel, not all of them; with an empty session cache it compiles them all.)
    The render path-traces, so the warm run loads the shading and hit stages too, closures of
    numba functions that numba alone never finds in its cache (ptrace.jit)."""
    cache = tmp_path / "cache"
    # a cold compile measured here before: the notice quotes it, and this one replaces it
    measured = _cache_without_the_render_kernel(cache) / "ptrace-compile-seconds.json"
    measured.write_text('{"first": 12.3, "backend": 4.5}')
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    args = [sys.executable, "-m", "ptrace", "-s", "1", "-m", "2", "-r", "8", "6", "-f",
            str(tmp_path / "x.png"), str(SHIPPED)]
    cold = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    assert cold.returncode == 0, cold.stderr
    assert cold.stderr.count("ptrace: compiling kernels (first run only, about 12 s)") == 1, \
        cold.stderr
    # and then how long it took, on a line of its own, left out of the summary's seconds
    compiled = re.search(r"^ptrace: compiled kernels in ([0-9.]+) s", cold.stderr, re.M)
    assert compiled, cold.stderr
    kept = json.loads(measured.read_text())
    assert kept["backend"] == 4.5 and abs(kept["first"] - float(compiled.group(1))) <= 0.1
    render = re.search(r" render ([0-9.]+) s rays", cold.stdout)
    build = re.search(r" build ([0-9.]+) s", cold.stdout)
    assert render and build, cold.stdout
    assert float(render.group(1)) + float(build.group(1)) < float(compiled.group(1))
    warm = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    assert warm.returncode == 0 and "compil" not in warm.stderr, warm.stderr


def test_a_reader_that_leaves_early_is_no_internal_error(tmp_path):
    """`ptrace --info SCENE | head -1`: the pipe closes under ptrace, which stops quietly
    (exit 141, as a shell reports such a writer), with no traceback and no 'internal error'.
    The reader's end is closed before ptrace starts, so its first write meets the closed pipe."""
    read, write = os.pipe()
    os.close(read)
    try:
        result = subprocess.run([sys.executable, "-m", "ptrace", "--info", str(SHIPPED)],
                                stdout=write, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write)
    assert result.returncode == 141, result.stderr
    assert "internal error" not in result.stderr and "Traceback" not in result.stderr
