"""Bad scene files raise ptrace.SceneError naming the file (and the element at fault)."""
import random
import tracemalloc

import pytest

import ptrace

PLANE = "simple/plane.dae"
PLANE_POSITIONS = 'count="12">1 1.5 -1 1 0 -1 -1 0 -1 -1 1.5 -1</float_array>'
PLANE_P = "<p>0 0 0 1 0 1 2 0 2 3 1 3 0 1 4 2 1 5</p>"
LIGHT_MATRIX = '<matrix sid="transform">0.6 0 0 0 0 0.8 0 0 0 0 1 1.49 0 0 0 1</matrix>'


def course_text(course_scene, relpath=PLANE):
    return course_scene(relpath).read_text(encoding="utf-8")


def corrupted(course_scene, tmp_path, old, new, relpath=PLANE, name="bad.dae"):
    """A copy of a course file with `old` replaced by `new` (which must occur)."""
    text = course_text(course_scene, relpath)
    assert old in text, f"{old!r} not in {relpath}"
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def assert_scene_error(path, *fragments):
    with pytest.raises(ptrace.SceneError) as caught:
        ptrace.load(path)
    message = str(caught.value)
    assert path.name in message
    for fragment in fragments:
        assert fragment in message, message
    return message


def peak_allocation(function, *args):
    """Bytes at the peak of what function(*args) allocates (Python objects, numpy buffers and
    expat's parser, which allocates through Python): the work a refusal did, in place of a
    wall-clock limit (speed lives in benchmarks/)."""
    tracemalloc.start()
    try:
        function(*args)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


# a few times what loading the small course file takes; far below what the claims ask for
REFUSAL_BYTES = 8 * 2 ** 20


def test_the_unmodified_base_file_loads(course_scene):
    assert ptrace.load(course_scene(PLANE)).triangle_count == 2


def test_missing_file(tmp_path):
    assert_scene_error(tmp_path / "nowhere.dae", "no such file")


def test_directory(tmp_path):
    folder = tmp_path / "folder.dae"
    folder.mkdir()
    assert_scene_error(folder, "directory")


@pytest.mark.parametrize("content", [b"", b"this is not xml <<<", b"\xff\xfe\x00garbage",
                                     b"<COLLADA><asset>",
                                     b'<?xml version="1.0" encoding="nope"?><a/>'])
def test_not_xml(tmp_path, content):
    path = tmp_path / "garbage.dae"
    path.write_bytes(content)
    assert_scene_error(path)


def test_truncated_course_file(course_scene, tmp_path):
    path = tmp_path / "truncated.dae"
    path.write_bytes(course_scene(PLANE).read_bytes()[:5000])
    assert_scene_error(path, "XML")


def test_xml_that_is_not_collada(tmp_path):
    path = tmp_path / "drawing.dae"
    path.write_text('<?xml version="1.0"?><svg xmlns="http://www.w3.org/2000/svg"><g/></svg>')
    assert_scene_error(path, "not a COLLADA file", "<svg>")


def test_missing_up_axis(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, "<up_axis>Z_UP</up_axis>", "")
    assert_scene_error(path, "up_axis")


def test_unknown_up_axis(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, "<up_axis>Z_UP</up_axis>", "<up_axis>W_UP</up_axis>")
    assert_scene_error(path, "W_UP")


def test_index_out_of_range(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, PLANE_P, PLANE_P.replace("2 3 1 3", "2 99 1 3"))
    assert_scene_error(path, "<p>", "99", "out of range", "backWall_002-mesh")


def test_p_shorter_than_the_polygons_need(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, PLANE_P, "<p>0 0 0 1 0 1 2 0 2</p>")
    assert_scene_error(path, "<p>", "need 18")


def test_float_array_shorter_than_count(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, PLANE_POSITIONS,
                     PLANE_POSITIONS.replace('count="12"', 'count="15"'))
    assert_scene_error(path, 'float_array id="backWall_002-mesh-positions-array"',
                       "count 15 but 12 numbers")


def test_huge_count_claim_is_refused_without_allocating(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, PLANE_POSITIONS,
                     PLANE_POSITIONS.replace('count="12"', 'count="2000000000"'))
    assert_scene_error(path, "count 2000000000 but 12 numbers")
    # the claim would be 16 GB of float64
    assert peak_allocation(assert_scene_error, path) < REFUSAL_BYTES


def test_huge_polygon_count_claim(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, "<vcount>3 3 </vcount>",
                     "<vcount>3 2000000000 </vcount>")
    assert_scene_error(path, "vcount")


@pytest.mark.parametrize("bad_number", ["nan", "inf", "-inf", "1e999", "NaN"])
def test_non_finite_coordinates(course_scene, tmp_path, bad_number):
    path = corrupted(course_scene, tmp_path, PLANE_POSITIONS,
                     PLANE_POSITIONS.replace(">1 1.5", f">{bad_number} 1.5"))
    assert_scene_error(path, "backWall_002-mesh-positions-array", "NaN or infinite")


def test_non_numeric_coordinate(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, PLANE_POSITIONS,
                     PLANE_POSITIONS.replace(">1 1.5", ">1 one.5"))
    assert_scene_error(path, "backWall_002-mesh-positions-array", "one.5")


