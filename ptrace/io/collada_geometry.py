"""COLLADA geometry in the course dialect (docs/course.md#meshes, #spheres): meshes and CGL spheres.

Meshes come back in their own (local) coordinates; the caller applies the node transform.
"""
import numpy as np

from .collada_document import FLOAT, INDEX

PRIMITIVE_TAGS = ("polylist", "triangles")
UNSUPPORTED_PRIMITIVE_TAGS = ("polygons", "lines", "linestrips", "trifans", "tristrips")


def cgl_techniques(document, element):
    """element/extra/technique[@profile="CGL"] elements, in document order."""
    return [technique
            for extra in document.children(element, "extra")
            for technique in document.children(extra, "technique")
            if technique.get("profile") == "CGL"]


def sphere_radius(document, geometry):
    """The CGL sphere radius of a <geometry>, or None if it is not a sphere."""
    for technique in cgl_techniques(document, geometry):
        sphere = document.child(technique, "sphere")
        if sphere is not None:
            radius = document.scalar(document.require_child(sphere, "radius"), "radius")
            if radius < 0:
                document.fail(f"{document.describe(sphere)}: negative radius {radius}")
            return radius
    return None


def read_mesh(document, mesh):
    """(positions (V, 3), faces (F, 3)) of a <mesh>: every <polylist> and <triangles>."""
    position_blocks = []
    vertex_range = {}            # <vertices> element -> (first row in positions, row count)
    face_blocks = []
    vertex_total = 0
    for primitive in mesh:
        if primitive.tag in UNSUPPORTED_PRIMITIVE_TAGS:
            document.notes.append(f"{document.describe(primitive)}: <{primitive.tag}> is not "
                                  f"read by the course dialect; skipped")
            continue
        if primitive.tag not in PRIMITIVE_TAGS:
            continue
        vertex_input, vertex_offset, stride = _vertex_input(document, primitive)
        vertices_element = document.resolve(vertex_input, "source", ("vertices", "source"))
        if vertices_element not in vertex_range:
            positions = read_positions(document, vertices_element)
            vertex_range[vertices_element] = (vertex_total, len(positions))
            position_blocks.append(positions)
            vertex_total += len(positions)
        first_row, row_count = vertex_range[vertices_element]
        faces = read_primitive_faces(document, primitive, vertex_offset, stride, row_count)
        face_blocks.append(faces + first_row)
    positions = np.concatenate(position_blocks) if position_blocks else np.empty((0, 3))
    faces = np.concatenate(face_blocks) if face_blocks else np.empty((0, 3), dtype=INDEX)
    return positions, faces


def _vertex_input(document, primitive):
    """(VERTEX <input>, its offset, index stride = max offset + 1)."""
    inputs = document.children(primitive, "input")
    if not inputs:
        document.fail(f"{document.describe(primitive)} has no <input>")
    offsets = [document.count_attribute(item, "offset") or 0 for item in inputs]
    vertex_inputs = [(item, offset) for item, offset in zip(inputs, offsets)
                     if item.get("semantic") == "VERTEX"]
    if not vertex_inputs:
        document.fail(f"{document.describe(primitive)} has no <input semantic=\"VERTEX\">")
    vertex_input, vertex_offset = vertex_inputs[0]
    return vertex_input, vertex_offset, max(offsets) + 1


