"""Materials, textures and lights that mesh files carry: the texture
lookup, what each file field becomes, and the physical lights of glTF."""
import dataclasses
import json
import math
import pathlib
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest
import trimesh

import ptrace
from ptrace.app.cli import scene_info
from ptrace.bsdf import conductor_fresnel
from ptrace.io.materials import conductor_from_colour, linear_rgb
from ptrace.scene import (
    CLAMP,
    DIFFUSE,
    EMISSION,
    GLASS,
    GLOSSY,
    GLTF_PBR,
    MICROFACET,
    MIRROR_REPEAT,
    PHYSICAL,
    POINT,
    REPEAT,
    SPOT,
    Textures,
)
from ptrace.textures import texture_lookup

from scenes_by_hand import floor_plane, looking_down, make_scene, pixel_hits_on_floor

ROOT = pathlib.Path(__file__).resolve().parents[2]
FILES = ROOT / "scenes" / "files"


def lookup(textures, t, s, v):
    return np.array(texture_lookup(textures.texels, textures.offset, textures.width,
                                   textures.height, textures.wrap, t, s, v))


def test_bilinear_lookup_hits_texel_centres_and_blends_between_them():
    """Texel (i, j) (row j from the top) sits at u = (i + 0.5) / W, v = 1 - (j + 0.5) / H; half
    way between two centres is their mean; a second texture is found at its offset."""
    rng = np.random.default_rng(0)
    first, second = rng.random((3, 4, 3)), rng.random((2, 5, 3))
    textures = Textures.from_images([first, second])
    for t, image in ((0, first), (1, second)):
        h, w = image.shape[:2]
        for j in range(h):
            for i in range(w):
                np.testing.assert_allclose(lookup(textures, t, (i + 0.5) / w, 1 - (j + 0.5) / h),
                                           image[j, i], rtol=1e-6)
    np.testing.assert_allclose(lookup(textures, 0, 1.0 / 4, 1 - 0.5 / 3),
                               0.5 * (first[0, 0] + first[0, 1]), rtol=1e-6)
    np.testing.assert_allclose(lookup(textures, 0, 0.5 / 4, 1 - 1.0 / 3),
                               0.5 * (first[0, 0] + first[1, 0]), rtol=1e-6)


@pytest.mark.parametrize("mode", [REPEAT, CLAMP, MIRROR_REPEAT])
def test_wrap_modes(mode):
    """Outside [0, 1]: repeat is periodic, clamp holds the edge texel, mirror reflects."""
    image = np.arange(4 * 3, dtype=np.float64).reshape(1, 4, 3)   # one row of 4 texels
    textures = Textures.from_images([image], wraps=[(mode, mode)])
    centre = lambda i: (i + 0.5) / 4   # noqa: E731
    below = lookup(textures, 0, centre(0) - 1.0, 0.5)         # a period to the left
    beyond = lookup(textures, 0, 1.0 + centre(1), 0.5)        # past the right edge
    if mode == REPEAT:
        np.testing.assert_allclose(below, image[0, 0])
        np.testing.assert_allclose(beyond, image[0, 1])
    elif mode == CLAMP:
        np.testing.assert_allclose(below, image[0, 0])
        np.testing.assert_allclose(beyond, image[0, 3])
    else:
        np.testing.assert_allclose(below, image[0, 3])   # [-1, 0) mirrors [0, 1)
        np.testing.assert_allclose(beyond, image[0, 2])


def test_srgb_textures_are_decoded_to_linear():
    """8-bit colour textures are sRGB: 188/255 is about 0.5 linear; linear data stays as is."""
    pixels = np.full((1, 1, 3), 188, np.uint8)
    assert linear_rgb(pixels, srgb=True)[0, 0, 0] == pytest.approx(0.5029, abs=2e-3)
    assert linear_rgb(pixels, srgb=False)[0, 0, 0] == pytest.approx(188 / 255, abs=1e-6)


