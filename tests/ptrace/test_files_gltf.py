"""glTF files as real exporters write them (ptrace.io.gltf, ptrace.io.gltf_materials): every
PNG colour type as colour, Draco and other required extensions refused in one line,
KHR_texture_transform applied, a metal's base-colour texture, materials matched to the JSON
by index, values the schema forbids refused naming the element, lights checked, and notes one
line per kind. Each test writes its files (files_by_hand)."""
import json
import math

import numpy as np
import pytest
from files_by_hand import QUAD, QUAD_FACES, gltf, png_bytes, quad

import ptrace
from ptrace.app.cli import grouped_notes
from ptrace.io.materials import linear_rgb
from ptrace.scene import AMBIENT, DIRECTIONAL, GLTF_PBR, SPOT

TEXTURED = {"name": "skin", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                                     "metallicFactor": 0.0}}


def load_error(path):
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    message = str(caught.value)
    assert path.name in message and "\n" not in message, message
    return message


@pytest.mark.parametrize("extension", ["gltf", "glb"])
@pytest.mark.parametrize("mode, colour, expected", [
    ("P", (255, 0, 0), (1.0, 0.0, 0.0)), ("L", 128, (128 / 255,) * 3),
    ("LA", 128, (128 / 255,) * 3), ("I;16", 65535 // 2, (0.5,) * 3),
    ("RGB", (0, 255, 0), (0.0, 1.0, 0.0))])
def test_every_png_colour_type_is_decoded_to_colour(tmp_path, extension, mode, colour,
                                                     expected):
    """A palette PNG was read as its indices (a textured box rendered grey)."""
    path = tmp_path / f"quad.{extension}"
    gltf(path, [quad(material=0)], materials=[TEXTURED], images=[png_bytes(mode, colour)])
    scene = ptrace.load(path)
    assert scene.materials.albedo_texture[0] == 0
    encoded = np.round(np.asarray(expected) * 65535).astype(np.uint16)[None, None]
    np.testing.assert_allclose(scene.textures.texels[0], linear_rgb(encoded, True)[0, 0],
                               atol=2e-3)


def draco_primitive():
    primitive = quad(material=0)
    primitive["extensions"] = {"KHR_draco_mesh_compression": {"bufferView": 0,
                                                              "attributes": {"POSITION": 0}}}
    return primitive


def test_draco_compressed_meshes_are_refused_naming_the_extension(tmp_path):
    """trimesh leaves placeholder zeros where a Draco mesh was (a black image, exit 0)."""
    path = tmp_path / "draco.gltf"
    document = gltf(path, [draco_primitive()], materials=[TEXTURED], images=[png_bytes("RGB")])
    del document["accessors"][0]["bufferView"]       # the data is only in the Draco blob
    path.write_text(json.dumps(document))
    assert "KHR_draco_mesh_compression" in load_error(path)
    document["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    path.write_text(json.dumps(document))
    assert "KHR_draco_mesh_compression" in load_error(path)


def test_an_unknown_required_extension_is_refused(tmp_path):
    path = tmp_path / "x.glb"
    gltf(path, [quad()], document={"extensionsRequired": ["EXT_made_up"],
                                   "extensionsUsed": ["EXT_made_up"]})
    assert "requires the glTF extension EXT_made_up" in load_error(path)


@pytest.mark.parametrize("text, words", [
    ("{not json", "JSON is malformed at line 1, column 2"),
    ('{"asset": {"version": "1.0"}}', "version 1.0"),
    ("[1, 2]", "not an object")])
def test_malformed_gltf_is_one_line_in_words(tmp_path, text, words):
    path = tmp_path / "model.gltf"
    path.write_text(text)
    message = load_error(path)
    assert words in message and "Error" not in message, message


def test_a_missing_buffer_is_refused_naming_it(tmp_path):
    path = tmp_path / "model.gltf"
    gltf(path, [quad()], buffer_uri="model.bin")
    (tmp_path / "model.bin").unlink()
    message = load_error(path)
    assert "buffer 0 'model.bin' was not found" in message


def test_reader_failures_inside_trimesh_are_words(tmp_path):
    """An index past its accessor (IndexError inside trimesh), a wrongly typed JSON value."""
    path = tmp_path / "index.gltf"
    gltf(path, [dict(positions=QUAD, indices=[0, 1, 99])])
    message = load_error(path)
    assert "points past the end" in message and "IndexError" not in message, message
    path = tmp_path / "types.gltf"
    gltf(path, [quad()], document={"meshes": [{"primitives": "not a list"}]})
    message = load_error(path)
    assert "could not be read as glTF" in message and "Error" not in message, message


def test_a_missing_image_is_a_note_and_the_material_keeps_its_factor(tmp_path):
    path = tmp_path / "model.gltf"
    gltf(path, [quad(material=0)], materials=[TEXTURED], images=["gone.png"])
    scene = ptrace.load(path)
    assert len(scene.textures) == 0 and scene.materials.kind[0] == GLTF_PBR
    assert any("gone.png" in n and "was not found" in n for n in scene.notes), scene.notes


def test_texture_transform_is_applied_to_the_texture_coordinates(tmp_path):
    """KHR_texture_transform: uv' = T R S uv in glTF's uv space (v down), R's sense as
    Khronos's TextureTransformTest model checks it; offset (0.5, 0.25), rotation 0.3, scale
    (0.5, 2)."""
    material = json.loads(json.dumps(TEXTURED))
    transform = {"offset": [0.5, 0.25], "rotation": 0.3, "scale": [0.5, 2.0]}
    material["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = {
        "KHR_texture_transform": transform}
    path = tmp_path / "t.glb"
    gltf(path, [quad(material=0)], materials=[material], images=[png_bytes("RGB")],
         document={"extensionsUsed": ["KHR_texture_transform"]})
    scene = ptrace.load(path)
    c, s = math.cos(0.3), math.sin(0.3)
    # the quad's corners in glTF's uv, through the extension's matrix, back to v up
    corner_uv = {(-1, -1): (0, 1), (1, -1): (1, 1), (1, 1): (1, 0), (-1, 1): (0, 0)}
    faces = scene.geometry.faces
    for f in range(len(faces)):
        for k in range(3):
            x, y, _ = scene.geometry.vertices[faces[f, k]]
            u, v = corner_uv[(round(x), round(y))]
            su, sv = 0.5 * u, 2.0 * v
            tu, tv = c * su + s * sv + 0.5, -s * su + c * sv + 0.25
            np.testing.assert_allclose(scene.uv[f, k], [tu, 1 - tv], atol=1e-6)


def test_a_metals_base_colour_texture_is_applied_as_a_texture(tmp_path):
    """glTF's BRDF takes the base colour at each point, metals included: the texture is the
    material's albedo texture and the factor its albedo, with nothing to note (before, a metal
    was a conductor of one colour, the texture's mean)."""
    material = {"name": "gold", "pbrMetallicRoughness": {
        "baseColorTexture": {"index": 0}, "metallicFactor": 1.0, "roughnessFactor": 0.3,
        "baseColorFactor": [0.5, 1.0, 1.0, 1.0]}}
    path = tmp_path / "gold.glb"
    gltf(path, [quad(material=0)], materials=[material], images=[png_bytes("RGB")])
    scene = ptrace.load(path)
    m = scene.materials
    assert m.kind[0] == GLTF_PBR and m.metallic[0] == 1.0
    assert m.albedo_texture[0] >= 0 and len(scene.textures) == 1
    np.testing.assert_allclose(m.albedo[0], [0.5, 1.0, 1.0])
    assert m.alpha[0] == pytest.approx(0.09)
    assert not any("gold" in n for n in scene.notes), scene.notes


def test_materials_of_one_name_are_each_their_own(tmp_path):
    """Materials are matched to the JSON by index: two named alike keep their own colours."""
    materials = [{"name": "paint", "pbrMetallicRoughness": {
        "baseColorFactor": [1, 0, 0, 1] if i == 0 else [0, 0, 1, 1], "metallicFactor": 0}}
        for i in range(2)]
    shifted = QUAD + [3.0, 0.0, 0.0]
    path = tmp_path / "two.glb"
    gltf(path, [quad(material=0), dict(positions=shifted, indices=QUAD_FACES.reshape(-1),
                                       material=1)], materials=materials)
    scene = ptrace.load(path)
    albedo = {tuple(scene.materials.albedo[m]) for m in set(scene.material_index.tolist())}
    assert albedo == {(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)}


@pytest.mark.parametrize("field, value, words", [
    ("baseColorFactor", [float("nan"), 0, 0, 1], "NaN"),
    ("metallicFactor", 1.5, "out of range"),
    ("roughnessFactor", -0.1, "out of range"),
    ("baseColorFactor", "red", "where a number belongs")])
def test_material_values_the_schema_forbids_are_refused(tmp_path, field, value, words):
    path = tmp_path / "bad.gltf"
    gltf(path, [quad(material=0)], materials=[{"name": "paint", "pbrMetallicRoughness": {
        field: value}}])
    message = load_error(path)
    assert "'paint'" in message and field in message and words in message, message


def lights_file(tmp_path, light, scale=(1.0, 1.0, 1.0)):
    path = tmp_path / "lit.gltf"
    nodes = [{"mesh": 0}, {"translation": [0, 2, 0], "scale": list(scale),
                           "extensions": {"KHR_lights_punctual": {"light": 0}}}]
    gltf(path, [quad()], nodes=nodes, extensions={
        "extensions": {"KHR_lights_punctual": {"lights": [light]}},
        "extensionsUsed": ["KHR_lights_punctual"]})
    return path


@pytest.mark.parametrize("light, words", [
    ({"type": "point", "intensity": -50}, "intensity -50 is out of range"),
    ({"type": "point", "intensity": float("nan")}, "NaN"),
    ({"type": "point", "color": [1, -1, 1]}, "color"),
    ({"type": "spot", "spot": {"innerConeAngle": 0.8, "outerConeAngle": 0.5}},
     "is not less than outerConeAngle"),
    ({"type": "spot", "spot": {"outerConeAngle": 2.0}}, "out of range")])
def test_lights_the_extension_forbids_are_refused_naming_the_light(tmp_path, light, words):
    message = load_error(lights_file(tmp_path, light))
    assert "light 0" in message and words in message, message


def test_a_light_whose_colour_times_intensity_passes_the_limit_is_refused(tmp_path):
    """Each factor is within 1e30 alone; 1e20 x 1e20 is not (a float32 .exr holds 3.4e38, and
    the emitters' power sums would overflow). 1e15 x 1e15 is at the limit: taken, as given."""
    message = load_error(lights_file(tmp_path, {"type": "point", "name": "lamp",
                                                "color": [1, 1e20, 1], "intensity": 1e20}))
    assert "lit.gltf" in message and "light 0 ('lamp')" in message, message
    assert "color times its intensity 1e+40 is beyond" in message, message
    scene = ptrace.load(lights_file(tmp_path, {"type": "point", "color": [1, 1e15, 0.5],
                                               "intensity": 1e15}))
    np.testing.assert_array_equal(scene.lights.radiance[0], [1e15, 1e30, 5e14])


def test_a_directional_light_on_a_zero_scale_node_is_dropped_with_a_note(tmp_path):
    """Zero scale is how glTF hides a node; the light has no direction (every sample would be
    NaN). The file then has no light: the default ambient light, noted."""
    scene = ptrace.load(lights_file(tmp_path, {"type": "directional"}, scale=(0, 0, 0)))
    assert list(scene.lights.kind) == [AMBIENT]
    assert any("zero scale" in n and "dropped" in n for n in scene.notes), scene.notes
    lit = ptrace.load(lights_file(tmp_path, {"type": "spot"}))
    assert list(lit.lights.kind) == [SPOT]
    np.testing.assert_allclose(lit.lights.direction[0], [0, 0, -1])
    np.testing.assert_allclose(lit.lights.position[0], [0, 2, 0])
    sun = ptrace.load(lights_file(tmp_path, {"type": "directional"}))
    assert list(sun.lights.kind) == [DIRECTIONAL]
    assert np.isfinite(sun.lights.direction).all()


def test_thirty_materials_give_one_note_line_per_kind(tmp_path):
    """A car with 30 materials printed 30 lines: now one per kind, with the count."""
    materials = [{"name": f"paint {i}", "pbrMetallicRoughness": {"metallicFactor": 0.7},
                  "normalTexture": {"index": 0}, "occlusionTexture": {"index": 0}}
                 for i in range(30)]
    primitives = [dict(positions=QUAD + [3.0 * i, 0, 0], indices=QUAD_FACES.reshape(-1),
                       material=i) for i in range(30)]
    path = tmp_path / "car.glb"
    gltf(path, primitives, materials=materials, images=[png_bytes("RGB")])
    lines = grouped_notes(ptrace.load(path).notes)
    about = [line for line in lines if "paint" in line]
    assert len(about) == 2, lines
    assert all("30 places" in line for line in about), about


def test_a_node_cycle_is_refused(tmp_path):
    path = tmp_path / "cycle.gltf"
    gltf(path, [quad()], nodes=[{"mesh": 0, "children": [1]}, {"children": [0]}])
    assert "cycle" in load_error(path)


def test_a_file_of_points_says_why_it_has_no_triangles(tmp_path):
    path = tmp_path / "points.glb"
    gltf(path, [quad(mode=0)])
    message = load_error(path)
    assert "no triangles" in message and "points" in message, message


def test_normalized_integer_texture_coordinates_drop_the_texture_with_a_note(tmp_path):
    """glTF allows them; trimesh reads them unscaled (every uv in the thousands): the texture
    is not applied rather than sampled at wrong places."""
    path = tmp_path / "q.glb"
    gltf(path, [quad(material=0, uv_normalized=True)], materials=[TEXTURED],
         images=[png_bytes("RGB")])
    scene = ptrace.load(path)
    assert scene.materials.albedo_texture[0] == -1
    assert any("normalized integers" in n for n in scene.notes), scene.notes


@pytest.mark.parametrize("alpha_mode", ["OPAQUE", "MASK"])
def test_an_opaque_materials_ior_is_noted_as_ignored_whatever_its_alpha_mode(tmp_path,
                                                                            alpha_mode):
    """KHR_materials_ior on an opaque (not transmissive) material: its f0 stays 0.04, said
    once, with or without an alphaMode."""
    material = {"name": "water", "alphaMode": alpha_mode,
                "extensions": {"KHR_materials_ior": {"ior": 1.33}}}
    path = tmp_path / "ior.gltf"
    gltf(path, [quad(material=0)], materials=[material])
    notes = ptrace.load(path).notes
    assert sum("KHR_materials_ior on an opaque material ignored" in n for n in notes) == 1, notes
