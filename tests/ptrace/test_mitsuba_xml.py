"""Mitsuba XML scenes (ptrace.io.mitsuba): parsing, shapes, materials, emitters, the sensor,
every refusal as one line and exit 2, and a render whose mean agrees with Mitsuba 3's own
render of the same file. Every scene is written here, into tmp_path."""
import json
import math
import os
import struct
import zlib

import numpy as np
import pytest

import ptrace
from ptrace.app.cli import main
from ptrace.bsdf import TABLE, THIN_GLASS, dielectric_sample, microfacet_eval
from ptrace.image import read_image
from ptrace.io.mitsuba_materials import CONDUCTORS, IOR
from ptrace.io.mitsuba_xml import Reader
from ptrace.scene import (
    ANGULAR,
    DIFFUSE,
    DIRECTIONAL,
    EXACT,
    GLASS,
    GLTF_PBR,
    MICROFACET,
    MIRROR,
    PLASTIC,
    POINT,
    ROUGH_PLASTIC,
    SPOT,
    Materials,
)


def write(tmp_path, body, name="scene.xml", version="3.0.0"):
    path = tmp_path / name
    path.write_text(f'<scene version="{version}">\n{body}\n</scene>\n', encoding="utf-8")
    return path


def front(scene):
    """(vertices, faces) of the scene's triangles without the black backs the reader gives an
    open shape of a one-sided BSDF (Mitsuba's default diffuse too): the shapes as placed."""
    back = [i for i, name in enumerate(scene.materials.names) if name == "back"]
    faces = scene.geometry.faces
    faces = faces[~np.isin(scene.material_index[:len(faces)], back)]
    return scene.geometry.vertices[np.unique(faces)], faces


def to_world(tmp_path, steps):
    """The to_world matrix the reader parses from these transform steps."""
    path = write(tmp_path, f'<shape type="rectangle"><transform name="to_world">{steps}'
                           f'</transform></shape>')
    return Reader(path).read().children[0].params["to_world"].matrix


# --- parsing --------------------------------------------------------------------------------

def test_transform_steps_compose_left_to_right(tmp_path):
    # scale 2, then a quarter turn about +z, then a translation: T R S
    m = to_world(tmp_path, '<scale value="2"/><rotate z="1" angle="90"/>'
                           '<translate x="1" y="2" z="3"/>')
    expected = np.array([[0, -2, 0, 1], [2, 0, 0, 2], [0, 0, 2, 3], [0, 0, 0, 1]], float)
    np.testing.assert_allclose(m, expected, atol=1e-12)


@pytest.mark.parametrize("steps, linear, offset", [
    ('<scale x="2" y="3"/>', np.diag([2.0, 3.0, 1.0]), (0, 0, 0)),
    ('<scale value="1, 2 3"/>', np.diag([1.0, 2.0, 3.0]), (0, 0, 0)),
    ('<translate value="4 5 6"/>', np.eye(3), (4, 5, 6)),
    ('<rotate value="0 1 0" angle="180"/>', np.diag([-1.0, 1.0, -1.0]), (0, 0, 0)),
    # Mitsuba 3 does not normalise a rotation's axis: the same formula, scaling too
    ('<rotate y="2" angle="90"/>', [[0, 0, 2], [0, 4, 0], [-2, 0, 0]], (0, 0, 0)),
    ('<rotate x="1" angle="90"/>', np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float),
     (0, 0, 0)),
    ('<matrix value="0 0 1 5  0 1 0 6  -1 0 0 7  0 0 0 1"/>',
     np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float), (5, 6, 7)),
    # Mitsuba's look-at: columns left, up, forward and the origin
    ('<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>',
     np.array([[-1, 0, 0], [0, 1, 0], [0, 0, -1]], float), (0, 0, 5)),
])
def test_each_transform_step(tmp_path, steps, linear, offset):
    m = to_world(tmp_path, steps)
    np.testing.assert_allclose(m[:3, :3], linear, atol=1e-12)
    np.testing.assert_allclose(m[:3, 3], offset, atol=1e-12)


def test_defaults_and_defines(tmp_path):
    path = write(tmp_path, '<default name="r" value="0.25"/><default name="kind" value="sphere"/>'
                           '<shape type="$kind"><float name="radius" value="$r"/></shape>')
    assert ptrace.load(path).geometry.radii.tolist() == [0.25]
    assert ptrace.load(path, defines={"r": "2"}).geometry.radii.tolist() == [2.0]


def test_values_and_references(tmp_path):
    path = write(tmp_path, '<bsdf type="diffuse" id="grey"><rgb name="reflectance" value="0.3"/>'
                           '</bsdf><bsdf type="diffuse" id="red"><spectrum name="reflectance" '
                           'value="0.6"/></bsdf>'
                           '<shape type="rectangle"><ref id="grey"/></shape>'
                           '<shape type="cube"><ref id="red" name="bsdf"/></shape>')
    scene = ptrace.load(path)
    albedo = scene.materials.albedo[scene.material_index]
    np.testing.assert_allclose(albedo[0], [0.3] * 3)
    np.testing.assert_allclose(albedo[-1], [0.6] * 3)


@pytest.mark.parametrize("pairs", ["400:0.5, 700:0.5", "400:0.1, 500:0.8, 600:0.2, 700:0.9"])
def test_spectra_convert_to_rgb_as_mitsubas_rgb_variants_do(tmp_path, pairs):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path = write(tmp_path, f'<shape type="sphere"><bsdf type="diffuse"><spectrum name='
                           f'"reflectance" value="{pairs}"/></bsdf></shape><shape type="cube">'
                           f'<emitter type="area"><spectrum name="radiance" value="{pairs}"/>'
                           f'</emitter></shape>')
    scene = ptrace.load(path)
    ours = [scene.materials.albedo[scene.material_index[-1]],      # the sphere
            scene.materials.emission[scene.material_index[0]]]     # the cube's front
    shapes = sorted(mi.load_file(str(path)).shapes(), key=lambda s: s.is_emitter())
    theirs = [mi.traverse(shapes[0].bsdf())["reflectance.value"],
              mi.traverse(shapes[1].emitter())["radiance.value"]]
    for mine, reference in zip(ours, theirs):
        np.testing.assert_allclose(mine, np.array(reference), rtol=2e-3)


def test_a_spectrum_from_a_file_converts_as_mitsubas_does(tmp_path):
    """A file of wavelength value lines (comments with #) is the spectrum of its pairs, the
    RGB Mitsuba's RGB variant gives it; a line that is not two numbers is refused naming it."""
    (tmp_path / "s.spd").write_text("# wavelength value\n400 0.1\n500 0.8\n\n600 0.2\n700 0.9\n")
    path = write(tmp_path, '<shape type="sphere"><bsdf type="diffuse"><spectrum name='
                           '"reflectance" filename="s.spd"/></bsdf></shape>')
    ours = ptrace.load(path).materials.albedo[0]
    pairs = write(tmp_path, '<shape type="sphere"><bsdf type="diffuse"><spectrum name='
                            '"reflectance" value="400:0.1, 500:0.8, 600:0.2, 700:0.9"/></bsdf>'
                            '</shape>', name="pairs.xml")
    np.testing.assert_array_equal(ours, ptrace.load(pairs).materials.albedo[0])
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    theirs = mi.traverse(mi.load_file(str(path)).shapes()[0].bsdf())["reflectance.value"]
    np.testing.assert_allclose(ours, np.array(theirs), rtol=2e-3)
    (tmp_path / "s.spd").write_text("400 0.1\n500\n")
    with pytest.raises(ptrace.SceneError, match=r"scene.xml:2: .*line 2 of 's.spd' is not"):
        ptrace.load(path)


def test_a_blackbody_emitter_is_what_mitsubas_spectral_variant_renders(tmp_path):
    """A 3000 K blackbody's RGB (Mitsuba's RGB variants refuse it) against the radiance
    Mitsuba's scalar_spectral renders of it seen straight on, within its noise (3 %)."""
    path = write(tmp_path, '<integrator type="path"/><sensor type="perspective"><float name='
                           '"fov" value="10"/><transform name="to_world"><lookat origin="0,0,5"'
                           ' target="0,0,0"/></transform><film type="hdrfilm"><integer name='
                           '"width" value="4"/><integer name="height" value="4"/></film>'
                           '</sensor><shape type="rectangle"><emitter type="area"><spectrum '
                           'type="blackbody" name="radiance"><float name="temperature" value='
                           '"3000"/></spectrum></emitter></shape>')
    scene = ptrace.load(path)
    ours = scene.materials.emission[scene.material_index[0]]
    assert any("blackbody" in note for note in scene.notes)
    bad = write(tmp_path, '<shape type="sphere"><bsdf type="diffuse"><spectrum type="blackbody"'
                          ' name="reflectance"><float name="temperature" value="3000"/>'
                          '</spectrum></bsdf></shape>', name="bad.xml")
    with pytest.raises(ptrace.SceneError, match="blackbody spectrum outside an emitter"):
        ptrace.load(bad)
    old = write(tmp_path, '<shape type="sphere"><emitter type="area"><blackbody name='
                          '"radiance" temperature="3000"/></emitter></shape>', name="old.xml",
                version="0.6.0")   # (0.6's element: the one line says what Mitsuba 3 reads)
    with pytest.raises(ptrace.SceneError, match='unknown element <blackbody>.*type="blackbody"'):
        ptrace.load(old)
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_spectral")
    try:
        image = np.array(mi.render(mi.load_file(str(path)), spp=256))[1:3, 1:3, :3]
    finally:
        mi.set_variant("scalar_rgb")
    np.testing.assert_allclose(ours, image.reshape(-1, 3).mean(axis=0), rtol=0.03)


