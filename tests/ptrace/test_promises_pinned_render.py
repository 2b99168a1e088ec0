"""Promises of the rendered image, each checked against an answer computed here: a closed form
for a diffuse floor's direct light, a numpy quadrature of the light a textured quad or a sphere
sends onto it, or a second route to the same image (the Python API with the lens written out,
the same file with its surface opaque). Tiny renders, direct light only."""
import dataclasses
import functools
import json
import math
import pathlib

import numpy as np
import pytest
from files_by_hand import QUAD, QUAD_FACES, QUAD_UV_GLTF, gltf
from test_gltf_alpha_normals import FLOOR, RED, SIZE, SUN  # its floor, sun and red floor

import ptrace
from ptrace.scene import BLEND_CUT, DIFFUSE, EMISSION, Textures

from scenes_by_hand import (
    directional_light,
    floor_plane,
    looking_down,
    make_scene,
    pixel_hits_on_floor,
)

SHIPPED = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "cornell.dae"


def sub_pixel_floor_points(camera, k=4):
    """(H, W, k * k, 3): where k x k rays spread over each pixel meet y = 0."""
    ys, xs = np.mgrid[0:camera.height, 0:camera.width]
    offsets = (np.arange(k) + 0.5) / k
    points = []
    for oy in offsets:
        for ox in offsets:
            d = camera.directions(xs + ox, (camera.height - 1 - ys) + oy)
            t = -camera.position[1] / d[..., 1]
            points.append(camera.position + t[..., None] * d)
    return np.stack(points, axis=2)


# -- 1. light sampling of a textured emitter reads the texture at the sampled point -----------

def test_a_textured_emitters_light_follows_its_texture_not_its_mirror_image():
    """A 1 x 1 emissive quad at height 1 (emission 4) over a diffuse floor (albedo 0.5); its
    64 x 64 texture is white on u, v in [1/8, 1/2) (world x, z in [-3/8, 0)) and black
    elsewhere, so the floor is lit from one quadrant only. Each floor pixel is albedo / pi x
    E, E = 4 x the integral over that lit rectangle of h^2 / r^4 dA (both cosines are h / r),
    computed here by quadrature over k x k points of each pixel. The floor's four quadrants
    about the emitter's axis match it to a few percent; a texture read mirrored in u or v, or
    transposed, lights another quadrant."""
    texture = np.zeros((64, 64, 3))
    texture[32:56, 8:32] = 1.0          # rows from the top: v = 1 - (j + 0.5) / 64
    floor = floor_plane(0.5, half=3.0)
    vertices = floor["vertices"] + [[-0.5, 1.0, -0.5], [0.5, 1.0, -0.5], [0.5, 1.0, 0.5],
                                    [-0.5, 1.0, 0.5]]
    scene = make_scene(vertices=vertices, faces=floor["faces"] + [[4, 5, 6], [4, 6, 7]],
                       materials=floor["materials"] + [dict(kind=EMISSION, emission=(4, 4, 4),
                                                            emission_texture=0)],
                       material_index=[0, 0, 1, 1])
    uv = np.zeros((4, 3, 2))
    corner_uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])   # u = x + 1/2
    uv[2], uv[3] = corner_uv[[0, 1, 2]], corner_uv[[0, 2, 3]]
    scene = dataclasses.replace(scene, uv=uv, textures=Textures.from_images([texture]))
    camera = looking_down(2.5, width=24, screen_dist=10.0)
    image = ptrace.render(scene, camera=camera, resolution=(24, 24), spp=192, light_samples=2,
                          max_depth=1, seed=5)[..., 0]
    # the lit rectangle x, z in [-3/8, 0) at y = 1, by the midpoint rule
    g = (np.arange(48) + 0.5) / 48 * 0.375 - 0.375
    qx, qz = [a.reshape(-1) for a in np.meshgrid(g, g)]
    dA = (0.375 / 48) ** 2
    points = sub_pixel_floor_points(camera)
    r2 = ((points[..., 0:1] - qx) ** 2 + 1.0 + (points[..., 2:3] - qz) ** 2)
    irradiance = 4.0 * (1.0 / r2 ** 2).sum(axis=-1) * dA
    expected = (0.5 / math.pi * irradiance).mean(axis=-1)
    centre = pixel_hits_on_floor(camera)
    ray = centre - camera.position                   # where the pixel's ray crosses y = 1
    at = camera.position + ray * ((camera.position[1] - 1.0) / camera.position[1])
    floor_seen = (np.abs(at[..., 0]) > 0.6) | (np.abs(at[..., 2]) > 0.6)
    means = {}
    for sx in (-1, 1):
        for sz in (-1, 1):
            part = floor_seen & (sx * centre[..., 0] > 0) & (sz * centre[..., 2] > 0)
            means[sx, sz] = (image[part].mean(), expected[part].mean())
    for key, (got, want) in means.items():
        assert got == pytest.approx(want, rel=0.04), (key, got / want, means)
    # the lit quadrant's side is much the brighter: the test can see a mirror
    assert means[-1, -1][1] > 1.3 * max(means[1, -1][1], means[-1, 1][1])


