"""Render a course scene with Mitsuba 3 (an independent renderer) as a reference EXR for ptrace.

    pip install mitsuba          # not a ptrace dependency; only this script needs it
    python -m benchmarks.mitsuba_reference [--spp 512] [--scene variants_sp23/sky/CBspheres_lambertian.dae]

The scene is mapped from ptrace's loaded Scene, so both renderers see the same numbers:
- each material's triangles -> one OBJ mesh with face normals and a `twosided` `diffuse` BSDF
  (the course's walls face out of the box and are lit from inside: ptrace is two-sided too);
- CGL spheres -> Mitsuba `sphere` shapes with the same centre and radius, `twosided` `diffuse`;
- the CGL area light -> a `rectangle` with an `area` emitter of the same radiance, centred at
  the light's centre with half-edges E_x/2, E_y/2 and normal N (one-sided, like ptrace), and a
  black BSDF; the integrator's `hide_emitters` keeps it out of camera rays, as ptrace does;
- the course camera (CS184.md 1.7) -> a `perspective` sensor at the same position and target,
  +Y up, with the same horizontal field of view for the requested window;
- ptrace's -m 5 (direct light at up to 5 vertices) -> Mitsuba `path` with max_depth 6 (Mitsuba
  counts segments: max_depth 2 is direct light only);
- a box pixel filter, like ptrace's uniform jitter within the pixel.
Only diffuse materials and area lights are mapped: the script refuses anything else.
Writes benchmarks/references/<scene>_m<depth>_mitsuba.exr and a Markdown note beside it.
"""
import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from . import report
from .accel_rays import scenes_dir

REFERENCES = Path(__file__).resolve().parent / "references"


def mitsuba_scene(scene, camera, max_depth, spp, seed, workdir):
    import mitsuba as mi
    import trimesh
    from ptrace.scene import AREA, DIFFUSE, LIGHT_NAMES
    bsdf = lambda rgb: {"type": "twosided", "bsdf": {
        "type": "diffuse", "reflectance": {"type": "rgb", "value": [float(c) for c in rgb]}}}
    materials = scene.materials
    if not np.all(materials.kind[np.unique(scene.material_index)] == DIFFUSE):
        raise SystemExit("only diffuse materials are mapped to Mitsuba")
    description = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth + 1, "hide_emitters": True},
        "sensor": {
            "type": "perspective", "fov_axis": "x", "fov": camera.hfov,
            "near_clip": camera.znear, "far_clip": camera.zfar,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=camera.position.tolist(), target=camera.target.tolist(), up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
        },
    }
    geometry = scene.geometry
    triangle_materials = scene.material_index[:geometry.triangle_count]
    for m in np.unique(triangle_materials):
        faces = geometry.faces[triangle_materials == m]
        path = os.path.join(workdir, f"material_{m}.obj")
        trimesh.Trimesh(geometry.vertices, faces, process=False).export(path)
        description[f"mesh_{m}"] = {"type": "obj", "filename": path, "face_normals": True,
                                    "bsdf": bsdf(materials.albedo[m])}
    for s in range(geometry.sphere_count):
        m = scene.material_index[geometry.triangle_count + s]
        description[f"sphere_{s}"] = {"type": "sphere", "center": geometry.centers[s].tolist(),
                                      "radius": float(geometry.radii[s]),
                                      "bsdf": bsdf(materials.albedo[m])}
    lights = scene.lights
    for i in range(len(lights)):
        if lights.kind[i] != AREA:
            raise SystemExit(f"only area lights are mapped; found {LIGHT_NAMES[lights.kind[i]]}")
        matrix = np.eye(4)
        matrix[:3, 0] = lights.edge_x[i] / 2
        matrix[:3, 1] = lights.edge_y[i] / 2
        matrix[:3, 2] = lights.direction[i]
        matrix[:3, 3] = lights.position[i]
        description[f"light_{i}"] = {
            "type": "rectangle", "to_world": mi.ScalarTransform4f(matrix.tolist()),
            "bsdf": {"type": "null"},
            "emitter": {"type": "area",
                        "radiance": {"type": "rgb", "value": lights.radiance[i].tolist()}}}
    return description


def main(argv=None):
    import ptrace
    from ptrace.camera import course_camera
    from ptrace.image import write_image
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="variants_sp23/sky/CBspheres_lambertian.dae")
    parser.add_argument("--spp", type=int, default=512)
    parser.add_argument("--max-depth", type=int, default=5, help="ptrace's -m")
    parser.add_argument("--resolution", type=int, nargs=2, default=(480, 360))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    scene = ptrace.load(os.path.join(scenes_dir(), args.scene))
    camera = course_camera(scene, *args.resolution)
    with tempfile.TemporaryDirectory() as workdir:
        loaded = mi.load_dict(mitsuba_scene(scene, camera, args.max_depth, args.spp, args.seed,
                                            workdir))
        start = time.perf_counter()
        image = np.array(mi.render(loaded), dtype=np.float32)
        seconds = time.perf_counter() - start
    name = Path(args.scene).stem
    REFERENCES.mkdir(exist_ok=True)
    output = REFERENCES / f"{name}_m{args.max_depth}_mitsuba.exr"
    write_image(output, image)
    note = (report.header(f"Mitsuba 3 reference: {args.scene}, ptrace -m {args.max_depth}")
            + f"Mitsuba {mi.__version__} (scalar_rgb), {args.spp} spp, "
            f"{args.resolution[0]}x{args.resolution[1]}, {seconds:.0f} s. Mapping: see the "
            f"docstring of benchmarks/mitsuba_reference.py.\n")
    output.with_suffix(".md").write_text(note)
    print(f"wrote {output} ({seconds:.0f} s); mean RGB {image.reshape(-1, 3).mean(axis=0)}")


if __name__ == "__main__":
    main()
