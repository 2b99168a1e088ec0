"""Mitsuba's <transform>: its steps (translate, rotate, scale, matrix, lookat) composed in
file order into one invertible 4 x 4 matrix, each checked (one SceneError naming the file and
the step)."""
import math

import numpy as np

from ..errors import SceneError

TRANSFORM_TAGS = ("translate", "rotate", "scale", "matrix", "lookat")


class ElementError(SceneError):
    """A SceneError at a line of an XML file: its text is 'file:line: message'."""

    def __init__(self, path, message, line=None):
        super().__init__(path, message)
        self.line = line
        if line is not None:
            self.args = (f"{self.path}:{line}: {message}",)

    def __reduce__(self):
        return type(self), (self.path, self.message, self.line)


def element_error(path, element, message):
    """The ElementError of `message` about `element` of the file `path`, at the element's
    line when the parser gave one (its sourceline)."""
    return ElementError(path, message, getattr(element, "sourceline", None))


def at(path, element, rest):
    """element_error of describe(element) followed by `rest` (': what is wrong')."""
    return element_error(path, element, f"{describe(element)}{rest}")


def describe(element):
    """'<shape type="obj" id="wall">': an element and its naming attributes."""
    words = [element.tag] + [f'{key}="{element.get(key)[:60]}"' for key in
                             ("type", "id", "name", "filename") if element.get(key) is not None]
    return "<" + " ".join(words) + ">"


class Transform:
    """A 4 x 4 matrix (float64), invertible, that maps local to world coordinates, and its
    inverse as Mitsuba keeps it (inverse: a rotation's is its transpose, whatever its axis)."""

    def __init__(self, matrix, inverse=None):
        self.matrix = np.asarray(matrix, dtype=np.float64)
        self.inverse = np.linalg.inv(self.matrix) if inverse is None else \
            np.asarray(inverse, dtype=np.float64)

    def apply(self, points):
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return points @ self.matrix[:3, :3].T + self.matrix[:3, 3]

    def vectors(self, vectors):
        return np.asarray(vectors, dtype=np.float64).reshape(-1, 3) @ self.matrix[:3, :3].T

    def normals(self, normals):
        inverse = np.linalg.inv(self.matrix[:3, :3])
        out = np.asarray(normals, dtype=np.float64).reshape(-1, 3) @ inverse
        return out / np.linalg.norm(out, axis=1, keepdims=True)


def parse_transform(reader, element, path):
    """The Transform of a <transform> element: each step left-multiplies what came before (the
    first step is applied first); reader gives the steps' attributes ($name substituted)."""
    matrix, steps = np.eye(4), []
    for step in element:
        if not isinstance(step.tag, str):
            continue
        tag = "lookat" if reader.upgrade and step.tag == "lookAt" else step.tag
        if tag not in TRANSFORM_TAGS:
            raise at(path, step, f": unknown transform <{tag}> in "
                                 f"{describe(element)} (known: "
                                 f"{', '.join(TRANSFORM_TAGS)})")
        steps.append((tag, _step(reader, step, tag, path)))
        matrix = steps[-1][1] @ matrix
    if not np.isfinite(matrix).all():
        raise at(path, element, ": the matrix overflows to infinity")
    linear = matrix[:3, :3]
    size = float(np.abs(linear).max())
    if np.any(matrix[3] != (0, 0, 0, 1)):
        raise at(path, element, ": a projective matrix (its last row is not "
                                "0 0 0 1) is not supported")
    if not size > 0 or abs(np.linalg.det(linear / size)) < 1e-12:
        raise at(path, element, ": the transform is not invertible "
                                "(it flattens space: determinant 0)")
    inverse = np.eye(4)
    for tag, step in steps:     # Mitsuba's: a rotation's inverse is its transpose
        inverse = inverse @ (step.T if tag == "rotate" else np.linalg.inv(step))
    return Transform(matrix, inverse)


def _vector3(reader, step, path, default):
    text = reader.attribute(step, "value", path)
    if text is not None:
        values = reader.numbers(step, path, text)
        if values.size == 1 and step.tag == "scale":
            return np.repeat(values, 3)
        if values.size != 3:
            raise at(path, step, ": value needs 3 numbers, has "
                                 f"{values.size}")
        return values
    return np.array([reader.number(step, path, reader.attribute(step, k, path, str(default)), k)
                     for k in "xyz"])


def _step(reader, step, tag, path):
    out = np.eye(4)
    if tag == "translate":
        out[:3, 3] = _vector3(reader, step, path, 0.0)
    elif tag == "scale":
        out[:3, :3] = np.diag(_vector3(reader, step, path, 1.0))
    elif tag == "rotate":
        axis = _vector3(reader, step, path, 0.0)
        angle = reader.number(step, path, reader.required(step, "angle", path), "angle")
        length = float(np.linalg.norm(axis))
        if not length > 0:
            raise at(path, step, ": the axis of rotation is zero")
        if abs(length - 1.0) > 1e-6:
            getattr(reader, "notes", []).append(
                f"{describe(step)}: its axis is not of unit length: Mitsuba 3 does not "
                f"normalise it (so it scales and shears as well as turns), nor does ptrace")
        out[:3, :3] = rotation(axis, math.radians(angle))
    elif tag == "matrix":
        values = reader.numbers(step, path, reader.required(step, "value", path))
        if values.size == 16:
            out = values.reshape(4, 4)
        elif values.size == 9:
            out[:3, :3] = values.reshape(3, 3)
        else:
            raise at(path, step, ": needs 16 (or 9) numbers, has "
                                 f"{values.size}")
    else:
        out = _lookat(reader, step, path)
    return out


def _lookat(reader, step, path):
    points = {}
    for key in ("origin", "target", "up"):
        text = reader.attribute(step, key, path)
        if text is None and key != "up":
            raise at(path, step, f" has no {key} attribute")
        if text is not None:
            points[key] = reader.numbers(step, path, text, key)
            if points[key].size != 3:
                raise at(path, step, f": {key} needs 3 numbers")
    return lookat(points["origin"], points["target"], points.get("up"),
                  lambda message: at(path, step, f": {message}"))


def rotation(axis, angle):
    """The 3 x 3 matrix of a right-handed rotation by angle (radians) about a unit axis (of
    another axis, Mitsuba's matrix of the same formula: cos I + (1 - cos) a a^T + sin [a]x)."""
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return np.array([[t * x * x + c, t * x * y - s * z, t * x * z + s * y],
                     [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
                     [t * x * z - s * y, t * y * z + s * x, t * z * z + c]])


def lookat(origin, target, up, error):
    """Mitsuba's look-at matrix: columns left, up, forward (target - origin) and origin. No up:
    one at right angles to the view, as Mitsuba picks it."""
    forward = np.asarray(target, float) - np.asarray(origin, float)
    if not np.linalg.norm(forward) > 0:
        raise error("origin and target are the same point: no direction to look in")
    forward = forward / np.linalg.norm(forward)
    if up is None:
        up = np.array([0.0, 1.0, 0.0]) if abs(forward[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    left = np.cross(up, forward)
    if not np.linalg.norm(left) > 1e-9 * max(float(np.linalg.norm(up)), 1e-300):
        raise error("up is zero or parallel to the view direction")
    left = left / np.linalg.norm(left)
    out = np.eye(4)
    out[:3, 0], out[:3, 1], out[:3, 2], out[:3, 3] = left, np.cross(forward, left), forward, \
        origin
    return out