def test_include_reads_the_included_scene(tmp_path):
    (tmp_path / "parts").mkdir()
    write(tmp_path / "parts", '<shape type="sphere"><float name="radius" value="3"/></shape>',
          name="ball.xml")
    path = write(tmp_path, '<include filename="parts/ball.xml"/>')
    assert ptrace.load(path).geometry.radii.tolist() == [3.0]


def test_path_folders_aliases_and_file_names_with_spaces(tmp_path):
    (tmp_path / "my meshes").mkdir()
    (tmp_path / "my meshes" / "a quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n")
    path = write(tmp_path, '<path value="my meshes"/><bsdf type="diffuse" id="grey"><rgb '
                           'name="reflectance" value="0.25"/></bsdf><alias id="grey" as="dull"/>'
                           '<shape type="obj"><string name="filename" value="a quad.obj"/>'
                           '<ref id="dull"/></shape>')
    scene = ptrace.load(path)
    assert len(front(scene)[1]) == 1
    np.testing.assert_allclose(scene.materials.albedo[scene.material_index[0]], [0.25] * 3)


def test_version_0_6_is_upgraded(tmp_path):
    path = write(tmp_path, '<sensor type="perspective"><float name="fov" value="30"/>'
                           '<string name="fovAxis" value="y"/><transform name="toWorld">'
                           '<lookAt origin="0 0 4" target="0 0 0" up="0 1 0"/></transform>'
                           '</sensor><shape type="sphere"><bsdf type="dielectric">'
                           '<string name="intIOR" value="diamond"/></bsdf></shape>',
                 version="0.6.0")
    scene = ptrace.load(path)
    camera = scene.file_cameras[0]
    assert camera.yfov == pytest.approx(30.0)
    np.testing.assert_allclose(camera.position, [0, 0, 4])
    assert scene.materials.ior[0] == pytest.approx(IOR["diamond"] / IOR["air"])
    assert any("upgraded" in note for note in scene.notes)


def test_a_0_6_scene_with_its_old_names(tmp_path):
    path = write(tmp_path, '<integrator type="bdpt"><integer name="maxDepth" value="6"/>'
                           '</integrator><sensor type="perspective"><float name="fov" value="45"/>'
                           '<float name="nearClip" value="0.1"/><sampler type="ldsampler">'
                           '<integer name="sampleCount" value="32"/></sampler><film '
                           'type="ldrfilm"><integer name="width" value="40"/><integer '
                           'name="height" value="30"/><boolean name="banner" value="false"/>'
                           '</film></sensor><emitter type="spot"><float name="cutoffAngle" '
                           'value="40"/><float name="beamWidth" value="30"/></emitter>'
                           '<shape type="sphere"><bsdf type="diffuse"><srgb name="reflectance" '
                           'value="0.5 0.5 0.5"/></bsdf></shape>', version="0.5.0")
    scene = ptrace.load(path)
    assert scene.file_cameras[0].znear == 0.1
    assert scene.lights.cos_outer[0] == pytest.approx(math.cos(math.radians(40)))
    # sRGB 0.5 is linear 0.214
    np.testing.assert_allclose(scene.materials.albedo[0], [0.21404] * 3, rtol=1e-4)
    notes = "\n".join(scene.notes)
    assert scene.render_defaults == {"resolution": (40, 30), "spp": 32, "max_depth": 5}
    assert "-r 40 30, -s 32, -m 5" in notes and "rendered by ptrace's path tracer" in notes
    assert "<sampler type=\"ldsampler\">: ptrace draws its own" in notes


def test_moment_renders_its_nested_integrator(tmp_path):
    path = write(tmp_path, '<integrator type="moment"><integrator type="path"><integer '
                           'name="max_depth" value="3"/></integrator></integrator><shape '
                           'type="sphere"/>')
    assert any("-m 2" in note for note in ptrace.load(path).notes)


# --- shapes ---------------------------------------------------------------------------------

def test_rectangle_vertices_and_normal(tmp_path):
    path = write(tmp_path, '<shape type="rectangle"><transform name="to_world">'
                           '<scale value="2"/><rotate x="1" angle="-90"/><translate y="-1"/>'
                           '</transform></shape>')
    scene = ptrace.load(path)
    vertices = scene.geometry.vertices
    corners = {tuple(np.round(v, 9) + 0.0) for v in front(scene)[0]}
    assert corners == {(-2.0, -1.0, 2.0), (2.0, -1.0, 2.0), (2.0, -1.0, -2.0),
                       (-2.0, -1.0, -2.0)}
    for a, b, c in front(scene)[1]:    # +z turned by -90 degrees about x is +y
        normal = np.cross(vertices[b] - vertices[a], vertices[c] - vertices[a])
        np.testing.assert_allclose(normal / np.linalg.norm(normal), [0, 1, 0], atol=1e-12)


def test_cube_faces_out_and_flip_normals_turns_them_in(tmp_path):
    for flip, sign in (("false", 1), ("true", -1)):
        path = write(tmp_path, f'<shape type="cube"><boolean name="flip_normals" '
                               f'value="{flip}"/></shape>')
        geometry = ptrace.load(path).geometry
        corners = geometry.vertices[geometry.faces]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        assert len(corners) == 12
        assert (sign * np.einsum("ij,ij->i", normals, corners.mean(axis=1)) > 0).all()


