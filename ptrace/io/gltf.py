"""glTF 2.0 files (.gltf, .glb): the document checked before trimesh reads the meshes (the
nodes' placement and the file's KHR_lights_punctual lights are ptrace.io.gltf_scene's, re-exported
here).

trimesh reads the geometry, texture coordinates and images, but it reads a malformed file
into a bare exception ("FileNotFoundError: model.gltf" for bad JSON), leaves placeholder zeros
where a Draco-compressed mesh was, drops a missing image without a word, opens whatever file
a URI names, and matches nothing back to the JSON (materials may share a name, or have none).
So the JSON is read here first (`read_document`: a .gltf, or a .glb's JSON chunk, as the
glTF 2.0 container specifies) and checked: its version, the extensions it requires, every
buffer and image it names (from the model's folder only, regular files only). trimesh then
reads a copy of the document whose materials are renamed by their index (so each of its
materials is found in the JSON exactly) and whose unreadable images are removed (so trimesh
opens nothing we refused). ptrace.io.gltf_materials reads the materials from the JSON.
"""
import json
import os
import struct

from .. import budget
from ..errors import SceneError
from . import files
from .gltf_materials import material_values
from .gltf_scene import _dict, _list, node_matrices

TAG = "ptrace-material-"      # the names trimesh sees: TAG + the material's index
JSON_CHUNK, BIN_CHUNK = 0x4E4F534A, 0x004E4942
# extensions a file may require that ptrace reads (or approximates, with a note)
READ_EXTENSIONS = {"KHR_materials_emissive_strength", "KHR_materials_transmission",
                   "KHR_materials_ior", "KHR_lights_punctual", "KHR_texture_transform"}
WHY_NOT = {"KHR_draco_mesh_compression": "Draco-compressed meshes, which ptrace cannot decode",
           "EXT_meshopt_compression": "meshoptimizer-compressed buffers, which ptrace cannot "
                                      "decode",
           "KHR_mesh_quantization": "quantized vertex attributes, which ptrace does not read",
           "KHR_texture_basisu": "KTX2 (Basis Universal) textures, which ptrace cannot decode",
           "EXT_texture_webp": "WebP textures in place of PNG or JPEG",
           "KHR_materials_pbrSpecularGlossiness": "the specular-glossiness material model, "
                                                  "which ptrace does not read"}
# primitive modes trimesh does not read as triangles (it reads 4, triangles, and 5, strips)
PRIMITIVE_MODES = {0: "points", 1: "lines", 2: "line loops", 3: "line strips",
                   6: "triangle fans"}


def read_document(path, data):
    """(document, BIN chunk bytes or None) of a .gltf's or .glb's bytes; SceneError in words
    for a file that is not glTF 2.0."""
    binary = None
    if path.lower().endswith(".glb") or data[:4] == b"glTF":
        if len(data) < 20 or data[:4] != b"glTF":
            raise SceneError(path, "is not a binary glTF (.glb): it does not start with the "
                                   "glTF magic and a 12-byte header")
        version, length = struct.unpack_from("<II", data, 4)
        if version != 2:
            raise SceneError(path, f"is a binary glTF of version {version}; ptrace reads "
                                   f"glTF 2.0")
        chunk_length, kind = struct.unpack_from("<II", data, 12)
        if kind != JSON_CHUNK or 20 + chunk_length > len(data):
            raise SceneError(path, "is not a valid binary glTF: its first chunk is not a "
                                   "whole JSON chunk (truncated or corrupt)")
        text = data[20:20 + chunk_length]
        rest = 20 + chunk_length + (-chunk_length % 4)
        if rest + 8 <= len(data):
            bin_length, bin_kind = struct.unpack_from("<II", data, rest)
            if bin_kind == BIN_CHUNK:
                binary = data[rest + 8:rest + 8 + bin_length]
    else:
        text = data
    try:
        document = json.loads(text.decode("utf-8-sig"))
    except UnicodeDecodeError:
        raise SceneError(path, "is not glTF: its JSON is not UTF-8 text") from None
    except json.JSONDecodeError as error:
        raise SceneError(path, f"is not valid glTF: its JSON is malformed at line "
                               f"{error.lineno}, column {error.colno} ({error.msg})") from None
    except RecursionError:
        raise SceneError(path, "is not valid glTF: its JSON is nested too deeply") from None
    if not isinstance(document, dict):
        raise SceneError(path, "is not valid glTF: its JSON is not an object")
    version = str((document.get("asset") or {}).get("version", "")) \
        if isinstance(document.get("asset"), dict) else ""
    if not version.startswith("2"):
        raise SceneError(path, f"is glTF of version {version or '(none given)'}; ptrace reads "
                               f"glTF 2.0")
    return document, binary


