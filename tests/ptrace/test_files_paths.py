"""Files a model names are read only from its own folder and only if they are regular files
(ptrace.io.files): `../outside.png`, absolute paths, symbolic links out of the folder and
FIFOs are refused with a note (or, for what the geometry needs, an error); nothing hangs."""
import os
import threading

import numpy as np
import pytest
from files_by_hand import gltf, png_bytes, quad

import ptrace

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"


def load_within(path, seconds=60):
    """ptrace.load(path) in a thread that must finish within `seconds` (a FIFO opened for
    reading would block it forever); the result, or the SceneError raised."""
    out = {}

    def run():
        try:
            out["scene"] = ptrace.load(path)
        except ptrace.SceneError as error:
            out["error"] = error
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():     # release it before failing: a writer unblocks the open
        for fifo in path.parent.rglob("*"):
            if fifo.is_fifo():
                try:
                    os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
                except OSError:
                    pass
        pytest.fail(f"loading {path.name} did not finish in {seconds} s")
    return out.get("scene"), out.get("error")


def model(tmp_path, field, reference):
    folder = tmp_path / "model"
    folder.mkdir()
    kind = "Ke 1 1 1" if field == "map_Ke" else "Kd 1 1 1"
    (folder / "m.mtl").write_text(f"newmtl m\n{kind}\n{field} {reference}\n")
    path = folder / "m.obj"
    path.write_text("mtllib m.mtl\nusemtl m\n" + TRIANGLE)
    return path


@pytest.mark.parametrize("field", ["map_Kd", "map_Ke"])
@pytest.mark.parametrize("reference, words", [
    ("../outside.png", "is outside the model's folder"),
    ("sub/../../outside.png", "is outside the model's folder"),
    ("link.png", "is outside the model's folder"),
    ("fifo.png", "FIFO"),
    ("{absolute}", "was not found in the model's folder")])
def test_a_texture_outside_the_folder_or_not_a_file_is_refused(tmp_path, field, reference,
                                                                 words):
    """map_Ke read any path (`../outside.png`, absolute paths); a FIFO hung the loader."""
    (tmp_path / "outside.png").write_bytes(png_bytes("RGB"))
    absolute = str(tmp_path / "outside.png")
    path = model(tmp_path, field, reference.format(absolute=absolute))
    os.symlink(tmp_path / "outside.png", path.parent / "link.png")
    os.mkfifo(path.parent / "fifo.png")
    scene, error = load_within(path)
    assert error is None, error
    assert len(scene.textures) == 0
    assert any(words in note and field in note for note in scene.notes), scene.notes


def test_an_absolute_path_is_read_by_its_base_name_from_the_folder(tmp_path):
    path = model(tmp_path, "map_Kd", r"C:\Users\someone\textures\skin.png")
    (path.parent / "skin.png").write_bytes(png_bytes("RGB", (0, 0, 255)))
    scene = ptrace.load(path)
    assert len(scene.textures) == 1
    np.testing.assert_allclose(scene.textures.texels[0], [0, 0, 1], atol=1e-4)
    assert any("absolute path" in note for note in scene.notes), scene.notes


def test_a_fifo_as_the_mtl_is_a_note_not_a_hang(tmp_path):
    path = model(tmp_path, "map_Kd", "x.png")
    (path.parent / "m.mtl").unlink()
    os.mkfifo(path.parent / "m.mtl")
    scene, error = load_within(path)
    assert error is None and any("FIFO" in n for n in scene.notes), (error, scene.notes)


@pytest.mark.parametrize("name", ["scene.obj", "scene.gltf", "scene.ply", "scene.dae"])
def test_a_fifo_as_the_scene_is_refused(tmp_path, name):
    os.mkfifo(tmp_path / name)
    scene, error = load_within(tmp_path / name)
    assert error is not None and "FIFO" in str(error), error


def test_gltf_images_and_buffers_that_are_fifos_or_outside_are_refused(tmp_path):
    folder = tmp_path / "model"
    folder.mkdir()
    os.mkfifo(folder / "fifo.png")
    (tmp_path / "outside.png").write_bytes(png_bytes("RGB"))
    material = {"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                                      "metallicFactor": 0}}
    path = folder / "image.gltf"
    gltf(path, [quad(material=0)], materials=[material, dict(material, name="n")],
         images=["fifo.png", "../outside.png"],
         textures=[{"source": 0}, {"source": 1}])
    scene, error = load_within(path)
    assert error is None and len(scene.textures) == 0, error
    assert any("FIFO" in n for n in scene.notes), scene.notes
    buffer = folder / "buffer.gltf"
    gltf(buffer, [quad()], buffer_uri="data.bin")
    (folder / "data.bin").unlink()
    os.mkfifo(folder / "data.bin")
    scene, error = load_within(buffer)
    assert error is not None and "FIFO" in str(error) and "buffer 0" in str(error), error
