"""Model no more than a scene needs: an analytic sphere against tessellated ones.

    python -m benchmarks.spheres_vs_meshes [--quick]

The shipped Cornell box (scenes/cornell.dae) has one analytic sphere. Each row replaces it by an
icosphere of subdivision level k (20 x 4^k triangles, vertices on the sphere, smooth shading
from ptrace's area-weighted vertex normals, as for any course mesh) and measures, against the
analytic sphere:
- silhouette error: the fraction of pixels whose camera ray hits the sphere in one image and
  not in the other (normal shading, pixel centres, 480x360; no noise);
- image error: relative MSE of a path-traced render (-m 5 -l 4) against a high-sample render of
  the analytic scene, at the same -s and seed for every row (the analytic row gives the noise
  floor);
- cost: BVH build seconds, render seconds (medians), primitives.
Writes benchmarks/results/spheres_vs_meshes.md and spheres_vs_meshes.png.
"""
import argparse
import dataclasses
import os
import statistics
import time

import numpy as np

import accel

from . import report

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(HERE, "scenes", "cornell.dae")


def tessellated(scene, level):
    """The scene with its analytic spheres replaced by icospheres of the given level."""
    import trimesh

    from ptrace.scene import area_weighted_normals
    g = scene.geometry
    n_tri = g.triangle_count
    vertices, faces = [g.vertices], [g.faces]
    materials = [scene.material_index[:n_tri]]
    offset = len(g.vertices)
    for i, (center, radius) in enumerate(zip(g.centers, g.radii)):
        ico = trimesh.creation.icosphere(subdivisions=level, radius=radius)
        vertices.append(np.asarray(ico.vertices) + center)
        faces.append(np.asarray(ico.faces) + offset)
        materials.append(np.full(len(ico.faces), scene.material_index[n_tri + i]))
        offset += len(ico.vertices)
    vertices, faces = np.concatenate(vertices), np.concatenate(faces)
    geometry = accel.Geometry(vertices, faces)
    return dataclasses.replace(scene, geometry=geometry,
                               vertex_normals=area_weighted_normals(vertices, faces),
                               material_index=np.concatenate(materials).astype(np.int32))


def main(argv=None):
    import ptrace
    from ptrace.camera import course_camera
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--output", default="spheres_vs_meshes.md")
    args = parser.parse_args(argv)
    levels = [0, 1, 2, 3] if args.quick else [0, 1, 2, 3, 4, 5, 6]
    resolution, spp, ref_spp, repeats = (((80, 60), 8, 64, 1) if args.quick
                                         else ((160, 120), 16, 512, 3))
    options = {"light_samples": 4, "max_depth": 5, "seed": 3}
    analytic = ptrace.load(SCENE)
    ptrace.render(analytic, spp=1, resolution=(8, 6), max_depth=2)   # compile / cache
    camera = course_camera(analytic, 480, 360)
    start = time.perf_counter()
    reference = ptrace.render(analytic, spp=ref_spp, resolution=resolution, **options)
    reference_seconds = time.perf_counter() - start

    def hits_sphere(scene):
        """Per pixel centre: does the camera ray's first hit belong to the sphere?"""
        backend = accel.build("bvh", scene.geometry)
        ys, xs = np.mgrid[0:360, 0:480]
        directions = camera.directions(xs.reshape(-1) + 0.5, ys.reshape(-1) + 0.5)
        rays = accel.Rays(np.broadcast_to(camera.position, directions.shape), directions,
                          camera.znear, camera.zfar)
        prim = backend.intersect(rays).prim
        n_tri_box = analytic.geometry.triangle_count
        return prim >= n_tri_box   # the sphere, or the icosphere's triangles after the box

    truth = hits_sphere(analytic)
    rows, points = [], []
    for level in [None] + levels:
        scene = analytic if level is None else tessellated(analytic, level)
        walls = []
        builds = []
        for _ in range(repeats):
            stats = {}
            start = time.perf_counter()
            image = ptrace.render(scene, spp=spp, resolution=resolution, stats=stats, **options)
            walls.append(time.perf_counter() - start)
            builds.append(stats["build_seconds"])
        wall, build = statistics.median(walls), statistics.median(builds)
        rel_mse = float(np.mean((image - reference) ** 2 / (reference ** 2 + 1e-2)))
        silhouette = float(np.mean(hits_sphere(scene) != truth))
        name = "analytic sphere" if level is None else f"icosphere level {level}"
        extra = scene.geometry.triangle_count - analytic.geometry.triangle_count
        prims = "1 sphere" if level is None else f"{extra:,} triangles"
        rows.append(f"| {name} | {prims} | {build * 1e3:.2f} | {wall:.2f} | "
                    f"{silhouette * 100:.3f} | {rel_mse:.5f} |")
        points.append((level, extra, wall, silhouette, rel_mse))
        print(rows[-1], flush=True)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    mesh = [p for p in points if p[0] is not None]
    tris = [p[1] for p in mesh]
    left.loglog(tris, [max(p[3], 1e-6) for p in mesh], "o-", label="icosphere: silhouette error")
    left.loglog(tris, [p[4] for p in mesh], "s-", label="icosphere: image relative MSE")
    left.axhline(points[0][4], color="k", ls="--", label="analytic: image relative MSE (noise)")
    left.set_xlabel("triangles in the sphere")
    left.set_ylabel("error")
    left.legend(fontsize=8)
    right.semilogx(tris, [p[2] for p in mesh], "o-", label="icosphere")
    right.axhline(points[0][2], color="k", ls="--", label="analytic sphere")
    right.set_xlabel("triangles in the sphere")
    right.set_ylabel(f"render seconds ({resolution[0]}x{resolution[1]}, -s {spp})")
    right.legend(fontsize=8)
    fig.tight_layout()
    chart = report.RESULTS / "spheres_vs_meshes.png"
    fig.savefig(chart, dpi=100)
    lines = [report.header("Analytic sphere against tessellated spheres"),
             f"Scene scenes/cornell.dae; path -m {options['max_depth']} -l "
             f"{options['light_samples']}, {resolution[0]}x{resolution[1]} at -s {spp}, seed "
             f"{options['seed']}, bvh, medians of {repeats}; reference: the analytic scene at "
             f"-s {ref_spp} ({reference_seconds:.1f} s). Silhouette error on 480x360 pixel "
             "centres. Relative MSE = mean over pixels and channels of (x - ref)^2 / "
             "(ref^2 + 0.01).", "",
             "| sphere | primitives | build ms | render s | silhouette error % | relative MSE |",
             "|---|---|---:|---:|---:|---:|", *rows, "",
             "![error and time against tessellation](spheres_vs_meshes.png)", ""]
    path = report.write(args.output, "\n".join(lines))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
