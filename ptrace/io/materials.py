"""The materials, textures and lights that mesh files carry, as ptrace's BSDFs and lights.

trimesh reads the files (meshes, texture coordinates, the OBJ .mtl, glTF's materials and their
images, PLY vertex colours); this module decides what each field means to ptrace and notes
every field it approximates or ignores. The README's table "What mesh files' materials become"
is the summary of these rules.

glTF: trimesh keeps the images and texture coordinates but not the extensions ptrace needs
(KHR_materials_transmission, KHR_materials_ior, KHR_materials_emissive_strength,
KHR_lights_punctual) nor the samplers' wrap modes, so the file's JSON is read here as well
(`gltf_json`: the JSON of a .gltf, or a .glb's first chunk, as the glTF 2.0 container
specifies), and its materials are matched to trimesh's by name.
"""
import json
import math
import os
import struct

import numpy as np

from ..scene import (
    CLAMP,
    DIFFUSE,
    DIRECTIONAL,
    EMISSION,
    GLASS,
    GLOSSY,
    MICROFACET,
    MIRROR,
    MIRROR_REPEAT,
    PHYSICAL,
    POINT,
    REPEAT,
    SPOT,
)

MIN_ALPHA = 0.01          # a roughness of 0 becomes this Beckmann alpha (0 has no density)
METALLIC_THRESHOLD = 0.5  # glTF metallic at or above: a conductor; below: diffuse
GLTF_WRAP = {10497: REPEAT, 33071: CLAMP, 33648: MIRROR_REPEAT}


class TexturePool:
    """The textures a file's materials use, each image converted once to linear RGB."""

    def __init__(self):
        self.images, self.wraps, self.names, self._index = [], [], [], {}

    def add(self, image, srgb, wrap=(REPEAT, REPEAT), name=""):
        """Index of the texture of a PIL image or an (H, W, C) array; srgb says whether its
        values are sRGB-encoded (colour textures) or linear (glTF's metallicRoughness)."""
        key = (id(image), srgb, tuple(wrap))
        if key not in self._index:
            self._index[key] = len(self.images)
            self.images.append(linear_rgb(image, srgb))
            self.wraps.append(tuple(wrap))
            self.names.append(name)
        return self._index[key]


def linear_rgb(image, srgb):
    """(H, W, 3) float32 linear RGB of an 8- or 16-bit image, top row first. The sRGB decode is
    OpenImageIO's colour conversion (ImageBufAlgo.colorconvert), not a formula of ours."""
    import OpenImageIO as oiio
    pixels = np.asarray(image)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.dtype == np.uint8:
        values = pixels.astype(np.float32) / 255.0
    elif pixels.dtype == np.uint16:
        values = pixels.astype(np.float32) / 65535.0
    elif pixels.dtype == bool:
        values = pixels.astype(np.float32)
    else:
        values = pixels.astype(np.float32)
    channels = values.shape[2]
    if channels in (1, 2):       # grey (and alpha): the grey in every channel
        values = np.repeat(values[:, :, :1], 3, axis=2)
    values = np.ascontiguousarray(values[:, :, :3])
    if srgb:
        buffer = oiio.ImageBuf(values)
        converted = oiio.ImageBufAlgo.colorconvert(buffer, "sRGB", "linear")
        if converted.has_error:
            raise ValueError(converted.geterror())
        values = converted.get_pixels(oiio.FLOAT).reshape(values.shape)
    return values.astype(np.float32)


def conductor_from_colour(colour):
    """(eta, k) per channel of a conductor whose reflectance at normal incidence is `colour`
    (Gulbrandsen 2014, "Artist Friendly Metallic Fresnel", with the edge tint 1): the course's
    microfacet BSDF takes a conductor's eta and k, glTF and OBJ give a colour."""
    r = np.clip(np.asarray(colour, dtype=np.float64)[:3], 1e-4, 0.999)
    eta = (1.0 - r) / (1.0 + r)
    k = np.sqrt(np.maximum(r * (eta + 1.0) ** 2 - (eta - 1.0) ** 2, 0.0) / (1.0 - r))
    return eta, k


# -- OBJ + MTL ---------------------------------------------------------------------------------

def _numbers(value, count=None):
    if value is None:
        return None
    if isinstance(value, (int, float)):
        values = [float(value)]
    else:
        try:
            values = [float(v) for v in np.atleast_1d(value)]
        except (TypeError, ValueError):
            return None
    if count == 3 and len(values) == 1:
        values = values * 3
    return values