# -- 2. stacked BLEND surfaces each take their own random number -----------------------------

def _blend_scene(alpha, stack):
    """A diffuse floor (albedo 0.5) under a directional light straight down (radiance 2), and
    black (albedo 0: they reflect nothing) BLEND surfaces of alpha `alpha` between it and the
    light: two parallel quads at y = 1 and y = 2, or a closed cube (12 triangles) over
    y in [1, 2]."""
    floor = floor_plane(0.5, half=4.0)
    vertices, faces = list(floor["vertices"]), list(floor["faces"])
    if stack == "quads":
        for y in (1.0, 2.0):
            base = len(vertices)
            vertices += [[-1.5, y, -1.5], [1.5, y, -1.5], [1.5, y, 1.5], [-1.5, y, 1.5]]
            faces += [[base, base + 2, base + 1], [base, base + 3, base + 2]]
    else:
        base = len(vertices)
        lower, upper = (-1.5, 1.0, -1.5), (1.5, 2.0, 1.5)
        vertices += [[(lower, upper)[i >> k & 1][k] for k in range(3)] for i in range(8)]
        for axis in range(3):
            for side in (0, 1):
                a, b, d, c = [base + i for i in range(8) if (i >> axis & 1) == side]
                faces += [[a, b, c], [a, c, d]]
    blend = dict(kind=DIFFUSE, albedo=(0.0, 0.0, 0.0), opacity=alpha, cutoff=BLEND_CUT)
    return make_scene(vertices=vertices, faces=faces, materials=floor["materials"] + [blend],
                      material_index=[0, 0] + [1] * (len(faces) - 2),
                      lights=[directional_light((0.0, 1.0, 0.0), 2.0)])


@pytest.mark.parametrize("stack", ["quads", "cube"])
def test_stacked_blend_surfaces_each_pass_a_ray_on_their_own(stack):
    """Seen from above through two BLEND layers of alpha 1/2 (two quads, or the top and the
    bottom faces of one closed cube), the floor shows where the camera ray passes both,
    probability (1 - a)^2, and is lit where the shadow ray passes both too, (1 - a)^2 again:
    the mean is (1 - a)^4 = 1/16 of the bare floor's albedo / pi x E (E = 2 under the light
    straight down), the layers reflecting nothing. One random number shared by the layers of
    a ray would give (1 - a)^2 = 1/4."""
    alpha = 0.5
    camera = looking_down(5.0, width=24, screen_dist=24.0)
    image = ptrace.render(_blend_scene(alpha, stack), camera=camera, resolution=(24, 24),
                          spp=256, max_depth=1, seed=3)
    floor = 0.5 / math.pi * 2.0
    points = pixel_hits_on_floor(camera)
    # pixels whose ray crosses both layers well inside the quads (|x|, |z| < 1.5 at y = 2)
    inside = (np.abs(points[..., 0]) < 1.0) & (np.abs(points[..., 2]) < 1.0)
    assert inside.sum() >= 64
    lit = image[..., 0][inside]
    assert lit.mean() == pytest.approx((1 - alpha) ** 4 * floor, rel=0.1), lit.mean() / floor


# -- 3. -b alone and -d alone make a lens -----------------------------------------------------

def _cli_image(tmp_path, name, flags):
    from ptrace.app import cli
    from ptrace.image import read_image
    output = tmp_path / f"{name}.exr"
    assert cli.main(["-q", "-s", "2", "-l", "1", "-m", "2", "-r", "32", "24", "-f",
                     str(output), *flags, str(SHIPPED)]) == 0
    return read_image(output)


