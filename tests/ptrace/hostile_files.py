"""Small files that describe large scenes, written on demand (tests and the hostile-inputs
report): a glTF binary that places one mesh many times, a course COLLADA file that instances
one geometry many times, a PNG whose header declares many texels in a file of a few KB."""
import json
import struct
import zlib

import numpy as np

from console import SHIPPED


def glb_instancing(path, instances, quads=1, image=None, metallic=0.0):
    """A .glb whose scene has `instances` nodes, each placing the same mesh: a row of `quads`
    quads (2 triangles each) with texture coordinates; image (PNG bytes) becomes its base
    colour texture (in the binary chunk)."""
    xs = np.arange(quads + 1, dtype=np.float32)
    positions = np.concatenate([np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], 1),
                                np.stack([xs, np.ones_like(xs), np.zeros_like(xs)], 1)])
    uv = np.concatenate([np.stack([xs / quads, np.ones_like(xs)], 1),
                         np.stack([xs / quads, np.zeros_like(xs)], 1)]).astype(np.float32)
    top = np.arange(quads, dtype=np.uint32)
    bottom = top + quads + 1
    indices = np.stack([top, top + 1, bottom + 1, top, bottom + 1, bottom], 1).reshape(-1)
    blobs = [positions.tobytes(), uv.tobytes(), indices.astype(np.uint32).tobytes()]
    if image is not None:
        blobs.append(image)
    views, offset = [], 0
    for blob in blobs:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(blob)})
        offset += len(blob) + (-len(blob) % 4)
    binary = b"".join(b + b"\x00" * (-len(b) % 4) for b in blobs)
    material = {"pbrMetallicRoughness": {"metallicFactor": metallic, "roughnessFactor": 1.0}}
    document = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": views,
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(positions), "type": "VEC3",
             "min": positions.min(0).tolist(), "max": positions.max(0).tolist()},
            {"bufferView": 1, "componentType": 5126, "count": len(uv), "type": "VEC2"},
            {"bufferView": 2, "componentType": 5125, "count": len(indices), "type": "SCALAR"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1},
                                    "indices": 2, "material": 0}]}],
        "materials": [material],
        "nodes": [{"mesh": 0, "translation": [0.0, 0.0, -0.01 * i]} for i in range(instances)],
        "scenes": [{"nodes": list(range(instances))}],
        "scene": 0,
    }
    if image is not None:
        document["images"] = [{"bufferView": 3, "mimeType": "image/png"}]
        document["textures"] = [{"source": 0}]
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + \
        struct.pack("<II", len(binary), 0x004E4942) + binary
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    return path


def png(width, height, channels=3, bit_depth=8, value=0):
    """The bytes of a valid PNG of width x height (grey if channels is 1, else RGB), every
    pixel `value`: rows of one value compress about a thousandfold, so a huge image is a
    small file."""
    kind = {1: 0, 3: 2}[channels]
    row = b"\x00" + bytes([value]) * ((width * channels * bit_depth + 7) // 8)
    compressor = zlib.compressobj(9)
    data = b"".join(compressor.compress(row) for _ in range(height)) + compressor.flush()

    def chunk(tag, payload):
        return struct.pack(">I", len(payload)) + tag + payload + \
            struct.pack(">I", zlib.crc32(tag + payload))
    header = struct.pack(">IIBBBBB", width, height, bit_depth, kind, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", data) + \
        chunk(b"IEND", b"")


def obj_with_map(folder, image_bytes, field="map_Kd"):
    """scene.obj: one textured quad whose material's `field` is big.png (image_bytes)."""
    (folder / "big.png").write_bytes(image_bytes)
    emitter = "Ke 1 1 1\n" if field == "map_Ke" else ""
    (folder / "scene.mtl").write_text(f"newmtl m\nKd 1 1 1\n{emitter}{field} big.png\n")
    path = folder / "scene.obj"
    path.write_text("mtllib scene.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    return path


BLOCK_NODE = ('<node id="copy{i}" name="copy{i}" type="NODE"><matrix>1 0 0 0 0 1 0 0 0 0 1 '
              '0 0 0 0 1</matrix><instance_geometry url="#block"><bind_material>'
              '<technique_common><instance_material symbol="block-material" '
              'target="#block-material"/></technique_common></bind_material>'
              '</instance_geometry></node>')


def dae_instancing(path, copies, instance_node=False):
    """The shipped Cornell box with `copies` more nodes: each instances its 12-triangle block
    (the course's dialect), or with instance_node each instances the block's node (generic
    COLLADA, which the course's reader refuses)."""
    text = SHIPPED.read_text()
    node = '<node id="ref{i}" type="NODE"><instance_node url="#block-node"/></node>' \
        if instance_node else BLOCK_NODE
    nodes = "".join(node.format(i=i) for i in range(copies))
    path.write_text(text.replace("</visual_scene>", nodes + "</visual_scene>"))
    return path
