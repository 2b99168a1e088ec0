"""glTF's alphaMode (MASK cuts a surface out, BLEND lets rays through with probability
1 - alpha) and tangent-space normal textures, on files written here: a quad in front of a
floor under a sun straight overhead, rendered with direct light only, so that each pixel's
value has an oracle: the same file without the quad, or with it opaque, or the cosine of the
bent normal."""
import io
import json
import math

import numpy as np
import pytest
from files_by_hand import QUAD, QUAD_FACES, QUAD_UV_GLTF, gltf

import ptrace
from ptrace.app.cli import grouped_notes
from ptrace.camera import Camera

SIZE = 24
FLOOR = dict(positions=QUAD * [2.0, 2.0, 0.0] + [0.0, 0.0, -1.0],
             indices=QUAD_FACES.reshape(-1), uv=QUAD_UV_GLTF, material=0)
SUN = {"extensions": {"KHR_lights_punctual": {"lights": [{"type": "directional",
                                                          "intensity": 2.0}]}},
       "extensionsUsed": ["KHR_lights_punctual"]}
RED = {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1.0],
                                                 "metallicFactor": 0.0, "roughnessFactor": 1.0}}


def png(pixels, mode):
    import PIL.Image
    stream = io.BytesIO()
    PIL.Image.fromarray(np.asarray(pixels, np.uint8), mode).save(stream, "PNG")
    return stream.getvalue()


def write(path, front=None, images=(), floor_only=False):
    """The floor (z = -1, red) and, unless floor_only, the 2 x 2 quad at z = 0 with material
    `front`; the sun shines straight down -z (the light node's default direction)."""
    primitives = [FLOOR] if floor_only else [FLOOR, dict(positions=QUAD,
                                                         indices=QUAD_FACES.reshape(-1),
                                                         uv=QUAD_UV_GLTF, material=1)]
    nodes = [{"mesh": i} for i in range(len(primitives))]
    nodes.append({"extensions": {"KHR_lights_punctual": {"light": 0}}})
    gltf(path, primitives, materials=[RED] + ([front] if front else []), images=images,
         nodes=nodes, extensions=SUN)
    return path


def render(path, **options):
    camera = Camera(np.array([0.0, 0.0, 4.0]), np.zeros(3), np.eye(3), 0.5 * SIZE * 4.0 / 2.6,
                    SIZE, SIZE, 1e-3, 1e3)
    scene = ptrace.load(path)
    return ptrace.render(scene, camera=camera, spp=options.pop("spp", 4), max_depth=1,
                         **options), scene


def white(alpha_mode=None, **extra):
    material = {"name": "front", "pbrMetallicRoughness": {
        "baseColorFactor": extra.pop("factor", [1.0, 1.0, 1.0, 1.0]), "metallicFactor": 0.0,
        "roughnessFactor": 1.0, **extra.pop("pbr", {})}, **extra}
    if alpha_mode:
        material["alphaMode"] = alpha_mode
    return material


def quad_pixels(within=0.85):
    """(rows, columns) of the pixels whose whole footprint sees the front quad (within
    `within` of its centre in x and y), its left half and its right half (the quad spans x, y
    in [-1, 1] at distance 4; a pixel's footprint is 0.22 across there)."""
    centres = (np.arange(SIZE) + 0.5 - SIZE / 2) / (SIZE * 4.0 / 2.6 / 2) * 4.0
    inside = np.abs(centres) < within
    left = inside & (centres < -0.15)
    right = inside & (centres > 0.15)
    return inside, left, right


def test_a_mask_cut_out_everywhere_renders_as_if_the_surface_were_not_there(tmp_path):
    """alpha 0 under MASK: every ray passes, so the image is the floor's alone, bit for bit
    (the floor is hit at the same t, u, v from the same origin, and no shadow falls)."""
    cut = render(write(tmp_path / "cut.gltf", white("MASK", factor=[1, 1, 1, 0.0])))[0]
    bare = render(write(tmp_path / "bare.gltf", floor_only=True))[0]
    opaque = render(write(tmp_path / "opaque.gltf", white()))[0]
    np.testing.assert_array_equal(cut, bare)
    inside = quad_pixels()[0]
    assert not np.allclose(opaque[np.ix_(inside, inside)], bare[np.ix_(inside, inside)])