def test_cube_texture_coordinates_are_mitsubas(tmp_path):
    """Each corner of each face of the cube has the (u, v) of Mitsuba's own cube mesh at that
    corner of that face (ptrace's v = 1 - Mitsuba's), so a texture lies on each face as in
    Mitsuba (a checkerboard showed the difference on a face seen edge-on)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    mesh = mi.load_dict({"type": "cube"})
    positions = np.array(mesh.vertex_positions_buffer()).reshape(-1, 3)
    coordinates = np.array(mesh.vertex_texcoords_buffer()).reshape(-1, 2)
    theirs = {}
    for triangle in np.array(mesh.faces_buffer()).reshape(-1, 3):
        corners = positions[triangle]
        normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        for index in triangle:
            key = tuple(np.round(np.concatenate([positions[index], normal]), 3))
            theirs[key] = (coordinates[index, 0], 1.0 - coordinates[index, 1])
    scene = ptrace.load(write(tmp_path, '<shape type="cube"><bsdf type="diffuse"><texture '
                                        'type="checkerboard" name="reflectance"/></bsdf>'
                                        '</shape>'))
    vertices, uv = scene.geometry.vertices, np.asarray(scene.uv).reshape(-1, 3, 2)
    for face, corners_uv in zip(scene.geometry.faces, uv):
        corners = vertices[face]
        normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        for corner, coordinate in zip(corners, corners_uv):
            key = tuple(np.round(np.concatenate([corner, normal]), 3))
            np.testing.assert_allclose(coordinate, theirs[key], atol=1e-6)


def test_disk_keeps_its_area_and_sphere_its_placement(tmp_path):
    path = write(tmp_path, '<shape type="disk"><transform name="to_world"><scale value="0.5"/>'
                           '</transform></shape><shape type="sphere"><point name="center" '
                           'x="1" y="0" z="0"/><transform name="to_world"><scale value="3"/>'
                           '<translate z="1"/></transform></shape>')
    scene = ptrace.load(path)
    geometry = scene.geometry
    corners = geometry.vertices[front(scene)[1]]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                         corners[:, 2] - corners[:, 0]), axis=1).sum()
    assert area == pytest.approx(math.pi * 0.25, rel=1e-9)
    np.testing.assert_allclose(geometry.centers, [[3, 0, 1]])
    np.testing.assert_allclose(geometry.radii, [3])


def test_obj_and_ply_shapes_are_read_by_ptrace_readers(tmp_path):
    (tmp_path / "quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    (tmp_path / "tri.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x"
                                      "\nproperty float y\nproperty float z\nelement face 1\n"
                                      "property list uchar int vertex_indices\nend_header\n"
                                      "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    path = write(tmp_path, '<shape type="obj"><string name="filename" value="quad.obj"/>'
                           '<transform name="to_world"><translate z="5"/></transform></shape>'
                           '<shape type="ply"><string name="filename" value="tri.ply"/></shape>'
                           '<shape type="obj"><string name="filename" value="quad.obj"/>'
                           '<boolean name="face_normals" value="true"/></shape>')
    scene = ptrace.load(path)
    faces = front(scene)[1]
    assert len(faces) == 2 + 1 + 2
    first = scene.geometry.vertices[faces[:2]]
    assert np.all(first[..., 2] == 5.0)
    # face_normals: the last quad's triangles share no vertex
    assert len(np.unique(faces[-2:])) == 6


@pytest.mark.parametrize("far", [0.5, 3e18])
def test_mesh_texture_coordinates_beyond_the_limit_are_refused_naming_the_shape(tmp_path, far):
    """An OBJ's vt or a serialized mesh's uv beyond ptrace.io.limits.UV_LIMIT (where a texel's
    index overflows and the lookup reads an arbitrary texel) is refused in one line naming the
    scene file, the shape's line and the triangle, as the mesh files' own loader refuses it;
    in range, the same files load."""
    (tmp_path / "quad.obj").write_text(f"v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\n"
                                       f"vt 1 {far}\nf 1/1 2/2 3/3\n")
    (tmp_path / "tri.serialized").write_bytes(serialized([([[0, 0, 0], [1, 0, 0], [1, 1, 0]],
                                                           [[0, 1, 2]],
                                                           [[0, 0], [1, 0], [far, 1]])]))
    for shape in ('<shape type="obj"><string name="filename" value="quad.obj"/></shape>',
                  '<shape type="serialized"><string name="filename" value="tri.serialized"/>'
                  '</shape>'):
        path = write(tmp_path, shape)
        if far < 1.0:
            assert len(front(ptrace.load(path))[1]) == 1
            continue
        with pytest.raises(ptrace.SceneError,
                           match=r"scene.xml:2: .*triangle 1: its texture coordinate [uv] at "
                                 r"corner 3 .*3e\+18 is beyond"):
            ptrace.load(path)


def test_texture_coordinates_follow_mitsuba(tmp_path):
    """Mitsuba's v runs down the image, ptrace's up: a rectangle's corner (-1, -1) has
    Mitsuba's (u, v) = (0, 0), so ptrace's (0, 1), and so has a PLY's or a serialized mesh's
    of (u, v) = (0, 0); an OBJ's vt (0, 0), which Mitsuba flips (flip_tex_coords), keeps
    ptrace's (0, 0). (Renders of the four, textured, agree with Mitsuba's to 0.01 per pixel.)"""
    write_texture(tmp_path / "tex.exr")
    (tmp_path / "quad.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\n"
                                       "vt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n")
    (tmp_path / "quad.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\n" + "".join(
            f"property float {p}\n" for p in "xyzuv") + "element face 2\nproperty list uchar "
        "int vertex_indices\nend_header\n-1 -1 0 0 0\n1 -1 0 1 0\n1 1 0 1 1\n-1 1 0 0 1\n"
        "3 0 1 2\n3 0 2 3\n")
    (tmp_path / "quad.serialized").write_bytes(serialized([(
        [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]],
        [[0, 0], [1, 0], [1, 1], [0, 1]])]))
    textured = ('<bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string '
                'name="filename" value="tex.exr"/></texture></bsdf>')
    for shape, expected in (('<shape type="rectangle">', [0, 1]),
                            ('<shape type="serialized"><string name="filename" '
                             'value="quad.serialized"/>', [0, 1]),
                            ('<shape type="obj"><string name="filename" value="quad.obj"/>',
                             [0, 0]),
                            ('<shape type="ply"><string name="filename" value="quad.ply"/>',
                             [0, 1])):
        scene = ptrace.load(write(tmp_path, f"{shape}{textured}</shape>"))
        corners = scene.geometry.vertices[scene.geometry.faces]
        lower_left = np.all(np.isclose(corners, [-1, -1, 0]), axis=-1)
        np.testing.assert_allclose(scene.uv[lower_left], [expected] * lower_left.sum())
        assert scene.materials.albedo_texture[scene.material_index[0]] == 0


@pytest.mark.parametrize("transform", [
    '<transform name="to_uv"><scale x="2" y="3"/><translate x="0.25" y="0.1"/></transform>',
    '<float name="uscale" value="2"/><float name="vscale" value="3"/><float name="uoffset" '
    'value="0.25"/><float name="voffset" value="0.1"/>',
])
def test_texture_coordinate_transforms(tmp_path, transform):
    """Mitsuba's (u, v) = (0, 0) at the rectangle's corner (-1, -1) becomes (0.25, 0.1), so
    ptrace's (0.25, 0.9); (1, 1) at (1, 1) becomes (2.25, 3.1), ptrace's (2.25, -2.1)."""
    write_texture(tmp_path / "tex.exr")
    scene = ptrace.load(write(tmp_path, '<shape type="rectangle"><bsdf type="diffuse"><texture '
                                        'type="bitmap" name="reflectance"><string name="'
                                        f'filename" value="tex.exr"/>{transform}</texture>'
                                        '</bsdf></shape>'))
    corners = scene.geometry.vertices[scene.geometry.faces]
    for point, expected in (([-1, -1, 0], [0.25, 0.9]), ([1, 1, 0], [2.25, -2.1])):
        at = np.all(np.isclose(corners, point), axis=-1)
        np.testing.assert_allclose(scene.uv[at], [expected] * at.sum(), atol=1e-12)


def test_a_textured_sphere_takes_the_texture_mean(tmp_path):
    write_texture(tmp_path / "tex.exr")
    scene = ptrace.load(write(tmp_path, '<shape type="sphere"><bsdf type="diffuse"><texture '
                                        'type="bitmap" name="reflectance"><string name="'
                                        'filename" value="tex.exr"/></texture></bsdf></shape>'))
    m = scene.material_index[0]
    assert scene.materials.albedo_texture[m] == -1
    np.testing.assert_allclose(scene.materials.albedo[m], [0.5, 0.5, 0.2], rtol=1e-6)
    assert any("mean colour" in note for note in scene.notes)


def test_checkerboard_is_baked_with_mitsubas_quadrants(tmp_path):
    """color0 where u and v are in the same half of their unit (the image's top-left and
    bottom-right quarters: Mitsuba's v runs down), color1 in the others."""
    scene = ptrace.load(write(tmp_path, '<shape type="rectangle"><bsdf type="diffuse"><texture '
                                        'type="checkerboard" name="reflectance"><rgb name="'
                                        'color0" value="1 0 0"/><rgb name="color1" value="0 0 '
                                        '1"/></texture></bsdf></shape>'))
    textures = scene.textures
    side = int(textures.width[0])
    image = textures.texels[:side * side].reshape(side, side, 3)
    np.testing.assert_allclose(image[0, 0], [1, 0, 0])
    np.testing.assert_allclose(image[-1, -1], [1, 0, 0])
    np.testing.assert_allclose(image[0, -1], [0, 0, 1])
    np.testing.assert_allclose(image[-1, 0], [0, 0, 1])


@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
def test_a_nearest_bitmap_looks_up_what_mitsubas_looks_up(tmp_path, wrap):
    """filter_type nearest: ptrace's lookup of the texture it stores against Mitsuba's own
    bitmap texture, at 500 (u, v) over three repeats of an 8 x 8 image, all but those within
    1/32 of a texel of a texel edge (where ptrace's ramps across it): the same texel's value,
    where the bilinear lookup of the image (what the reader drew before) differs."""
    from ptrace.textures import texture_lookup
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    image = np.random.default_rng(5).uniform(0.1, 0.9, (8, 8, 3)).astype(np.float32)
    write_texture_exr(tmp_path / "tex.exr", image)
    scene = ptrace.load(write(tmp_path, f'<shape type="rectangle"><bsdf type="diffuse"><texture '
                                        f'type="bitmap" name="reflectance"><string name="filename"'
                                        f' value="tex.exr"/><string name="filter_type" value='
                                        f'"nearest"/><string name="wrap_mode" value="{wrap}"/>'
                                        f'</texture></bsdf></shape>'))
    textures = scene.textures
    texels = np.ascontiguousarray(textures.texels, np.float32).reshape(-1, 3)
    wraps = np.asarray(textures.wrap, np.int64).reshape(-1, 2)
    theirs = mi.load_dict({"type": "bitmap", "filename": str(tmp_path / "tex.exr"),
                           "filter_type": "nearest", "wrap_mode": wrap, "raw": True})
    bilinear = mi.load_dict({"type": "bitmap", "filename": str(tmp_path / "tex.exr"),
                             "filter_type": "bilinear", "wrap_mode": wrap, "raw": True})
    compared = moved = 0
    for u, v in np.random.default_rng(6).uniform(-1.0, 2.0, (500, 2)):
        fractions = np.array([u, v]) * 8 % 1.0
        if np.any(np.minimum(fractions, 1 - fractions) < 1 / 32):
            continue
        si = mi.SurfaceInteraction3f()
        si.uv = mi.Point2f(u, v)
        expected = np.array(theirs.eval(si))
        ours = texture_lookup(texels, textures.offset, textures.width, textures.height, wraps,
                              0, u, 1.0 - v)      # ptrace's v runs up the image
        np.testing.assert_allclose(ours, expected, rtol=1e-5, atol=1e-6)
        compared += 1
        moved += np.abs(np.array(bilinear.eval(si)) - expected).max() > 1e-3
    assert compared > 300 and moved > compared // 2


def write_texture(path):
    """An 8 x 8 EXR: red grows to the right, green down the image."""
    import OpenImageIO as oiio
    y, x = np.mgrid[0:8, 0:8]
    pixels = np.stack([x / 7, y / 7, np.full((8, 8), 0.2)], axis=-1).astype(np.float32)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(8, 8, 3, oiio.FLOAT))
    out.write_image(pixels)
    out.close()


def serialized(meshes, version=4):
    """The bytes of a Mitsuba serialized file of these (vertices, faces, uv or None) meshes,
    single precision, written from the format's description."""
    chunks, offsets, at = [], [], 0
    for vertices, faces, uv in meshes:
        flags = 0x1000 | (0x0002 if uv is not None else 0)
        body = struct.pack("<I", flags) + (b"part\0" if version == 4 else b"")
        body += struct.pack("<QQ", len(vertices), len(faces))
        body += np.asarray(vertices, "<f4").tobytes()
        body += b"" if uv is None else np.asarray(uv, "<f4").tobytes()
        body += np.asarray(faces, "<u4").tobytes()
        chunk = struct.pack("<HH", 0x041C, version) + zlib.compress(body)
        offsets.append(at)
        chunks.append(chunk)
        at += len(chunk)
    width = "<Q" if version == 4 else "<I"
    return b"".join(chunks) + b"".join(struct.pack(width, o) for o in offsets) + \
        struct.pack("<I", len(meshes))


