"""Write the scenes where path guiding matters, as Mitsuba 3 XML that ptrace and Mitsuba both read:

    guiding_ceiling.xml   a Cornell box whose lamp, a small square below the ceiling, faces up:
                          every surface the camera sees is lit by light off the ceiling
    guiding_door.xml      a closed room lit only through a door left ajar from a lamp in the next
                          room, out of the camera's sight (after Veach's scene)

Each has a glossy variant (*_glossy.xml) whose floor is rough plastic.
Run: python scenes/make_guiding.py (writes beside this file).
"""
from pathlib import Path

HERE = Path(__file__).resolve().parent

WHITE, RED, GREEN = "0.725 0.71 0.68", "0.63 0.065 0.05", "0.14 0.45 0.091"


def bsdfs(glossy):
    floor = ('<bsdf type="roughplastic" id="floor"><float name="alpha" value="0.15"/>'
             f'<rgb name="diffuse_reflectance" value="{WHITE}"/></bsdf>') if glossy else \
        f'<bsdf type="diffuse" id="floor"><rgb name="reflectance" value="{WHITE}"/></bsdf>'
    return "\n".join([
        f'  <bsdf type="diffuse" id="white"><rgb name="reflectance" value="{WHITE}"/></bsdf>',
        f'  <bsdf type="diffuse" id="red"><rgb name="reflectance" value="{RED}"/></bsdf>',
        f'  <bsdf type="diffuse" id="green"><rgb name="reflectance" value="{GREEN}"/></bsdf>',
        # the lamps' emitting fronts reflect nothing: ptrace's never do, Mitsuba's would
        '  <bsdf type="diffuse" id="lamp"><rgb name="reflectance" value="0 0 0"/></bsdf>',
        f"  {floor}"])


def rect(bsdf, transform, emit=None):
    """Mitsuba's rectangle ([-1, 1]^2, normal +z) under `transform` (XML of to_world)."""
    light = (f'<emitter type="area"><rgb name="radiance" value="{emit}"/></emitter>'
             if emit else "")
    return (f'  <shape type="rectangle"><transform name="to_world">{transform}</transform>'
            f'<ref id="{bsdf}"/>{light}</shape>')


def cube(bsdf, transform):
    return (f'  <shape type="cube"><transform name="to_world">{transform}</transform>'
            f'<ref id="{bsdf}"/></shape>')


def header(origin, target, fov, size, depth):
    return f"""<scene version="3.0.0">
  <default name="res" value="{size}"/>
  <integrator type="path"><integer name="max_depth" value="{depth}"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="{fov}"/>
    <transform name="to_world"><lookat origin="{origin}" target="{target}" up="0 1 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
    <film type="hdrfilm"><integer name="width" value="$res"/>
      <integer name="height" value="$res"/></film>
  </sensor>"""


def ceiling(glossy):
    """A Cornell box of [-1, 1]^3, open towards the camera at z = +1; the lamp (0.5 x 0.5 at
    y = 0.9) faces the ceiling, and its back (white) faces down."""
    walls = [
        rect("floor", '<rotate x="1" angle="-90"/><translate y="-1"/>'),
        rect("white", '<rotate x="1" angle="90"/><translate y="1"/>'),
        rect("white", '<translate z="-1"/>'),
        rect("red", '<rotate y="1" angle="90"/><translate x="-1"/>'),
        rect("green", '<rotate y="1" angle="-90"/><translate x="1"/>'),
        rect("lamp", '<scale value="0.25"/><rotate x="1" angle="-90"/><translate y="0.9"/>',
             emit="40 40 40"),
        rect("white", '<scale value="0.25"/><rotate x="1" angle="90"/><translate y="0.899"/>'),
        cube("white", '<scale x="0.3" y="0.6" z="0.3"/><rotate y="1" angle="20"/>'
                      '<translate x="-0.35" y="-0.4" z="-0.3"/>'),
        cube("white", '<scale value="0.3"/><rotate y="1" angle="-17"/>'
                      '<translate x="0.35" y="-0.7" z="0.3"/>'),
    ]
    return "\n".join([header("0 0 3.9", "0 0 0", 39.3, 256, 6), bsdfs(glossy), *walls,
                      "</scene>", ""])