def test_a_mask_texture_cuts_where_its_alpha_is_below_the_cutoff(tmp_path):
    """The base colour texture's alpha: 0 on its left half, 1 on its right. Left of the quad
    the floor shows (as without the quad); right of it the quad (as when opaque). The
    material's alphaCutoff decides: at 0.0 nothing is cut."""
    texels = np.full((1, 4, 4), 255, np.uint8)
    texels[0, :2, 3] = 0
    image = png(texels, "RGBA")
    material = white("MASK", pbr={"baseColorTexture": {"index": 0}})
    masked, scene = render(write(tmp_path / "mask.gltf", material, images=[image]))
    bare = render(write(tmp_path / "bare.gltf", floor_only=True))[0]
    opaque = render(write(tmp_path / "opaque.gltf", white(pbr={"baseColorTexture": {"index": 0}}),
                          images=[image]))[0]
    inside, left, right = quad_pixels()
    np.testing.assert_array_equal(masked[np.ix_(inside, left)], bare[np.ix_(inside, left)])
    np.testing.assert_array_equal(masked[np.ix_(inside, right)], opaque[np.ix_(inside, right)])
    assert not any("alphaMode" in note for note in scene.notes), scene.notes
    never = dict(material, alphaCutoff=0.0)
    kept = render(write(tmp_path / "never.gltf", never, images=[image]))[0]
    np.testing.assert_array_equal(kept[np.ix_(inside, inside)], opaque[np.ix_(inside, inside)])


def test_a_cut_out_occluder_lets_the_light_through(tmp_path):
    """Seen from below the quad, the floor under a MASK quad cut out everywhere is lit as if
    nothing stood above it; under an opaque quad it is black (direct light only)."""
    camera = Camera(np.array([0.0, -4.0, -0.5]), np.array([0.0, 0.0, -1.0]),
                    np.array([[1.0, 0.0, 0.0], [0.0, 0.124, -0.992], [0.0, 0.992, 0.124]]),
                    20.0, 16, 16, 1e-3, 1e3)
    images = {}
    for name, front in (("cut", white("MASK", factor=[1, 1, 1, 0.0])), ("opaque", white()),
                        ("bare", None)):
        scene = ptrace.load(write(tmp_path / f"{name}.gltf", front, floor_only=front is None))
        images[name] = ptrace.render(scene, camera=camera, spp=2, max_depth=1)
    np.testing.assert_array_equal(images["cut"], images["bare"])
    shadowed = (images["opaque"].sum(axis=-1) == 0.0) & (images["bare"].sum(axis=-1) > 0.0)
    assert shadowed.sum() > 5, shadowed.sum()


def test_blend_passes_rays_with_probability_one_minus_alpha(tmp_path):
    """BLEND at alpha 0.25, rendered as stochastic transparency: a pixel on the quad is on
    average 0.25 of the opaque quad's value plus 0.75 of the floor's, and the floor there is
    lit through the quad with probability 0.75 too (the camera's and the shadow ray's choices
    are independent), so the mean is 0.25 quad + 0.5625 bare floor, per channel (the quad is
    white, the floor red), on pixels that see, through the quad, floor under the quad. The
    note says how BLEND is rendered."""
    blend, scene = render(write(tmp_path / "blend.gltf", white("BLEND", factor=[1, 1, 1, 0.25])),
                          spp=64)
    bare = render(write(tmp_path / "bare.gltf", floor_only=True), spp=64)[0]
    opaque = render(write(tmp_path / "opaque.gltf", white()), spp=64)[0]
    inside = quad_pixels(within=0.6)[0]
    block = np.ix_(inside, inside)
    expected = (0.25 * opaque[block].mean(axis=(0, 1))
                + 0.5625 * bare[block].mean(axis=(0, 1)))
    np.testing.assert_allclose(blend[block].mean(axis=(0, 1)), expected, rtol=0.03)
    assert any("BLEND" in line and "stochastic" in line for line in grouped_notes(scene.notes))


