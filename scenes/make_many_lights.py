"""Write scenes/many_lights.dae: a room lit by many lights, for choosing lights by power.

    python scenes/make_many_lights.py [--tiles 32] [--lights 8] [--brightest-only] [-o FILE]

A 16 x 3 x 16 m room open toward +Z, where the course's camera rule puts the camera (white
floor and ceiling, three grey walls, four pillars) in the CS184 COLLADA dialect, lit by a
ceiling of tiles x tiles small emissive squares (2 tiles^2 triangles; four
radiances from 0.25 to 2) and lights x lights small area lights under the ceiling whose
radiances span 1 to 64 (a fixed pseudo-random order). Most lights are far from most of the
room, so at a point few of them matter: the case for one light per sample chosen by power
over every light at every vertex. --brightest-only writes the same room lit by its brightest
area light alone (the paths-per-second yardstick). The defaults give 1,024 tiles and 64 lights.
"""
import argparse
import os

import numpy as np

ROOM = 8.0        # half the room's width and depth
HEIGHT = 3.0


def _effect(name, diffuse=None, emission=None):
    if emission is not None:
        return (f'<effect id="{name}-effect"><extra><technique profile="CGL"><emission>'
                f'<radiance>{emission} {emission} {emission}</radiance></emission></technique>'
                f'</extra></effect>')
    r, g, b = diffuse
    return (f'<effect id="{name}-effect"><profile_COMMON><technique sid="common"><lambert>'
            f'<diffuse><color>{r} {g} {b} 1</color></diffuse></lambert></technique>'
            f'</profile_COMMON></effect>')


def _geometry(name, vertices, triangles):
    floats = " ".join(f"{v:.6g}" for v in np.asarray(vertices).ravel())
    indices = " ".join(str(i) for i in np.asarray(triangles).ravel())
    count = len(vertices)
    return (f'<geometry id="{name}" name="{name}"><mesh>'
            f'<source id="{name}-positions"><float_array id="{name}-array" count="{3 * count}">'
            f'{floats}</float_array><technique_common><accessor source="#{name}-array" '
            f'count="{count}" stride="3"><param name="X" type="float"/><param name="Y" '
            f'type="float"/><param name="Z" type="float"/></accessor></technique_common>'
            f'</source><vertices id="{name}-vertices"><input semantic="POSITION" '
            f'source="#{name}-positions"/></vertices><triangles count="{len(triangles)}">'
            f'<input semantic="VERTEX" source="#{name}-vertices" offset="0"/><p>{indices}</p>'
            f'</triangles></mesh></geometry>')


def _quads(corners):
    """Vertices and triangles of quads given as (Q, 4, 3) corners in order around each."""
    corners = np.asarray(corners, dtype=float)
    vertices = corners.reshape(-1, 3)
    base = 4 * np.arange(len(corners))[:, None]
    triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    return vertices, triangles


def _box(lower, upper):
    (x0, y0, z0), (x1, y1, z1) = lower, upper
    return [[(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)],
            [(x0, y0, z1), (x0, y1, z1), (x1, y1, z1), (x1, y0, z1)],
            [(x0, y0, z0), (x0, y1, z0), (x0, y1, z1), (x0, y0, z1)],
            [(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)],
            [(x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)]]


