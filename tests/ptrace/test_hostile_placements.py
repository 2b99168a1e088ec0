"""Numbers that are each in range but whose products are not: placements, clip distances and
triangle sizes at the edges of what the loaders and backends accept.

A glTF light or camera under nested nodes, each matrix finite and within ptrace.io.limits.LIMIT,
can be placed beyond the limit (or its axes' lengths overflow): it is refused in one line naming
the file, the light or camera and its node, or it keeps its direction. A COLLADA camera's znear
and zfar are within the limit. A scene whose triangles are too large for Embree's float32 (it
draws them black where bvh draws them) gets one warning with --accel embree naming the sizes and
--accel bvh."""
import numpy as np
import pytest
from files_by_hand import QUAD, QUAD_FACES, gltf

import accel
import ptrace
from accel.types import Geometry, Rays
from ptrace.app import cli
from ptrace.image import read_image
from ptrace.rendering.renderer import FLOAT32_MAX, embree_overflow
from ptrace.scene import DIRECTIONAL

TINY = ["-r", 32, 24, "-s", 1, "-m", 1, "-t", 1]
MESH = [dict(positions=QUAD, indices=QUAD_FACES.reshape(-1))]
POINT = {"extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 10.0}]}},
         "extensionsUsed": ["KHR_lights_punctual"]}
SUN = {"extensions": {"KHR_lights_punctual": {"lights": [{"type": "directional",
                                                           "intensity": 3.0}]}},
       "extensionsUsed": ["KHR_lights_punctual"]}
CAMERA = {"cameras": [{"type": "perspective", "name": "far",
                       "perspective": {"yfov": 0.6, "znear": 0.05}}]}


def one_line(capsys, *args):
    """(exit code, the one stderr line) of the CLI run in this process; fails on more lines."""
    code = cli.main([str(a) for a in args])
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return code, lines[0]


def nested(path, leaf, parents, document):
    """The quad (node 0, a root) and `leaf` under a chain of parent nodes (root: node 1)."""
    nodes = [{"mesh": 0}] + [dict(parent, children=[i + 2]) for i, parent in enumerate(parents)]
    gltf(path, MESH, nodes=nodes + [leaf], document={**document, "scenes": [{"nodes": [0, 1]}]})
    return path


# --- glTF lights and cameras placed by nested nodes -----------------------------------------

def test_a_light_placed_beyond_the_limit_by_its_nodes_is_refused_naming_them(tmp_path, capsys):
    """A parent's scale 1e20 times its child's translation 1e20: each in range, the light at
    1e40. It used to render black, exit 0, without a note (its light 1e40 away)."""
    lamp = {"name": "lamp", "translation": [0.0, 0.0, 1e20],
            "extensions": {"KHR_lights_punctual": {"light": 0}}}
    path = nested(tmp_path / "far.gltf", lamp, [{"scale": [1e20] * 3}], POINT)
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and line.startswith("ptrace: error: ") and "far.gltf" in line, line
    assert "light 0" in line and "node 2 ('lamp')" in line and "1e+40" in line, line
    assert "1e+30" in line and "-d" not in line, line
    assert not (tmp_path / "x.png").exists()


def test_a_light_whose_nodes_overflow_to_infinity_is_one_line_naming_the_node(tmp_path, capsys):
    lamp = {"extensions": {"KHR_lights_punctual": {"light": 0}}}
    path = nested(tmp_path / "inf.gltf", lamp, [{"scale": [1e30] * 3}] * 11, POINT)
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and "inf.gltf" in line and "node 11" in line and "overflow" in line, line


def test_a_sun_under_scales_whose_product_is_1e300_keeps_its_direction(tmp_path):
    """Ten nested scales of 1e30: the axis's length (1e300) squared overflowed, and the sun
    pointed nowhere (direction 0, 0, 0): the image was black, without a note."""
    sun = {"name": "sun", "extensions": {"KHR_lights_punctual": {"light": 0}}}
    scene = ptrace.load(nested(tmp_path / "sun.gltf", sun, [{"scale": [1e30] * 3}] * 10, SUN))
    suns = np.nonzero(scene.lights.kind == DIRECTIONAL)[0]
    assert len(suns) == 1
    np.testing.assert_allclose(scene.lights.direction[suns[0]], [0.0, 0.0, 1.0], atol=1e-12)


