"""glTF's metallic-roughness BRDF in rendering (material kind GLTF_PBR): what the glTF loader
makes of a material's factors and its metallicRoughness texture, a white furnace of a rough
white metal sphere against an independent quadrature of the specification's formulas, and an
emissive glTF material that emits as an emitter does and reflects as well."""
import math

import numpy as np
import pytest
from files_by_hand import gltf, png_bytes, quad
from numba import njit

import ptrace
from ptrace.camera import Camera
from ptrace.emitters import emitter_arrays
from ptrace.environment import Environment
from ptrace.integrator import scene_records
from ptrace.scene import EMISSION, GLTF_PBR
from ptrace.textures import surface_albedo

from scenes_by_hand import floor_plane, looking_down, make_scene


def test_a_metallic_roughness_material_becomes_gltf_pbr_with_its_values(tmp_path):
    """metallic 0.3 is kept as 0.3 (blended by the BRDF, not rounded to a dielectric), alpha
    is roughness squared, the base colour factor the albedo; nothing is noted about it."""
    material = {"name": "paint", "pbrMetallicRoughness": {
        "baseColorFactor": [0.8, 0.4, 0.2, 1.0], "metallicFactor": 0.3, "roughnessFactor": 0.5}}
    path = tmp_path / "paint.gltf"
    gltf(path, [quad(material=0)], materials=[material])
    scene = ptrace.load(path)
    m = scene.materials
    assert m.kind[0] == GLTF_PBR and scene.bsdf_kinds() == ["gltf_pbr"]
    assert m.metallic[0] == pytest.approx(0.3) and m.alpha[0] == pytest.approx(0.25)
    np.testing.assert_allclose(m.albedo[0], [0.8, 0.4, 0.2])
    assert not m.emits()[0]
    assert not any("paint" in n for n in scene.notes), scene.notes


@njit
def _albedo_at(shapes, materials, m, prim, u, v):
    return surface_albedo(shapes, materials, m, prim, u, v)


def test_the_metallic_roughness_texture_scales_roughness_by_g_and_metallic_by_b(tmp_path):
    """glTF's metallicRoughnessTexture: roughness = factor x G, metallic = factor x B (linear
    data, not sRGB), so alpha = (factor x G)^2."""
    material = {"name": "worn", "pbrMetallicRoughness": {
        "metallicFactor": 0.8, "roughnessFactor": 0.5,
        "metallicRoughnessTexture": {"index": 0}}}
    path = tmp_path / "worn.glb"
    gltf(path, [quad(material=0)], materials=[material],
         images=[png_bytes("RGB", (0, 153, 128))])
    scene = ptrace.load(path)
    assert scene.materials.roughness_texture[0] >= 0
    shapes, materials, _ = scene_records(scene)
    _, _, _, alpha, metallic = _albedo_at(shapes, materials, 0, 0, 0.3, 0.3)
    assert metallic == pytest.approx(0.8 * 128 / 255, rel=1e-5)
    assert alpha == pytest.approx((0.5 * 153 / 255) ** 2, rel=1e-5)


def ggx_albedo_of_a_white_metal(alpha, mu, n_theta=600, n_phi=240):
    """E(mu) = the integral of D Vis cos over the hemisphere (F = 1 for a white metal), from
    the specification's formulas in numpy (midpoint rule; independent of ptrace.gltf_brdf)."""
    wo = np.array([math.sqrt(1 - mu * mu), 0.0, mu])
    theta = (np.arange(n_theta) + 0.5) / n_theta * 0.5 * math.pi
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * math.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    wi = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    a2 = alpha * alpha
    nh = h[..., 2]
    d = a2 / (math.pi * (nh * nh * (a2 - 1) + 1) ** 2)
    no, ni = wo[2], wi[..., 2]
    vis = 0.5 / (no * np.sqrt(ni * ni * (1 - a2) + a2) + ni * np.sqrt(no * no * (1 - a2) + a2))
    cell = (0.5 * math.pi / n_theta) * (2 * math.pi / n_phi)
    return float((d * vis * ni * np.sin(t)).sum() * cell)


