"""Every course scene loads, with the contents the course's notes list
(docs/course.md#course-scenes)."""
import numpy as np
import pytest

import ptrace
from ptrace.scene import AREA, DIFFUSE, DIRECTIONAL, GLASS, MIRROR, POINT

# the course's list (docs/course.md#course-scenes): file -> (triangles, spheres,
# {light kind: radiance}, BSDF kinds used).
DIFFUSE_ONLY = {"diffuse"}
BOX = {"diffuse", "emission"}                  # CB box with the emissive quad
COURSE_SCENES = {
    "keenan/banana.dae": (2458, 0, {"ambient": 1, "directional": 1}, DIFFUSE_ONLY),
    "keenan/building.dae": (39506, 0, {"ambient": 1, "directional": 1}, DIFFUSE_ONLY),
    "meshedit/beetle.dae": (7558, 0, {"directional": 1}, DIFFUSE_ONLY),
    "meshedit/cow.dae": (5856, 0, {"directional": 1}, DIFFUSE_ONLY),
    "meshedit/maxplanck.dae": (50801, 0, {"directional": 1}, DIFFUSE_ONLY),
    "meshedit/peter.dae": (40018, 0, {"directional": 1}, DIFFUSE_ONLY),
    "meshedit/teapot.dae": (2464, 0, {"directional": 1}, DIFFUSE_ONLY),
    "simple/cube.dae": (12, 0, {"point": 1}, DIFFUSE_ONLY),
    "simple/plane.dae": (2, 0, {"point": 1}, DIFFUSE_ONLY),
    "sky/CBbunny.dae": (28588, 0, {"area": 10}, BOX),
    "sky/CBbunny_microfacet_cu.dae": (28588, 0, {"area": 10}, BOX | {"microfacet"}),
    "sky/CBcoil.dae": (7884, 0, {"area": 5}, BOX | {"mirror"}),
    "sky/CBempty.dae": (12, 0, {"point": 5}, BOX),
    "sky/CBgems.dae": (252, 0, {"area": 10}, BOX | {"glass"}),
    "sky/CBspheres.dae": (12, 2, {"area": 10}, BOX | {"mirror", "glass"}),
    "sky/CBspheres_lambertian.dae": (12, 2, {"area": 10}, BOX),
    "sky/CBspheres_microfacet_al_ag.dae": (12, 2, {"area": 10}, BOX | {"microfacet"}),
    "sky/CBspheres_tex.dae": (12, 2, {"area": 10}, BOX | {"mirror", "glass"}),
    "sky/bunny.dae": (33696, 0, {"ambient": 1}, DIFFUSE_ONLY),
    "sky/bunny_unlit.dae": (33696, 0, {"ambient": 0}, DIFFUSE_ONLY),
    "sky/bunny_microfacet_cu.dae": (33696, 0, {"ambient": 1}, {"diffuse", "microfacet"}),
    "sky/bunny_microfacet_cu_unlit.dae": (33696, 0, {"ambient": 0}, {"diffuse", "microfacet"}),
    "variants_sp23/sky/CBspheres_refract.dae": (10, 2, {"area": 10},
                                                {"diffuse", "mirror", "refraction"}),
    "variants_sp23/sky/CBspheres_lambertian.dae": (10, 2, {"area": 10}, DIFFUSE_ONLY),
    "variants_sp23/sky/CBempty.dae": (10, 0, {"point": 5}, DIFFUSE_ONLY),
}

_cache = {}


def load_course(course_scene, relpath):
    """Each scene is loaded once per test session."""
    if relpath not in _cache:
        _cache[relpath] = ptrace.load(course_scene(relpath))
    return _cache[relpath]


def test_every_course_file_loads(scenes_dir):
    found = sorted(p.relative_to(scenes_dir).as_posix() for p in scenes_dir.rglob("*.dae"))
    assert len(found) == 25, found
    assert set(found) == set(COURSE_SCENES)
    for relpath in found:
        scene = ptrace.load(scenes_dir / relpath)
        assert scene.triangle_count + scene.sphere_count > 0, relpath


