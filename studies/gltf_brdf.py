"""Study: glTF's metallic-roughness BRDF as ptrace renders it (material kind gltf_pbr) against
Mitsuba 3's `principled` BSDF, on a grid of spheres under a uniform white environment.

    PYTHONPATH=. python studies/gltf_brdf.py [--size 240] [--spp 64] [--seeds 4]
        [--variant llvm_ad_rgb] [--output gltf_brdf.md]

Run it with a Python that has mitsuba (the main checkout's venv has 3.9.1). It writes a .glb of
3 x 3 spheres (trimesh icospheres of subdivision 5, radius 1, 2.6 apart; metallic 0, 0.5, 1
from left to right, roughness 0.2, 0.5, 0.9 from top to bottom, base colour BASE), loads it
with ptrace (no default light) and lights it by a constant environment of radiance 1. Mitsuba
renders the same triangles with ptrace's vertex normals (OBJ files), each sphere a
`principled` BSDF of the same base colour, metallic and roughness and specular 0.5 (f0 0.04,
the specification's ior 1.5), the same pinhole camera and environment, `path` with max depth
DEPTH + 1 (ptrace's -m DEPTH counts the same paths). Each renderer renders --seeds images of
--spp samples per pixel; per sphere, the mean RGB radiance over the pixels whose centre ray
passes within 0.9 radii of its centre (no silhouette pixels), and its standard error from the
spread over the seeds. Beside them, what the two BRDFs' formulas predict: each sphere pixel
under a uniform white environment is the BRDF's directional albedo E(mu) at its view angle
(one bounce; a convex sphere does not see itself, only a little of its neighbours), computed
by quadrature in numpy from the glTF specification's formulas and from Mitsuba's principled
source (src/bsdfs/principled.cpp, principledhelpers.h: Disney diffuse with retro-reflection,
dielectric Fresnel of eta 1.5, separable Smith G), averaged over the same pixels; the diffuse
and specular parts' shares of it for glTF and for Mitsuba show where the difference comes from.
Writes benchmarks/results/OUTPUT with the tables.
"""
import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

METALLIC = (0.0, 0.5, 1.0)      # columns, left to right
ROUGHNESS = (0.2, 0.5, 0.9)     # rows, top to bottom
BASE = (0.9, 0.6, 0.3)
SPACING, RADIUS, DISTANCE = 2.6, 1.0, 20.0
DEPTH = 7
INNER = 0.9     # pixels whose centre ray passes within INNER radii of a sphere's centre


def centre(row, column):
    return np.array([(column - 1) * SPACING, (1 - row) * SPACING, 0.0])


def write_grid(path):
    """The sphere grid as a .glb of nine meshes, one glTF material each."""
    import trimesh
    from trimesh.visual.material import PBRMaterial
    meshes = []
    for row, roughness in enumerate(ROUGHNESS):
        for column, metallic in enumerate(METALLIC):
            mesh = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
            mesh.apply_translation(centre(row, column))
            mesh.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(
                name=f"m{metallic:g} r{roughness:g}", baseColorFactor=[*BASE, 1.0],
                metallicFactor=metallic, roughnessFactor=roughness))
            meshes.append(mesh)
    trimesh.Scene(meshes).export(path)


def grid_camera(size):
    from ptrace.camera import Camera, look_at
    position, target = np.array([0.0, 0.0, DISTANCE]), np.zeros(3)
    half = SPACING + 1.3 * RADIUS
    screen_dist = 0.5 * size / (half / DISTANCE)
    return Camera(position, target, look_at(position, target), screen_dist, size, size,
                  1e-3, 1e3)


