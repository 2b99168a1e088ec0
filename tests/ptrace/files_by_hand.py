"""Small model files written byte by byte for the tests of ptrace's file readers: glTF (JSON
and numpy bytes, .gltf or .glb), PNGs of every colour type (Pillow; 16-bit RGB through
OpenImageIO), and a lit camera-facing quad's geometry. Nothing here is third-party data."""
import base64
import io
import json
import struct

import numpy as np

QUAD = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
QUAD_UV_GLTF = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]])  # v down
QUAD_FACES = np.array([[0, 1, 2], [0, 2, 3]])


def png_bytes(mode, colour=(255, 0, 0), size=(4, 4)):
    """A PNG of one colour in a Pillow mode: "P" (palette), "L", "LA", "I;16", "1", "RGB",
    "RGBA"; colour is RGB for P/RGB/RGBA, a grey level otherwise."""
    import PIL.Image
    if mode == "P":
        image = PIL.Image.new("P", size, 0)
        image.putpalette(list(colour) + [0, 0, 0] * 255)
    elif mode == "I;16":
        image = PIL.Image.fromarray(np.full(size[::-1], colour, np.uint16))
    elif mode in ("RGB", "RGBA"):
        image = PIL.Image.new(mode, size, tuple(colour) + ((255,) if mode == "RGBA" else ()))
    else:
        image = PIL.Image.new(mode, size, colour if mode != "LA" else (colour, 255))
    stream = io.BytesIO()
    image.save(stream, "PNG")
    return stream.getvalue()


def rgb16_png(path, colour):
    """A 4 x 4 16-bit RGB PNG of one colour (values 0..65535), written by OpenImageIO."""
    import OpenImageIO as oiio
    pixels = np.tile(np.asarray(colour, np.uint16), (4, 4, 1))
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(4, 4, 3, oiio.UINT16))
    out.write_image(pixels)
    out.close()


def gltf(path, primitives, materials=(), images=(), samplers=(), textures=None, nodes=None,
         extensions=None, document=None, buffer_uri=None):
    """Write a glTF 2.0 file (.gltf with an embedded buffer, or a .glb by path's extension).

    primitives: dicts with "positions" (N, 3), "indices" (M,) and optional "uv" (N, 2, glTF's
    v down; "uv_normalized": stored as normalized uint16), "colours" (N, 3 or 4 floats),
    "material" (index), "mode", "extensions". Each
    becomes one mesh on one node (unless nodes is given). images: bytes (embedded in the
    buffer) or a str URI. textures: default one per image. document: entries merged last.
    buffer_uri: write the buffer to this file name beside the .gltf instead of embedding."""
    blob, views, accessors, meshes = bytearray(), [], [], []

    def accessor(array, component, kind):
        array = np.ascontiguousarray(array)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": array.nbytes})
        blob.extend(array.tobytes())
        blob.extend(b"\x00" * (-len(blob) % 4))
        entry = {"bufferView": len(views) - 1, "componentType": component,
                 "count": int(array.shape[0]), "type": kind}
        if kind == "VEC3" and component == 5126:
            entry["min"] = array.min(axis=0).tolist()
            entry["max"] = array.max(axis=0).tolist()
        accessors.append(entry)
        return len(accessors) - 1

    for primitive in primitives:
        attributes = {"POSITION": accessor(np.asarray(primitive["positions"], np.float32),
                                           5126, "VEC3")}
        if primitive.get("uv") is not None and primitive.get("uv_normalized"):
            attributes["TEXCOORD_0"] = accessor(
                np.round(np.asarray(primitive["uv"]) * 65535).astype(np.uint16), 5123, "VEC2")
            accessors[-1]["normalized"] = True
        elif primitive.get("uv") is not None:
            attributes["TEXCOORD_0"] = accessor(np.asarray(primitive["uv"], np.float32), 5126,
                                                "VEC2")
        if primitive.get("colours") is not None:
            colours = np.asarray(primitive["colours"], np.float32)
            attributes["COLOR_0"] = accessor(colours, 5126, f"VEC{colours.shape[1]}")
        entry = {"attributes": attributes,
                 "indices": accessor(np.asarray(primitive["indices"], np.uint32), 5125,
                                     "SCALAR")}
        for key in ("material", "mode", "extensions"):
            if key in primitive:
                entry[key] = primitive[key]
        meshes.append({"primitives": [entry]})
    image_entries = []
    for image in images:
        if isinstance(image, bytes):
            views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(image)})
            blob.extend(image)
            blob.extend(b"\x00" * (-len(blob) % 4))
            image_entries.append({"bufferView": len(views) - 1, "mimeType": "image/png"})
        else:
            image_entries.append({"uri": image})
    out = {"asset": {"version": "2.0"}, "scene": 0,
           "nodes": nodes if nodes is not None else [{"mesh": i} for i in range(len(meshes))],
           "meshes": meshes, "accessors": accessors, "bufferViews": views}
    out["scenes"] = [{"nodes": list(range(len(out["nodes"])))}]
    if materials:
        out["materials"] = list(materials)
    if image_entries:
        out["images"] = image_entries
        out["textures"] = textures if textures is not None else [
            {"source": i} for i in range(len(image_entries))]
    if samplers:
        out["samplers"] = list(samplers)
    if extensions:
        out.update(extensions)
    out.update(document or {})
    binary = str(path).endswith(".glb")
    buffer = {"byteLength": len(blob)}
    if buffer_uri is not None:
        (path.parent / buffer_uri).write_bytes(bytes(blob))
        buffer["uri"] = buffer_uri
    elif not binary:
        buffer["uri"] = "data:application/octet-stream;base64," + \
            base64.b64encode(bytes(blob)).decode()
    out["buffers"] = [buffer]
    if not binary:
        path.write_text(json.dumps(out))
        return out
    text = json.dumps(out).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text
    if buffer_uri is None:
        body += struct.pack("<II", len(blob), 0x004E4942) + bytes(blob)
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    return out


def quad(**extra):
    """The camera-facing quad (z = 0, 2 x 2) as a glTF primitive, with texture coordinates."""
    return dict(positions=QUAD, indices=QUAD_FACES.reshape(-1), uv=QUAD_UV_GLTF, **extra)
