"""Write the small mesh-file scenes in scenes/files/ that show what ptrace reads of the materials
mesh files carry (docs/usage.md's table "What mesh files' materials become"):

- room.obj + room.mtl + checker.png + glow.png: OBJ and MTL, a map_Kd checker floor, a red Kd
  wall, a Ke light panel with a map_Ke pattern, a Ks/Ns glossy sphere and an Ni/illum 7 glass
  sphere;
- pbr.glb: glTF 2.0 metallic-roughness: a baseColorTexture floor, a metal sphere with a
  metallicRoughnessTexture, an emissive panel with emissiveTexture and
  KHR_materials_emissive_strength, a KHR_materials_transmission + KHR_materials_ior glass
  sphere, and KHR_lights_punctual spot and point lights;
- colours.ply: a sphere with vertex colours.

Run from the repository root: python scenes/make_file_materials.py. trimesh writes the meshes
and the .glb (its exporter does not write the extensions above, so they are added to the JSON
chunk afterwards); OpenImageIO writes the PNGs. Deterministic: the same files every run.
"""
import json
import os
import struct

import numpy as np
import OpenImageIO as oiio
import PIL.Image
import trimesh

HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "files")


def checker(size=64, cells=8, a=(0.9, 0.9, 0.85), b=(0.15, 0.2, 0.45)):
    y, x = np.mgrid[0:size, 0:size] * cells // size
    on = ((x + y) % 2 == 0)[..., None]
    return np.where(on, np.array(a), np.array(b)).astype(np.float32)


