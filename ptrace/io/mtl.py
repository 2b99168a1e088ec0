"""An OBJ file's materials: its .mtl libraries read, each material as a ptrace material
record, and the parts of the scene put together (ptrace.io.obj reads the geometry).

What each MTL field becomes is docs/usage.md's table "What mesh files' materials become". A
library, a material or a texture the file names but that cannot be read is a note, and the
faces concerned get what is left (the default material, the material's colour alone): never
silently. A NaN, infinite or negative value is refused with the material and field named.
"""
import math
import os

import numpy as np

from ..errors import SceneError
from ..scene import CLAMP, DIFFUSE, EMISSION, GLASS, GLOSSY, MICROFACET, MIRROR, REPEAT
from . import files
from .limits import is_float
from .materials import (
    DEFAULT_ALBEDO,
    MIN_ALPHA,
    TexturePool,
    check_numbers,
    conductor_from_colour,
    linear_rgb,
)

IGNORED = ("ka", "map_ka", "map_ks", "map_ns", "map_d", "map_bump", "bump", "norm", "disp",
           "decal", "refl", "tf", "pr", "pm", "ps", "pc", "pcr", "aniso", "anisor", "map_pr",
           "map_pm", "map_ps", "sharpness", "map_refl")
SPELLING = {"ka": "Ka", "map_ka": "map_Ka", "map_ks": "map_Ks", "map_ns": "map_Ns",
            "map_bump": "map_Bump", "tf": "Tf", "pr": "Pr", "pm": "Pm", "ps": "Ps",
            "pc": "Pc", "pcr": "Pcr", "map_pr": "map_Pr", "map_pm": "map_Pm", "map_ps": "map_Ps"}
# a map statement's options and how many words follow each (-o, -s, -t: one to three numbers)
MAP_OPTIONS = {"-blendu": 1, "-blendv": 1, "-bm": 1, "-boost": 1, "-cc": 1, "-clamp": 1,
               "-imfchan": 1, "-mm": 2, "-texres": 1, "-type": 1, "-o": 3, "-s": 3, "-t": 3}


def read_libraries(path, directory, statements, notes):
    """{material name: (fields, .mtl path)} of the libraries an OBJ's mtllib statements name
    (each read from the model's folder only); a library that cannot be read is a note."""
    library = {}
    for statement in statements:
        names = [statement] if " " not in statement else [statement] + statement.split()
        found = False
        for name in names:
            mtl_path, reason, remark = files.resolve_reference(directory, name)
            if mtl_path is None:
                continue
            found = True
            data = files.read_bytes(mtl_path)
            try:
                text = data.decode("utf-8")
            except UnicodeDecodeError:
                text = data.decode("latin-1")
            for material, fields in parse_mtl(text).items():
                library.setdefault(material, (fields, mtl_path))
            if remark:
                notes.append(f"<mtllib {name!r}>: {remark}")
            if name == statement:
                break
        if not found:
            _, reason, _ = files.resolve_reference(directory, statement)
            notes.append(f"<mtllib {statement!r}>: {reason}: the faces that use its materials "
                         f"get the default diffuse material (albedo {DEFAULT_ALBEDO})")
    return library


def parse_mtl(text):
    """{material name: {lower-case field: the rest of its line}} of an .mtl's text."""
    materials, current = {}, None
    for line in text.replace("\\\r\n", " ").replace("\\\n", " ").splitlines():
        words = line.split(None, 1)
        if not words or words[0].startswith("#"):
            continue
        key, rest = words[0].lower(), (words[1].strip() if len(words) > 1 else "")
        if key == "newmtl":
            current = materials.setdefault(rest, {})
        elif current is not None:
            current.setdefault(key, rest)
    return materials


