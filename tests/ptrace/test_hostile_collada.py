"""COLLADA values out of range are refused with one line naming the element: negative colours
(lights, emission, reflectance, transmittance, diffuse, conductor eta and k), ior and alpha that
are not positive, a negative roughness, an area light scaled to nothing, znear >= zfar. NaN and
infinities are refused by the document reader already (one case each here, so that stays so).
The course's own files hold none of these: they load unchanged (test_load_course_scenes.py) and
their values are checked against the same rules below."""
import glob
import json

import numpy as np
import pytest

import ptrace
from ptrace.scene import MICROFACET

from conftest import scenes_root

SPHERES, MICRO = "sky/CBspheres.dae", "sky/CBspheres_microfacet_al_ag.dae"
PLANE = "simple/plane.dae"
AREA_COLOUR = '<area>\n            <color sid="color">10 10 10</color>'   # the CGL light in use

# (name, scene, text, replacement, fragments of the one-line error)
CASES = [
    ("negative light colour", SPHERES, AREA_COLOUR, AREA_COLOUR.replace("10 10", "10 -10"),
     ["negative light colour", "<color"]),
    ("NaN light colour", SPHERES, AREA_COLOUR, AREA_COLOUR.replace("10 10", "10 nan"),
     ["NaN or infinite"]),
    ("negative diffuse", PLANE, '<color sid="diffuse">0.6 0.6 0.6 1</color>',
     '<color sid="diffuse">0.6 -0.6 0.6 1</color>', ["negative colour"]),
    ("negative emission", SPHERES, "<radiance>10 10 10</radiance>",
     "<radiance>-1 10 10</radiance>", ["negative radiance", "<radiance>"]),
    ("negative transmittance", SPHERES, "<transmittance>1 1 1</transmittance>",
     "<transmittance>1 -1 1</transmittance>", ["negative transmittance"]),
    ("zero ior", SPHERES, "<ior>1.45</ior>", "<ior>0</ior>", ["ior 0 must be greater than 0"]),
    ("negative ior", SPHERES, "<ior>1.45</ior>", "<ior>-1.45</ior>", ["ior -1.45"]),
    ("infinite ior", SPHERES, "<ior>1.45</ior>", "<ior>inf</ior>", ["NaN or infinite"]),
    ("negative roughness", SPHERES, "<roughness>0</roughness>", "<roughness>-1</roughness>",
     ["roughness -1 must be at least 0"]),
    ("zero alpha", MICRO, "<alpha>0.025</alpha>", "<alpha>0</alpha>",
     ["alpha 0 must be greater than 0"]),
    ("negative eta", MICRO, "<eta>1.3352 1.0109 0.68955</eta>",
     "<eta>-1.3352 1.0109 0.68955</eta>", ["negative eta"]),
    ("znear past zfar", SPHERES, '<znear sid="znear">0.1</znear>',
     '<znear sid="znear">200</znear>', ["znear 200 and zfar 100", "<perspective"]),
    ("znear equal to zfar", SPHERES, '<zfar sid="zfar">100</zfar>',
     '<zfar sid="zfar">0.1</zfar>', ["0 <= znear < zfar"]),
    ("negative znear", SPHERES, '<znear sid="znear">0.1</znear>',
     '<znear sid="znear">-1</znear>', ["znear -1"]),
]


@pytest.mark.parametrize("name, relpath, old, new, fragments", CASES, ids=[c[0] for c in CASES])
def test_out_of_range_values_are_refused_naming_the_element(tmp_path, course_scene, name,
                                                            relpath, old, new, fragments):
    text = course_scene(relpath).read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "bad.dae"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{path}: ")
    for fragment in fragments:
        assert fragment in message, message


def test_an_area_light_scaled_to_nothing_is_refused(tmp_path, course_scene):
    text = course_scene(SPHERES).read_text(encoding="utf-8")
    start = text.index("<area>")
    # the area light's node: its instance_light names the light; scale its x axis to 0
    light_id = text[text.rindex('<light id="', 0, start) + 11:].split('"', 1)[0]
    instance = text.index(f'<instance_light url="#{light_id}"')
    matrix_start = text.rindex('<matrix sid="transform">', 0, instance)
    matrix_end = text.index("</matrix>", matrix_start)
    numbers = text[matrix_start + len('<matrix sid="transform">'):matrix_end].split()
    numbers[0] = numbers[4] = numbers[8] = "0"   # the first column: the light's x edge
    path = tmp_path / "flat.dae"
    path.write_text(text[:matrix_start] + '<matrix sid="transform">' + " ".join(numbers)
                    + text[matrix_end:], encoding="utf-8")
    with pytest.raises(ptrace.SceneError, match="zero area|zero length"):
        ptrace.load(path)


def test_the_course_files_are_inside_the_rules():
    """The rules refuse nothing the course relies on: every course scene loads, and its values
    are what the rules allow (so the loader returns them unchanged)."""
    files = sorted(glob.glob(str(scenes_root() / "**" / "*.dae"), recursive=True))
    assert len(files) >= 20
    for file in files:
        scene = ptrace.load(file)
        assert (np.asarray(scene.lights.radiance) >= 0).all(), file
        materials = scene.materials
        for name in ("albedo", "transmittance", "emission", "eta", "k"):
            assert (getattr(materials, name) >= 0).all(), (file, name)
        assert (materials.ior > 0).all() and (materials.roughness >= 0).all(), file
        assert (materials.alpha[materials.kind == MICROFACET] > 0).all(), file
        if scene.camera is not None:
            assert 0 <= scene.camera.znear < scene.camera.zfar, file


@pytest.mark.parametrize("old, new, words", [
    ("<zfar>100</zfar>", "<zfar>0.5</zfar>", "zfar 0.5"),
    ("<znear>0.1</znear>", "<znear>50</znear>", "znear 50"),
])
def test_a_collada_camera_whose_rays_cannot_reach_the_scene_is_noted(tmp_path, capsys, old,
                                                                      new, words):
    """The shipped Cornell box with its camera's zfar short of the box, or its znear past it:
    the render would show nothing of the scene, and one note says so, naming the file."""
    from pathlib import Path

    from ptrace.app.cli import main
    text = (Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae").read_text()
    assert old in text
    path = tmp_path / "cornell.dae"
    path.write_text(text.replace(old, new))
    assert main(["--info", str(path)]) == 0
    notes = [n for n in json.loads(capsys.readouterr().out)["notes"] if "not seen" in n]
    assert len(notes) == 1 and words in notes[0] and str(path) in notes[0], notes