def check_extensions(path, document, notes):
    """Refuse a file that requires an extension ptrace does not read (the glTF specification:
    a loader that does not support a required extension must not load the file), and one
    whose meshes are compressed (Draco: trimesh would leave zeros in their place)."""
    required = [str(e)[:60] for e in _list(document.get("extensionsRequired"))
                if e not in READ_EXTENSIONS]
    if required:
        whys = "; ".join(f"{name} ({WHY_NOT.get(name, 'which ptrace does not read')})"
                         for name in required)
        raise SceneError(path, f"requires the glTF extension{'s' if len(required) > 1 else ''} "
                               f"{whys}")
    for mesh in _list(document.get("meshes")):
        for primitive in _list(_dict(mesh).get("primitives")):
            primitive = _dict(primitive)
            position = _dict(primitive.get("attributes")).get("POSITION")
            accessors = _list(document.get("accessors"))
            accessor = _dict(accessors[position]) if isinstance(position, int) and \
                0 <= position < len(accessors) else {}
            draco = "KHR_draco_mesh_compression"
            if draco in _dict(primitive.get("extensions")) and "bufferView" not in accessor:
                raise SceneError(path, f"uses the glTF extension {draco} ({WHY_NOT[draco]})")
            mode = primitive.get("mode", 4)
            if mode not in (4, 5):
                kind = PRIMITIVE_MODES.get(mode, f"mode {mode}")
                notes.append(f"<mesh {_dict(mesh).get('name', '')!r}>: a primitive of {kind} "
                             f"skipped (ptrace renders triangles)")
    used = set(_list(document.get("extensionsUsed"))) - READ_EXTENSIONS
    for name in sorted(used & {"KHR_materials_pbrSpecularGlossiness", "EXT_texture_webp",
                               "KHR_texture_basisu", "KHR_mesh_quantization"}):
        notes.append(f"glTF: extension {name} used ({WHY_NOT[name]}): the parts that use it "
                     f"may be missing or approximated")


def why_empty(document):
    """Why a file trimesh read no triangles from has none, in words, or None."""
    scenes = _list(document.get("scenes"))
    index = document.get("scene", 0)
    if not scenes or not (isinstance(index, int) and 0 <= index < len(scenes)) or \
            not _list(_dict(scenes[index]).get("nodes")):
        return "it has no scene with nodes (nothing to render)"
    modes = {_dict(p).get("mode", 4) for m in _list(document.get("meshes"))
             for p in _list(_dict(m).get("primitives"))}
    if modes and not modes & {4, 5}:
        kinds = sorted(PRIMITIVE_MODES.get(m, f"mode {m}") for m in modes)
        return f"its primitives are {', '.join(kinds)}, which ptrace does not render"
    return None


def check_nodes(path, document):
    """Refuse a node hierarchy that is not a forest (a node with two parents, or a cycle):
    the glTF specification forbids both, and trimesh reads such a file into nothing."""
    nodes = _list(document.get("nodes"))
    parent = {}
    for i, node in enumerate(nodes):
        for child in _list(_dict(node).get("children")):
            if not isinstance(child, int) or not 0 <= child < len(nodes):
                raise SceneError(path, f"node {i} has a child {str(child)[:20]} that is not a "
                                       f"node of the file")
            if child in parent:
                raise SceneError(path, f"node {child} has two parents (nodes {parent[child]} "
                                       f"and {i}); glTF nodes form trees")
            parent[child] = i
    for start in parent:
        seen, i = set(), start
        while i in parent:
            if i in seen:
                raise SceneError(path, f"its nodes form a cycle (node {i} is its own "
                                       f"ancestor); glTF nodes form trees")
            seen.add(i)
            i = parent[i]