def stripes(size=32):
    """Warm light stripes, for an emission texture."""
    y, _ = np.mgrid[0:size, 0:size]
    on = ((y * 4 // size) % 2 == 0)[..., None]
    return np.where(on, np.array([1.0, 0.85, 0.6]), np.array([0.35, 0.3, 0.25])) \
        .astype(np.float32)


def write_png(path, pixels):
    """An 8-bit sRGB PNG of linear pixels (OpenImageIO converts and writes)."""
    buffer = oiio.ImageBuf(np.ascontiguousarray(pixels))
    buffer = oiio.ImageBufAlgo.colorconvert(buffer, "linear", "sRGB")
    buffer.set_write_format(oiio.UINT8)
    if not buffer.write(path):
        raise RuntimeError(buffer.geterror())


def srgb_image(pixels):
    """A PIL image (what trimesh's glTF exporter takes) of linear pixels, sRGB-encoded."""
    buffer = oiio.ImageBufAlgo.colorconvert(oiio.ImageBuf(np.ascontiguousarray(pixels)),
                                            "linear", "sRGB")
    values = buffer.get_pixels(oiio.FLOAT)
    return PIL.Image.fromarray(np.clip(np.round(values * 255), 0, 255).astype(np.uint8))


def quad(corner, edge_u, edge_v):
    """Two triangles with texture coordinates (0, 0) at corner, (1, 1) at the far corner."""
    corner, edge_u, edge_v = map(np.asarray, (corner, edge_u, edge_v))
    vertices = np.array([corner, corner + edge_u, corner + edge_u + edge_v, corner + edge_v])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return vertices, np.array([[0, 1, 2], [0, 2, 3]]), uv


def sphere(centre, radius, subdivisions=2):
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    mesh.apply_translation(centre)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def write_obj():
    write_png(os.path.join(HERE, "checker.png"), checker())
    write_png(os.path.join(HERE, "glow.png"), stripes())
    parts = [  # (material, vertices, faces, uv or None)
        ("floor", *quad((-1.5, 0.0, 1.5), (3.0, 0.0, 0.0), (0.0, 0.0, -3.0))),
        ("wall", *quad((-1.5, 0.0, -1.5), (3.0, 0.0, 0.0), (0.0, 2.0, 0.0))),
        ("light", *quad((-0.5, 1.99, 0.5), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))),
        ("gold", *sphere((-0.6, 0.45, 0.0), 0.45), None),
        ("glass", *sphere((0.6, 0.45, 0.3), 0.45), None),
    ]
    lines, base_v, base_t = ["mtllib room.mtl"], 1, 1
    for name, vertices, faces, uv in parts:
        lines.append(f"o {name}")
        lines += [f"v {x:.6g} {y:.6g} {z:.6g}" for x, y, z in vertices]
        if uv is not None:
            lines += [f"vt {u:.6g} {v:.6g}" for u, v in uv]
        lines.append(f"usemtl {name}")
        for face in faces:
            if uv is not None:
                lines.append("f " + " ".join(f"{base_v + i}/{base_t + i}" for i in face))
            else:
                lines.append("f " + " ".join(str(base_v + i) for i in face))
        base_v += len(vertices)
        base_t += 0 if uv is None else len(uv)
    with open(os.path.join(HERE, "room.obj"), "w") as stream:
        stream.write("\n".join(lines) + "\n")
    mtl = """# written by scenes/make_file_materials.py
newmtl floor
Kd 1 1 1
map_Kd checker.png

newmtl wall
Kd 0.7 0.12 0.1

newmtl light
Ke 6 6 6
map_Ke glow.png

newmtl gold
Kd 0 0 0
Ks 1.0 0.71 0.29
Ns 150

newmtl glass
Ni 1.5
illum 7
"""
    with open(os.path.join(HERE, "room.mtl"), "w") as stream:
        stream.write(mtl)


def textured_mesh(vertices, faces, uv, material):
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    if uv is None:   # spheres: a planar projection (any texture coordinates do for a factor)
        uv = (vertices[:, [0, 1]] - vertices[:, [0, 1]].min(0)) / np.ptp(vertices[:, [0, 1]], 0)
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    return mesh


def write_glb():
    from trimesh.visual.material import PBRMaterial
    # a roughness pattern: smooth (G = 0.1) and rough (G = 0.8) rings, metallic 1 (B)
    y, x = np.mgrid[0:32, 0:32]
    rings = (((x - 16) ** 2 + (y - 16) ** 2) // 40 % 2 == 0)
    roughness = np.zeros((32, 32, 3), np.uint8)
    roughness[..., 1] = np.where(rings, 25, 205)
    roughness[..., 2] = 255
    materials = {
        "floor": PBRMaterial(name="floor", baseColorFactor=[1.0, 1.0, 1.0, 1.0],
                             baseColorTexture=srgb_image(checker(a=(0.8, 0.8, 0.8),
                                                                 b=(0.1, 0.35, 0.15))),
                             metallicFactor=0.0, roughnessFactor=1.0),
        "metal": PBRMaterial(name="metal", baseColorFactor=[0.95, 0.64, 0.54, 1.0],
                             metallicFactor=1.0, roughnessFactor=1.0,
                             metallicRoughnessTexture=PIL.Image.fromarray(roughness)),
        "panel": PBRMaterial(name="panel", emissiveFactor=[1.0, 1.0, 1.0],
                             emissiveTexture=srgb_image(stripes()),
                             baseColorFactor=[0.0, 0.0, 0.0, 1.0], metallicFactor=0.0),
        "glass": PBRMaterial(name="glass", baseColorFactor=[0.9, 1.0, 0.95, 1.0],
                             metallicFactor=0.0, roughnessFactor=0.0),
    }
    scene = trimesh.Scene()
    for name, (vertices, faces, uv) in {
        "floor": quad((-1.5, 0.0, 1.5), (3.0, 0.0, 0.0), (0.0, 0.0, -3.0)),
        "panel": quad((-1.5, 0.3, -1.2), (3.0, 0.0, 0.0), (0.0, 0.4, 0.0)),
        "metal": (*sphere((-0.6, 0.45, 0.0), 0.45), None),
        "glass": (*sphere((0.6, 0.45, 0.3), 0.45), None),
    }.items():
        scene.add_geometry(textured_mesh(vertices, faces, uv, materials[name]), node_name=name,
                           geom_name=name)
    data = scene.export(file_type="glb")
    # the glb's JSON chunk: add the extensions trimesh's exporter does not write
    length, kind = struct.unpack_from("<II", data, 12)
    document = json.loads(data[20:20 + length].decode("utf-8"))
    rest = data[20 + length:]
    for material in document["materials"]:
        if material.get("name") == "glass":
            material["extensions"] = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                                      "KHR_materials_ior": {"ior": 1.5}}
        if material.get("name") == "panel":
            material["extensions"] = {"KHR_materials_emissive_strength":
                                      {"emissiveStrength": 2.0}}
    document.setdefault("extensions", {})["KHR_lights_punctual"] = {"lights": [
        {"type": "spot", "color": [1.0, 0.95, 0.85], "intensity": 12.0,
         "spot": {"innerConeAngle": 0.35, "outerConeAngle": 0.6}},
        {"type": "point", "color": [0.6, 0.7, 1.0], "intensity": 1.5},
    ]}
    nodes = document["nodes"]
    # the spot 2.5 above the floor looking straight down (-Z turned to -Y), a point light
    # behind the camera's side
    down = [-0.7071068, 0.0, 0.0, 0.7071068]     # a quarter turn about +X: -Z becomes -Y
    nodes.append({"name": "spot", "translation": [0.0, 2.5, 0.2], "rotation": down,
                  "extensions": {"KHR_lights_punctual": {"light": 0}}})
    nodes.append({"name": "fill", "translation": [1.2, 1.6, 1.8],
                  "extensions": {"KHR_lights_punctual": {"light": 1}}})
    root = document["scenes"][document.get("scene", 0)]["nodes"]
    world = nodes[root[0]] if len(root) == 1 and "children" in nodes[root[0]] else None
    if world is not None:
        world["children"] += [len(nodes) - 2, len(nodes) - 1]
    else:
        root += [len(nodes) - 2, len(nodes) - 1]
    used = set(document.get("extensionsUsed", []))
    document["extensionsUsed"] = sorted(used | {"KHR_lights_punctual",
                                                "KHR_materials_transmission",
                                                "KHR_materials_ior",
                                                "KHR_materials_emissive_strength"})
    text = json.dumps(document, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + rest
    with open(os.path.join(HERE, "pbr.glb"), "wb") as stream:
        stream.write(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)


def write_ply():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    v = np.asarray(mesh.vertices)
    colours = np.clip(0.5 + 0.5 * v, 0.0, 1.0)        # the position as a colour
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=np.round(
        np.concatenate([colours, np.ones((len(v), 1))], axis=1) * 255).astype(np.uint8))
    floor = trimesh.Trimesh(vertices=[[-3, -1, 3], [3, -1, 3], [3, -1, -3], [-3, -1, -3]],
                            faces=[[0, 1, 2], [0, 2, 3]], process=False)
    floor.visual = trimesh.visual.ColorVisuals(floor, vertex_colors=np.full((4, 4), 200,
                                                                            np.uint8))
    trimesh.util.concatenate([mesh, floor]).export(os.path.join(HERE, "colours.ply"),
                                                  encoding="ascii")


if __name__ == "__main__":
    os.makedirs(HERE, exist_ok=True)
    write_obj()
    write_glb()
    write_ply()
    for name in sorted(os.listdir(HERE)):
        print(f"{os.path.join('scenes', 'files', name)}: "
              f"{os.path.getsize(os.path.join(HERE, name))} bytes")