@pytest.mark.parametrize("relpath", sorted(COURSE_SCENES))
def test_contents_match_the_course_table(course_scene, relpath):
    triangles, spheres, lights, bsdfs = COURSE_SCENES[relpath]
    scene = load_course(course_scene, relpath)
    assert scene.triangle_count == triangles
    assert scene.sphere_count == spheres
    assert scene.lights.counts() == {kind: 1 for kind in lights}
    for kind, radiance in zip(scene.lights.kind, scene.lights.radiance):
        expected = lights[ptrace.scene.LIGHT_NAMES[kind]]
        np.testing.assert_allclose(radiance, [expected] * 3)
    assert set(scene.bsdf_kinds()) == bsdfs
    assert scene.camera is not None
    assert len(scene.material_index) == triangles + spheres
    assert scene.vertex_normals.shape == scene.geometry.vertices.shape


@pytest.mark.parametrize("relpath", sorted(COURSE_SCENES))
def test_vertex_normals_are_unit_length(course_scene, relpath):
    scene = load_course(course_scene, relpath)
    used = np.unique(scene.geometry.faces)
    lengths = np.linalg.norm(scene.vertex_normals[used], axis=1)
    np.testing.assert_allclose(lengths, 1.0, atol=1e-9)


def test_cbspheres_spheres_and_materials(course_scene):
    scene = load_course(course_scene, "sky/CBspheres.dae")
    materials = scene.materials
    sphere_materials = scene.material_index[scene.triangle_count:]
    by_kind = {int(materials.kind[m]): (center, radius, m) for center, radius, m in
               zip(scene.geometry.centers, scene.geometry.radii, sphere_materials)}
    mirror_center, mirror_radius, mirror = by_kind[MIRROR]
    glass_center, glass_radius, glass = by_kind[GLASS]
    np.testing.assert_allclose(mirror_center, [-0.4, 0.3, -0.3], atol=1e-9)
    np.testing.assert_allclose(glass_center, [0.4, 0.3, 0.3], atol=1e-9)
    assert mirror_radius == pytest.approx(0.3) and glass_radius == pytest.approx(0.3)
    np.testing.assert_allclose(materials.albedo[mirror], [1, 1, 1])
    assert materials.ior[glass] == pytest.approx(1.45)
    np.testing.assert_allclose(materials.albedo[glass], [1, 1, 1])
    np.testing.assert_allclose(materials.transmittance[glass], [1, 1, 1])


def test_cbspheres_area_light(course_scene):
    lights = load_course(course_scene, "sky/CBspheres.dae").lights
    assert list(lights.kind) == [AREA]
    np.testing.assert_allclose(lights.position[0], [0, 1.49, 0], atol=1e-9)
    np.testing.assert_allclose(lights.direction[0], [0, -1, 0], atol=1e-9)
    np.testing.assert_allclose(lights.edge_x[0], [0.6, 0, 0], atol=1e-9)
    np.testing.assert_allclose(lights.edge_y[0], [0, 0, 0.8], atol=1e-9)
    assert lights.area[0] == pytest.approx(0.48)
    np.testing.assert_allclose(lights.radiance[0], [10, 10, 10])


def test_cbempty_point_light(course_scene):
    lights = load_course(course_scene, "sky/CBempty.dae").lights
    assert list(lights.kind) == [POINT]
    np.testing.assert_allclose(lights.position[0], [0, 1.49, 0.004], atol=1e-3)
    np.testing.assert_allclose(lights.radiance[0], [5, 5, 5])


def test_cow_directional_light_keeps_the_translation_quirk(course_scene):
    lights = load_course(course_scene, "meshedit/cow.dae").lights
    assert list(lights.kind) == [DIRECTIONAL]
    np.testing.assert_allclose(lights.direction[0], [-0.471, 0.746, 0.471], atol=1e-3)