@pytest.mark.slow
@pytest.mark.parametrize("roughness, lowest", [(0.2, 0.98), (0.5, 0.85)])
def test_white_furnace_of_a_rough_white_metal_sphere(roughness, lowest):
    """A sphere of metallic 1, base colour 1 under a uniform white environment: each pixel on
    it reflects the environment once (a convex surface does not see itself), so it is the
    directional albedo E(mu) of single-scattering GGX at its view angle: at most 1, close to 1
    when nearly smooth, and lower when rough (a metal conserves energy but loses what would
    scatter more than once between microfacets, which the specification's BRDF leaves out:
    about 11 % on average at roughness 0.5). The background is exactly 1. Pixels well inside
    the sphere match E(mu) at their centres, each to 2 % (64 samples) and on average to 0.5 %."""
    alpha = roughness * roughness
    scene = make_scene(centers=[[0.0, 0.0, 0.0]], radii=[1.0],
                       materials=[dict(kind=GLTF_PBR, albedo=(1.0, 1.0, 1.0), metallic=1.0,
                                       alpha=alpha)], material_index=[0])
    scene = scene.with_environment(Environment.constant((1.0, 1.0, 1.0)))
    size, distance = 32, 4.0
    camera = Camera(np.array([0.0, 0.0, distance]), np.zeros(3), np.eye(3), 53.0, size, size,
                    1e-3, 1e3)
    image = ptrace.render(scene, camera=camera, spp=64, max_depth=3)
    ys, xs = np.mgrid[0:size, 0:size]
    d = camera.directions(xs + 0.5, (size - 1 - ys) + 0.5)
    o = camera.position
    # the ray's closest approach to the centre: inside 0.85 it meets the sphere with its
    # whole pixel; outside 1.15 its whole pixel misses
    b = np.linalg.norm(np.cross(d, -o), axis=-1)
    inside, outside = b < 0.85, b > 1.15
    assert inside.sum() > 200 and outside.sum() > 200
    np.testing.assert_array_equal(image[outside], 1.0)
    t = -(d @ o) - np.sqrt(np.maximum(1.0 - b * b, 0.0))
    normal = o + t[..., None] * d
    mu = -(normal * d).sum(axis=-1)[inside]
    nodes = np.linspace(mu.min() - 1e-3, 1.0, 12)
    expected = np.interp(mu, nodes, [ggx_albedo_of_a_white_metal(alpha, c) for c in nodes])
    seen = image[inside]
    print(f"furnace: mean {seen.mean():.4f} expected {expected.mean():.4f}, "
          f"min {seen.min():.4f} max {seen.max():.4f}")
    assert np.abs(seen - seen[:, :1]).max() < 1e-6     # white: the channels agree
    assert abs(seen[:, 1].mean() - expected.mean()) < 0.005 * expected.mean()
    assert np.abs(seen[:, 1] - expected).max() < 0.02
    assert lowest < seen.mean() <= 1.0


@pytest.mark.slow
def test_an_emissive_gltf_material_emits_like_an_emitter_and_reflects():
    """A sphere over a diffuse floor, either an emitter or a glTF material of the same
    emission: it is the floor's only light either way (a light of emissive geometry), the
    floor is lit to the same bits at -m 1; under a white environment, the glTF sphere adds
    its reflection to its emission and the emitter does not reflect."""
    def scene_of(kind):
        floor = floor_plane(0.5)
        sphere = dict(kind=kind, emission=(2.0, 2.0, 2.0), albedo=(0.5, 0.5, 0.5))
        return make_scene(vertices=floor["vertices"], faces=floor["faces"],
                          centers=[[0.0, 1.0, 0.0]], radii=[0.5],
                          materials=[floor["materials"][0], sphere], material_index=[0, 0, 1])
    camera = looking_down(4.0)
    images = {}
    for kind in (EMISSION, GLTF_PBR):
        scene = scene_of(kind)
        assert emitter_arrays(scene)[1].tolist() == [2]     # the sphere is a light
        images[kind] = ptrace.render(scene, camera=camera, spp=8, max_depth=1)
    assert (images[GLTF_PBR] > 0.0).all()      # the floor is lit everywhere
    np.testing.assert_array_equal(images[GLTF_PBR], images[EMISSION])
    centre = {kind: ptrace.render(scene_of(kind).with_environment(
        Environment.constant((1.0, 1.0, 1.0))), camera=camera, spp=16, max_depth=2,
        crop=(15, 15, 2, 2)).mean() for kind in (EMISSION, GLTF_PBR)}
    assert centre[EMISSION] == pytest.approx(2.0)
    assert centre[GLTF_PBR] > 2.0 + 0.2       # a grey dielectric seen head-on: ~0.5 more