def test_b_without_d_and_d_without_b_still_make_a_lens(tmp_path):
    """-b R alone is a thin lens of radius R focused at the course's default distance 4.7:
    the command line's image is the Python API's with that lens written out, and not the
    pinhole's. -d D alone keeps the camera's own lens radius (a -c file's lensRadius) and
    focuses it at D: the API's image with the file's radius and D, not the file's focus."""
    scene = ptrace.load(SHIPPED)
    course = ptrace.course_camera(scene, 32, 24)
    kwargs = dict(resolution=(32, 24), spp=2, light_samples=1, max_depth=2, seed=0)
    pinhole = ptrace.render(scene, camera=course, **kwargs)
    lens_b = ptrace.render(scene, camera=dataclasses.replace(course, lens_radius=0.1,
                                                             focal_distance=4.7), **kwargs)
    np.testing.assert_array_equal(_cli_image(tmp_path, "none", []), pinhole)
    b_only = _cli_image(tmp_path, "b", ["-b", "0.1"])
    np.testing.assert_array_equal(b_only, lens_b)
    assert np.abs(b_only - pinhole).mean() > 0.01 * pinhole.mean()
    # a camera file with its own lens (focal distance 3.5, radius 0.2)
    from ptrace.camera import load_camera_settings
    dump = tmp_path / "cam.txt"
    dump.write_text("50 40 1.33 0.1 100 0 1 4 0 1 0 0 0 4 1 10 1 0 0 0 1 0 0 0 1 800 600 700 "
                    "3.5 0.2")
    own = load_camera_settings(dump, 32, 24)
    assert (own.lens_radius, own.focal_distance) == (0.2, 3.5)
    file_focus = _cli_image(tmp_path, "c", ["-c", str(dump)])
    d_only = _cli_image(tmp_path, "d", ["-c", str(dump), "-d", "1.5"])
    expected = ptrace.render(scene, camera=dataclasses.replace(own, lens_radius=0.2,
                                                               focal_distance=1.5), **kwargs)
    np.testing.assert_array_equal(d_only, expected)
    assert not np.array_equal(d_only, file_focus)
    flat = ptrace.render(scene, camera=dataclasses.replace(own, lens_radius=0.0), **kwargs)
    assert not np.array_equal(d_only, flat)


# -- 4. and 5. glTF normal texture scale, and a MASK alpha equal to its cutoff ----------------



def _png(pixels, mode):
    import io

    import PIL.Image
    stream = io.BytesIO()
    PIL.Image.fromarray(np.asarray(pixels, np.uint8), mode).save(stream, "PNG")
    return stream.getvalue()


def _front(**extra):
    pbr = {"baseColorFactor": extra.pop("factor", [1.0, 1.0, 1.0, 1.0]), "metallicFactor": 0.0,
           "roughnessFactor": 1.0, **extra.pop("pbr", {})}
    return {"name": "front", "pbrMetallicRoughness": pbr, **extra}


def _quad_file(path, front, images=(), sun=(0.0, 0.0)):
    """A red floor at z = -1 and a 2 x 2 quad of material `front` at z = 0, under a sun whose
    light comes from direction (sx, sy, sqrt(1 - sx^2 - sy^2))."""
    sx, sy = sun
    z = math.sqrt(1.0 - sx * sx - sy * sy)
    light = {"extensions": {"KHR_lights_punctual": {"light": 0}}}
    if sx or sy:
        axis = np.cross([0.0, 0.0, 1.0], [sx, sy, z])
        half = 0.5 * math.acos(z)
        light["rotation"] = list(axis / np.linalg.norm(axis) * math.sin(half)) + [
            math.cos(half)]
    gltf(path, [FLOOR, dict(positions=QUAD, indices=QUAD_FACES.reshape(-1), uv=QUAD_UV_GLTF,
                            material=1)],
         materials=[RED, front], images=images, nodes=[{"mesh": 0}, {"mesh": 1}, light],
         extensions=SUN)
    return path


def _render_file(path, spp=4):
    from ptrace.camera import Camera
    camera = Camera(np.array([0.0, 0.0, 4.0]), np.zeros(3), np.eye(3), 0.5 * SIZE * 4.0 / 2.6,
                    SIZE, SIZE, 1e-3, 1e3)
    return ptrace.render(ptrace.load(path), camera=camera, spp=spp, max_depth=1)


def _quad_block(within=0.85):
    """The pixels whose footprint lies wholly on the front quad (x, y within `within`)."""
    centres = (np.arange(SIZE) + 0.5 - SIZE / 2) / (SIZE * 4.0 / 2.6 / 2) * 4.0
    inside = np.abs(centres) < within
    return np.ix_(inside, inside)


@pytest.mark.parametrize("scale, sun", [(0.5, (0.0, 0.0)), (2.0, (0.0, 0.0)),
                                        (0.5, (-0.5, 0.0))])