def test_non_finite_matrix(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, LIGHT_MATRIX, LIGHT_MATRIX.replace("1.49", "nan"))
    assert_scene_error(path, "<matrix", 'node id="Area"', "NaN or infinite")


def test_positions_overflowing_after_the_transform(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, PLANE_POSITIONS,
                     PLANE_POSITIONS.replace(">1 1.5", ">1e300 1.5"))
    node_matrix = "-1 2.69452e-14 1.50996e-7 -2.62268e-8"
    text = path.read_text()
    assert node_matrix in text
    path.write_text(text.replace(node_matrix, "-1e300 2.69452e-14 1.50996e-7 -2.62268e-8"))
    assert_scene_error(path, 'node id="backWall"', "overflow")


def test_non_finite_light_colour(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, '<color sid="color">1 1 1</color>',
                     '<color sid="color">1 inf 1</color>')
    assert_scene_error(path, "colour", "NaN or infinite")


def test_non_finite_sphere_radius(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, "<radius>.3</radius>", "<radius>nan</radius>",
                     relpath="sky/CBspheres.dae")
    assert_scene_error(path, "radius", "NaN or infinite")


def test_url_naming_nothing(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, 'url="#backWall_002-mesh"', 'url="#no-such-mesh"')
    assert_scene_error(path, "no-such-mesh", "instance_geometry")


def test_material_target_naming_nothing(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, 'target="#backWall_002-material"',
                     'target="#no-such-material"')
    assert_scene_error(path, "no-such-material")


def test_translate_node_is_refused(course_scene, tmp_path):
    path = corrupted(course_scene, tmp_path, LIGHT_MATRIX, "<translate>0 0 1.49</translate>")
    assert_scene_error(path, "<translate>", 'node id="Area"', "does not support")


def test_unknown_light_type(course_scene, tmp_path):
    text = course_text(course_scene).replace("<point>", "<laser>").replace("</point>", "</laser>")
    path = tmp_path / "laser.dae"
    path.write_text(text)
    assert_scene_error(path, "unknown light type <laser>", 'light id="Area-light"')


def test_billion_laughs_entity_bomb(tmp_path):
    entities = ['<!ENTITY lol0 "lol">'] + [
        f'<!ENTITY lol{i} "{("&lol%d;" % (i - 1)) * 10}">' for i in range(1, 10)]
    path = tmp_path / "bomb.dae"
    path.write_text('<?xml version="1.0"?>\n<!DOCTYPE COLLADA [\n' + "\n".join(entities)
                    + '\n]>\n<COLLADA><asset><up_axis>&lol9;</up_axis></asset></COLLADA>\n')
    assert_scene_error(path, "unsafe XML")
    # expanded, &lol9; would be 3 * 10**9 characters
    assert peak_allocation(assert_scene_error, path) < REFUSAL_BYTES


def test_external_entity(tmp_path):
    path = tmp_path / "external.dae"
    path.write_text('<?xml version="1.0"?>\n<!DOCTYPE COLLADA [\n'
                    '<!ENTITY x SYSTEM "file:///etc/passwd">\n]>\n'
                    "<COLLADA><asset><up_axis>&x;</up_axis></asset></COLLADA>\n")
    message = assert_scene_error(path, "unsafe XML")
    assert "root:" not in message


def test_unknown_extension(tmp_path):
    path = tmp_path / "scene.xyz"
    path.write_text("whatever")
    assert_scene_error(path, ".xyz", ".dae", ".obj", ".ply", ".glb", ".gltf", ".stl")


def test_deeply_nested_nodes(tmp_path):
    from ptrace.io.collada import MAX_NODE_DEPTH

    def nested(depth):
        path = tmp_path / f"deep{depth}.dae"
        path.write_text('<COLLADA><asset><up_axis>Y_UP</up_axis></asset>'
                        '<library_cameras><camera id="c"/></library_cameras>'
                        '<library_visual_scenes><visual_scene id="s">'
                        '<node><instance_camera url="#c"/></node>' + "<node>" * depth
                        + "</node>" * depth + "</visual_scene></library_visual_scenes></COLLADA>")
        return path
    assert ptrace.load(nested(MAX_NODE_DEPTH)).triangle_count == 0   # walked without recursion
    for depth in (MAX_NODE_DEPTH + 1, 50_000):
        with pytest.raises(ptrace.SceneError, match="nested more than"):
            ptrace.load(nested(depth))


@pytest.mark.parametrize("relpath", [PLANE, "sky/CBspheres.dae"])
def test_random_corruptions_raise_only_scene_error(course_scene, tmp_path, relpath):
    original = course_scene(relpath).read_bytes()
    generator = random.Random(184)
    path = tmp_path / "fuzzed.dae"
    for _ in range(150):
        data = bytearray(original)
        for _ in range(generator.randint(1, 4)):
            position = generator.randrange(len(data))
            action = generator.choice(["delete", "replace", "truncate", "duplicate"])
            if action == "delete":
                del data[position:position + generator.randint(1, 40)]
            elif action == "replace":
                data[position] = generator.choice(b"0123456789.-e <>/\"#xn")
            elif action == "truncate":
                del data[position:]
            else:
                data[position:position] = data[position:position + generator.randint(1, 80)]
            if not data:
                break
        path.write_bytes(bytes(data))
        try:
            ptrace.load(path)
        except ptrace.SceneError as error:
            assert path.name in str(error)
