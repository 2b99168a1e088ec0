"""A glTF material as a ptrace material record: its factors and extensions from the file's
JSON, its images as trimesh decoded them (ptrace.io.gltf explains the split).

What each field becomes is docs/usage.md's table "What mesh files' materials become". Every
value the glTF schema bounds is checked (factors in [0, 1], strengths at least 0, all finite):
a value outside is refused with the material and field named, since no image made of it would
be what the file means. A texture that is missing or cannot be decoded is a note and the
material keeps its factors.

An opaque material becomes ptrace's gltf_pbr, the specification's metallic-roughness BRDF
(ptrace.gltf_brdf) with metallic blended as the specification mixes it, and its emission added
to what it reflects; a transmissive one smooth glass.
"""
import math

import numpy as np

from ..budget import BudgetError
from ..errors import SceneError
from ..scene import BLEND_CUT, CLAMP, EMISSION, GLASS, GLTF_PBR, MIRROR_REPEAT, REPEAT
from .materials import check_numbers

SPEC_IOR = 1.5    # the index of refraction the core specification's BRDF fixes (f0 = 0.04)
GLTF_WRAP = {10497: REPEAT, 33071: CLAMP, 33648: MIRROR_REPEAT}
HANDLED = {"KHR_materials_emissive_strength", "KHR_materials_transmission",
           "KHR_materials_ior"}


def _dict(value):
    return value if isinstance(value, dict) else {}


def material_record(index, material, document, missing, pool, notes, path):
    """(record, texture-coordinate transform (3 x 3, glTF's uv space) or None) of material
    `index` of the document; `material` is trimesh's PBRMaterial of it (its images), missing
    {image index: why ptrace.io.gltf removed it}."""
    spec, name, values = material_values(path, document, index)
    where = f"material {name!r}"
    pbr = _dict(spec.get("pbrMetallicRoughness"))
    extensions = _dict(spec.get("extensions"))
    base, metallic, roughness = values["base"], values["metallic"], values["roughness"]
    emissive, strength = values["emissive"], values["strength"]
    transmission, ior = values["transmission"], values["ior"]
    for extension in sorted(set(extensions) - HANDLED):
        notes.append(f"<{where}>: extension {extension} ignored")
    if "occlusionTexture" in spec:
        notes.append(f"<{where}>: occlusionTexture ignored (a path tracer finds the occlusion)")
    mode = spec.get("alphaMode", "OPAQUE")
    if mode not in ("OPAQUE", "MASK", "BLEND"):
        raise SceneError(path, f"{where}: alphaMode {str(mode)[:20]!r} is none of OPAQUE, MASK "
                               f"and BLEND")
    transforms = {}

    def texture(field, ref, image, srgb, channel="rgb"):
        """The pool index of a referenced texture (its image's channel "rgb" or "alpha"), or
        None (noted) if it cannot be used."""
        if not isinstance(ref, dict):
            return None
        source = _source(document, ref)
        if source in missing:
            notes.append(f"<{where}>: {field}: its image {missing[source]}: ignored")
            return None
        coord = ref.get("texCoord", 0)
        transform_ext = _dict(_dict(ref.get("extensions")).get("KHR_texture_transform"))
        coord = transform_ext.get("texCoord", coord)
        for extension in sorted(set(_dict(ref.get("extensions"))) - {"KHR_texture_transform"}):
            notes.append(f"<{where}>: {field}'s {extension} ignored")
        if coord != 0:
            notes.append(f"<{where}>: {field} uses texture coordinate set {coord}; ptrace "
                         f"reads the first set only: texture ignored")
            return None
        if image is None:
            notes.append(f"<{where}>: {field}: its image is missing or could not be decoded: "
                         f"ignored")
            return None
        try:
            index = pool.add(image, srgb=srgb, wrap=_wrap(document, ref),
                             name=f"{name} {field}", key=("gltf image", source, channel))
        except BudgetError:
            raise
        except Exception as error:      # Pillow decodes lazily: any decoder error lands here
            notes.append(f"<{where}>: {field}: its image could not be decoded "
                         f"({str(error)[:80] or 'no message'}): ignored")
            return None
        transforms[field] = _transform_matrix(path, where, field, transform_ext)
        return index

    base_image = getattr(material, "baseColorTexture", None)
    emissive_image = getattr(material, "emissiveTexture", None)
    rough_image = getattr(material, "metallicRoughnessTexture", None)
    rough_ref = pbr.get("metallicRoughnessTexture")
    record = {"name": name}
    glows = max(emissive) * strength > 0.0
    if glows:
        record.update(emission=[e * strength for e in emissive])
    if transmission > 0.0:
        record.update(kind=GLASS, albedo=(1.0, 1.0, 1.0), transmittance=tuple(base), ior=ior)
        if transmission < 1.0 or roughness > 0.0:
            notes.append(f"<{where} (transmission {transmission:g}, roughness "
                         f"{roughness:g})>: glass rendered fully transmissive and smooth")
        if glows:   # ptrace's glass does not emit: the material's light wins
            record.update(kind=EMISSION)
            notes.append(f"<{where}>: emissive and transmissive: rendered as an emitter only "
                         f"(ptrace's glass does not emit)")
    else:   # the specification's BRDF: base colour, metallic and roughness, blended
        record.update(kind=GLTF_PBR, albedo=tuple(base), metallic=metallic,
                      alpha=roughness * roughness)
        t = texture("baseColorTexture", pbr.get("baseColorTexture"), base_image, True)
        if t is not None:
            record["albedo_texture"] = t
        t = texture("metallicRoughnessTexture", rough_ref, rough_image, False)
        if t is not None:
            record["roughness_texture"] = t
        if ior != SPEC_IOR:
            notes.append(f"<{where} (ior {ior:g})>: KHR_materials_ior on an opaque material "
                         f"ignored: its dielectric reflects as ior 1.5 does (f0 0.04)")
    if record["kind"] != EMISSION:
        normal_ref = spec.get("normalTexture")
        t = texture("normalTexture", normal_ref, getattr(material, "normalTexture", None), False)
        if t is not None:
            record.update(normal_texture=t, normal_scale=values["normal_scale"])
            notes.append(f"<{where}>: normalTexture applied with tangents from the texture "
                         f"coordinates (the file's TANGENT not read)")
    if mode != "OPAQUE" and glows:
        notes.append(f"<{where}>: alphaMode {mode} ignored on an emitting material (rendered "
                     f"opaque: its light is sampled over its whole surface)")
    elif mode != "OPAQUE":
        record.update(opacity=values["opacity"],
                      cutoff=values["cutoff"] if mode == "MASK" else BLEND_CUT)
        alpha = _alpha_image(base_image) if "albedo_texture" in record else None
        if alpha is not None:
            t = texture("baseColorTexture", pbr.get("baseColorTexture"), alpha, False, "alpha")
            if t is not None:
                record["alpha_texture"] = t
        cutoff = values["cutoff"]     # MASK: an alpha at or above it is opaque
        if mode == "MASK" and cutoff > 1.0:
            notes.append(f"<{where}>: alphaMode MASK with alphaCutoff {cutoff:g}, above 1 "
                         f"(the largest alpha): every texel is cut away, so the material is "
                         f"invisible")
        elif mode == "MASK" and "alpha_texture" not in record and values["opacity"] < cutoff:
            notes.append(f"<{where}>: alphaMode MASK with its alpha {values['opacity']:g} "
                         f"(baseColorFactor) below alphaCutoff {cutoff:g}: it is cut away "
                         f"everywhere, so the material is invisible")
        if mode == "BLEND":
            notes.append(f"<{where}>: alphaMode BLEND rendered as stochastic transparency (a "
                         f"ray passes with probability 1 - alpha: the mean is the blend)")
    if record["kind"] != GLASS and glows:
        t = texture("emissiveTexture", spec.get("emissiveTexture"), emissive_image, True)
        if t is not None:
            record["emission_texture"] = t
    return record, _one_transform(where, transforms, notes)