def sphere_masks(camera):
    """{(row, column): (H, W) bool} of the pixels whose centre ray passes within INNER radii of
    that sphere's centre (image rows top first)."""
    size = camera.width
    ys, xs = np.mgrid[0:size, 0:size]
    d = camera.directions(xs + 0.5, (size - 1 - ys) + 0.5)
    masks = {}
    for row in range(len(ROUGHNESS)):
        for column in range(len(METALLIC)):
            to_centre = centre(row, column) - camera.position
            distance = np.linalg.norm(np.cross(d, to_centre), axis=-1)
            masks[row, column] = distance < INNER * RADIUS
    return masks


def ptrace_images(scene, camera, spp, seeds):
    import ptrace
    ptrace.render(scene, camera=camera.resized(8, 8), spp=1, max_depth=DEPTH)   # compile
    images, seconds = [], 0.0
    for seed in range(seeds):
        start = time.perf_counter()
        images.append(ptrace.render(scene, camera=camera, spp=spp, max_depth=DEPTH, seed=seed,
                                     threads=2))
        seconds += time.perf_counter() - start
    return images, seconds


def mitsuba_description(mi, scene, camera, spp, workdir):
    from benchmarks.mitsuba_reference import _write_obj
    from ptrace.scene import GLTF_PBR
    materials, geometry = scene.materials, scene.geometry
    description = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": DEPTH + 1},
        "sensor": {
            "type": "perspective", "fov_axis": "x", "fov": camera.hfov,
            "near_clip": camera.znear, "far_clip": camera.zfar,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=camera.position.tolist(), target=camera.target.tolist(), up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "environment": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0] * 3}},
    }
    for m in np.unique(scene.material_index):
        assert materials.kind[m] == GLTF_PBR, materials.names[m]
        path = os.path.join(workdir, f"material_{m}.obj")
        _write_obj(path, geometry.vertices, scene.vertex_normals,
                   geometry.faces[scene.material_index == m])
        description[f"mesh_{m}"] = {"type": "obj", "filename": path, "bsdf": {
            "type": "principled",
            "base_color": {"type": "rgb", "value": materials.albedo[m].tolist()},
            "metallic": float(materials.metallic[m]),
            "roughness": float(np.sqrt(materials.alpha[m])),
            "specular": 0.5}}
    return description


def mitsuba_images(scene, camera, spp, seeds, variant):
    from benchmarks.paths_per_second import import_mitsuba, set_variant
    mi, libllvm, note = import_mitsuba()
    if mi is None:
        raise SystemExit(note)
    problem = set_variant(mi, variant, 2, libllvm)
    if problem:
        raise SystemExit(problem)
    with tempfile.TemporaryDirectory() as workdir:
        loaded = mi.load_dict(mitsuba_description(mi, scene, camera, spp, workdir))
    mi.render(loaded, seed=1000, spp=1)     # JIT compilation
    images, seconds = [], 0.0
    for seed in range(seeds):
        start = time.perf_counter()
        images.append(np.array(mi.render(loaded, seed=seed, spp=spp)))
        seconds += time.perf_counter() - start
    return images, seconds, f"Mitsuba {mi.__version__} {variant}"


def _half_vector_grid(alpha, n_s=400, n_phi=256):
    """Nodes h (n_s, n_phi, 3) and their weights dwh, graded so that tan theta_h = alpha tan s
    for s uniform in [0, pi/2): the GGX lobe at any alpha and the rest of the hemisphere."""
    s = (np.arange(n_s) + 0.5) / n_s * 0.5 * np.pi
    theta = np.arctan(alpha * np.tan(s))
    dtheta = alpha / np.cos(s) ** 2 / (1 + (alpha * np.tan(s)) ** 2) * (0.5 * np.pi / n_s)
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    h = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    return h, (np.sin(t) * dtheta[:, None]) * (2 * np.pi / n_phi)


def _schlick_weight(c):
    return np.clip(1 - c, 0, 1) ** 5