@pytest.mark.parametrize("version", [3, 4])
def test_serialized_meshes_read_as_mitsuba_reads_them(tmp_path, version):
    square = ([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]],
              [[0, 0], [1, 0], [1, 1], [0, 1]])
    triangle = ([[0, 0, 1], [2, 0, 1], [0, 3, 1]], [[0, 1, 2]], None)
    (tmp_path / "parts.serialized").write_bytes(serialized([square, triangle], version))
    path = write(tmp_path, '<shape type="serialized"><string name="filename" '
                           'value="parts.serialized"/><integer name="shape_index" value="1"/>'
                           '<transform name="to_world"><translate x="5"/></transform></shape>')
    scene = ptrace.load(path)
    geometry = scene.geometry
    np.testing.assert_allclose(geometry.vertices[geometry.faces[0]],
                               [[5, 0, 1], [7, 0, 1], [5, 3, 1]])
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    shape = mi.load_file(str(path)).shapes()[0]
    theirs = np.array(mi.traverse(shape)["vertex_positions"]).reshape(-1, 3)
    np.testing.assert_allclose(np.sort(theirs, axis=0), np.sort(front(scene)[0], axis=0))


@pytest.mark.parametrize("lie, fragment", [
    ("count", "more than its"),
    ("index", "past its 3 vertices"),
    ("table", "table of meshes claims"),
])
def test_a_serialized_file_that_lies_about_its_sizes(tmp_path, capsys, lie, fragment):
    vertices, faces = [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]
    if lie == "index":
        faces = [[0, 1, 7]]
    data = serialized([(vertices, faces, None)])
    if lie == "count":      # a header claiming a billion vertices over the same data
        body = zlib.decompress(data[4:-12])
        body = body[:9] + struct.pack("<Q", 10 ** 9) + body[17:]
        data = data[:4] + zlib.compress(body) + struct.pack("<QI", 0, 1)
    if lie == "table":
        data = data[:-4] + struct.pack("<I", 10 ** 6)
    (tmp_path / "m.serialized").write_bytes(data)
    path = write(tmp_path, '<shape type="serialized"><string name="filename" '
                           'value="m.serialized"/></shape>')
    assert main(["-q", "-r", "4", "3", "-f", str(tmp_path / "o.png"), str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and fragment in err and "m.serialized" in err


def test_the_memory_budget_counts_every_mesh_placed(tmp_path):
    """Each placement of a mesh file is charged, and so is the black back each open quad of
    Mitsuba's default (one-sided) diffuse gets: three quads and their backs, 12 triangles."""
    (tmp_path / "quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    one = '<shape type="obj"><string name="filename" value="quad.obj"/></shape>'
    path = write(tmp_path, one * 3)
    per_quad = ptrace.budget.LOAD_BYTES_PER_TRIANGLE * 2
    scene = ptrace.load(path, max_memory=6 * per_quad)
    assert len(front(scene)[1]) == 6 and scene.triangle_count == 12
    with pytest.raises(ptrace.budget.BudgetError, match="memory budget") as caught:
        ptrace.load(path, max_memory=6 * per_quad - 1)
    assert 'the back of <shape type="obj">' in caught.value.message


def test_the_memory_budget_counts_a_black_back_before_it_is_made(tmp_path):
    """A one-sided open mesh's back doubles its triangles: a budget that holds the file's
    triangles but not their back refuses the scene, naming the back, before making it; the same
    mesh under a two-sided BSDF (no back) fits that budget."""
    n = 20
    rows = ["v %d 0 0\nv %d 1 0" % (i, i) for i in range(n + 1)]
    strip = "\n".join(rows) + "\n" + "\n".join(
        f"f {2 * i + 1} {2 * i + 3} {2 * i + 4} {2 * i + 2}" for i in range(n)) + "\n"
    (tmp_path / "strip.obj").write_text(strip)
    path = write(tmp_path, '<shape type="obj"><string name="filename" value="strip.obj"/>'
                           '<bsdf type="diffuse"/></shape>')
    per = ptrace.budget.LOAD_BYTES_PER_TRIANGLE
    assert ptrace.load(path, max_memory=4 * n * per).triangle_count == 4 * n
    with pytest.raises(ptrace.budget.BudgetError) as caught:
        ptrace.load(path, max_memory=3 * n * per)
    assert caught.value.path == str(path)
    assert "the back of <shape type=\"obj\">" in caught.value.message
    assert f"({2 * n:,} triangles)" in caught.value.message
    two_sided = write(tmp_path, '<shape type="obj"><string name="filename" '
                                'value="strip.obj"/><bsdf type="twosided"><bsdf '
                                'type="diffuse"/></bsdf></shape>')
    assert ptrace.load(two_sided, max_memory=3 * n * per).triangle_count == 2 * n


def test_the_memory_budget_counts_the_meshes_before_reading_any(tmp_path):
    """The budget is checked for every mesh file's triangles (a PLY's and a serialized
    mesh's header, an OBJ's faces) before any file is read: an OBJ whose face points past its
    vertices is not reached when the PLY after it claims too many faces."""
    (tmp_path / "bad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n")
    (tmp_path / "big.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex "
                                       b"3\nproperty float x\nproperty float y\nproperty "
                                       b"float z\nelement face 1000000\nproperty list uchar "
                                       b"int vertex_indices\nend_header\n")
    square = ([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], None)
    (tmp_path / "m.serialized").write_bytes(serialized([square]))
    path = write(tmp_path, "".join(
        f'<shape type="{kind}"><string name="filename" value="{name}"/></shape>'
        for kind, name in (("obj", "bad.obj"), ("serialized", "m.serialized"),
                           ("ply", "big.ply"))))
    per = ptrace.budget.LOAD_BYTES_PER_TRIANGLE
    with pytest.raises(ptrace.budget.BudgetError) as caught:
        ptrace.load(path, max_memory=10 ** 6 * per)
    assert caught.value.path == str(path)
    assert "the 1,000,003 triangles of its 3 mesh files" in caught.value.message
    with pytest.raises(ptrace.SceneError, match="bad.obj"):     # within the budget: read
        ptrace.load(path, max_memory=2 * 10 ** 6 * per)


def binary_ply(path, vertices, faces, extra=()):
    """A binary little-endian PLY of float x y z (and the named extra float columns of each
    vertex row after them) and faces of any size."""
    names = ["x", "y", "z", *extra]
    head = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {len(vertices)}\n" + \
        "".join(f"property float {n}\n" for n in names) + f"element face {len(faces)}\n" + \
        "property list uchar int vertex_indices\nend_header\n"
    body = np.asarray(vertices, "<f4").tobytes()
    body += b"".join(struct.pack("<B", len(f)) + np.asarray(f, "<i4").tobytes() for f in faces)
    path.write_bytes(head.encode() + body)


def test_a_binary_ply_is_read_as_mitsuba_reads_it(tmp_path):
    """A binary PLY of triangles is read straight (its vertices unmerged, its u v kept), the
    same triangles as trimesh reads; one with a quad goes through trimesh, fan-triangulated."""
    from ptrace.io import mitsuba_shapes
    rows = [[0, 0, 0, 0, 0, 0.5], [1, 0, 0, 1, 0, 0.5], [1, 1, 0, 1, 1, 0.5],
            [0, 1, 0, 0, 1, 0.5], [0, 1, 0, 0, 1, 0.5]]          # a duplicate vertex
    binary_ply(tmp_path / "t.ply", rows, [[0, 1, 2], [0, 2, 4]], extra=("u", "v", "w"))
    parts = mitsuba_shapes._binary_ply(str(tmp_path / "t.ply"))
    assert len(parts["vertices"]) == 5
    np.testing.assert_array_equal(parts["faces"], [[0, 1, 2], [0, 2, 4]])
    np.testing.assert_allclose(parts["uv"][1], [[0, 0], [1, 1], [0, 1]])
    scene = ptrace.load(write(tmp_path, '<shape type="ply"><string name="filename" '
                                        'value="t.ply"/></shape>'))
    np.testing.assert_allclose(scene.geometry.vertices[front(scene)[1]],
                               np.array(rows)[:, :3][[[0, 1, 2], [0, 2, 4]]])
    binary_ply(tmp_path / "q.ply", np.array(rows)[:4, :3], [[0, 1, 2, 3]])
    assert mitsuba_shapes._binary_ply(str(tmp_path / "q.ply")) is None
    scene = ptrace.load(write(tmp_path, '<shape type="ply"><string name="filename" '
                                        'value="q.ply"/></shape>', name="q.xml"))
    assert len(front(scene)[1]) == 2


# --- materials ------------------------------------------------------------------------------

def material_of(tmp_path, bsdf):
    scene = ptrace.load(write(tmp_path, f'<shape type="sphere">{bsdf}</shape>'))
    index = scene.material_index[0]
    return scene.materials, index, scene.notes


def test_diffuse_and_twosided(tmp_path):
    materials, i, _ = material_of(tmp_path, '<bsdf type="twosided"><bsdf type="diffuse">'
                                            '<rgb name="reflectance" value="0.1 0.2 0.3"/>'
                                            '</bsdf></bsdf>')
    assert materials.kind[i] == DIFFUSE
    np.testing.assert_allclose(materials.albedo[i], [0.1, 0.2, 0.3])


def fresnel_reflectance(cos_i, eta):
    """The textbook unpolarised Fresnel reflectance of a boundary met from the side of index 1
    (the other eta), for the tests' own numbers."""
    cos_t = math.sqrt(1.0 - (1.0 - cos_i ** 2) / eta ** 2)
    rs = ((cos_i - eta * cos_t) / (cos_i + eta * cos_t)) ** 2
    rp = ((eta * cos_i - cos_t) / (eta * cos_i + cos_t)) ** 2
    return 0.5 * (rs + rp)


THIN = ('<bsdf type="thindielectric"><float name="int_ior" value="1.5"/><rgb name="specular_'
        'reflectance" value="0.9 0.8 0.7"/><rgb name="specular_transmittance" value="0.6 0.5 '
        '0.4"/></bsdf>')


@pytest.mark.parametrize("theta", [0.0, 60.0, 85.0])
@pytest.mark.parametrize("inside", [False, True])
def test_a_thindielectric_reflects_as_a_slab_at_the_angle_met(tmp_path, theta, inside):
    """Mitsuba's thindielectric: a thin slab that reflects with probability R' = 2 R / (1 + R)
    (R the exact Fresnel reflectance of one face at that angle: R' 0.077 straight on, 0.164 at
    60 degrees, 0.760 at 85, from either side), its weight the specular_reflectance, and else
    passes the ray straight through, its weight the specular_transmittance. (It was a mirror
    cut-out of R' at normal incidence whatever the angle: the glass of Mitsuba's
    bsdf_thindielectric_glass.xml, seen mostly at an angle, rendered 0.962 of Mitsuba's mean.)"""
    materials, m, _ = material_of(tmp_path, THIN)
    t = math.radians(theta)
    wo = np.array([math.sin(t) * math.cos(0.4), math.sin(t) * math.sin(0.4), math.cos(t)])
    wo = -wo if inside else wo
    r = fresnel_reflectance(math.cos(t), materials.ior[m])   # 1.5 over air's 1.000277
    r = 2.0 * r / (1.0 + r)
    sample = lambda u3: dielectric_sample(*materials.albedo[m], materials.transmittance,
                                          materials.ior, 0.0, 0.0, materials.eta, materials.k,
                                          materials.specular, m, *wo, 0.5, 0.5, u3)
    x, y, z, fr, fg, fb, pdf = sample(r * 0.999)
    assert pdf == pytest.approx(r, rel=1e-9)
    assert (x, y, z) == pytest.approx((-wo[0], -wo[1], wo[2]))
    np.testing.assert_allclose(np.array([fr, fg, fb]) * abs(z) / pdf, [0.9, 0.8, 0.7])
    x, y, z, fr, fg, fb, pdf = sample(min(r * 1.001, 0.999))
    assert pdf == pytest.approx(1.0 - r, rel=1e-9)
    assert (x, y, z) == pytest.approx(tuple(-wo))
    np.testing.assert_allclose(np.array([fr, fg, fb]) * abs(z) / pdf, [0.6, 0.5, 0.4])


def test_a_thindielectric_samples_as_mitsubas(tmp_path):
    """The reader's thindielectric against Mitsuba's own BSDF, on 100 directions from either
    side and several sample1 values: the direction, the branch probability and the weight."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    theirs = mi.load_dict({"type": "thindielectric", "int_ior": 1.5,
                           "specular_reflectance": {"type": "rgb", "value": [0.9, 0.8, 0.7]},
                           "specular_transmittance": {"type": "rgb", "value": [0.6, 0.5, 0.4]}})
    materials, m, _ = material_of(tmp_path, THIN)
    rng = np.random.default_rng(3)
    for _ in range(100):
        wo = rng.normal(size=3)
        wo /= np.linalg.norm(wo)
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wo)      # Mitsuba's wi is ptrace's wo
        si.n = mi.Normal3f(0, 0, 1)
        si.sh_frame = mi.Frame3f(si.n)
        for u in (0.01, 0.1, 0.3, 0.6, 0.95):
            sampled, weight = theirs.sample(mi.BSDFContext(), si, u, mi.Point2f(0.5, 0.5))
            x, y, z, fr, fg, fb, pdf = dielectric_sample(
                *materials.albedo[m], materials.transmittance, materials.ior, 0.0, 0.0,
                materials.eta, materials.k, materials.specular, m, *wo, 0.5, 0.5, u)
            assert pdf == pytest.approx(float(sampled.pdf), rel=1e-5)
            assert (x, y, z) == pytest.approx(tuple(np.array(sampled.wo)), abs=1e-6)
            np.testing.assert_allclose(np.array([fr, fg, fb]) * abs(z) / pdf,
                                       np.array(weight), rtol=1e-5)


def test_conductors(tmp_path):
    materials, i, _ = material_of(tmp_path, '<bsdf type="conductor"><rgb name="specular_'
                                            'reflectance" value="0.9 0.8 0.7"/></bsdf>')
    assert materials.kind[i] == MIRROR
    np.testing.assert_allclose(materials.albedo[i], [0.9, 0.8, 0.7])
    materials, i, _ = material_of(tmp_path, '<bsdf type="roughconductor"><string name="'
                                            'material" value="Au"/><float name="alpha" '
                                            'value="0.2"/></bsdf>')
    assert materials.kind[i] == MICROFACET and materials.alpha[i] == 0.2
    np.testing.assert_allclose(materials.eta[i], CONDUCTORS["Au"][0])
    np.testing.assert_allclose(materials.k[i], CONDUCTORS["Au"][1])


def test_a_rough_conductor_s_specular_reflectance_scales_its_fresnel(tmp_path):
    """Mitsuba's roughconductor with eta and k multiplies its Fresnel by specular_reflectance
    (Veach's MIS scene's plates have 0.3 and rendered 1.5x too bright when it was ignored):
    ptrace's microfacet f is the same material's without it, times it, channel by channel;
    and a microfacet from any other record (the course's, MTL's) has a factor of 1."""
    base = ('<bsdf type="roughconductor"><float name="alpha" value="0.15"/><rgb name="eta" '
            'value="0.2 0.9 1.1"/><rgb name="k" value="3.9 2.4 2.2"/>{}</bsdf>')
    plain, i, _ = material_of(tmp_path, base.format(""))
    scaled, j, notes = material_of(tmp_path, base.format(
        '<rgb name="specular_reflectance" value="0.3 0.5 0.7"/>'))
    assert scaled.kind[j] == MICROFACET and not any("specular" in note for note in notes)
    np.testing.assert_allclose(plain.specular[i, :3], [1.0] * 3)
    np.testing.assert_allclose(scaled.specular[j, :3], [0.3, 0.5, 0.7])
    wo, wi = np.array([0.3, -0.2, 0.93]), np.array([-0.25, 0.3, 0.92])
    wo, wi = wo / np.linalg.norm(wo), wi / np.linalg.norm(wi)
    one = microfacet_eval(0, 0, 0, plain.alpha[i], 0.0, plain.eta, plain.k, plain.specular, i,
                          *wo, *wi)
    two = microfacet_eval(0, 0, 0, scaled.alpha[j], 0.0, scaled.eta, scaled.k, scaled.specular,
                          j, *wo, *wi)
    assert min(one) > 0
    np.testing.assert_allclose(two, np.array(one) * [0.3, 0.5, 0.7], rtol=1e-12)
    course = Materials.from_records([dict(kind=MICROFACET, alpha=0.2, eta=(1, 1, 1),
                                          k=(2, 2, 2))])
    np.testing.assert_allclose(course.specular[0, :3], [1.0] * 3)


def test_dielectrics_plastic_principled(tmp_path):
    materials, i, notes = material_of(tmp_path, '<bsdf type="dielectric"><float name="int_ior" '
                                                'value="1.5"/><float name="ext_ior" '
                                                'value="1.25"/></bsdf>')
    assert materials.kind[i] == GLASS and materials.ior[i] == pytest.approx(1.2)
    assert materials.fresnel[i] == EXACT and not any("Fresnel" in note for note in notes)
    materials, i, _ = material_of(tmp_path, '<bsdf type="thindielectric"/>')
    assert materials.kind[i] == GLASS and materials.fresnel[i] == EXACT
    assert materials.k[i, 0] == THIN_GLASS and materials.cutoff[i] == 0.0
    assert materials.ior[i] == pytest.approx(IOR["bk7"] / IOR["air"])
    materials, i, _ = material_of(tmp_path, '<bsdf type="roughplastic"><rgb name="diffuse_'
                                            'reflectance" value="0.4"/><float name="alpha" '
                                            'value="0.3"/><float name="int_ior" value="1.5"/>'
                                            '<float name="ext_ior" value="1"/></bsdf>')
    assert materials.kind[i] == ROUGH_PLASTIC and materials.alpha[i] == 0.3
    assert materials.ior[i] == 1.5 and materials.eta[i, 0] == 1.5
    assert materials.eta[i, 2] == pytest.approx(1.0 / 1.4)   # specular weight: 1 / (1 + 0.4)
    assert materials.specular.shape == (len(materials), 3 + TABLE)
    np.testing.assert_allclose(materials.specular[i, :3], [1.0] * 3)
    table = materials.specular[i, 3:]      # the coat passes more light the steeper it arrives
    assert np.all(np.diff(table) > 0) and 0.0 < table[0] and table[-1] < 1.0
    np.testing.assert_allclose(materials.albedo[i], [0.4] * 3)
    materials, i, _ = material_of(tmp_path, '<bsdf type="plastic"><rgb name="diffuse_'
                                            'reflectance" value="0.2 0.4 0.6"/><boolean name='
                                            '"nonlinear" value="true"/></bsdf>')
    assert materials.kind[i] == PLASTIC and materials.k[i, 0] == 1.0
    assert materials.eta[i, 0] == pytest.approx(IOR["polypropylene"] / IOR["air"])
    materials, i, _ = material_of(tmp_path, '<bsdf type="principled"><rgb name="base_color" '
                                            'value="0.8 0.1 0.1"/><float name="roughness" '
                                            'value="0.5"/><float name="metallic" value="1"/>'
                                            '</bsdf>')
    assert materials.kind[i] == GLTF_PBR and materials.alpha[i] == pytest.approx(0.25)
    assert materials.metallic[i] == 1.0


@pytest.mark.parametrize("ior", [1.5, 1.33, 2.4])
def test_a_dielectric_reflects_as_mitsubas(ior):
    """ptrace.bsdf.dielectric_sample (the glass of a Mitsuba dielectric) against Mitsuba's
    smooth dielectric, entering and leaving at 40 angles: the probability of reflection (the
    Fresnel reflectance, 1 past total internal reflection) and the direction of each lobe;
    Schlick's (glass_sample, the course's) differs by more than 1e-3 at some of them."""
    from ptrace.bsdf import dielectric_sample, glass_sample
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    bsdf = mi.load_dict({"type": "dielectric", "int_ior": ior, "ext_ior": 1.0})
    albedo, iors = np.ones((1, 3)), np.array([ior])
    schlick_differs = False
    for sign in (1.0, -1.0):
        for theta in np.linspace(0.0, 1.55, 40):
            wo = (math.sin(theta), 0.0, sign * math.cos(theta))
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wo)
            si.n = mi.Normal3f(0, 0, 1)
            si.sh_frame = mi.Frame3f(si.n)
            for u3 in (0.0, 0.999999):
                sample, _ = bsdf.sample(mi.BSDFContext(), si, u3, mi.Point2f(0.5, 0.5))
                ours = dielectric_sample(1.0, 1.0, 1.0, albedo, iors, np.zeros(1), np.zeros(1),
                                         albedo, albedo, albedo, 0, *wo, 0.5, 0.5, u3)
                np.testing.assert_allclose(ours[:3], np.array(sample.wo), atol=1e-5)
                assert ours[6] == pytest.approx(float(sample.pdf), abs=1e-5), (sign, theta)
                schlick = glass_sample(1.0, 1.0, 1.0, albedo, iors, np.zeros(1), np.zeros(1),
                                       albedo, albedo, albedo, 0, *wo, 0.5, 0.5, u3)
                schlick_differs |= abs(schlick[6] - float(sample.pdf)) > 1e-3
    assert schlick_differs


def test_one_note_per_kind_through_the_cli(tmp_path, capsys):
    plastic = '<bsdf type="roughdielectric"><float name="alpha" value="0.01"/></bsdf>'
    path = write(tmp_path, f'<shape type="sphere">{plastic}</shape><shape type="sphere">'
                           f'<point name="center" x="3" y="0" z="0"/>{plastic}</shape>'
                           '<shape type="sphere"><bsdf type="diffuse"><float name="bogus" '
                           'value="1"/></bsdf></shape>')
    assert main(["--info", str(path)]) == 0
    notes = "\n".join(json.loads(capsys.readouterr().out)["notes"])
    assert notes.count("drawn smooth") == 1
    assert "'bogus' ignored" in notes
    assert notes.count("outside a twosided") == 1


def test_a_twosided_diffuse_is_not_noted_as_one_sided(tmp_path):
    scene = ptrace.load(write(tmp_path, '<shape type="sphere"><bsdf type="twosided"><bsdf '
                                        'type="diffuse"/></bsdf></shape><shape type="cube">'
                                        '<bsdf type="diffuse"/></shape>'))
    assert sum("outside a twosided" in note for note in scene.notes) == 1


# --- emitters and the sensor ----------------------------------------------------------------

def test_emitters(tmp_path):
    path = write(tmp_path, '<emitter type="point"><point name="position" x="1" y="2" z="3"/>'
                           '<rgb name="intensity" value="5"/></emitter>'
                           '<emitter type="spot"><transform name="to_world"><lookat '
                           'origin="0 4 0" target="0 0 0" up="0 0 1"/></transform>'
                           '<float name="cutoff_angle" value="30"/></emitter>'
                           '<emitter type="directional"><vector name="direction" x="0" y="-2" '
                           'z="0"/><rgb name="irradiance" value="2"/></emitter>'
                           '<emitter type="constant"><rgb name="radiance" value="0.5"/>'
                           '</emitter><shape type="rectangle"><emitter type="area"><rgb '
                           'name="radiance" value="7"/></emitter></shape>')
    scene = ptrace.load(path)
    lights = scene.lights
    point, spot, directional = (list(lights.kind).index(k) for k in (POINT, SPOT, DIRECTIONAL))
    np.testing.assert_allclose(lights.position[point], [1, 2, 3])
    np.testing.assert_allclose(lights.radiance[point], [5, 5, 5])
    np.testing.assert_allclose(lights.direction[spot], [0, -1, 0])
    assert lights.cos_outer[spot] == pytest.approx(math.cos(math.radians(30)))
    assert lights.cos_inner[spot] == pytest.approx(math.cos(math.radians(22.5)))   # 3/4 cutoff
    assert lights.falloff[spot] == ANGULAR
    np.testing.assert_allclose(lights.direction[directional], [0, 1, 0])   # toward the light
    np.testing.assert_allclose(scene.environment.image, 0.5)
    # the rectangle's front emits and reflects (Mitsuba's default diffuse: glTF's BRDF)
    emitting = scene.materials.emits()[scene.material_index]
    assert emitting.sum() == 2 and (scene.materials.emission[scene.material_index[emitting]]
                                    == 7).all()


def test_an_envmap_looks_up_what_mitsubas_looks_up(tmp_path):
    """ptrace's lookup of a resampled envmap (turned by a to_world) against Mitsuba's own
    lookup of the file, in 300 directions: a smooth 16 x 32 image, whose rows Mitsuba spreads
    from pole to pole and whose columns it centres on cells."""
    from ptrace.environment import environment_radiance
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rows, columns = np.mgrid[0:16, 0:32]
    ring = np.sin(np.pi * rows / 15)    # 0 on the first and last rows, which are the poles
    image = np.stack([1 + np.sin(rows / 3.0), 1 + 0.5 * ring * np.cos(columns / 5.0),
                      0.2 + ring * columns / 20.0], axis=-1).astype(np.float32)
    write_texture_exr(tmp_path / "env.exr", image)
    path = write(tmp_path, '<emitter type="envmap"><string name="filename" value="env.exr"/>'
                           '<transform name="to_world"><rotate x="0.8" y="0.6" angle="35"/>'
                           '</transform></emitter>')
    ours = ptrace.load(path).environment.image
    emitter = mi.load_file(str(path)).emitters()[0]
    errors = []
    for d in np.random.default_rng(3).normal(size=(300, 3)):
        d /= np.linalg.norm(d)
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d))
        theirs = np.array(emitter.eval(si))
        errors.append(np.abs(np.array(environment_radiance(ours, *d)) - theirs).max())
    # ptrace's lookup of the map resampled finer: close, not the same bits; the image
    # spans 0 to 2
    assert np.median(errors) < 0.002 and np.max(errors) < 0.05, (np.median(errors),
                                                                  np.max(errors))


def write_texture_exr(path, pixels):
    import OpenImageIO as oiio
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, oiio.FLOAT))
    out.write_image(np.ascontiguousarray(pixels))
    out.close()


@pytest.mark.parametrize("beam, cutoff", [(15.0, 20.0), (1.0, 60.0), (30.0, 30.0)])
def test_a_spot_falls_off_as_mitsubas(tmp_path, beam, cutoff):
    """What a point lit by a spot receives (ptrace.lights.sample_light_angular, the sampler of a
    scene of Mitsuba spots) against Mitsuba's own spot emitter (sample_direction's weight), at
    angles across the beam, the ramp and past the cutoff; glTF's falloff (sample_light) differs
    on the ramp."""
    from ptrace.integrator import scene_records
    from ptrace.lights import sample_light, sample_light_angular
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path = write(tmp_path, f'<emitter type="spot"><transform name="to_world"><lookat '
                           f'origin="0 0 0" target="0 0 1" up="0 1 0"/></transform><float '
                           f'name="cutoff_angle" value="{cutoff}"/><float name="beam_width" '
                           f'value="{beam}"/>'
                           f'<rgb name="intensity" value="4"/></emitter>'
                           f'<shape type="sphere"><point name="center" x="0" y="0" z="-5"/>'
                           f'<float name="radius" value="0.1"/></shape>')
    lights = scene_records(ptrace.load(path))[2]
    emitter = mi.load_file(str(path)).emitters()[0]
    ramp = []
    for angle in np.linspace(0.0, min(cutoff + 5.0, 89.0), 41):
        p = 2.0 * np.array([math.sin(math.radians(angle)), 0.0, math.cos(math.radians(angle))])
        it = mi.Interaction3f()
        it.p = mi.Point3f(*p)
        theirs = float(emitter.sample_direction(it, mi.Point2f(0.5, 0.5))[1][0])
        ours = sample_light_angular(lights, 0, *p, 0.5, 0.5)
        assert ours[0] == pytest.approx(theirs, rel=1e-4, abs=1e-6), angle
        assert ours[7] == 1.0 or ours[0] == 0.0
        if beam < angle < cutoff:
            ramp.append(abs(sample_light(lights, 0, *p, 0.5, 0.5)[0] - theirs) > 1e-3)
    assert all(ramp) if beam < cutoff else not ramp


def agrees_per_pixel(mi, path, size=(16, 12), spp=16, batches=6):
    """benchmarks.mitsuba_scenes' z-test of ptrace's and Mitsuba's renders of one file, each in
    `batches` batches of `spp` with their own seeds: (share of pixel channels at p < 0.01,
    whether that share is what agreeing images give)."""
    from benchmarks.mitsuba_scenes import z_test
    defines = {"width": str(size[0]), "height": str(size[1]), "spp": str(spp)}
    scene = mi.load_file(str(path), **defines)
    theirs = np.stack([np.array(mi.render(scene, spp=spp, seed=1 + s))[:, :, :3]
                       for s in range(batches)])
    ours = ptrace.load(path, defines=defines)
    ours = np.stack([np.asarray(ptrace.render(ours, seed=1 + s)) for s in range(batches)])
    return z_test(ours.astype(np.float64), theirs.astype(np.float64))


SPOT_ON_A_FLOOR = """<default name="spp" value="16"/><default name="width" value="16"/>
<default name="height" value="12"/><integrator type="direct"/>
<sensor type="perspective"><float name="fov" value="50"/>
  <transform name="to_world"><lookat origin="0, 3, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
  <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
  <film type="hdrfilm"><integer name="width" value="$width"/><integer name="height"
    value="$height"/><rfilter type="box"/></film></sensor>
<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/>
  </transform><bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf></shape>
<emitter type="spot"><transform name="to_world"><lookat origin="0.5, 2, 0.5" target="0, 0, 0"/>
  </transform><float name="cutoff_angle" value="35"/><float name="beam_width" value="10"/>
  <rgb name="intensity" value="10"/></emitter>
"""


def test_a_spot_lit_floor_agrees_with_mitsuba_per_pixel(tmp_path):
    """A floor lit by a spot whose ramp (10 to 35 degrees) covers most of the image: the same
    file rendered by both, compared pixel by pixel (a z-test over batches); the image ptrace
    drew before it had Mitsuba's falloff (glTF's, squared in the cosine) differed on the ramp."""
    mi = pytest.importorskip("mitsuba")
    pytest.importorskip("scipy")
    mi.set_variant("scalar_rgb")
    share, agrees = agrees_per_pixel(mi, write(tmp_path, SPOT_ON_A_FLOOR))
    assert agrees, share


@pytest.mark.parametrize("axis, expected", [
    ("x", 2 * math.degrees(math.atan(math.tan(math.radians(30)) * 48 / 64))),
    ("y", 60.0),
    ("diagonal", 2 * math.degrees(math.atan(math.tan(math.radians(30)) * 48 / 80))),
])
def test_sensor(tmp_path, axis, expected):
    path = write(tmp_path, f'<sensor type="perspective"><float name="fov" value="60"/>'
                           f'<string name="fov_axis" value="{axis}"/><float name="near_clip" '
                           f'value="0.5"/><transform name="to_world"><lookat origin="1 2 3" '
                           f'target="1 2 0" up="0 1 0"/></transform><film type="hdrfilm">'
                           f'<integer name="width" value="64"/><integer name="height" '
                           f'value="48"/></film></sensor><shape type="sphere"/>')
    camera = ptrace.load(path).file_cameras[0]
    assert camera.yfov == pytest.approx(expected)
    assert camera.znear == 0.5 and camera.aspect == pytest.approx(64 / 48)
    np.testing.assert_allclose(camera.position, [1, 2, 3])
    np.testing.assert_allclose(camera.camera_to_world, np.eye(3), atol=1e-12)


# --- refusals: one line naming the file and the element, exit 2 -----------------------------

REFUSALS = {
    "missing_file": ('<shape type="obj"><string name="filename" value="gone.obj"/></shape>',
                     "file 'gone.obj' not found"),
    "unknown_plugin": ('<shape type="teapot"/>', "shape type 'teapot' is not supported"),
    "unknown_ref": ('<shape type="sphere"><ref id="nothing"/></shape>',
                    "no object has id 'nothing'"),
    "include_cycle": ('<include filename="scene.xml"/>', "includes itself"),
    "undefined_name": ('<shape type="sphere"><float name="radius" value="$size"/></shape>',
                       "$size has no value"),
    "singular_transform": ('<shape type="cube"><transform name="to_world"><scale z="0"/>'
                           '</transform></shape>', "not invertible"),
    "outside_folder": ('<include filename="../other.xml"/>', "outside the scene's folder"),
    "blend": ('<shape type="sphere"><bsdf type="blendbsdf"/></shape>', "blendbsdf"),
    "bump": ('<shape type="sphere"><bsdf type="bumpmap"/></shape>', "bumpmap"),
    "medium": ('<shape type="sphere"><medium type="homogeneous" name="interior"/></shape>',
               "participating media"),
    "entity": (None, "refused unsafe XML"),
    "wrong_type": ('<shape type="sphere"><string name="radius" value="big"/></shape>',
                   "parameter 'radius' must be a number"),
    "not_a_number": ('<shape type="sphere"><float name="radius" value="1e999"/></shape>',
                     "inf is not a finite number"),
    "beyond_limit": ('<shape type="sphere"><float name="radius" value="1e31"/></shape>',
                     "1e+31 is beyond"),
    "placed_beyond": ('<shape type="cube"><transform name="to_world"><scale value="1e20"/>'
                      '<scale value="1e20"/></transform></shape>', "out of range"),
    "mirrored_camera": ('<sensor type="perspective"><transform name="to_world"><scale x="-1"/>'
                        '</transform></sensor>', "mirrors the image"),
    "empty_number": ('<shape type="cube"><transform name="to_world"><translate x=""/>'
                     '</transform></shape>', "x needs one number, has 0"),
    "aov_integrator": ('<integrator type="aov"/>', "integrator type 'aov' is not supported"),
    "spectrum_pairs": ('<shape type="sphere"><bsdf type="diffuse"><spectrum name="reflectance" '
                       'value="400:0.1, 300:0.5"/></bsdf></shape>', "wavelengths increasing"),
    "old_version": ("version 1.0", "versions 0.4 to 0.6"),
}


@pytest.mark.parametrize("case", sorted(REFUSALS))
def test_refusals_are_one_line_and_exit_2(tmp_path, capsys, case):
    body, fragment = REFUSALS[case]
    if case == "entity":
        path = tmp_path / "scene.xml"
        path.write_text('<?xml version="1.0"?><!DOCTYPE scene [<!ENTITY a "aaaa">]>'
                        '<scene version="3.0.0">&a;</scene>')
    elif case == "old_version":
        path = write(tmp_path, "", version="1.0.0")
    else:
        path = write(tmp_path, body)
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    assert fragment in str(caught.value) and "scene.xml" in str(caught.value)
    assert main(["-q", "-r", "4", "3", "-f", str(tmp_path / "out.png"), str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ptrace: error: ") and fragment in err
    assert "Traceback" not in err


def test_an_include_cycle_is_refused_in_the_file_that_closes_it(tmp_path):
    write(tmp_path, '<include filename="scene.xml"/>', name="part.xml")
    path = write(tmp_path, '<include filename="part.xml"/>')
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    assert caught.value.path.endswith("part.xml")
    assert "scene.xml -> part.xml -> scene.xml" in caught.value.message


@pytest.mark.parametrize("sensor", [
    "",                                                     # Mitsuba's default: 50mm
    '<string name="focal_length" value="35mm"/>',
    '<float name="fov" value="50"/><string name="fov_axis" value="smaller"/>',
    '<float name="fov" value="50"/><string name="fov_axis" value="larger"/>',
])
def test_field_of_view_as_mitsuba_reads_it(tmp_path, sensor):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path = write(tmp_path, f'<sensor type="perspective">{sensor}<film type="hdrfilm"><integer '
                           f'name="width" value="48"/><integer name="height" value="64"/>'
                           f'</film></sensor><shape type="sphere"/>')
    x_fov = mi.traverse(mi.load_file(str(path)).sensors()[0])["x_fov"]
    x_fov = float(x_fov[0] if hasattr(x_fov, "__len__") else x_fov)
    yfov = math.degrees(2 * math.atan(math.tan(math.radians(x_fov) / 2) * 64 / 48))
    assert ptrace.load(path).file_cameras[0].yfov == pytest.approx(yfov, rel=1e-6)


def test_a_fifo_is_never_opened(tmp_path):
    os.mkfifo(tmp_path / "pipe.obj")
    path = write(tmp_path, '<shape type="obj"><string name="filename" value="pipe.obj"/>'
                           '</shape>')
    with pytest.raises(ptrace.SceneError, match="not a regular file"):
        ptrace.load(path)


def test_defines_on_the_command_line(tmp_path, capsys):
    path = write(tmp_path, '<shape type="sphere"><float name="radius" value="$size"/></shape>')
    assert main(["--info", "-D", "size=4", str(path)]) == 0
    bounds = json.loads(capsys.readouterr().out)["bounds"]
    assert bounds[1] == pytest.approx([4, 4, 4])


# --- the same file, rendered by both --------------------------------------------------------

BOX = """
<default name="spp" value="64"/>
<integrator type="path"><integer name="max_depth" value="5"/></integrator>
<sensor type="perspective">
  <float name="fov" value="40"/>
  <transform name="to_world"><lookat origin="0, 0, 3.9" target="0, 0, 0" up="0, 1, 0"/>
  </transform>
  <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
  <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/>
  </film>