def test_a_normal_texture_scale_tilts_the_normal_by_the_scaled_amount(tmp_path, scale, sun):
    """glTF's normalTexture.scale multiplies the texel's x and y before the normal is
    normalised: texel (0.6, 0, 0.8) at scale s is n = (0.6 s, 0, 0.8) / |.|. Under a sun from
    l, the quad's diffuse light is the untextured quad's times (n . l) / l.z (computed here
    from the texel as 8 bits store it), to within the weak specular lobe glTF's BRDF adds."""
    texel = np.round((np.array([0.6, 0.0, 0.8]) * 0.5 + 0.5) * 255)
    image = _png(np.tile(texel, (2, 2, 1)), "RGB")
    bent = _render_file(_quad_file(tmp_path / "bent.gltf", _front(
        normalTexture={"index": 0, "scale": scale}), [image], sun))
    plain = _render_file(_quad_file(tmp_path / "plain.gltf", _front(), sun=sun))
    light = np.array([sun[0], sun[1], math.sqrt(1 - sun[0] ** 2 - sun[1] ** 2)])
    m = texel / 255 * 2 - 1
    n = np.array([m[0] * scale, m[1] * scale, m[2]])
    ratio = max(n @ light, 0.0) / np.linalg.norm(n) / light[2]
    block = _quad_block()
    np.testing.assert_allclose(bent[block], plain[block] * ratio, rtol=0.02)


def test_a_normal_texture_scale_tilts_a_diffuse_plane_exactly():
    """The same by hand on a Lambertian floor (albedo 0.5) under a directional light of
    radiance 2 from l = (-0.6, 0.8, 0): texel (0.6, 0, 0.8) along the floor's +u (+x) at
    scale 0.5 gives the normal n = (0.3, 0.8, 0) / |.| (y is the floor's normal), and the
    floor's value albedo / pi x 2 x (n . l), exactly (the light has no noise)."""
    floor = floor_plane(0.5, half=3.0)
    vertices = np.array(floor["vertices"], float)
    uv = (vertices[np.array(floor["faces"])][..., [0, 2]] + 3.0) / 6.0     # u = x, v = z
    texture = np.tile((np.array([0.6, 0.0, 0.8]) + 1.0) / 2.0, (2, 2, 1))
    material = dict(floor["materials"][0], normal_texture=0, normal_scale=0.5)
    light = np.array([-0.6, 0.8, 0.0])
    scene = make_scene(vertices=vertices, faces=floor["faces"], materials=[material],
                       material_index=[0, 0], lights=[directional_light(light, 2.0)])
    scene = dataclasses.replace(scene, uv=uv, textures=Textures.from_images([texture]))
    image = ptrace.render(scene, camera=looking_down(2.0, width=16), resolution=(16, 16),
                          max_depth=1)
    n = np.array([0.3, 0.8, 0.0]) / np.linalg.norm([0.3, 0.8])
    np.testing.assert_allclose(image, 0.5 / math.pi * 2.0 * (n @ light), rtol=1e-5)


@pytest.mark.parametrize("case", ["factor", "texel"])
def test_a_mask_alpha_equal_to_its_cutoff_is_opaque(tmp_path, case):
    """glTF: a MASK surface is opaque where alpha >= alphaCutoff. Alpha exactly at the cutoff
    (a baseColorFactor alpha of 0.5 with alphaCutoff 0.5; a texture whose texels' alpha is
    255 with alphaCutoff 1.0) renders as the same quad opaque, bit for bit; just above the
    cutoff it is cut away, as the bare floor."""
    if case == "factor":
        images, pbr, factor_alpha, cutoff, above = [], {}, 0.5, 0.5, 0.625
    else:
        images = [_png(np.full((2, 2, 4), 255), "RGBA")]
        pbr, factor_alpha, cutoff, above = {"baseColorTexture": {"index": 0}}, 1.0, 1.0, None
    front = _front(factor=[1.0, 1.0, 1.0, factor_alpha], pbr=pbr, alphaMode="MASK",
                   alphaCutoff=cutoff)
    masked = _render_file(_quad_file(tmp_path / "mask.gltf", front, images))
    opaque_front = _front(factor=[1.0, 1.0, 1.0, factor_alpha], pbr=pbr)
    opaque = _render_file(_quad_file(tmp_path / "opaque.gltf", opaque_front, images))
    block = _quad_block()
    np.testing.assert_array_equal(masked, opaque)
    if above is not None:
        cut = _render_file(_quad_file(tmp_path / "cut.gltf", dict(front, alphaCutoff=above)))
        assert not np.allclose(cut[block], opaque[block])
    document = json.loads((tmp_path / "mask.gltf").read_text())
    assert document["materials"][1]["alphaCutoff"] == cutoff