def scene_text(tiles=32, lights=8, brightest_only=False):
    rng = np.random.default_rng(184)
    r, h = ROOM, HEIGHT
    effects = [_effect("floor", (0.7, 0.7, 0.7)), _effect("wall", (0.5, 0.5, 0.55)),
               _effect("pillar", (0.6, 0.45, 0.3))]
    geometries, nodes = [], []

    def add(name, material, corners):
        vertices, triangles = _quads(corners)
        geometries.append(_geometry(name, vertices, triangles))
        nodes.append(f'<node id="{name}-node" name="{name}" type="NODE"><matrix>1 0 0 0 0 1 0 0 '
                     f'0 0 1 0 0 0 0 1</matrix><instance_geometry url="#{name}"><bind_material>'
                     f'<technique_common><instance_material symbol="{material}-material" '
                     f'target="#{material}-material"/></technique_common></bind_material>'
                     f'</instance_geometry></node>')

    add("floor", "floor", [[(-r, 0, -r), (-r, 0, r), (r, 0, r), (r, 0, -r)]])
    add("ceiling", "floor", [[(-r, h, -r), (r, h, -r), (r, h, r), (-r, h, r)]])
    add("walls", "wall", [[(-r, 0, -r), (r, 0, -r), (r, h, -r), (-r, h, -r)],
                          [(-r, 0, -r), (-r, h, -r), (-r, h, r), (-r, 0, r)],
                          [(r, 0, -r), (r, 0, r), (r, h, r), (r, h, -r)]])
    pillars = []
    for x, z in ((-3.5, -3.5), (3.5, -3.5), (-3.5, 3.5), (3.5, 3.5)):
        pillars += _box((x - 0.4, 0, z - 0.4), (x + 0.4, h, z + 0.4))
    add("pillars", "pillar", pillars)
    lights_xml, light_nodes = [], []
    if brightest_only:
        tiles = 0
    radiances = (0.25, 0.5, 1.0, 2.0)
    if tiles:
        size = 2 * r / tiles
        centres = (np.arange(tiles) + 0.5) * size - r
        kind = rng.integers(0, len(radiances), size=(tiles, tiles))
        y = h - 0.01
        for k, radiance in enumerate(radiances):
            effects.append(_effect(f"tile{k}", emission=radiance))
            half = 0.3 * size
            quads = [[(x - half, y, z - half), (x + half, y, z - half), (x + half, y, z + half),
                      (x - half, y, z + half)]
                     for i, x in enumerate(centres) for j, z in enumerate(centres)
                     if kind[i, j] == k]
            add(f"tiles{k}", f"tile{k}", quads)
    centres = (np.arange(lights) + 0.5) * (2 * r / lights) - r
    powers = np.geomspace(1.0, 64.0, lights * lights)[rng.permutation(lights * lights)]
    places = [(x, z) for x in centres for z in centres]
    if brightest_only:
        best = int(np.argmax(powers))
        places, powers = [places[best]], powers[best:best + 1]
    for n, ((x, z), radiance) in enumerate(zip(places, powers)):
        lights_xml.append(f'<light id="light{n}" name="light{n}"><extra><technique profile='
                          f'"CGL"><area><color>{radiance:.4g} {radiance:.4g} {radiance:.4g}'
                          f'</color></area></technique></extra></light>')
        light_nodes.append(f'<node id="light{n}-node" name="light{n}" type="NODE"><matrix>'
                           f'-0.25 0 0 {x:.6g} 0 0 1 {h - 0.1:.6g} 0 0.25 0 {z:.6g} 0 0 0 1'
                           f'</matrix><instance_light url="#light{n}"/></node>')
    materials = [f'<material id="{name}-material"><instance_effect url="#{name}-effect"/>'
                 f'</material>' for name in ["floor", "wall", "pillar"]
                 + [f"tile{k}" for k in range(len(radiances)) if tiles]]
    camera = ('<node id="camera-node" name="camera" type="NODE"><matrix>1 0 0 0 0 1 0 1.5 '
              '0 0 1 7.5 0 0 0 1</matrix><instance_camera url="#camera"/></node>')
    return f"""<?xml version="1.0" encoding="utf-8"?>
<!-- written by scenes/make_many_lights.py: a room lit by {len(places)} area lights and
     {tiles * tiles} emissive ceiling tiles, in the CS184 COLLADA dialect. Y_UP, metres. -->
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="meter" meter="1"/><up_axis>Y_UP</up_axis></asset>
  <library_cameras><camera id="camera" name="camera"><optics><technique_common><perspective>
    <xfov>70</xfov><aspect_ratio>1.333333</aspect_ratio><znear>0.05</znear><zfar>100</zfar>
  </perspective></technique_common></optics></camera></library_cameras>
  <library_lights>
    {chr(10).join(lights_xml)}
  </library_lights>
  <library_effects>
    {chr(10).join(effects)}
  </library_effects>
  <library_materials>
    {chr(10).join(materials)}
  </library_materials>
  <library_geometries>
    {chr(10).join(geometries)}
  </library_geometries>
  <library_visual_scenes><visual_scene id="Scene" name="Scene">
    {camera}
    {chr(10).join(light_nodes)}
    {chr(10).join(nodes)}
  </visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#Scene"/></scene>
</COLLADA>
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiles", type=int, default=32)
    parser.add_argument("--lights", type=int, default=8)
    parser.add_argument("--brightest-only", action="store_true")
    parser.add_argument("-o", "--output", default=os.path.join(os.path.dirname(
        os.path.abspath(__file__)), "many_lights.dae"))
    args = parser.parse_args()
    with open(args.output, "w") as out:
        out.write(scene_text(args.tiles, args.lights, args.brightest_only))
    print(args.output)


if __name__ == "__main__":
    main()