def material_values(path, document, index):
    """(JSON of material `index`, its name, its factors checked against the glTF schema:
    {"base", "metallic", "roughness", "emissive", "strength", "transmission", "ior"}).
    A value the schema forbids (not a number, NaN, infinite, outside its range) is refused
    with the material and the field named."""
    specs = document.get("materials") if isinstance(document.get("materials"), list) else []
    spec = _dict(specs[index]) if 0 <= index < len(specs) else {}
    name = str(spec.get("name") or f"#{index}")
    where = f"material {name!r}"
    pbr = _dict(spec.get("pbrMetallicRoughness"))
    extensions = _dict(spec.get("extensions"))

    def numbers(value, default, field, count=1, high=1.0):
        values = default if value is None else value
        values = values if isinstance(values, list) else [values]
        checked = check_numbers(values, f"{where}: {field}", low=0.0, high=high)
        if isinstance(checked, str):
            raise SceneError(path, checked)
        if len(checked) < count:
            raise SceneError(path, f"{where}: {field} has {len(checked)} numbers, not {count}")
        return checked[:count] if count > 1 else checked[0]

    base = numbers(pbr.get("baseColorFactor"), [1.0] * 4, "baseColorFactor", 4)
    return spec, name, {
        "base": base[:3], "opacity": base[3],
        "cutoff": numbers(spec.get("alphaCutoff"), 0.5, "alphaCutoff", high=None),
        "normal_scale": numbers(_dict(spec.get("normalTexture")).get("scale"), 1.0,
                                "normalTexture scale", high=None),
        "metallic": numbers(pbr.get("metallicFactor"), 1.0, "metallicFactor"),
        "roughness": numbers(pbr.get("roughnessFactor"), 1.0, "roughnessFactor"),
        "emissive": numbers(spec.get("emissiveFactor"), [0.0] * 3, "emissiveFactor", 3),
        "strength": numbers(_dict(extensions.get("KHR_materials_emissive_strength"))
                            .get("emissiveStrength"), 1.0, "emissiveStrength", high=None),
        "transmission": numbers(_dict(extensions.get("KHR_materials_transmission"))
                                .get("transmissionFactor"), 0.0, "transmissionFactor"),
        "ior": numbers(_dict(extensions.get("KHR_materials_ior")).get("ior"), 1.5, "ior",
                       high=None)}