def obj_material(material, directory, pool, notes, where):
    """A ptrace material record from trimesh's SimpleMaterial of an OBJ's .mtl (its kwargs hold
    the .mtl's fields by their lower-case names)."""
    fields = dict(getattr(material, "kwargs", {}) or {})
    name = getattr(material, "name", None) or "mtl"
    kd = _numbers(fields.get("kd"), 3) or [0.5, 0.5, 0.5]
    ks = _numbers(fields.get("ks"), 3) or [0.0, 0.0, 0.0]
    ke = _numbers(fields.get("ke"), 3) or [0.0, 0.0, 0.0]
    ns = (_numbers(fields.get("ns")) or [0.0])[0]
    ni = (_numbers(fields.get("ni")) or [1.5])[0]
    d = (_numbers(fields.get("d")) or [1.0])[0]
    tr = _numbers(fields.get("tr"))
    if tr is not None and "d" not in fields:
        d = 1.0 - tr[0]
    illum = int((_numbers(fields.get("illum")) or [2])[0])
    record = {"name": name}
    ignored = [key for key in ("ka", "map_ka", "map_ks", "map_ns", "map_d", "map_bump", "bump",
                               "norm", "disp", "tf", "pr", "pm", "map_pr", "map_pm", "sharpness")
               if key in fields]
    image = getattr(material, "image", None)
    if max(ke) > 0.0:
        record.update(kind=EMISSION, emission=ke[:3])
        if "map_ke" in fields:
            texture = _read_map(fields["map_ke"], directory, pool, notes, where)
            if texture is not None:
                record["emission_texture"] = texture
        if image is not None or "kd" in fields:
            notes.append(f"{where}: material {name!r}: Ke makes it an emitter; its Kd and "
                         f"map_Kd are ignored (an emitter does not reflect)")
    elif illum in (4, 6, 7, 9) or d < 1.0:
        record.update(kind=GLASS, albedo=(1.0, 1.0, 1.0), transmittance=(1.0, 1.0, 1.0), ior=ni)
        notes.append(f"{where}: material {name!r}: glass of ior {ni:g} (illum {illum}, d {d:g}); "
                     f"clear: Kd, Ks and the partial opacity of d are not used")
    elif max(ks) > 0.0 and max(kd) == 0.0 and image is None:
        if ns >= 1000.0 or illum == 3 and ns == 0.0:
            record.update(kind=MIRROR, albedo=ks[:3])
        else:
            eta, k = conductor_from_colour(ks)
            record.update(kind=MICROFACET, alpha=max(math.sqrt(2.0 / (ns + 2.0)), MIN_ALPHA),
                          eta=tuple(eta), k=tuple(k))
    else:
        record.update(kind=DIFFUSE, albedo=kd[:3])
        if max(ks) > 0.0:   # a diffuse base under a glossy coat of reflectance Ks
            record.update(kind=GLOSSY, specular=tuple(min(v, 1.0) for v in ks[:3]),
                          alpha=max(math.sqrt(2.0 / (ns + 2.0)), MIN_ALPHA))
        if image is not None:
            record["albedo_texture"] = pool.add(image, srgb=True,
                                                wrap=_obj_wrap(fields.get("map_kd")),
                                                name=f"{name} map_Kd")
    if ignored:
        notes.append(f"{where}: material {name!r}: ignored " + ", ".join(sorted(ignored)))
    return record


def _obj_wrap(value):
    """The -clamp option of an .mtl map statement: clamp to the edge, else repeat."""
    words = [str(v).lower() for v in np.atleast_1d(value)] if value is not None else []
    if "-clamp" in words and words[words.index("-clamp") + 1:][:1] == ["on"]:
        return (CLAMP, CLAMP)
    return (REPEAT, REPEAT)


def _read_map(value, directory, pool, notes, where):
    """A map statement's image (its last word is the file name, after any options), read by
    OpenImageIO relative to the .obj's folder; None (with a note) if it cannot be read."""
    import OpenImageIO as oiio
    words = [str(v) for v in np.atleast_1d(value)]
    if not words:
        return None
    path = os.path.join(directory, words[-1])
    buffer = oiio.ImageBuf(path)
    if buffer.has_error:
        notes.append(f"{where}: texture {words[-1]!r} could not be read ({buffer.geterror()}): "
                     f"ignored")
        return None
    pixels = buffer.get_pixels(oiio.FLOAT)
    srgb = buffer.spec().format.basetype in (oiio.UINT8, oiio.UINT16)
    return pool.add(pixels, srgb=srgb, wrap=_obj_wrap(value), name=words[-1])


# -- glTF 2.0 ----------------------------------------------------------------------------------

def gltf_json(path):
    """The JSON document of a .gltf file, or of a .glb's JSON chunk (the glTF 2.0 container:
    a 12-byte header, then chunks of (length, type, data); the first is the JSON)."""
    with open(path, "rb") as stream:
        data = stream.read()
    if path.lower().endswith(".glb"):
        if len(data) < 20 or data[:4] != b"glTF":
            raise ValueError("not a binary glTF (no glTF magic)")
        length, kind = struct.unpack_from("<II", data, 12)
        if kind != 0x4E4F534A:     # "JSON"
            raise ValueError("the first chunk of the .glb is not its JSON")
        data = data[20:20 + length]
    return json.loads(data.decode("utf-8"))