def door(glossy):
    """Two rooms side by side: the camera's, x in [-2, 1], and the lamp's, x in [1, 3], both
    y in [-1, 1] and z in [-1.5, 1.5], parted by a wall at x = 1 with a doorway
    (z in [-0.4, 0.4], y < 0.6) whose door, hinged at z = 0.4, stands ajar by 12 degrees. The
    lamp lights the far room's floor; the camera sees the near room only."""
    w = []
    # the camera's room: floor, ceiling, back wall, left wall, front wall behind the camera
    w.append(rect("floor", '<scale x="1.5" y="1.5"/><rotate x="1" angle="-90"/>'
                           '<translate x="-0.5" y="-1"/>'))
    w.append(rect("white", '<scale x="1.5" y="1.5"/><rotate x="1" angle="90"/>'
                           '<translate x="-0.5" y="1"/>'))
    w.append(rect("white", '<scale x="1.5" y="1"/><translate x="-0.5" z="-1.5"/>'))
    w.append(rect("red", '<scale x="1.5" y="1"/><rotate y="1" angle="90"/>'
                         '<translate x="-2"/>'))
    w.append(rect("white", '<scale x="2.5" y="1"/><rotate y="1" angle="180"/>'
                           '<translate x="0.5" z="1.5"/>'))
    # the parting wall at x = 1, facing both ways (a thin box), around the doorway
    w.append(cube("white", '<scale x="0.02" y="1" z="0.55"/><translate x="1" z="-0.95"/>'))
    w.append(cube("white", '<scale x="0.02" y="1" z="0.55"/><translate x="1" z="0.95"/>'))
    w.append(cube("white", '<scale x="0.02" y="0.2" z="0.4"/><translate x="1" y="0.8"/>'))
    # the door: 0.8 wide, hinged at z = 0.4 on the far room's side, turned 12 degrees open
    w.append(cube("green", '<scale x="0.015" y="0.8" z="0.4"/><translate z="-0.4"/>'
                           '<rotate y="1" angle="-12"/><translate x="1.03" y="-0.2" z="0.4"/>'))
    # the lamp's room: floor, ceiling, far wall, back wall (the near room's front wall goes on)
    w.append(rect("white", '<rotate x="1" angle="-90"/><scale x="1" z="1.5"/>'
                           '<translate x="2" y="-1"/>'))
    w.append(rect("white", '<rotate x="1" angle="90"/><scale x="1" z="1.5"/>'
                           '<translate x="2" y="1"/>'))
    w.append(rect("white", '<scale x="1.5" y="1"/><rotate y="1" angle="-90"/>'
                           '<translate x="3"/>'))
    w.append(rect("white", '<scale x="1" y="1"/><translate x="2" z="-1.5"/>'))
    # the lamp: a small square under the far room's ceiling, facing down
    w.append(rect("lamp", '<scale value="0.2"/><rotate x="1" angle="90"/>'
                           '<translate x="2.3" y="0.98"/>', emit="150 150 150"))
    w.append(rect("white", '<scale value="0.2"/><rotate x="1" angle="-90"/>'
                           '<translate x="2.3" y="0.981"/>'))
    return "\n".join([header("-1.9 0 1.4", "1 -0.2 -0.6", 55, 256, 8), bsdfs(glossy), *w,
                      "</scene>", ""])


def main():
    for name, make in (("guiding_ceiling", ceiling), ("guiding_door", door)):
        for glossy in (False, True):
            path = HERE / f"{name}{'_glossy' if glossy else ''}.xml"
            path.write_text(make(glossy), encoding="utf-8")
            print(path)


if __name__ == "__main__":
    main()