def test_a_camera_placed_beyond_the_limit_is_refused_naming_the_file_and_node(tmp_path,
                                                                              capsys):
    """It used to be refused as "the focal distance (-d) ... got 1e+40": no -d was given, and
    no file named."""
    eye = {"name": "eye", "camera": 0, "translation": [0.0, 0.0, 1e20]}
    path = nested(tmp_path / "eye.gltf", eye, [{"scale": [1e20] * 3}], CAMERA)
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and "eye.gltf" in line and "camera 0 ('far')" in line, line
    assert "node 2 ('eye')" in line and "1e+40" in line and "-d" not in line, line


def test_a_camera_whose_focus_passes_the_limit_names_the_file_and_camera(tmp_path, capsys):
    """The camera at z = 1e30 and the quad at z = -1e30, each in range: the default focus (the
    bounds' centre, 2e30 ahead) is not. It used to be "the focal distance (-d) must be ...,
    got 2e+30", naming no file."""
    nodes = [{"mesh": 0, "translation": [0.0, 0.0, -1e30]},
             {"name": "eye", "camera": 0, "translation": [0.0, 0.0, 1e30]}]
    path = tmp_path / "focus.gltf"
    gltf(path, MESH, nodes=nodes, document=CAMERA)
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and "focus.gltf" in line and "camera 0 ('far', on node 1)" in line, line
    assert "2e+30" in line and "-d" not in line, line
    with pytest.raises(ptrace.SceneError, match=r"focus\.gltf: the file's camera 0"):
        ptrace.render(ptrace.load(path), resolution=(8, 6))


