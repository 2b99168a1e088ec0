"""A glTF sampler's wrapS and wrapT become the texture's u and v wrap modes (glTF's codes 10497
REPEAT, 33071 CLAMP_TO_EDGE, 33648 MIRRORED_REPEAT), each on its own axis: a tiny glTF written
here, one triangle with a base colour texture per sampler."""
import base64
import json

import numpy as np
import OpenImageIO as oiio
import pytest

import ptrace
from ptrace.scene import CLAMP, MIRROR_REPEAT, REPEAT

CODES = {REPEAT: 10497, CLAMP: 33071, MIRROR_REPEAT: 33648}


def tiny_gltf(folder, samplers):
    """One triangle per sampler, each with a material whose base colour texture uses it."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    uvs = np.array([[0, 0], [1, 0], [0, 1]], np.float32)
    data = positions.tobytes() + uvs.tobytes()
    n = len(samplers)
    document = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": list(range(n))}],
        "nodes": [{"mesh": i, "translation": [2.0 * i, 0, 0]} for i in range(n)],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1},
                                    "material": i}]} for i in range(n)],
        "materials": [{"name": f"m{i}", "pbrMetallicRoughness": {
            "baseColorTexture": {"index": i}, "metallicFactor": 0.0}} for i in range(n)],
        "textures": [{"sampler": i, "source": i} for i in range(n)],
        "images": [{"uri": f"texture{i}.png"} for i in range(n)],
        "samplers": samplers,
        "buffers": [{"byteLength": len(data), "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(data).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                        {"buffer": 0, "byteOffset": 36, "byteLength": 24}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}],
    }
    rng = np.random.default_rng(0)
    for i in range(n):   # distinct pixels, so that no two textures are pooled as one
        path = str(folder / f"texture{i}.png")
        output = oiio.ImageOutput.create(path)
        assert output.open(path, oiio.ImageSpec(4, 4, 3, oiio.UINT8))
        assert output.write_image(rng.integers(0, 256, (4, 4, 3)).astype(np.uint8))
        output.close()
    path = folder / "wraps.gltf"
    path.write_text(json.dumps(document))
    return path


@pytest.mark.parametrize("u_wrap, v_wrap", [(CLAMP, MIRROR_REPEAT), (MIRROR_REPEAT, CLAMP),
                                            (REPEAT, CLAMP), (CLAMP, REPEAT)])
def test_a_samplers_wrap_s_and_t_become_the_textures_u_and_v_wrap(tmp_path, u_wrap, v_wrap):
    path = tiny_gltf(tmp_path, [{"wrapS": CODES[u_wrap], "wrapT": CODES[v_wrap]}])
    scene = ptrace.load(path)
    assert len(scene.textures.names) == 1, scene.notes
    assert tuple(scene.textures.wrap[0]) == (u_wrap, v_wrap)


def test_each_texture_keeps_its_own_samplers_wrap_and_a_missing_one_repeats(tmp_path):
    samplers = [{"wrapS": CODES[CLAMP], "wrapT": CODES[MIRROR_REPEAT]}, {},
                {"wrapT": CODES[CLAMP]}]
    scene = ptrace.load(tiny_gltf(tmp_path, samplers))
    wraps = {name.split()[0]: tuple(int(w) for w in wrap)
             for name, wrap in zip(scene.textures.names, scene.textures.wrap)}
    assert wraps == {"m0": (CLAMP, MIRROR_REPEAT), "m1": (REPEAT, REPEAT),
                     "m2": (REPEAT, CLAMP)}, scene.notes