def _dielectric_fresnel(c, eta):
    """Unpolarised Fresnel reflectance from outside a dielectric of relative ior eta."""
    sin_t2 = (1 - c * c) / eta ** 2
    ct = np.sqrt(np.maximum(0, 1 - sin_t2))
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return np.where(sin_t2 >= 1, 1.0, 0.5 * (rs * rs + rp * rp))


def model_albedo(model, base, metallic, roughness, mu):
    """(diffuse part, specular part) of the directional albedo (RGB, (3,) each) at view cosine
    mu of model "gltf" (the specification's Appendix B) or "mitsuba" (principled, specular 0.5,
    nothing else on)."""
    alpha = max(roughness * roughness, 1e-4)
    base = np.asarray(base, float)
    h, dwh = _half_vector_grid(alpha)
    wo = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
    vh = h @ wo
    wi = 2 * vh[..., None] * h - wo
    ci, co, nh = wi[..., 2], mu, h[..., 2]
    keep = (vh > 0) & (ci > 0)
    weight = np.where(keep, 4 * vh * dwh * ci, 0.0)[..., None]     # dwi cos_i
    ci = np.maximum(ci, 1e-12)
    a2 = alpha * alpha
    d = a2 / (np.pi * (nh * nh * (a2 - 1) + 1) ** 2)
    if model == "gltf":
        vis = 0.5 / (co * np.sqrt(ci * ci * (1 - a2) + a2) + ci * np.sqrt(co * co * (1 - a2) + a2))
        w = _schlick_weight(vh)[..., None]
        f_dielectric = 0.04 + 0.96 * w
        diffuse = (1 - metallic) * (1 - f_dielectric) * base / np.pi
        specular = ((1 - metallic) * f_dielectric + metallic * (base + (1 - base) * w)) * \
            (d * vis)[..., None]
    else:
        g1 = lambda c: 2 * c / (c + np.sqrt(a2 + (1 - a2) * c * c))
        w = _schlick_weight(vh)[..., None]
        fresnel = ((1 - metallic) * _dielectric_fresnel(vh, 1.5)[..., None]
                   + metallic * (base + (1 - base) * w))
        specular = fresnel * (d * g1(co) * g1(ci) / (4 * co * ci))[..., None]
        fo, fi = _schlick_weight(ci), _schlick_weight(co)
        rr = 2 * roughness * vh * vh
        lobe = (1 - 0.5 * fi) * (1 - 0.5 * fo) + rr * (fo + fi + fo * fi * (rr - 1))
        diffuse = (1 - metallic) * base / np.pi * lobe[..., None]
    return ((diffuse * weight).sum(axis=(0, 1)),
            (specular * np.broadcast_to(weight, specular.shape)).sum(axis=(0, 1)))


def predicted_means(camera, masks):
    """{(model, row, column): (diffuse RGB, specular RGB)} averaged over each sphere's pixels:
    E(mu) on a grid of mu, interpolated at each pixel's mu."""
    size = camera.width
    ys, xs = np.mgrid[0:size, 0:size]
    d = camera.directions(xs + 0.5, (size - 1 - ys) + 0.5)
    out = {}
    for (row, column), mask in masks.items():
        o = camera.position - centre(row, column)
        rays = d[mask]
        b = rays @ o
        t = -b - np.sqrt(np.maximum(b * b - (o @ o - RADIUS * RADIUS), 0.0))
        mu = -((o + t[:, None] * rays) / RADIUS * rays).sum(axis=1)
        nodes = np.linspace(mu.min() - 1e-3, 1.0, 16)
        for model in ("gltf", "mitsuba"):
            parts = [model_albedo(model, BASE, METALLIC[column], ROUGHNESS[row], m)
                     for m in nodes]
            out[model, row, column] = tuple(
                np.array([np.interp(mu, nodes, [p[k][c] for p in parts]).mean()
                          for c in range(3)]) for k in (0, 1))
    return out