def read_positions(document, vertices_element):
    """(V, 3) positions: <vertices> -> POSITION <source> -> <float_array> via its accessor."""
    if vertices_element.tag == "source":
        source = vertices_element
    else:
        position_input = next((item for item in document.children(vertices_element, "input")
                               if item.get("semantic") == "POSITION"), None)
        if position_input is None:
            document.fail(f"{document.describe(vertices_element)} has no "
                          f"<input semantic=\"POSITION\">")
        source = document.resolve(position_input, "source", ("source",))
    float_array = document.require_child(source, "float_array")
    values = document.floats(float_array, "coordinates")
    declared = document.count_attribute(float_array)
    if declared is not None:
        if values.size < declared:
            document.fail(f"{document.describe(float_array)}: count {declared} but "
                          f"{values.size} numbers")
        values = values[:declared]
    accessor = document.find_path(source, "technique_common", "accessor")
    stride, offset, count = 3, 0, None
    if accessor is not None:
        stride = document.count_attribute(accessor, "stride") or 3
        offset = document.count_attribute(accessor, "offset") or 0
        count = document.count_attribute(accessor, "count")
    if stride < 3:
        document.fail(f"{document.describe(accessor)}: stride {stride} is less than 3 "
                      f"(positions need x, y, z)")
    if offset > values.size:
        document.fail(f"{document.describe(accessor)}: offset {offset} is past the end of "
                      f"{document.describe(float_array)} ({values.size} numbers)")
    available = (values.size - offset) // stride
    if count is None:
        count = available
    elif count > available:
        document.fail(f"{document.describe(accessor)}: count {count} with stride {stride} "
                      f"needs {offset + count * stride} numbers but "
                      f"{document.describe(float_array)} has {values.size}")
    if count == 0:
        return np.empty((0, 3), dtype=FLOAT)
    block = values[offset:offset + count * stride].reshape(count, stride)
    return np.ascontiguousarray(block[:, :3], dtype=FLOAT)


def read_primitive_faces(document, primitive, vertex_offset, stride, vertex_count):
    """(F, 3) vertex indices of a <polylist> or <triangles>; polygons are fan-triangulated."""
    where = document.describe(primitive)
    count = document.count_attribute(primitive)
    vcount_element = document.child(primitive, "vcount")
    if vcount_element is not None:
        corner_counts = document.indices(vcount_element, "corner counts")
        if count is not None:
            if corner_counts.size < count:
                document.fail(f"{document.describe(vcount_element)}: {corner_counts.size} "
                              f"corner counts but {where} has count {count}")
            corner_counts = corner_counts[:count]
    elif primitive.tag == "triangles":
        corner_counts = None
    else:
        document.fail(f"{where} has no <vcount>")
    p_element = document.child(primitive, "p")
    if p_element is None:
        if count == 0 or (corner_counts is not None and corner_counts.sum() == 0):
            return np.empty((0, 3), dtype=INDEX)
        document.fail(f"{where} has no <p>")
    indices = document.indices(p_element)
    if corner_counts is None:
        if count is None:
            count = indices.size // (3 * stride)
        corner_total = 3 * count
    else:
        if corner_counts.size and corner_counts.max() > indices.size:
            document.fail(f"{document.describe(vcount_element)}: a polygon with "
                          f"{corner_counts.max()} corners but <p> has {indices.size} indices")
        corner_total = int(corner_counts.sum())
    needed = corner_total * stride
    if indices.size < needed:
        document.fail(f"<p> in {where}: {indices.size} indices but {corner_total} corners "
                      f"x stride {stride} need {needed}")
    corner_vertices = indices[vertex_offset:needed:stride]
    if corner_vertices.size and corner_vertices.max() >= vertex_count:
        document.fail(f"<p> in {where}: vertex index {corner_vertices.max()} out of range "
                      f"(the positions have {vertex_count} vertices)")
    if corner_counts is None:
        return corner_vertices.reshape(-1, 3)
    return fan_triangulate(document, where, corner_vertices, corner_counts)


def fan_triangulate(document, where, corner_vertices, corner_counts):
    """Triangles (c0, ci, ci+1) for each polygon; polygons with < 3 corners are skipped."""
    if corner_counts.size and (corner_counts == 3).all():
        return corner_vertices.reshape(-1, 3)
    short = int((corner_counts < 3).sum())
    if short:
        document.notes.append(f"{where}: skipped {short} polygon(s) with fewer than 3 corners")
    long = int((corner_counts > 3).sum())
    if long:
        document.notes.append(f"{where}: fan-triangulated {long} polygon(s) with more than "
                              f"3 corners")
    first_corner = np.cumsum(corner_counts) - corner_counts
    triangles_per_polygon = np.maximum(corner_counts - 2, 0)
    polygon_of_triangle = np.repeat(np.arange(corner_counts.size), triangles_per_polygon)
    first_triangle = np.cumsum(triangles_per_polygon) - triangles_per_polygon
    fan_step = (np.arange(polygon_of_triangle.size)
                - first_triangle[polygon_of_triangle] + 1)
    base = first_corner[polygon_of_triangle]
    return np.stack([corner_vertices[base],
                     corner_vertices[base + fan_step],
                     corner_vertices[base + fan_step + 1]], axis=1)