def placed_triangles(path, document):
    """(triangles, mesh instances, meshes instanced) of the file's scene as its nodes place
    them, each node counting its mesh's triangles (from the accessors' counts: triangle lists
    and strips), read from the JSON before any mesh is read or expanded."""
    accessors, meshes = _list(document.get("accessors")), _list(document.get("meshes"))

    def count(index):
        accessor = _dict(accessors[index]) if isinstance(index, int) and \
            0 <= index < len(accessors) else {}
        value = accessor.get("count", 0)
        return value if isinstance(value, int) and value > 0 else 0

    per_mesh = {}
    for m, mesh in enumerate(meshes):
        total = 0
        for primitive in _list(_dict(mesh).get("primitives")):
            primitive = _dict(primitive)
            corners = count(primitive["indices"]) if "indices" in primitive else \
                count(_dict(primitive.get("attributes")).get("POSITION"))
            mode = primitive.get("mode", 4)
            total += corners // 3 if mode == 4 else max(corners - 2, 0) if mode == 5 else 0
        per_mesh[m] = total
    nodes = _list(document.get("nodes"))
    triangles, instances, used = 0, 0, set()
    for i in node_matrices(path, document):
        mesh = _dict(nodes[i]).get("mesh")
        if isinstance(mesh, int) and mesh in per_mesh:
            triangles += per_mesh[mesh]
            instances += 1
            used.add(mesh)
    return triangles, instances, len(used)


def prepare(path):
    """What trimesh needs to read a glTF file safely: (bytes of a copy of the file whose
    materials are renamed TAG + index and whose unreadable images are removed, file type,
    resolver of the model's folder), and (document, notes, {image index: why it is
    missing})."""
    data = files.read_bytes(path)
    document, binary = read_document(path, data)
    notes = []
    check_extensions(path, document, notes)
    check_nodes(path, document)
    triangles, instances, meshes = placed_triangles(path, document)
    budget.current().triangles(path, triangles, f"the {triangles:,} triangles its nodes place "
                                                f"({instances:,} instances of {meshes:,} "
                                                f"mesh{'es' if meshes != 1 else ''})")
    for i in range(len(_list(document.get("materials")))):
        material_values(path, document, i)        # refuses values the schema forbids
    directory = os.path.dirname(os.path.abspath(path))
    for i, buffer in enumerate(_list(document.get("buffers"))):
        uri = _dict(buffer).get("uri")
        if uri is None:
            if i != 0 or binary is None:
                raise SceneError(path, f"buffer {i} has no uri and is not the .glb's binary "
                                       f"chunk: its data is missing")
            continue
        if not isinstance(uri, str):
            raise SceneError(path, f"buffer {i}'s uri is not a string")
        if uri.startswith("data:"):
            continue
        where, reason, _ = files.resolve_reference(directory, uri, uri=True)
        if where is None:
            raise SceneError(path, f"buffer {i} {uri[:80]!r} {reason}: the meshes in it "
                                   f"cannot be read")
    missing = {}
    copy = json.loads(json.dumps(document))
    for i, image in enumerate(_list(copy.get("images"))):
        image = _dict(image)
        uri = image.get("uri")
        if image.get("mimeType") == "image/ktx2" or str(uri).lower().endswith(".ktx2"):
            missing[i] = "is a KTX2 texture, which ptrace cannot decode"
        if isinstance(uri, str) and not uri.startswith("data:") and i not in missing:
            where, reason, _ = files.resolve_reference(directory, uri, uri=True)
            if where is None:
                missing[i] = f"{uri[:80]!r} {reason}"
        if i in missing:
            image.pop("uri", None)
            image.pop("bufferView", None)
    for i, material in enumerate(_list(copy.get("materials"))):
        if isinstance(material, dict):
            material["name"] = f"{TAG}{i}"
    accessors = _list(copy.get("accessors"))
    for mesh in _list(copy.get("meshes")):
        for primitive in _list(_dict(mesh).get("primitives")):
            attributes = _dict(_dict(primitive).get("attributes"))
            uv = attributes.get("TEXCOORD_0")
            if isinstance(uv, int) and 0 <= uv < len(accessors) and \
                    _dict(accessors[uv]).get("componentType", 5126) != 5126:
                # trimesh reads normalized integers unscaled: drop them, not a wrong texture
                del attributes["TEXCOORD_0"]
                notes.append(f"<mesh {_dict(mesh).get('name', '')!r}>: texture coordinates "
                             f"stored as normalized integers are not read: its textures are "
                             f"not applied")
    text = json.dumps(copy).encode("utf-8")
    resolver = files.trimesh_resolver(directory, uri=True)
    if binary is None and not path.lower().endswith(".glb"):
        return (text, "gltf", resolver), (document, notes, missing)
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), JSON_CHUNK) + text
    if binary is not None:
        pad = binary + b"\x00" * (-len(binary) % 4)
        body += struct.pack("<II", len(pad), BIN_CHUNK) + pad
    glb = b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body
    return (glb, "glb", resolver), (document, notes, missing)