@pytest.mark.parametrize("relpath", ["sky/CBempty.dae", "sky/CBspheres.dae"])
def test_cornell_box_extents(course_scene, relpath):
    lower, upper = load_course(course_scene, relpath).bounds()
    np.testing.assert_allclose(lower, [-1, 0, -1], atol=1e-6)
    np.testing.assert_allclose(upper, [1, 1.5, 1], atol=1e-6)


def _triangles_per_albedo(scene):
    """{rounded diffuse albedo: triangle count}."""
    triangle_materials = scene.material_index[:scene.triangle_count]
    counts = {}
    for material, count in zip(*np.unique(triangle_materials, return_counts=True)):
        assert scene.materials.kind[material] == DIFFUSE
        key = tuple(np.round(scene.materials.albedo[material], 3))
        counts[key] = counts.get(key, 0) + int(count)
    return counts


def test_bunny_materials(course_scene):
    counts = _triangles_per_albedo(load_course(course_scene, "sky/bunny.dae"))
    assert counts == {(0.48, 0.48, 0.48): 28576, (0.25, 0.25, 0.25): 5120}


def test_banana_ground_without_material_is_grey(course_scene):
    counts = _triangles_per_albedo(load_course(course_scene, "keenan/banana.dae"))
    assert counts == {(0.64, 0.373, 0.038): 2422, (0.506, 0.375, 0.276): 28,
                      (0.5, 0.5, 0.5): 8}


def test_building_ground_without_material_is_grey(course_scene):
    counts = _triangles_per_albedo(load_course(course_scene, "keenan/building.dae"))
    assert counts == {(0.8, 0.671, 0.52): 39498, (0.5, 0.5, 0.5): 8}


def test_peter_uses_the_last_camera(course_scene):
    camera = load_course(course_scene, "meshedit/peter.dae").camera
    direction = camera.view_point / np.linalg.norm(camera.view_point)
    # docs/course.md#camera-table: the orbit camera ends at (0, 0.7338, -3.3250) with R = 3.4050
    # about (0,0,0).
    np.testing.assert_allclose(direction * 3.4050, [0, 0.7338, -3.3250], atol=1e-3)
    assert camera.hfov == pytest.approx(39.5978)
    assert camera.znear == pytest.approx(0.00999999) and camera.zfar == pytest.approx(10000)


def test_cbgems_camera_with_15_matrix_numbers(course_scene):
    scene = load_course(course_scene, "sky/CBgems.dae")
    direction = scene.camera.view_point / np.linalg.norm(scene.camera.view_point)
    np.testing.assert_allclose(direction, [0, 0, 1], atol=1e-9)
    assert any("15 numbers" in note for note in scene.notes)


def test_camera_fov_from_aspect_ratio(course_scene):
    camera = load_course(course_scene, "sky/CBspheres.dae").camera
    assert camera.hfov == pytest.approx(49.13434)
    assert camera.vfov == pytest.approx(37.849, abs=1e-3)   # aspect 1.333333
    assert (camera.znear, camera.zfar) == (pytest.approx(0.1), pytest.approx(100))
    np.testing.assert_allclose(camera.position, [0, 0, 3], atol=1e-9)


def test_cbbunny_camera_looks_from_minus_z(course_scene):
    camera = load_course(course_scene, "sky/CBbunny.dae").camera
    direction = camera.view_point / np.linalg.norm(camera.view_point)
    np.testing.assert_allclose(direction, [0, 0, -1], atol=1e-9)


def test_each_mesh_instance_gets_its_own_vertices(course_scene):
    scene = load_course(course_scene, "sky/CBspheres.dae")
    # six box meshes of four vertices each, none shared between instances
    assert len(scene.geometry.vertices) == 24
    faces = scene.geometry.faces
    for block in range(6):
        assert (set(np.unique(faces[2 * block:2 * block + 2]))
                == set(range(4 * block, 4 * block + 4)))