def test_the_same_seed_gives_the_same_blend_whatever_the_threads_and_backend(tmp_path):
    path = write(tmp_path / "blend.gltf", white("BLEND", factor=[1, 1, 1, 0.5]))
    one = render(path, threads=1)[0]
    np.testing.assert_array_equal(one, render(path, threads=2)[0])
    np.testing.assert_array_equal(one, render(path, accel="naive")[0])


def normal_png(nx, ny, nz):
    """A 2 x 2 normal texture of one tangent-space normal, encoded as glTF stores it."""
    value = np.round((np.array([nx, ny, nz]) * 0.5 + 0.5) * 255).astype(np.uint8)
    return png(np.tile(value, (2, 2, 1)), "RGB")


def sun_from(x, y):
    """The sun's node, turned so that its light comes from direction (x, y, z) (unit, z > 0):
    the node's -z axis becomes -(x, y, z)."""
    z = math.sqrt(1.0 - x * x - y * y)
    axis = np.cross([0.0, 0.0, 1.0], [x, y, z])
    half = 0.5 * math.acos(z)
    if np.linalg.norm(axis) == 0.0:
        return {"extensions": {"KHR_lights_punctual": {"light": 0}}}
    q = list(axis / np.linalg.norm(axis) * math.sin(half)) + [math.cos(half)]
    return {"rotation": q, "extensions": {"KHR_lights_punctual": {"light": 0}}}


@pytest.mark.parametrize("tilt, sun", [((0.6, 0.0), (0.0, 0.0)), ((0.0, -0.6), (0.0, 0.0)),
                                       ((0.6, 0.0), (0.5, 0.0)), ((-0.6, 0.0), (0.5, 0.0)),
                                       ((0.0, 0.6), (0.0, 0.5)), ((0.0, -0.6), (0.0, 0.5))])
def test_a_normal_texture_bends_the_shading_normal(tmp_path, tilt, sun):
    """A constant tangent-space normal (tilted along the texture's u or v: +u is +x and +v is
    +y on this quad, and the texture's green is +v) under the sun from direction l: the quad
    reflects about albedo / pi * E * (n . l), so its pixels are the untextured quad's times
    (n . l) / l.z for the decoded bent normal n, to within what glTF's BRDF adds beyond the
    diffuse (a weak rough dielectric lobe). A normal bent toward the sun is brighter than one
    bent away, which pins the tangent's and the bitangent's signs. The flat texture's
    (0, 0, 1) renders as the untextured quad, but for its 8-bit rounding."""
    (tx, ty), (lx, ly) = tilt, sun
    light = np.array([lx, ly, math.sqrt(1.0 - lx * lx - ly * ly)])

    def scene_file(name, front, images=()):
        path = write(tmp_path / name, front, images=images)
        document = json.loads(path.read_text())
        document["nodes"][-1] = sun_from(lx, ly)
        path.write_text(json.dumps(document))
        return path

    flat = render(scene_file("flat.gltf", white(normalTexture={"index": 0}),
                             [normal_png(0.0, 0.0, 1.0)]))[0]
    plain = render(scene_file("plain.gltf", white()))[0]
    bent, scene = render(scene_file("bent.gltf", white(normalTexture={"index": 0}),
                                    [normal_png(tx, ty, math.sqrt(1.0 - tx * tx - ty * ty))]))
    inside = quad_pixels()[0]
    block = np.ix_(inside, inside)

    def ratio(nx, ny):
        """(n . l) / l.z for the normal as the 8-bit texture stores it"""
        n = np.round((np.array([nx, ny, math.sqrt(1 - nx * nx - ny * ny)]) * 0.5 + 0.5)
                     * 255) / 255 * 2 - 1
        return (n @ light) / np.linalg.norm(n) / light[2]

    # the flat texel (128, 128, 255) decodes to (0.0039, 0.0039, 1), bent by 0.3 degrees
    np.testing.assert_allclose(flat[block], plain[block] * ratio(0.0, 0.0), rtol=2e-4)
    np.testing.assert_allclose(bent[block], plain[block] * ratio(tx, ty), rtol=0.02)
    assert any("normalTexture applied" in line for line in grouped_notes(scene.notes))