def _gltf_wrap(document, texture_ref):
    textures, samplers = document.get("textures", []), document.get("samplers", [])
    try:
        sampler = samplers[textures[texture_ref["index"]]["sampler"]]
    except (KeyError, IndexError, TypeError):
        return (REPEAT, REPEAT)
    return (GLTF_WRAP.get(sampler.get("wrapS", 10497), REPEAT),
            GLTF_WRAP.get(sampler.get("wrapT", 10497), REPEAT))


def gltf_material(material, document, pool, notes, where):
    """A ptrace material record from a glTF material: the JSON's fields (document's materials,
    matched by name; its factors exactly as written) and trimesh's PBRMaterial's images."""
    name = getattr(material, "name", None) or "gltf"
    spec = next((m for m in document.get("materials", []) if m.get("name") == name), None)
    if spec is None:   # a material without a name in the JSON: trimesh's values
        spec = {"pbrMetallicRoughness": {
            "baseColorFactor": _unit_colour(getattr(material, "baseColorFactor", None), 4),
            "metallicFactor": getattr(material, "metallicFactor", None),
            "roughnessFactor": getattr(material, "roughnessFactor", None)},
            "emissiveFactor": _unit_colour(getattr(material, "emissiveFactor", None), 3)}
        spec = {key: value for key, value in spec.items() if value is not None}
        notes.append(f"{where}: material {name!r} not found by name in the file's JSON: its "
                     f"extensions and samplers are not read")
    pbr = spec.get("pbrMetallicRoughness", {})
    extensions = spec.get("extensions", {})
    base = [float(v) for v in (pbr.get("baseColorFactor") or [1.0, 1.0, 1.0, 1.0])][:3]
    metallic = float(pbr.get("metallicFactor", 1.0) if pbr.get("metallicFactor") is not None
                     else 1.0)
    roughness = float(pbr.get("roughnessFactor", 1.0) if pbr.get("roughnessFactor") is not None
                      else 1.0)
    emissive = [float(v) for v in (spec.get("emissiveFactor") or [0.0, 0.0, 0.0])][:3]
    strength = float(extensions.get("KHR_materials_emissive_strength", {})
                     .get("emissiveStrength", 1.0))
    transmission = float(extensions.get("KHR_materials_transmission", {})
                         .get("transmissionFactor", 0.0))
    ior = float(extensions.get("KHR_materials_ior", {}).get("ior", 1.5))
    base_image = getattr(material, "baseColorTexture", None)
    emissive_image = getattr(material, "emissiveTexture", None)
    rough_image = getattr(material, "metallicRoughnessTexture", None)
    record = {"name": name}
    handled = {"KHR_materials_emissive_strength", "KHR_materials_transmission",
               "KHR_materials_ior"}
    for extension in sorted(set(extensions) - handled):
        notes.append(f"{where}: material {name!r}: extension {extension} ignored")
    for field, ref in (("baseColorTexture", pbr.get("baseColorTexture")),
                       ("metallicRoughnessTexture", pbr.get("metallicRoughnessTexture")),
                       ("emissiveTexture", spec.get("emissiveTexture"))):
        if isinstance(ref, dict):   # a texture reference's own options: ptrace reads none
            for extension in sorted(ref.get("extensions", {})):
                notes.append(f"{where}: material {name!r}: {field}'s {extension} ignored")
            if ref.get("texCoord", 0) != 0:
                notes.append(f"{where}: material {name!r}: {field} uses texCoord "
                             f"{ref['texCoord']}; ptrace reads the first set of texture "
                             f"coordinates only")
    for field in ("normalTexture", "occlusionTexture"):
        if field in spec:
            notes.append(f"{where}: material {name!r}: {field} ignored")
    if spec.get("alphaMode", "OPAQUE") != "OPAQUE":
        notes.append(f"{where}: material {name!r}: alphaMode {spec['alphaMode']} ignored "
                     f"(rendered opaque)")
    if max(emissive) * strength > 0.0:
        record.update(kind=EMISSION, emission=[e * strength for e in emissive])
        if emissive_image is not None:
            record["emission_texture"] = pool.add(
                emissive_image, srgb=True, wrap=_gltf_wrap(document, spec.get("emissiveTexture")),
                name=f"{name} emissiveTexture")
        notes.append(f"{where}: material {name!r}: emissive, so an emitter; its base colour, "
                     f"metallic and roughness are ignored (ptrace's emitters do not reflect)")
    elif transmission > 0.0:
        record.update(kind=GLASS, albedo=(1.0, 1.0, 1.0), transmittance=tuple(base), ior=ior)
        if transmission < 1.0 or roughness > 0.0:
            notes.append(f"{where}: material {name!r}: glass (transmission {transmission:g}, "
                         f"ior {ior:g}); rendered fully transmissive and smooth")
    elif metallic >= METALLIC_THRESHOLD:
        eta, k = conductor_from_colour(base)
        record.update(kind=MICROFACET, alpha=max(roughness * roughness, MIN_ALPHA),
                      eta=tuple(eta), k=tuple(k))
        if rough_image is not None:
            record["roughness_texture"] = pool.add(
                rough_image, srgb=False,
                wrap=_gltf_wrap(document, pbr.get("metallicRoughnessTexture")),
                name=f"{name} metallicRoughnessTexture")
        if base_image is not None:
            notes.append(f"{where}: material {name!r}: a metal's baseColorTexture ignored "
                         f"(its factor sets the conductor's colour)")
        if metallic < 1.0:
            notes.append(f"{where}: material {name!r}: metallic {metallic:g} rendered as a "
                         f"metal (ptrace has no blend)")
    else:   # a dielectric: the base colour under a glossy coat of the ior's reflectance
        r0 = ((ior - 1.0) / (ior + 1.0)) ** 2
        record.update(kind=GLOSSY, albedo=tuple(base), specular=(r0, r0, r0),
                      alpha=max(roughness * roughness, MIN_ALPHA))
        if base_image is not None:
            record["albedo_texture"] = pool.add(
                base_image, srgb=True, wrap=_gltf_wrap(document, pbr.get("baseColorTexture")),
                name=f"{name} baseColorTexture")
        if rough_image is not None:
            record["roughness_texture"] = pool.add(
                rough_image, srgb=False,
                wrap=_gltf_wrap(document, pbr.get("metallicRoughnessTexture")),
                name=f"{name} metallicRoughnessTexture")
        if metallic > 0.0:
            notes.append(f"{where}: material {name!r}: metallic {metallic:g} rendered as a "
                         f"dielectric (ptrace has no blend)")
    return record


