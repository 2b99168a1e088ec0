"""Promises that a plausible wrong rule used to slip past (each has a mutant in tests/mutants.py):

- the last vertex's delta rule: a mirror or glass surface at the last vertex (-m 1 here) still
  shows the light its reflected ray meets, under --direct light, under -H, and in a scene whose
  only light is a point light (its emissive face is what the mirror sees), not only under
  multiple importance sampling with an area light;
- an emissive panel moved sideways within its light's plane, off the light, is no longer that
  light's face (a light of its own);
- the embree backend's grazing-hit refinement gives float64 u and v as well as t.
"""
import dataclasses

import numpy as np
import pytest

import accel
import ptrace
from accel import embree, raygen
from ptrace.emitters import emitter_arrays
from ptrace.scene import AREA, DIRECTIONAL, EMISSION, GLASS, MIRROR, POINT

from scenes_by_hand import looking_down, make_scene

EMITTED = 2.0
HALF = 50.0     # the emissive panel's half size: every reflected camera ray meets it
PANEL_Y = 2.0


def mirror_under_a_panel(light, floor=MIRROR):
    """A floor (y = 0) of a delta BSDF under an emissive panel facing down at y = 2, with one
    light: "area" (the panel is its face), "point" (at the panel's centre: its face) or
    "directional" (straight down; the panel is then a light of its own)."""
    floor_vertices = [[-HALF, 0, -HALF], [HALF, 0, -HALF], [HALF, 0, HALF], [-HALF, 0, HALF]]
    panel = [[x, PANEL_Y, z] for x, _, z in floor_vertices]
    floor_material = (dict(kind=MIRROR, albedo=(1.0,) * 3) if floor == MIRROR else
                      dict(kind=GLASS, albedo=(1.0,) * 3, transmittance=(1.0,) * 3, ior=1.5))
    records = {
        "area": dict(kind=AREA, radiance=(EMITTED,) * 3, position=[0.0, PANEL_Y, 0.0],
                     direction=[0.0, -1.0, 0.0], edge_x=[2 * HALF, 0, 0],
                     edge_y=[0, 0, 2 * HALF], area=4 * HALF * HALF),
        "point": dict(kind=POINT, radiance=(1.0,) * 3, position=[0.0, PANEL_Y, 0.0]),
        "directional": dict(kind=DIRECTIONAL, radiance=(1.0,) * 3, direction=[0.0, -1.0, 0.0]),
    }
    return make_scene(vertices=floor_vertices + panel,
                      faces=[[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]],
                      materials=[floor_material, dict(kind=EMISSION, emission=(EMITTED,) * 3)],
                      material_index=[0, 0, 1, 1], lights=[records[light]])


DIRECT = {"mis": dict(direct="mis"), "light": dict(direct="light"), "H": dict(hemisphere=True)}


@pytest.mark.parametrize("light", ["area", "point", "directional"])
@pytest.mark.parametrize("direct", list(DIRECT))
def test_a_mirror_at_the_last_vertex_shows_the_light_its_ray_meets(light, direct):
    scene = mirror_under_a_panel(light)
    faced = emitter_arrays(scene)[0]
    assert list(faced) == [int(light != "directional")]   # the scene is what it says
    image = ptrace.render(scene, camera=looking_down(1.0, width=8), resolution=(8, 8), spp=2,
                          max_depth=1, **DIRECT[direct])
    np.testing.assert_allclose(image, EMITTED, rtol=1e-6)


@pytest.mark.parametrize("direct", list(DIRECT))
def test_glass_at_the_last_vertex_shows_the_light_its_reflection_meets(direct):
    """Glass reflects with its Fresnel probability (about 4% head on at ior 1.5) and refracts
    down into nothing otherwise: the image is the panel's emission times that probability on
    average, never black."""
    scene = mirror_under_a_panel("point", floor=GLASS)
    image = ptrace.render(scene, camera=looking_down(1.0, width=8), resolution=(8, 8), spp=64,
                          max_depth=1, **DIRECT[direct])
    mean = float(image.mean())
    assert 0.01 * EMITTED < mean < 0.2 * EMITTED, mean


def test_an_emissive_panel_moved_sideways_in_the_lights_plane_is_not_its_face(course_scene):
    """The course quad slid along x within the light's plane, clear of the light's centre: it
    lies in the plane (the test that catches a panel moved out of it passes) but no longer on
    the light, so it is a light of its own, sampled by power."""
    scene = ptrace.load(course_scene("sky/CBspheres_lambertian.dae"))
    quad = np.nonzero(scene.materials.kind[scene.material_index] == EMISSION)[0]
    moved = np.unique(scene.geometry.faces[quad])
    vertices = scene.geometry.vertices.copy()
    width = np.ptp(vertices[moved, 0])
    for shift in (0.6 * width + 1e-3, 2.0):   # just clear of the light's centre, and far
        shifted = vertices.copy()
        shifted[moved, 0] += shift
        geometry = dataclasses.replace(scene.geometry, vertices=shifted)
        faced, prims, cdf, _ = emitter_arrays(dataclasses.replace(scene, geometry=geometry))
        assert list(faced) == [0] and sorted(prims) == sorted(quad), shift
        np.testing.assert_allclose(cdf[-1], 1.0)
    faced, prims, _, _ = emitter_arrays(scene)   # unmoved: the light's face
    assert list(faced) == [1] and prims.size == 0


def test_embree_grazing_hits_are_refined_in_u_and_v_too():
    """On grazing hits embree's float32 t, u and v are recomputed in float64 on the triangle it
    found: all three then equal the naive backend's bit for bit (t alone is not enough: a
    texture or a shading normal reads u and v)."""
    rng = np.random.default_rng(4)
    corners = rng.random((300, 1, 3)) + 0.15 * rng.normal(size=(300, 3, 3))
    geometry = accel.Geometry(corners.reshape(-1, 3), np.arange(900).reshape(300, 3))
    backend, naive = accel.build("embree", geometry), accel.build("naive", geometry)
    rays = raygen.surface_rays(geometry, 3000, seed=2)
    ours, reference = backend.intersect(rays), naive.intersect(rays)
    same = (ours.prim == reference.prim) & (ours.prim >= 0)
    corners = geometry.vertices[geometry.faces[ours.prim[same]]]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    cosine = np.abs(np.einsum("ij,ij->i", normal, rays.directions[same]))
    cosine /= np.linalg.norm(normal, axis=1) * np.linalg.norm(rays.directions[same], axis=1)
    grazing = cosine < 0.9 * embree.GRAZING_COSINE   # clear of the float32 normal's noise
    assert grazing.sum() >= 3
    for name in ("t", "u", "v"):
        np.testing.assert_array_equal(getattr(ours, name)[same][grazing],
                                      getattr(reference, name)[same][grazing], err_msg=name)
    # and not trivially: away from grazing, embree's float32 u and v differ from float64's
    assert (ours.u[same][~grazing] != reference.u[same][~grazing]).any()