# -- 8. a spherical light whose centre is below the shading point's tangent plane -------------

def _sphere_irradiance(rho, centre_y, radius, steps=(300, 600)):
    """Irradiance at (rho, 0, 0) on the plane y = 0 (normal +y) from a sphere of unit radiance
    centred at (0, centre_y, 0): the integral of cos theta over the directions above the plane
    that meet the sphere, by the midpoint rule in (theta, phi)."""
    n_theta, n_phi = steps
    theta = (np.arange(n_theta) + 0.5) / n_theta * (math.pi / 2)
    phi = (np.arange(n_phi) + 0.5) / n_phi * (2 * math.pi)
    t, f = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(t) * np.cos(f), np.cos(t), np.sin(t) * np.sin(f)], axis=-1)
    oc = np.array([rho, 0.0, 0.0]) - [0.0, centre_y, 0.0]
    b = d @ oc
    c = oc @ oc - radius * radius
    hit = (b * b - c > 0) & (-b + np.sqrt(np.maximum(b * b - c, 0)) > 0)
    weight = np.cos(t) * np.sin(t) * (math.pi / 2 / n_theta) * (2 * math.pi / n_phi)
    return float((weight * hit).sum())


@functools.lru_cache(maxsize=None)
def _sphere_table(centre_y, radius):
    """(distances from the sphere's axis, _sphere_irradiance at each) for np.interp."""
    rhos = np.linspace(0.0, 5.0, 51)
    return rhos, np.array([_sphere_irradiance(r, centre_y, radius) for r in rhos])


@pytest.mark.parametrize("sampler, direct", [("all", "light"), ("bvh", "light"),
                                             ("all", "mis")])
def test_a_sphere_light_mostly_below_the_horizon_lights_the_floor_as_quadrature_says(sampler,
                                                                                     direct):
    """An emissive sphere (radius 1, radiance 3) centred 0.6 below a diffuse floor (albedo
    0.5): every floor point sees its cap above the floor, with its centre below the point's
    tangent plane. Each pixel's value is albedo / pi x 3 x the irradiance from the visible
    cap (numpy quadrature over the hemisphere, as a function of the distance from the
    sphere's axis); rings of floor pixels, and each eighth of a ring, match it to a few
    percent. With light sampling alone (direct="light"), every light sampler's choice of the
    sphere and the point it samples on it carry the whole estimate; with MIS, BSDF samples
    share it."""
    centre_y, radius = -0.6, 1.0
    floor = floor_plane(0.5, half=6.0)
    scene = make_scene(vertices=floor["vertices"], faces=floor["faces"],
                       centers=[[0.0, centre_y, 0.0]], radii=[radius],
                       materials=floor["materials"] + [dict(kind=EMISSION, emission=(3, 3, 3))],
                       material_index=[0, 0, 1])
    camera = looking_down(4.0, width=24, screen_dist=14.0)
    image = ptrace.render(scene, camera=camera, resolution=(24, 24), spp=64, light_samples=4,
                          max_depth=1, seed=11, light_sampler=sampler,
                          direct=direct)[..., 0]
    rhos, table = _sphere_table(centre_y, radius)
    points = sub_pixel_floor_points(camera, k=4)
    rho = np.hypot(points[..., 0], points[..., 2])
    expected = (0.5 / math.pi * 3.0 * np.interp(rho, rhos, table)).mean(axis=-1)
    hits = pixel_hits_on_floor(camera)
    ring, angle = np.hypot(hits[..., 0], hits[..., 2]), np.arctan2(hits[..., 2], hits[..., 0])
    # rings, and eighths of the ring 1.2 .. 2.5 (a sampler that misses part of the sphere's
    # cone can be right on average around the sphere and wrong on each side of it); pixels
    # nearer than 1.2 straddle the steep light just outside the cap's rim (0.8)
    parts = {f"ring {low}": (ring > low) & (ring < high)
             for low, high in ((1.2, 1.6), (1.6, 2.2), (2.2, 3.0))}
    for k in range(8):
        parts[f"eighth {k}"] = ((ring > 1.2) & (ring < 2.5) & (angle >= k * math.pi / 4 - math.pi)
                                & (angle < (k + 1) * math.pi / 4 - math.pi))
    for name, part in parts.items():
        assert part.sum() > 15, (name, part.sum())
        assert image[part].mean() == pytest.approx(expected[part].mean(), rel=0.04), (
            name, image[part].mean() / expected[part].mean())