def assemble(path, directory, library, names, material_of_face, has_uv, uv, vertices, faces,
             colours, notes):
    """The scene parts (see ptrace.io.meshes) of an OBJ's triangles and their materials.
    Faces without texture coordinates get their material without its textures (noted), not
    the colour at (0, 0) of the texture."""
    pool, ignored = TexturePool(path), {}
    by_name = {index: name for name, index in names.items()}
    records, keys, built = [], {}, {}
    material_index = np.zeros(len(faces), np.int32)
    defaulted = 0
    file_uv = uv if has_uv.any() else None    # as the file gives them (Mitsuba's obj reads)
    copied = False
    for key in sorted(set(zip(material_of_face.tolist(), has_uv.tolist()))):
        material, with_uv = key
        chosen = (material_of_face == material) & (has_uv == with_uv)
        name = by_name.get(material)
        if name is None or name not in library:
            if name is not None:
                notes.append(f"<material {name!r}>: used by faces but defined in no .mtl the "
                             f"file names: the default diffuse material (albedo "
                             f"{DEFAULT_ALBEDO})")
            record, transform = {"kind": DIFFUSE, "albedo": (DEFAULT_ALBEDO,) * 3,
                                 "name": "default"}, None
            defaulted += int(chosen.sum())
        else:
            if name not in built:
                fields, mtl_path = library[name]
                built[name] = material_record(name, fields, mtl_path, directory, pool, notes,
                                              ignored)
            record, transform = built[name]
            textures = [k for k in ("albedo_texture", "emission_texture") if k in record]
            if textures and not with_uv:
                record = {k: v for k, v in record.items() if k not in textures}
                notes.append(f"<material {name!r}>: faces without texture coordinates (vt): "
                             f"its texture is not applied to them")
            if transform is not None and with_uv:
                scale, offset = transform
                if not copied:      # file_uv stays as the file gives them
                    uv, copied = uv.copy(), True
                uv[chosen] = uv[chosen] * scale + offset
        record_key = (name if name in library else None, record.get("albedo_texture", -1),
                      record.get("emission_texture", -1))
        if record_key not in keys:
            keys[record_key] = len(records)
            records.append(record)
        material_index[chosen] = keys[record_key]
    for field, places in ignored.items():
        notes.append(f"<material {places[0]!r}>: {field} ignored"
                     + (f" (and in {len(places) - 1} more materials)" if len(places) > 1
                        else ""))
    vertex_colours = None
    if colours is not None:
        encoded = np.round(np.clip(colours, 0.0, 1.0) * 65535).astype(np.uint16)
        vertex_colours = linear_rgb(encoded[None], srgb=True)[0].astype(np.float64)
        notes.append("OBJ: vertex colours (v x y z r g b, read as sRGB) multiply the albedo")
    textured = any(r.get("albedo_texture", -1) >= 0 or r.get("emission_texture", -1) >= 0
                   for r in records)
    return {"vertices": vertices, "faces": faces, "material_index": material_index,
            "materials": records, "uv": uv if textured else None, "file_uv": file_uv,
            "vertex_colours": vertex_colours, "textures": pool, "notes": notes, "lights": [],
            "defaulted": defaulted}