def test_a_camera_under_scales_whose_product_is_1e300_keeps_its_axes(tmp_path):
    """Its axes' lengths overflowed, and it was ignored with a note calling its scale zero
    (1e-299 placed by 1e300: z = 10)."""
    eye = {"name": "eye", "camera": 0, "translation": [0.0, 0.0, 1e-299]}
    scene = ptrace.load(nested(tmp_path / "big.gltf", eye, [{"scale": [1e30] * 3}] * 10,
                               CAMERA))
    assert len(scene.file_cameras) == 1, scene.notes
    np.testing.assert_allclose(scene.file_cameras[0].camera_to_world, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(scene.file_cameras[0].position, [0.0, 0.0, 10.0], rtol=1e-9)
    assert not any("zero or degenerate scale" in note for note in scene.notes), scene.notes


# --- COLLADA znear and zfar -----------------------------------------------------------------

@pytest.mark.parametrize("old, new, words", [
    ('<zfar sid="zfar">100</zfar>', '<zfar sid="zfar">1e308</zfar>', "zfar 1e+308 is beyond"),
    ('<zfar sid="zfar">100</zfar>', '<zfar sid="zfar">1e31</zfar>', "zfar 1e+31 is beyond"),
    ('<znear sid="znear">0.1</znear>', '<znear sid="znear">-1e31</znear>',
     "znear -1e+31 is beyond"),
])
def test_a_collada_clip_distance_beyond_the_limit_is_refused_naming_it(tmp_path, capsys,
                                                                      course_scene, old, new,
                                                                      words):
    """zfar 1e308 passed `0 <= znear < zfar` and rendered: finite, but not a number ptrace
    takes."""
    text = course_scene("sky/CBspheres.dae").read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "clip.dae"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    code, line = one_line(capsys, *TINY, "-f", tmp_path / "x.png", path)
    assert code == 2 and "clip.dae" in line and words in line and "1e+30" in line, line
    assert '<camera id="Camera-camera">' in line, line


@pytest.mark.parametrize("znear", ["0", "-0"])
def test_a_collada_znear_of_zero_is_taken(tmp_path, course_scene, znear):
    """znear 0 starts camera rays at the eye, which a ray tracer can do (there is no depth
    buffer to divide by it): taken, as docs/usage.md says (0 <= znear < zfar)."""
    text = course_scene("sky/CBspheres.dae").read_text(encoding="utf-8")
    path = tmp_path / "near.dae"
    path.write_text(text.replace('<znear sid="znear">0.1</znear>',
                                 f'<znear sid="znear">{znear}</znear>', 1), encoding="utf-8")
    assert ptrace.load(path).camera.znear == 0.0


def test_the_course_cameras_are_within_the_limit(course_scene):
    """The course's files keep loading (test_hostile_collada loads every one): their znear
    and zfar (0.1 and 100, 0.00999999 and 10000) are well inside."""
    for name in ("sky/CBspheres.dae", "meshedit/cow.dae"):
        camera = ptrace.load(course_scene(name)).camera
        assert 0 < camera.znear < camera.zfar <= 1e4, (name, camera)


# --- Embree's float32 --------------------------------------------------------------------------

def square(folder, half):
    path = folder / f"square_{half:g}.obj"
    path.write_text(f"v {-half} {-half} 0\nv {half} {-half} 0\nv {half} {half} 0\n"
                    f"v {-half} {half} 0\nf 1 2 3\nf 1 3 4\n")
    return path


def embree_loses(geometry, size, rays=4000):
    """How many of `rays` random rays (origins from inside to 20 sizes away, aimed at points
    of the box, finite tmax) hit with bvh and miss with embree."""
    rng = np.random.default_rng(1)
    direction = rng.normal(size=(rays, 3))
    origins = direction / np.linalg.norm(direction, axis=1)[:, None] * \
        (size * np.geomspace(0.01, 20, rays))[:, None]
    aims = rng.uniform(-size, size, size=(rays, 3)) - origins
    batch = Rays(origins, aims / np.linalg.norm(aims, axis=1)[:, None], 1e-3, 100 * size)
    hit = accel.build("bvh", geometry).intersect(batch).prim >= 0
    return int((hit & ~(accel.build("embree", geometry).intersect(batch).prim >= 0)).sum())


def cube(half):
    corners = [[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)]
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7],
             [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return Geometry(vertices=corners, faces=faces)


def test_embree_loses_hits_only_where_the_warning_says_it_can():
    """Measured against bvh, independently of the warning's rule: a cube 6e12 across loses
    hits, one 2e12 across none; the warning's bound holds for the first and is silent on the
    second (it starts at 3.2e12 across: conservative, never late)."""
    assert embree_loses(cube(3e12), 3e12) > 0
    found = embree_overflow(cube(3e12))
    assert found is not None and found[2] > FLOAT32_MAX
    assert embree_loses(cube(1e12), 1e12) == 0
    assert embree_overflow(cube(1e12)) is None


def test_embree_draws_a_square_6e12_across_black_and_says_so(tmp_path, capsys):
    """The one warning names embree, the sizes and --accel bvh; bvh draws the square (whose
    image embree leaves black), and neither a smaller square nor bvh gets the warning."""
    path = square(tmp_path, 3e12)
    for kind in ("embree", "bvh"):
        assert cli.main([str(a) for a in TINY + ["--accel", kind, "-f",
                                                 tmp_path / f"{kind}.png", path]]) == 0
        warned = [line for line in capsys.readouterr().err.splitlines()
                  if line.startswith("ptrace: warning: ")]
        if kind == "embree":
            assert len(warned) == 1, warned
            assert "--accel embree" in warned[0] and "float32" in warned[0], warned
            assert "6e+12" in warned[0] and "--accel bvh" in warned[0], warned
        else:
            assert warned == [], warned
    embree, bvh = (read_image(tmp_path / f"{kind}.png") for kind in ("embree", "bvh"))
    assert bvh.max() > 0 and embree.max() == 0      # what the warning is about
    assert cli.main([str(a) for a in TINY + ["--accel", "embree", "-f", tmp_path / "s.png",
                                             square(tmp_path, 5e11)]]) == 0
    assert "warning" not in capsys.readouterr().err