</sensor>
<bsdf type="twosided" id="white"><bsdf type="diffuse"><rgb name="reflectance" value="0.7"/>
</bsdf></bsdf>
<bsdf type="diffuse" id="red"><rgb name="reflectance" value="0.6 0.1 0.1"/></bsdf>
<bsdf type="diffuse" id="green"><rgb name="reflectance" value="0.1, 0.6, 0.1"/></bsdf>
<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/>
  <translate y="-1"/></transform><ref id="white"/></shape>
<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/>
  <translate y="1"/></transform><ref id="white"/></shape>
<shape type="rectangle"><transform name="to_world"><translate z="-1"/></transform>
  <ref id="white"/></shape>
<shape type="rectangle"><transform name="to_world"><rotate y="1" angle="90"/>
  <translate x="-1"/></transform><ref id="red"/></shape>
<shape type="rectangle"><transform name="to_world"><rotate y="1" angle="-90"/>
  <translate x="1"/></transform><ref id="green"/></shape>
<shape type="cube"><transform name="to_world"><scale value="0.3"/><rotate y="1" angle="20"/>
  <translate x="-0.3" y="-0.7" z="-0.2"/></transform><ref id="white"/></shape>
<shape type="sphere"><point name="center" x="0.4" y="-0.6" z="0.3"/>
  <float name="radius" value="0.35"/><ref id="white"/></shape>