def test_conductor_from_colour_reflects_the_colour_at_normal_incidence():
    colour = (0.95, 0.64, 0.54)
    eta, k = conductor_from_colour(colour)
    for c in range(3):
        assert conductor_fresnel(eta[c], k[c], 1.0) == pytest.approx(colour[c], rel=1e-9)


def textured_quad_scene(tmp_path, extension):
    """A unit quad facing +Z, texture coordinates (0, 0) bottom left to (1, 1) top right, whose
    texture is red in its top half and blue in its bottom half, written through trimesh."""
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    mesh = trimesh.Trimesh(vertices=vertices, faces=[[0, 1, 2], [0, 2, 3]], process=False)
    image = np.zeros((64, 64, 3), np.uint8)   # fine, so that bilinear blends only at v = 1/2
    image[:32, :, 0] = 255     # top rows red
    image[32:, :, 2] = 255     # bottom rows blue
    import PIL.Image
    texture = PIL.Image.fromarray(image)
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    if extension == "obj":
        material = trimesh.visual.material.SimpleMaterial(image=texture, diffuse=(255,) * 4)
    else:
        material = trimesh.visual.material.PBRMaterial(
            name="quad", baseColorTexture=texture, baseColorFactor=[1.0, 1.0, 1.0, 1.0],
            metallicFactor=0.0)
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    path = tmp_path / f"quad.{extension}"
    mesh.export(path)
    return path