def material_record(name, fields, mtl_path, directory, pool, notes, ignored):
    """(ptrace material record, (scale, offset) of the texture coordinates or None) of one
    MTL material. `ignored` collects {field: [material names]} for one note per field."""
    where = f"material {name!r}"

    def numbers(key, count, default):
        rest = fields.get(key)
        if rest is None:
            return default
        words = rest.split("#", 1)[0].split()
        if words and words[0].lower() in ("spectral", "xyz"):
            notes.append(f"<{where}>: {key.capitalize()} given as {words[0]}: not read; "
                         f"{default} used")
            return default
        values = []
        for word in words[:count]:
            try:
                values.append(float(word))
            except ValueError:
                raise SceneError(mtl_path, f"{where}: {key.capitalize()} has {word[:40]!r} "
                                           f"where a number belongs") from None
        if not values:
            raise SceneError(mtl_path, f"{where}: {key.capitalize()} has no value")
        if count == 3 and len(values) < 3:
            values = values[:1] * 3
        checked = check_numbers(values, f"{where}: {key.capitalize()}", low=0.0)
        if isinstance(checked, str):
            raise SceneError(mtl_path, checked)
        return checked

    kd = numbers("kd", 3, [DEFAULT_ALBEDO] * 3)
    ks = numbers("ks", 3, [0.0] * 3)
    ke = numbers("ke", 3, [0.0] * 3)
    ns = numbers("ns", 1, [0.0])[0]
    ni = numbers("ni", 1, [1.5])[0]
    d = numbers("d", 1, [1.0])[0]
    if "tr" in fields and "d" not in fields:
        d = 1.0 - numbers("tr", 1, [0.0])[0]
    illum = int(numbers("illum", 1, [2.0])[0])
    if max(kd) > 1.0:
        notes.append(f"<{where}>: Kd above 1 clamped to 1 (a surface cannot reflect more "
                     f"light than it receives)")
        kd = [min(v, 1.0) for v in kd]
    for key in IGNORED:
        if key in fields:
            ignored.setdefault(SPELLING.get(key, key), []).append(name)
    record, transform = {"name": name}, None
    if max(ke) > 0.0:
        record.update(kind=EMISSION, emission=ke[:3])
        if "map_ke" in fields:
            texture, transform = read_map(fields["map_ke"], "map_Ke", where, directory,
                                          mtl_path, pool, notes)
            if texture is not None:
                record["emission_texture"] = texture
        if "map_kd" in fields or "kd" in fields:
            notes.append(f"<{where}>: Ke makes it an emitter; its Kd and map_Kd are ignored "
                         f"(an emitter does not reflect)")
    elif illum in (4, 6, 7, 9) or d < 1.0:
        ior = ni if ni > 0.0 else 1.5
        record.update(kind=GLASS, albedo=(1.0, 1.0, 1.0), transmittance=(1.0, 1.0, 1.0),
                      ior=ior)
        notes.append(f"<{where} (illum {illum}, d {d:g}, Ni {ni:g})>: glass (illum 4, 6, 7 "
                     f"or 9, or d < 1), clear, of ior Ni (1.5 if Ni is 0): Kd, Ks and the "
                     f"partial opacity of d are not used")
    elif max(ks) > 0.0 and max(kd) == 0.0 and "map_kd" not in fields:
        if ns >= 1000.0 or illum == 3 and ns == 0.0:
            record.update(kind=MIRROR, albedo=[min(v, 1.0) for v in ks[:3]])
        else:
            eta, k = conductor_from_colour(ks)
            record.update(kind=MICROFACET, alpha=max(math.sqrt(2.0 / (ns + 2.0)), MIN_ALPHA),
                          eta=tuple(eta), k=tuple(k))
    else:
        record.update(kind=DIFFUSE, albedo=kd[:3])
        if max(ks) > 0.0:   # a diffuse base under a glossy coat of reflectance Ks
            record.update(kind=GLOSSY, specular=tuple(min(v, 1.0) for v in ks[:3]),
                          alpha=max(math.sqrt(2.0 / (ns + 2.0)), MIN_ALPHA))
        if "map_kd" in fields:
            texture, transform = read_map(fields["map_kd"], "map_Kd", where, directory,
                                          mtl_path, pool, notes)
            if texture is not None:
                record["albedo_texture"] = texture
    return record, transform


def read_map(statement, field, where, directory, mtl_path, pool, notes):
    """(texture index or None, (scale, offset) or None) of a map statement: its options, then
    the file name (which may hold spaces, relative to the .mtl's folder), read from the
    model's folder only. A file that cannot be read is a note; the material keeps its colour
    alone."""
    words = statement.split()
    wrap, scale, offset = (REPEAT, REPEAT), np.ones(2), np.zeros(2)
    i = 0
    while i < len(words) - 1 and words[i].lower() in MAP_OPTIONS:
        option, count = words[i].lower(), MAP_OPTIONS[words[i].lower()]
        args = []
        while len(args) < count and i + 1 + len(args) < len(words) - 1:
            word = words[i + 1 + len(args)]
            if option in ("-o", "-s", "-t") and not is_float(word):
                break
            args.append(word)
        i += 1 + len(args)
        if option == "-clamp":
            wrap = (CLAMP, CLAMP) if args[:1] == ["on"] else (REPEAT, REPEAT)
        elif option in ("-s", "-o") and args:
            checked = check_numbers(args[:2], f"{where}: {field} option {option}")
            if isinstance(checked, str):
                raise SceneError(mtl_path, checked)
            values = np.array(checked + [0.0] * (2 - len(checked)))
            if option == "-s":
                scale = np.where(np.arange(2) < len(checked), values, 1.0)
            else:
                offset = values
        else:
            notes.append(f"<{where}>: {field} option {option} ignored")
    name = " ".join(words[i:])
    label = f"{where}, {field} {name!r}"
    path, reason, remark = files.resolve_reference(directory, name,
                                                   base=os.path.dirname(mtl_path))
    if path is None:
        notes.append(f"<{label}>: the texture {reason}: ignored (the material's colour alone)")
        return None, None
    if remark:
        notes.append(f"<{label}>: {remark}")
    try:
        texture = pool.add_file(path, srgb=True, wrap=wrap, name=name,
                                what=f"{name!r} ({field} of <{where}>)", model=mtl_path)
    except ValueError as error:
        notes.append(f"<{label}>: the texture could not be read as an image ({error}): "
                     f"ignored (the material's colour alone)")
        return None, None
    changed = not (np.array_equal(scale, np.ones(2)) and np.array_equal(offset, np.zeros(2)))
    return texture, ((scale, offset) if changed else None)