<shape type="rectangle">
  <transform name="to_world"><scale x="0.25" y="0.25"/><rotate x="1" angle="90"/>
    <translate y="0.99"/></transform>
  <emitter type="area"><rgb name="radiance" value="15"/></emitter>
</shape>
"""


# the box with a rough plastic cube, a glass sphere and a rough gold sphere
MATERIALS_BOX = BOX.replace(
    '<translate x="-0.3" y="-0.7" z="-0.2"/></transform><ref id="white"/></shape>',
    '<translate x="-0.3" y="-0.7" z="-0.2"/></transform><bsdf type="roughplastic"><rgb name='
    '"diffuse_reflectance" value="0.2 0.3 0.6"/><float name="alpha" value="0.2"/></bsdf>'
    '</shape><shape type="sphere"><point name="center" x="-0.5" y="0.2" z="-0.5"/><float '
    'name="radius" value="0.25"/><bsdf type="roughconductor"><string name="material" '
    'value="Au"/><float name="alpha" value="0.15"/></bsdf></shape>').replace(
    '<float name="radius" value="0.35"/><ref id="white"/>',
    '<float name="radius" value="0.35"/><bsdf type="dielectric"/>')


@pytest.mark.slow
@pytest.mark.parametrize("box, spp", [(BOX, 64), (MATERIALS_BOX, 128)],
                         ids=["diffuse", "materials"])
def test_cornell_box_mean_agrees_with_mitsuba(tmp_path, box, spp):
    """The same file rendered by Mitsuba 3 (4 times ptrace's samples) and by ptrace at -m 4
    (Mitsuba's max_depth 5, which counts the camera's segment too)."""
    assert box.count("bsdf type") >= (3 if box is BOX else 6)
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path = write(tmp_path, box)
    reference = np.array(mi.render(mi.load_file(str(path)), spp=4 * spp))[:, :, :3]
    out = tmp_path / "box.exr"
    assert main(["-q", "-r", "32", "24", "-s", str(spp), "-m", "4", "-f", str(out),
                 str(path)]) == 0
    ratio = float(read_image(out)[:, :, :3].mean() / reference.mean())
    assert ratio == pytest.approx(1.0, abs=0.03), ratio


# --- the file's film, sampler and integrator as the render's defaults -----------------------

LIT_FLOOR = """
<integrator type="path">{integrator}</integrator>
<sensor type="perspective">
  <float name="fov" value="40"/>
  <transform name="to_world"><lookat origin="0, 3, 0.01" target="0, 0, 0" up="0, 1, 0"/>
  </transform>
  <sampler type="independent"><integer name="sample_count" value="3"/></sampler>
  <film type="hdrfilm"><integer name="width" value="6"/><integer name="height" value="4"/>
  </film>
</sensor>
<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="5"/>
  </transform><bsdf type="diffuse"/></shape>
<emitter type="point"><point name="position" x="0" y="2" z="0"/>
  <rgb name="intensity" value="10"/></emitter>
"""


def test_the_files_settings_are_the_render_defaults(tmp_path):
    """film 6x4, sample_count 3, max_depth 1 (the emitters seen: the lit floor black) and
    rr_depth 7 are what ptrace.render uses unless its caller says otherwise."""
    path = write(tmp_path, LIT_FLOOR.format(
        integrator='<integer name="max_depth" value="1"/><integer name="rr_depth" value="7"/>'))
    scene = ptrace.load(path)
    assert scene.render_defaults == {"resolution": (6, 4), "spp": 3, "max_depth": 0,
                                     "rr_depth": 7}
    stats = {}
    image = ptrace.render(scene, stats=stats)
    assert image.shape == (4, 6, 3) and stats["spp"] == 3
    assert image.max() == 0     # -m 0: a point light is never seen, the floor not lit
    stats = {}
    image = ptrace.render(scene, resolution=(5, 3), spp=2, max_depth=1, stats=stats)
    assert image.shape == (3, 5, 3) and stats["spp"] == 2 and image.min() > 0


def test_mitsubas_own_defaults_where_the_file_leaves_them_out(tmp_path):
    """No <integrator>: Mitsuba's path tracer of unbounded depth (ptrace's largest -m); a
    sensor without film or sampler: 768x576 and 4 samples; no sensor: ptrace's own."""
    bare = ptrace.load(write(tmp_path, '<sensor type="perspective"/><shape type="sphere"/>'))
    assert bare.render_defaults == {"resolution": (768, 576), "spp": 4, "max_depth": 10_000}
    sensorless = ptrace.load(write(tmp_path, '<shape type="sphere"/>', name="s.xml"))
    assert sensorless.render_defaults == {"max_depth": 10_000}
    deep = ptrace.load(write(tmp_path, '<integrator type="path"><integer name="max_depth" '
                                       'value="99999"/></integrator>', name="d.xml"))
    assert deep.render_defaults["max_depth"] == 10_000