def _unit_colour(value, count):
    if value is None:
        return None
    array = np.asarray(value)
    if array.dtype == np.uint8:
        array = array / 255.0
    return [float(v) for v in array.reshape(-1)[:count]]


def gltf_lights(document, node_transform, notes):
    """ptrace light records of glTF's KHR_lights_punctual (point, spot and directional lights,
    all of the PHYSICAL model: intensity times colour as the radiance numerator, inverse-square
    falloff, cones as the extension defines them). node_transform(i) gives node i's world
    matrix, or None if it is not in the scene."""
    lights = document.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
    records = []
    for i, node in enumerate(document.get("nodes", [])):
        ref = node.get("extensions", {}).get("KHR_lights_punctual")
        if ref is None:
            continue
        where = f"glTF node {node.get('name', i)!r}"
        try:
            light = lights[ref["light"]]
        except (KeyError, IndexError, TypeError):
            notes.append(f"{where}: its KHR_lights_punctual light does not exist: ignored")
            continue
        matrix = node_transform(i)
        if matrix is None:
            notes.append(f"{where}: a light outside the file's scene: ignored")
            continue
        colour = np.asarray(light.get("color", [1.0, 1.0, 1.0]), dtype=np.float64)[:3]
        radiance = tuple(colour * float(light.get("intensity", 1.0)))
        position = tuple(matrix[:3, 3])
        axis = matrix[:3, :3] @ np.array([0.0, 0.0, -1.0])   # lights point down their -Z
        axis = axis / np.linalg.norm(axis)
        kind = light.get("type")
        if light.get("range") is not None:
            notes.append(f"{where}: light range {light['range']} ignored (no cut-off)")
        if kind == "point":
            records.append({"kind": POINT, "radiance": radiance, "position": position,
                            "model": PHYSICAL})
        elif kind == "spot":
            spot = light.get("spot", {})
            inner = float(spot.get("innerConeAngle", 0.0))
            outer = float(spot.get("outerConeAngle", math.pi / 4))
            records.append({"kind": SPOT, "radiance": radiance, "position": position,
                            "direction": tuple(axis), "model": PHYSICAL,
                            "cos_inner": math.cos(inner), "cos_outer": math.cos(outer)})
        elif kind == "directional":
            # toward the light, as the course's directional lights
            records.append({"kind": DIRECTIONAL, "radiance": radiance,
                            "direction": tuple(-axis), "model": PHYSICAL})
        else:
            notes.append(f"{where}: light type {kind!r} unknown: ignored")
    if records:
        notes.append(f"glTF: {len(records)} KHR_lights_punctual light(s), intensity taken as "
                     f"radiometric (no lumen-to-watt factor), inverse-square falloff")
    return records