@pytest.mark.parametrize("extension", ["obj", "glb"])
def test_texture_orientation_end_to_end(tmp_path, extension):
    """The image's top row is at the top of the surface (v = 1), for OBJ and glTF alike (they
    count v from opposite ends; trimesh gives both as OBJ's)."""
    scene = ptrace.load(textured_quad_scene(tmp_path, extension))
    assert len(scene.textures) == 1 and scene.materials.albedo_texture[0] == 0
    image = ptrace.render(scene, resolution=(40, 30), spp=4)
    rows = image[:, 20]
    lit = rows.sum(axis=1) > 0
    top, bottom = rows[lit][: lit.sum() // 3], rows[lit][-lit.sum() // 3:]
    # (the glTF quad is a dielectric: a faint white coat over the texture)
    assert (top[:, 0] > 3 * top[:, 2]).all() and (top[:, 1] <= top[:, 2]).all()
    assert (bottom[:, 2] > 3 * bottom[:, 0]).all() and (bottom[:, 1] <= bottom[:, 0]).all()


def test_room_obj_fields_become_ptrace_materials():
    """scenes/files/room.obj + .mtl: map_Kd, Kd, Ke + map_Ke, Ks + Ns, Ni + illum 7."""
    scene = ptrace.load(FILES / "room.obj")
    by_name = {name: i for i, name in enumerate(scene.materials.names)}
    m = scene.materials
    floor, wall, light, gold, glass = (by_name[n] for n in ("floor", "wall", "light", "gold",
                                                            "glass"))
    assert m.kind[floor] == DIFFUSE and m.albedo_texture[floor] >= 0
    assert m.kind[wall] == DIFFUSE and m.albedo_texture[wall] == -1
    np.testing.assert_allclose(m.albedo[wall], [0.7, 0.12, 0.1])
    assert m.kind[light] == EMISSION and m.emission_texture[light] >= 0
    np.testing.assert_allclose(m.emission[light], [6, 6, 6])
    assert m.kind[gold] == MICROFACET
    assert m.alpha[gold] == pytest.approx(math.sqrt(2 / 152))
    for c, ks in enumerate((1.0, 0.71, 0.29)):
        assert conductor_fresnel(m.eta[gold, c], m.k[gold, c], 1.0) == pytest.approx(
            min(ks, 0.999), rel=1e-6)
    assert m.kind[glass] == GLASS and m.ior[glass] == 1.5
    # texture coordinates reach the floor's corners: (0, 0) .. (1, 1)
    floor_faces = scene.material_index == floor
    assert scene.uv[floor_faces].min() == 0.0 and scene.uv[floor_faces].max() == 1.0
    assert len(scene.lights) == 0      # an emitter: no default ambient light


def test_pbr_glb_fields_and_lights():
    """scenes/files/pbr.glb: base colour texture, metallic + roughness texture, emissive
    texture with KHR_materials_emissive_strength, KHR_materials_transmission + ior, and
    KHR_lights_punctual spot and point lights of the physical model, placed by their nodes."""
    scene = ptrace.load(FILES / "pbr.glb")
    m = scene.materials
    by_name = {name: i for i, name in enumerate(m.names)}
    floor, metal, panel, glass = (by_name[n] for n in ("floor", "metal", "panel", "glass"))
    # glTF's BRDF: a dielectric (metallic 0) with its base colour texture, a metal whose
    # metallicRoughnessTexture scales roughness (G) and metallic (B)
    assert m.kind[floor] == GLTF_PBR and m.albedo_texture[floor] >= 0
    assert m.metallic[floor] == 0.0 and m.alpha[floor] == pytest.approx(1.0)
    assert m.kind[metal] == GLTF_PBR and m.roughness_texture[metal] >= 0
    assert m.metallic[metal] == 1.0
    assert m.alpha[metal] == pytest.approx(1.0)    # roughnessFactor 1, squared
    # an emissive material emits and still reflects (its black base colour)
    assert m.kind[panel] == GLTF_PBR and m.emission_texture[panel] >= 0 and m.emits()[panel]
    np.testing.assert_allclose(m.emission[panel], [2, 2, 2])   # factor 1 x strength 2
    assert m.kind[glass] == GLASS and m.ior[glass] == pytest.approx(1.5)
    # the base colour as the file says it (trimesh's exporter wrote 0.9 as 230/255)
    np.testing.assert_allclose(m.transmittance[glass], [0.9, 1.0, 0.95], atol=1 / 255)
    lights = scene.lights
    assert sorted(lights.kind.tolist()) == sorted([SPOT, POINT])
    assert (lights.model == PHYSICAL).all()
    spot = int(np.nonzero(lights.kind == SPOT)[0][0])
    np.testing.assert_allclose(lights.position[spot], [0.0, 2.5, 0.2], atol=1e-6)
    np.testing.assert_allclose(lights.direction[spot], [0.0, -1.0, 0.0], atol=1e-6)
    assert lights.cos_inner[spot] == pytest.approx(math.cos(0.35))
    assert lights.cos_outer[spot] == pytest.approx(math.cos(0.6))
    np.testing.assert_allclose(lights.radiance[spot], np.array([1.0, 0.95, 0.85]) * 12)


def test_info_says_each_lights_model():
    out = subprocess.run([sys.executable, "-m", "ptrace", "--info", str(FILES / "pbr.glb")],
                         capture_output=True, text=True, check=True).stdout
    info = json.loads(out)
    models = {light["type"]: light["model"] for light in info["lights"]}
    assert models["point"].startswith("physical") and models["spot"].startswith("physical")
    assert any("metallicRoughnessTexture" in t for t in info["textures"])
    course = scene_info(ptrace.load(ROOT / "scenes" / "cornell.dae"))
    assert all(light.get("model", "course").startswith("course") for light in course["lights"])


def physical_light(kind, position, radiance, direction=(0, -1, 0), inner=0.0, outer=0.0):
    return dict(kind=kind, radiance=(radiance,) * 3, position=position, direction=direction,
                model=PHYSICAL, cos_inner=math.cos(inner), cos_outer=math.cos(outer))


def test_physical_point_light_falls_off_with_the_squared_distance():
    """A diffuse plane under a glTF point light of intensity I at height h: L = a I cos / (pi
    r^2), exactly (one light sample, no noise)."""
    albedo, intensity, height = 0.6, 3.0, 1.5
    scene = make_scene(**floor_plane(albedo),
                       lights=[physical_light(POINT, (0, height, 0), intensity)])
    camera = looking_down(4.0)
    image = ptrace.render(scene, camera=camera, resolution=(32, 32), max_depth=1)
    hit = pixel_hits_on_floor(camera)
    r2 = np.sum((hit - [0, height, 0]) ** 2, axis=-1)
    expected = albedo / math.pi * intensity * (height / np.sqrt(r2)) / r2
    np.testing.assert_allclose(image[..., 0], expected, rtol=1e-5)


def test_spot_cone_lights_inside_and_falls_off_between_its_angles():
    """A spot pointing down from height h: full intensity inside the inner cone, none outside
    the outer cone, the squared linear ramp in cos theta between."""
    albedo, intensity, height = 0.5, 2.0, 1.0
    inner, outer = math.radians(20), math.radians(40)
    scene = make_scene(**floor_plane(albedo),
                       lights=[physical_light(SPOT, (0, height, 0), intensity, inner=inner,
                                              outer=outer)])
    camera = looking_down(2.0, width=64)
    image = ptrace.render(scene, camera=camera, resolution=(64, 64), max_depth=1)
    hit = pixel_hits_on_floor(camera)
    to_point = hit - [0, height, 0]
    r2 = np.sum(to_point ** 2, axis=-1)
    cos_axis = height / np.sqrt(r2)
    ramp = np.clip((cos_axis - math.cos(outer)) / (math.cos(inner) - math.cos(outer)), 0, 1)
    expected = albedo / math.pi * intensity * cos_axis / r2 * ramp ** 2
    np.testing.assert_allclose(image[..., 0], expected, rtol=1e-5, atol=1e-12)
    assert (image[..., 0][cos_axis < math.cos(outer)] == 0).all()
    assert (expected > 0).sum() > 100 and (expected == 0).sum() > 100


def test_vertex_colours_are_the_albedo(tmp_path):
    """A PLY with vertex colours renders them (sRGB decoded) as a diffuse albedo: under an
    ambient light a flat colour's quad is that colour times what the albedo 1 quad gets."""
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    colours = np.array([[255, 128, 0, 255]] * 4, np.uint8)
    renders = []
    for vertex_colors in (colours, np.full((4, 4), 255, np.uint8)):
        mesh = trimesh.Trimesh(vertices=vertices, faces=[[0, 1, 2], [0, 2, 3]], process=False,
                               vertex_colors=vertex_colors)
        path = tmp_path / "quad.ply"
        mesh.export(path)
        renders.append(ptrace.render(ptrace.load(path), resolution=(20, 15), spp=4, seed=3))
    coloured, white = renders
    lit = white[..., 0] > 0
    expected = linear_rgb(colours[None, :1, :3], srgb=True)[0, 0]
    for c in range(3):
        np.testing.assert_allclose(coloured[..., c][lit], expected[c] * white[..., c][lit],
                                   rtol=1e-4, atol=1e-7)


def emitter_over_floor(texture):
    """A floor lit only by an emissive quad above it whose emission is textured."""
    floor = floor_plane(0.5, half=3.0)
    vertices = floor["vertices"] + [[-0.5, 1.0, -0.5], [0.5, 1.0, -0.5], [0.5, 1.0, 0.5],
                                    [-0.5, 1.0, 0.5]]
    faces = floor["faces"] + [[4, 5, 6], [4, 6, 7]]
    scene = make_scene(vertices=vertices, faces=faces,
                       materials=floor["materials"] + [dict(kind=EMISSION, emission=(4, 4, 4),
                                                            emission_texture=0)],
                       material_index=[0, 0, 1, 1])
    uv = np.zeros((4, 3, 2))
    corner_uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    uv[2], uv[3] = corner_uv[[0, 1, 2]], corner_uv[[0, 2, 3]]
    return dataclasses.replace(scene, uv=uv, textures=Textures.from_images([texture]))


def test_textured_emitter_light_sampling_agrees_with_bsdf_sampling():
    """Light sampling reads the emission texture at the sampled point; BSDF sampling at the
    point its ray finds. Hemisphere sampling (-H, BSDF rays alone) and light sampling with
    multiple importance sampling must give the same floor, within noise; and the emitter
    seen directly is its emission times its texture."""
    texture = np.zeros((16, 16, 3))     # a checker of four 8 x 8 blocks: red-orange, blue
    texture[:8, :8] = texture[8:, 8:] = (1.0, 0.2, 0.0)
    texture[:8, 8:] = texture[8:, :8] = (0.0, 0.3, 1.0)
    scene = emitter_over_floor(texture)
    camera = looking_down(2.5, width=24, screen_dist=12.0)
    light = ptrace.render(scene, camera=camera, resolution=(24, 24), spp=512, light_samples=1,
                          max_depth=1, seed=1)
    hemi = ptrace.render(scene, camera=camera, resolution=(24, 24), spp=512, light_samples=4,
                         max_depth=1, hemisphere=True, seed=2)
    floor = np.ones((24, 24), bool)
    floor[6:18, 6:18] = False            # the emitter's own pixels and their edge
    for c in range(3):
        a, b = light[..., c][floor].mean(), hemi[..., c][floor].mean()
        assert a == pytest.approx(b, rel=0.03), (c, a, b)
    # red-orange and blue texels light different sides of the floor differently
    assert light[2, 2, 0] != pytest.approx(light[2, 21, 0], rel=0.05)
    # the emitter seen from above: 4 x its texels (nearest the centres of its quadrants)
    seen = light[8:16, 8:16]
    assert seen[..., 0].max() == pytest.approx(4.0, rel=1e-3)
    assert seen[..., 2].max() == pytest.approx(4.0, rel=1e-3)


def test_mesh_file_renders_and_its_notes_name_what_was_ignored(tmp_path):
    """The shipped pbr.glb renders with its own lights (no default ambient light) and its
    notes say what was approximated (intensity units), and nothing of its materials: an
    emissive one reflects as well (glTF's BRDF), none is approximated."""
    out = tmp_path / "pbr.png"
    run = subprocess.run([sys.executable, "-m", "ptrace", "-s", "4", "-r", "64", "48", "-f",
                          str(out), str(FILES / "pbr.glb")], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    notes = [line for line in run.stderr.splitlines() if line.startswith("ptrace: note:")]
    assert not any("material" in n for n in notes), notes
    assert any("KHR_lights_punctual" in n for n in notes), notes
    assert not any("ambient light" in n for n in notes), notes
    image = oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)
    assert image.mean() > 0.03   # lit by its lights: its emitters alone (-m 0) give 0.016


def test_obj_diffuse_with_specular_is_a_glossy_coat(tmp_path):
    """Kd with Ks: the base Kd under a glossy coat of normal reflectance Ks, alpha from Ns."""
    (tmp_path / "plastic.mtl").write_text("newmtl plastic\nKd 0.6 0.2 0.1\nKs 0.05 0.05 0.05\n"
                                          "Ns 98\n")
    (tmp_path / "plastic.obj").write_text("mtllib plastic.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                          "usemtl plastic\nf 1 2 3\n")
    m = ptrace.load(tmp_path / "plastic.obj").materials
    assert m.kind[0] == GLOSSY
    np.testing.assert_allclose(m.albedo[0], [0.6, 0.2, 0.1])
    np.testing.assert_allclose(m.specular[0], 0.05)
    assert m.alpha[0] == pytest.approx(math.sqrt(2 / 100))


def test_gltf_texture_reference_options_are_noted(tmp_path):
    """A texture reference's own extension that ptrace does not read, and a second texCoord
    set, are each a note, not silence (KHR_texture_transform is applied: test_files_gltf)."""
    path = textured_quad_scene(tmp_path, "glb")
    from ptrace.io.gltf import read_document
    document, _ = read_document(str(path), path.read_bytes())
    ref = document["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]
    ref["extensions"] = {"EXT_made_up": {"scale": [2, 2]}}
    ref["texCoord"] = 1
    import struct
    data = path.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + data[20 + length:]
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    notes = ptrace.load(path).notes
    assert any("baseColorTexture's EXT_made_up ignored" in n for n in notes), notes
    assert any("texture coordinate set 1" in n for n in notes), notes