def test_the_command_line_takes_the_files_settings_unless_given(tmp_path, capsys):
    path = write(tmp_path, LIT_FLOOR.format(integrator='<integer name="max_depth" value="1"/>'))
    out = tmp_path / "o.exr"
    assert main(["-q", "-f", str(out), str(path)]) == 0
    assert capsys.readouterr().out.startswith("6x4 spp 3 ")
    assert read_image(out).shape[:2] == (4, 6) and read_image(out)[:, :, :3].max() == 0
    assert main(["-q", "-r", "5", "3", "-s", "2", "-m", "1", "-f", str(out), str(path)]) == 0
    assert capsys.readouterr().out.startswith("5x3 spp 2 ")
    assert read_image(out).shape[:2] == (3, 5) and read_image(out)[:, :, :3].min() > 0


def test_a_reconstruction_filter_other_than_a_box_is_noted(tmp_path):
    film = '<sensor type="perspective"><film type="hdrfilm">{}</film></sensor>'
    for rfilter, noted in (("", True), ('<rfilter type="tent"/>', True),
                           ('<rfilter type="box"/>', False)):
        notes = "\n".join(ptrace.load(write(tmp_path, film.format(rfilter))).notes)
        assert ("reconstruction filter" in notes) == noted, rfilter


def test_the_files_settings_are_said_in_a_note(tmp_path, capsys):
    path = write(tmp_path, LIT_FLOOR.format(integrator='<integer name="max_depth" value="4"/>'))
    assert main(["-r", "2", "2", "-f", str(tmp_path / "o.png"), str(path)]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "-r 6 4, -s 3, -m 3" in
             line]
    assert len(notes) == 1 and notes[0].startswith("ptrace: note: ")