def sphere_means(images, masks):
    """{(row, column): (mean RGB (3,), standard error of the RGB mean's mean)} over seeds."""
    out = {}
    for key, mask in masks.items():
        per_seed = np.array([image[mask].mean(axis=0) for image in images])   # (seeds, 3)
        grey = per_seed.mean(axis=1)
        out[key] = (per_seed.mean(axis=0),
                    grey.std(ddof=1) / np.sqrt(len(images)) if len(images) > 1 else np.nan)
    return out


def table(ours, theirs, predicted):
    lines = ["| metallic | roughness | ptrace RGB | Mitsuba RGB | ptrace mean | Mitsuba mean "
             "| difference (worst channel) | formulas predict | glTF diffuse + specular | "
             "Mitsuba diffuse + specular |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for row, roughness in enumerate(ROUGHNESS):
        for column, metallic in enumerate(METALLIC):
            (a, sa), (b, sb) = ours[row, column], theirs[row, column]
            diff = a.mean() / b.mean() - 1.0
            worst = (a / b - 1.0)[np.argmax(np.abs(a / b - 1.0))]
            gd, gs = predicted["gltf", row, column]
            md, ms = predicted["mitsuba", row, column]
            expect = (gd + gs).mean() / (md + ms).mean() - 1.0
            rgb = lambda c: " ".join(f"{x:.4f}" for x in c)
            lines.append(f"| {metallic:g} | {roughness:g} | {rgb(a)} | {rgb(b)} | "
                         f"{a.mean():.4f} ± {sa:.4f} | {b.mean():.4f} ± {sb:.4f} | "
                         f"{100 * diff:+.1f} % ({100 * worst:+.1f} %) | {100 * expect:+.1f} % | "
                         f"{gd.mean():.3f} + {gs.mean():.3f} | {md.mean():.3f} + "
                         f"{ms.mean():.3f} |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=240)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--output", default="gltf_brdf.md")
    parser.add_argument("--images", help="folder to save both renders as .npy")
    args = parser.parse_args(argv)
    import ptrace
    from ptrace.environment import Environment
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "spheres.glb")
        write_grid(path)
        scene = ptrace.load(path, default_light=False)
    scene = scene.with_environment(Environment.constant((1.0, 1.0, 1.0)))
    camera = grid_camera(args.size)
    masks = sphere_masks(camera)
    ours, our_seconds = ptrace_images(scene, camera, args.spp, args.seeds)
    theirs, their_seconds, mitsuba = mitsuba_images(scene, camera, args.spp, args.seeds,
                                                    args.variant)
    if args.images:
        os.makedirs(args.images, exist_ok=True)
        np.save(os.path.join(args.images, "ptrace.npy"), np.mean(ours, axis=0))
        np.save(os.path.join(args.images, "mitsuba.npy"), np.mean(theirs, axis=0))
    text = table(sphere_means(ours, masks), sphere_means(theirs, masks),
                 predicted_means(camera, masks))
    pixels = min(int(m.sum()) for m in masks.values())
    command = ("PYTHONPATH=. python studies/gltf_brdf.py " + " ".join(sys.argv[1:])).strip()
    print(text)
    summary = (f"{args.size}x{args.size}, {args.seeds} seeds x {args.spp} spp each, at least "
               f"{pixels} pixels per sphere; ptrace {our_seconds:.0f} s, {mitsuba} "
               f"{their_seconds:.0f} s (render calls, after compilation)")
    print(summary)
    out = ROOT / "benchmarks" / "results" / args.output
    body = out.read_text() if out.exists() else ""
    marker = "<!-- table -->"
    block = f"{marker}\n`{command}`: {summary}.\n\n{text}\n{marker}"
    if body.count(marker) == 2:
        start, end = body.index(marker), body.rindex(marker) + len(marker)
        body = body[:start] + block + body[end:]
    else:
        body = body + ("\n" if body else "") + block + "\n"
    tmp = out.with_suffix(".md.tmp")
    tmp.write_text(body)
    os.replace(tmp, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