@pytest.mark.parametrize("tilt, sun, brighter", [((0.6, 0.0), (0.5, 0.0), False),
                                               ((0.0, 0.6), (0.0, 0.5), True)])
def test_mirrored_texture_coordinates_turn_the_tangent_not_the_bitangent(tmp_path, tilt, sun,
                                                                         brighter):
    """The quad's u mirrored (u = 1 at x = -1): the texture's +u is now -x, so a normal bent
    along +u turns away from a sun on the +x side, while +v is still +y (the bitangent keeps
    dP/dv's side, not the tangent frame's handedness)."""
    mirrored = dict(positions=QUAD, indices=QUAD_FACES.reshape(-1),
                    uv=QUAD_UV_GLTF * [-1.0, 1.0] + [1.0, 0.0], material=1)
    images = {}
    for name, front, pictures in (("plain", white(), []), ("bent", white(
            normalTexture={"index": 0}), [normal_png(*tilt, math.sqrt(1 - tilt[0] ** 2 -
                                                                      tilt[1] ** 2))])):
        path = tmp_path / f"{name}.gltf"
        gltf(path, [FLOOR, mirrored], materials=[RED, front], images=pictures,
             nodes=[{"mesh": 0}, {"mesh": 1}, sun_from(*sun)], extensions=SUN)
        images[name] = render(path)[0]
    inside = quad_pixels()[0]
    block = np.ix_(inside, inside)
    ratio = images["bent"][block].mean() / images["plain"][block].mean()
    assert (ratio > 1.05) if brighter else (ratio < 0.6), ratio


def test_a_normal_texture_scale_bends_less(tmp_path):
    """normalTexture.scale multiplies the texel's x and y: at scale 0 the texture does
    nothing."""
    image = normal_png(0.6, 0.0, 0.8)
    none = render(write(tmp_path / "none.gltf", white(normalTexture={"index": 0, "scale": 0.0}),
                        images=[image]))[0]
    plain = render(write(tmp_path / "plain.gltf", white()))[0]
    inside = quad_pixels()[0]
    np.testing.assert_allclose(none[np.ix_(inside, inside)], plain[np.ix_(inside, inside)],
                               rtol=1e-12)


def test_an_unknown_alpha_mode_is_refused_in_one_line(tmp_path):
    path = write(tmp_path / "odd.gltf", white("CUTOUT"))
    with pytest.raises(ptrace.SceneError) as error:
        ptrace.load(path)
    message = str(error.value)
    assert "odd.gltf" in message and "alphaMode" in message and "CUTOUT" in message, message
    assert "\n" not in message


def test_what_alpha_does_not_reach_is_noted(tmp_path):
    """An emitting material's alphaMode is ignored (its light is sampled over its whole
    surface, so a cut-out would make light from nowhere), and COLOR_0's alpha is not read:
    each says so once."""
    glowing = white("MASK", factor=[1, 1, 1, 0.0], emissiveFactor=[1.0, 1.0, 1.0])
    scene = ptrace.load(write(tmp_path / "glow.gltf", glowing))
    assert scene.materials.cutoff.tolist() == [0.0, 0.0]
    assert any("alphaMode MASK ignored on an emitting material" in n for n in scene.notes)
    path = tmp_path / "colours.gltf"
    front = dict(positions=QUAD, indices=QUAD_FACES.reshape(-1), uv=QUAD_UV_GLTF, material=1,
                 colours=np.tile([1.0, 1.0, 1.0, 0.5], (4, 1)))
    gltf(path, [FLOOR, front], materials=[RED, white("BLEND")],
         nodes=[{"mesh": 0}, {"mesh": 1}, {"extensions": {"KHR_lights_punctual": {"light": 0}}}],
         extensions=SUN)
    scene = ptrace.load(path)
    assert sorted(scene.materials.cutoff.tolist()) == [-1.0, 0.0]
    assert any("COLOR_0's alpha not read" in n for n in scene.notes), scene.notes
