"""COLLADA materials, lights and cameras in the course dialect (docs/course.md#materials to
#camera)."""
import math

import numpy as np

from ..scene import (
    AMBIENT,
    AREA,
    DIFFUSE,
    DIRECTIONAL,
    EMISSION,
    GLASS,
    LIGHT_NAMES,
    MICROFACET,
    MIRROR,
    POINT,
    REFRACTION,
    SPOT,
    CameraSpec,
)
from .collada_geometry import cgl_techniques
from .limits import problem

DEFAULT_ALBEDO = (0.5, 0.5, 0.5)
COMMON_SHADERS = ("phong", "lambert", "blinn")


def apply(matrix, point):
    """xyz of matrix @ (x, y, z, 1), no division by w (like the course)."""
    return matrix[:3, :3] @ np.asarray(point, dtype=np.float64) + matrix[:3, 3]


# --- materials (1.5) ------------------------------------------------------------------------

def colour(document, element, what):
    """Three numbers of element's text, each >= 0 (every colour, radiance, reflectance,
    transmittance and conductor eta and k of the dialect): a negative one is refused rather than
    rendered as light taken away."""
    values = document.vector(element, 3, what)
    _within_limits(document, element, values, what)
    if (values < 0).any():
        document.fail(f"{document.describe(element)}: negative {what} "
                      f"({' '.join(f'{v:g}' for v in values)}); it must be at least 0")
    return tuple(values)


def _within_limits(document, element, values, what):
    """Refuse numbers of magnitude above ptrace.io.limits.LIMIT (finite, but what follows from
    them would overflow), naming the element."""
    words = problem(values)
    if words is not None:
        document.fail(f"{document.describe(element)}: {what}: {words}")


def placed(document, where, values, what):
    """Refuse a placement (world positions, a light's or camera's frame, a sphere) whose
    numbers pass ptrace.io.limits.LIMIT or overflow to infinity, naming `where`."""
    words = problem(values)
    if words is not None:
        document.fail(f"{where}: {what} would overflow: {words}")


def _rgb(document, parent, tag):
    return colour(document, document.require_child(parent, tag), tag)


# what a BSDF's scalar must be: ior > 0 (a ratio of speeds), roughness >= 0 (parsed, unused),
# alpha > 0 (the Beckmann width divides by it)
SCALAR_RULES = {"ior": (0.0, False), "roughness": (0.0, True), "alpha": (0.0, False)}


def _number(document, parent, tag):
    element = document.require_child(parent, tag)
    value = document.scalar(element, tag)
    _within_limits(document, element, value, tag)
    low, inclusive = SCALAR_RULES[tag]
    if not (value >= low if inclusive else value > low):
        document.fail(f"{document.describe(element)}: {tag} {value:g} must be "
                      f"{'at least' if inclusive else 'greater than'} {low:g}")
    return value


def _emission(document, element):
    return {"kind": EMISSION, "emission": _rgb(document, element, "radiance")}


def _mirror(document, element):
    return {"kind": MIRROR, "albedo": _rgb(document, element, "reflectance")}


def _glass(document, element):
    return {"kind": GLASS, "transmittance": _rgb(document, element, "transmittance"),
            "albedo": _rgb(document, element, "reflectance"),
            "roughness": _number(document, element, "roughness"),
            "ior": _number(document, element, "ior")}


def _refraction(document, element):
    return {"kind": REFRACTION, "transmittance": _rgb(document, element, "transmittance"),
            "roughness": _number(document, element, "roughness"),
            "ior": _number(document, element, "ior")}


def _microfacet(document, element):
    return {"kind": MICROFACET, "alpha": _number(document, element, "alpha"),
            "eta": _rgb(document, element, "eta"), "k": _rgb(document, element, "k")}


CGL_BSDF_READERS = {"emission": _emission, "mirror": _mirror, "glass": _glass,
                    "refraction": _refraction, "microfacet": _microfacet}


def read_effect(document, effect):
    """A material record for an <effect>: CGL extra (last recognised child wins), else the
    profile_COMMON diffuse colour, else 0.5 grey."""
    record = None
    for technique in cgl_techniques(document, effect):
        for child in technique:
            reader = CGL_BSDF_READERS.get(child.tag)
            if reader is not None:
                record = reader(document, child)
            else:
                document.notes.append(f"{document.describe(child)}: unknown CGL BSDF "
                                      f"<{child.tag}> ignored")
    if record is not None:
        return record
    profile_common = document.child(effect, "profile_COMMON")
    techniques = [] if profile_common is None else document.children(profile_common, "technique")
    for technique in techniques:
        for shader in COMMON_SHADERS:
            color = document.find_path(technique, shader, "diffuse", "color")
            if color is not None:
                return {"kind": DIFFUSE, "albedo": colour(document, color, "colour")}
    document.notes.append(f"{document.describe(effect)}: no diffuse colour; albedo 0.5")
    return {"kind": DIFFUSE, "albedo": DEFAULT_ALBEDO}