# --- line numbers ---------------------------------------------------------------------------

@pytest.mark.parametrize("case", ["unknown_plugin", "undefined_name", "singular_transform",
                                  "missing_file", "unknown_ref", "wrong_type"])
def test_a_refusal_names_the_line_of_its_element(tmp_path, capsys, case):
    """The element at fault sits on line 4 (after the <scene> line and two comment lines)."""
    body, fragment = REFUSALS[case]
    path = write(tmp_path, f"<!-- one -->\n<!-- two -->\n{body}")
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    assert str(caught.value).startswith(f"{path}:4: ") and fragment in str(caught.value)
    assert caught.value.path == str(path)
    assert main(["-q", "-f", str(tmp_path / "out.png"), str(path)]) == 2
    err = capsys.readouterr().err
    assert err == f"ptrace: error: {caught.value}\n"


def test_the_line_is_the_one_of_the_element_in_its_own_file(tmp_path):
    """A fault in an included file names that file and the line there; a nested value names
    its own line, not its plugin's."""
    write(tmp_path, '\n\n<shape type="cube">\n<transform name="to_world">\n<scale z="0"/>\n'
                    '</transform></shape>', name="part.xml")
    path = write(tmp_path, '<include filename="part.xml"/>')
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    assert caught.value.path.endswith("part.xml") and caught.value.line == 5
    assert str(caught.value).startswith(f"{caught.value.path}:5: ")
    path = write(tmp_path, '<shape type="sphere">\n\n<float name="radius"\n value="x"/>'
                           '</shape>', name="value.xml")
    with pytest.raises(ptrace.SceneError, match=r"value\.xml:4: <float name=\"radius\">"):
        ptrace.load(path)


def test_xml_that_is_not_well_formed_names_the_parsers_line(tmp_path):
    path = tmp_path / "broken.xml"
    path.write_text('<scene version="3.0.0">\n<shape type="sphere">\n</scene>\n')
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    assert str(caught.value).startswith(f"{path}:3: not well-formed XML")