def _alpha_image(image):
    """The alpha channel of a decoded base colour image, as a grey PIL image, or None if it has
    none (or it is opaque everywhere)."""
    if image is None or not hasattr(image, "mode"):
        return None
    if image.mode not in ("RGBA", "LA", "PA", "RGBa", "La") and "transparency" not in image.info:
        return None
    alpha = image.convert("RGBA").getchannel("A")
    return None if alpha.getextrema()[0] == 255 else alpha


def _source(document, ref):
    textures = document.get("textures") if isinstance(document.get("textures"), list) else []
    i = ref.get("index")
    if isinstance(i, int) and 0 <= i < len(textures):
        return _dict(textures[i]).get("source")
    return None


def _wrap(document, ref):
    textures = document.get("textures") if isinstance(document.get("textures"), list) else []
    samplers = document.get("samplers") if isinstance(document.get("samplers"), list) else []
    try:
        sampler = _dict(samplers[textures[ref["index"]]["sampler"]])
    except (KeyError, IndexError, TypeError):
        return (REPEAT, REPEAT)
    return (GLTF_WRAP.get(sampler.get("wrapS", 10497), REPEAT),
            GLTF_WRAP.get(sampler.get("wrapT", 10497), REPEAT))


def _transform_matrix(path, where, field, extension):
    """KHR_texture_transform's matrix (translation x rotation x scale, in glTF's uv space:
    origin at the image's top left, v down), or None for the identity."""
    if not extension:
        return None
    values = []
    for key, default, count in (("offset", [0.0, 0.0], 2), ("rotation", 0.0, 1),
                                ("scale", [1.0, 1.0], 2)):
        value = extension.get(key, default)
        checked = check_numbers(value if isinstance(value, list) else [value],
                                f"{where}: {field} KHR_texture_transform {key}")
        if isinstance(checked, str) or len(checked) != count:
            raise SceneError(path, checked if isinstance(checked, str) else
                             f"{where}: {field} KHR_texture_transform {key} has "
                             f"{len(checked)} numbers, not {count}")
        values.append(checked)
    (ox, oy), (angle,), (sx, sy) = values
    c, s = math.cos(angle), math.sin(angle)
    # The rotation's sense is the one Khronos's conformance model TextureTransformTest checks
    # (its arrow meets the green marker) and three.js's loader uses: u' = c u + s v,
    # v' = -s u + c v. The extension's GLSL listing, mat3(c, s, 0, -s, c, 0, 0, 0, 1), read as
    # GLSL's column-major, gives the opposite sense, which that model marks red.
    matrix = (np.array([[1, 0, ox], [0, 1, oy], [0, 0, 1]]) @
              np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) @ np.diag([sx, sy, 1.0]))
    return None if np.allclose(matrix, np.eye(3)) else matrix


def _one_transform(where, transforms, notes):
    """The one transform of a material's texture coordinates (ptrace keeps one set of them per
    face): its textures' KHR_texture_transform when they agree, else the first's (noted)."""
    found = [(field, m) for field, m in transforms.items()]
    if not found:
        return None
    field, first = found[0]
    for other, matrix in found[1:]:
        if (matrix is None) != (first is None) or (matrix is not None and
                                                   not np.allclose(matrix, first)):
            notes.append(f"<{where}>: its textures have different KHR_texture_transforms: "
                         f"{field}'s is applied to all")
            break
    return first


def apply_transform(uv, matrix):
    """Texture coordinates (..., 2) in ptrace's convention (v up) through a glTF texture
    transform (defined with v down)."""
    u, v = uv[..., 0], 1.0 - uv[..., 1]
    tu = matrix[0, 0] * u + matrix[0, 1] * v + matrix[0, 2]
    tv = matrix[1, 0] * u + matrix[1, 1] * v + matrix[1, 2]
    return np.stack([tu, 1.0 - tv], axis=-1)