class MaterialTable:
    """Material records, one per distinct <effect> plus the default grey when it is used."""

    def __init__(self, document):
        self.document = document
        self.records = []
        self._index_of_effect = {}
        self._default_index = None

    def index_for(self, instance_geometry):
        """Material index for an <instance_geometry>: its first bound instance_material."""
        document = self.document
        instance_material = document.find_path(instance_geometry, "bind_material",
                                               "technique_common", "instance_material")
        if instance_material is None:
            return self.default_index()
        material = document.resolve(instance_material, "target", ("material",))
        instance_effect = document.require_child(material, "instance_effect")
        effect = document.resolve(instance_effect, "url", ("effect",))
        if effect not in self._index_of_effect:
            record = read_effect(document, effect)
            record["name"] = material.get("id") or effect.get("id") or ""
            self._index_of_effect[effect] = len(self.records)
            self.records.append(record)
        return self._index_of_effect[effect]

    def default_index(self):
        if self._default_index is None:
            self._default_index = len(self.records)
            self.records.append({"kind": DIFFUSE, "albedo": DEFAULT_ALBEDO,
                                 "name": "default (no material bound)"})
        return self._default_index


# --- lights (1.6) ---------------------------------------------------------------------------

def _unit(document, node, vector, what):
    length = float(np.linalg.norm(vector))
    if not (length > 0 and math.isfinite(length)):
        document.fail(f"{document.describe(node)}: the {what} has zero length")
    return vector / length


def read_light(document, light, node, world):
    """A light record for a <light> placed by its node's world matrix."""
    techniques = cgl_techniques(document, light)
    technique = techniques[0] if techniques else document.child(light, "technique_common")
    if technique is None:
        document.fail(f"{document.describe(light)} has neither a CGL technique nor "
                      f"<technique_common>")
    kind_element = next(iter(technique), None)
    if kind_element is None:
        document.fail(f"{document.describe(technique)} is empty")
    if kind_element.tag not in LIGHT_NAMES:
        document.fail(f"{document.describe(light)}: unknown light type <{kind_element.tag}> "
                      f"(known: {', '.join(LIGHT_NAMES)})")
    radiance = colour(document, document.require_child(kind_element, "color"), "light colour")
    record = {"kind": LIGHT_NAMES.index(kind_element.tag), "radiance": radiance}
    if record["kind"] == AMBIENT:
        return record
    centre = apply(world, (0, 0, 0))
    front = apply(world, (0, 0, -1))
    if record["kind"] == DIRECTIONAL:
        # w = 1: the node's translation leaks into the direction, as in the course.
        record["direction"] = _unit(document, node, front, "directional light direction")
    elif record["kind"] == POINT:
        record["position"] = centre
    elif record["kind"] == AREA:
        edge_x = apply(world, (-1, 0, 0)) - centre
        edge_y = apply(world, (0, 1, 0)) - centre
        record.update(position=centre, edge_x=edge_x, edge_y=edge_y,
                      direction=_unit(document, node, front - centre, "area light normal"),
                      area=float(np.linalg.norm(edge_x) * np.linalg.norm(edge_y)))
        if not record["area"] > 0:
            document.fail(f"{document.describe(node)}: the area light has zero area (its node "
                          f"scales it to nothing)")
    elif record["kind"] == SPOT:
        record.update(position=centre,
                      direction=_unit(document, node, front - centre, "spot light direction"))
        document.notes.append(f"{document.describe(node)}: a spot light contributes no light "
                              f"(as in the course, whose spot lights return nothing)")
    values = np.concatenate([np.ravel(value) for key, value in record.items() if key != "kind"])
    placed(document, document.describe(node), values, "light placement")
    return record


# --- cameras (1.7) --------------------------------------------------------------------------

def read_camera(document, camera, world):
    """CameraSpec for a <camera> placed by its node's world matrix."""
    hfov, vfov, znear, zfar = 50.0, 35.0, 0.001, 1000.0
    perspective = document.find_path(camera, "optics", "technique_common", "perspective")
    if perspective is None:
        document.notes.append(f"{document.describe(camera)} has no <perspective>; using "
                              f"hfov 50, vfov 35")
    else:
        value = lambda tag, default: default if document.child(perspective, tag) is None \
            else document.scalar(document.child(perspective, tag), tag)
        hfov = value("xfov", hfov)
        znear = value("znear", znear)
        zfar = value("zfar", zfar)
        if document.child(perspective, "yfov") is not None:
            vfov = value("yfov", vfov)
        else:
            aspect_element = document.child(perspective, "aspect_ratio")
            if aspect_element is None:
                document.fail(f"{document.describe(perspective)} has neither <yfov> nor "
                              f"<aspect_ratio>")
            aspect = document.scalar(aspect_element, "aspect_ratio")
            if not aspect > 0:
                document.fail(f"{document.describe(aspect_element)}: aspect ratio {aspect} "
                              f"is not positive")
            vfov = math.degrees(2 * math.atan(math.tan(math.radians(hfov) / 2) / aspect))
    for tag, number in (("znear", znear), ("zfar", zfar)):
        words = problem(number)      # finite (the reader refuses NaN and inf), maybe huge
        if words is not None:
            document.fail(f"{document.describe(document.child(perspective, tag))}: {tag} "
                          f"{words}")
    if not 0 <= znear < zfar:
        document.fail(f"{document.describe(perspective)}: znear {znear:g} and zfar {zfar:g}: "
                      f"camera rays run from znear to zfar, so 0 <= znear < zfar is needed")
    for name, degrees in (("xfov", hfov), ("yfov", vfov)):
        if not 0 < degrees < 180:
            document.fail(f"{document.describe(camera)}: {name} {degrees} is not between "
                          f"0 and 180 degrees")
    view_point = apply(world, (0, 0, -1))
    position = apply(world, (0, 0, 0))
    placed(document, document.describe(camera), np.concatenate([view_point, position]),
           "camera placement")
    return CameraSpec(view_point=view_point, position=position, hfov=hfov, vfov=vfov,
                      znear=znear, zfar=zfar)
