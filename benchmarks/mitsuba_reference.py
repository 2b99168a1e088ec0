"""Render a course scene with Mitsuba 3 (an independent renderer) as a reference for ptrace.

    pip install mitsuba          # not a ptrace dependency; only this script needs it
    python -m benchmarks.mitsuba_reference [--spp 512]
        [--scene variants_sp23/sky/CBspheres_lambertian.dae]
    python -m benchmarks.mitsuba_reference --pixels all [--spp 16384] [--batches 32]

The scene is mapped from ptrace's loaded Scene, so both renderers see the same numbers:
- each material's triangles -> one OBJ mesh with ptrace's own vertex normals (the area-weighted
  ones of docs/course.md#meshes, so curved meshes shade smoothly in both) and a `twosided` BSDF (the
  course's walls face out of the box and are lit from inside: ptrace is two-sided too);
- CGL spheres -> Mitsuba `sphere` shapes with the same centre and radius;
- BSDFs: diffuse -> `diffuse` (reflectance = albedo); mirror -> `conductor` with `material:
  none` and specular_reflectance = the reflectance (two-sided, like ptrace's opaque surfaces);
  glass -> `dielectric` with int_ior = ior, ext_ior 1, specular_reflectance and
  specular_transmittance (Mitsuba uses the exact Fresnel equations where ptrace, like the course,
  uses Schlick's approximation; both scale transmitted radiance by 1/eta^2). Anything else
  (refraction, microfacet) is refused;
- emissive triangles are refused unless emissive=True (benchmarks.paths_per_second relies on
  the refusal); then each becomes an `area` emitter of the same radiance on a black two-sided
  diffuse mesh (ptrace: f = 0, paths end there) with face normals, plus a copy with reversed
  winding EMITTER_GAP behind it: ptrace's emission is two-sided, Mitsuba's area emitter is not;
- the CGL area light -> a `rectangle` with an `area` emitter of the same radiance, centred at
  the light's centre with half-edges E_x/2, E_y/2 and normal N (one-sided, like ptrace), and a
  `null` BSDF (ptrace's area light is no geometry: rays pass it); the integrator's
  `hide_emitters` keeps emitters out of camera rays, as ptrace does for area lights;
- the course camera (docs/course.md#orbit-camera) -> a `perspective` sensor at the same
  position and target, +Y up, with the same horizontal field of view for the requested window;
- ptrace's -m 5 (direct light at up to 5 vertices) -> Mitsuba max_depth 6 (Mitsuba counts
  segments: max_depth 2 is direct light only), with the `volpath` integrator (no media: on
  surfaces it is Mitsuba's path tracer) because Mitsuba's `path` counts a crossing of the light
  rectangle's `null` BSDF as a bounce: paths that pass the light (to the 1 cm above it, and
  back) lose depth, and a CB scene at max_depth 6 comes out about 0.6 % darker than ptrace's
  -m 5 (measured on CBspheres_lambertian; volpath does not count null interfaces). The library
  function mitsuba_scene keeps `path` by default for its other callers
  (benchmarks.paths_per_second); CBspheres_lambertian_m5_mitsuba.exr was made with `path`;
- a box pixel filter, like ptrace's uniform jitter within the pixel.
Writes tests/references/<scene>_m<depth>_mitsuba.exr and a Markdown note beside it.

--pixels CASE ... (or `all`) makes the small per-pixel references of PIXEL_CASES for
tests/ptrace/test_per_pixel.py instead: the case's scene (pixel_case: built in memory from a
course file, the same way the test builds it), at PIXEL_RESOLUTION through pixel_camera, in
--batches independent Mitsuba renders (seeds 0..K-1) of --spp / K samples each, in the
llvm_ad_rgb variant by default. Per pixel it stores the mean RGB over all samples and the
variance of the mean luminance (0.2126, 0.7152, 0.0722), from the spread of the K batch means
(var over batches, ddof 1, / K: the batch means are near Gaussian, so this needs no
assumption about the heavy-tailed per-sample distribution), as float32 in
tests/references/<case>_m<depth>_pixels.npz (np.savez_compressed), with a note beside it.
--glass schlick maps glass to register_schlick_glass's Python BSDF (ptrace's Schlick Fresnel)
instead of `dielectric` and writes <case>_m<depth>_pixels_schlick.npz: the difference between
the two is what the exact Fresnel equations change.
"""
import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from ptrace.scene import LUMINANCE

from . import report
from .rays import scenes_dir

REFERENCES = Path(__file__).resolve().parents[1] / "tests" / "references"   # test fixtures
EMITTER_GAP = 1e-4     # world units between an emissive triangle and its reversed copy

# per-pixel references: the course's 480x360 view at a fifth of its resolution. (A 96x72
# `resolution` in ptrace would be the central 96x72 crop of the 800x600 view at the course's
# focal length: the back wall between the spheres. pixel_camera keeps the 480x360 framing and
# divides the focal length in pixels by 5; both renderers get that camera.)
PIXEL_VIEW = (480, 360)
PIXEL_SCALE = 5
PIXEL_RESOLUTION = (PIXEL_VIEW[0] // PIXEL_SCALE, PIXEL_VIEW[1] // PIXEL_SCALE)
PIXEL_DEPTH = 5
# case -> (course file, what is changed in memory; see pixel_case)
PIXEL_CASES = {
    "CBspheres_lambertian": ("variants_sp23/sky/CBspheres_lambertian.dae", "as is"),
    "CBbunny": ("sky/CBbunny.dae", "no quad"),
    "CBcoil": ("sky/CBcoil.dae", "no quad"),
    "CBspheres": ("sky/CBspheres.dae", "no quad"),
    "CBspheres_lambertian_quad_light": ("sky/CBspheres_lambertian.dae", "quad as the light"),
}


def without_emissive_primitives(scene):
    """The scene without its emissive triangles and spheres (the sp19 CB files' light quad,
    docs/course.md#light-faces): geometry and material_index lose them; vertices, vertex
    normals (the quad shares no vertex with other faces), materials, lights and camera are kept."""
    from accel import Geometry
    from ptrace.scene import EMISSION
    emissive = scene.materials.kind[scene.material_index] == EMISSION
    geometry = scene.geometry
    faces_kept = ~emissive[:geometry.triangle_count]
    spheres_kept = ~emissive[geometry.triangle_count:]
    kept = Geometry(geometry.vertices, geometry.faces[faces_kept],
                    geometry.centers[spheres_kept], geometry.radii[spheres_kept])
    return dataclasses.replace(scene, geometry=kept,
                               material_index=scene.material_index[~emissive].copy())


def without_lights(scene):
    """The scene with no light sources (scene.lights empty); emissive geometry is kept."""
    from ptrace.scene import Lights
    return dataclasses.replace(scene, lights=Lights.from_records([]))


def pixel_camera(scene):
    """The course camera of the 480x360 view (ptrace.camera.course_camera) at 1/PIXEL_SCALE
    of the resolution: same position, axes and field of view, PIXEL_RESOLUTION pixels."""
    from ptrace.camera import course_camera
    camera = course_camera(scene, *PIXEL_VIEW)
    return dataclasses.replace(camera, width=PIXEL_RESOLUTION[0], height=PIXEL_RESOLUTION[1],
                               screen_dist=camera.screen_dist / PIXEL_SCALE)


def pixel_case(name, root=None):
    """(scene, camera, Mitsuba mapping options) of a per-pixel case, built in memory from the
    course file the same way for ptrace and for Mitsuba:
    - "as is": the file as loaded (variants_sp23 files have no quad);
    - "no quad": the emissive quad dropped (without_emissive_primitives): Mitsuba cannot
      reproduce the sp19 split of a quad that camera and delta-bounce rays see and an area light
      that lights the room; the area light is kept;
    - "quad as the light": the <light> dropped (without_lights) and the quad kept, as a
      two-sided Mitsuba area emitter, visible to camera rays (hide_emitters off), as in ptrace."""
    import ptrace
    path, change = PIXEL_CASES[name]
    scene = ptrace.load(os.path.join(root or scenes_dir(), path))
    options = dict(emissive=False, hide_emitters=True)
    if change == "no quad":
        scene = without_emissive_primitives(scene)
    elif change == "quad as the light":
        scene = without_lights(scene)
        options = dict(emissive=True, hide_emitters=False)
    return scene, pixel_camera(scene), options


def _write_obj(path, vertices, normals, faces):
    """A minimal OBJ: the used vertices (with normals, if given) and 1-based faces."""
    used, inverse = np.unique(faces.reshape(-1), return_inverse=True)
    faces = inverse.reshape(-1, 3) + 1
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices[used].tolist()]
    if normals is not None:
        lines += [f"vn {x!r} {y!r} {z!r}" for x, y, z in normals[used].tolist()]
        lines += [f"f {a}//{a} {b}//{b} {c}//{c}" for a, b, c in faces.tolist()]
    else:
        lines += [f"f {a} {b} {c}" for a, b, c in faces.tolist()]
    Path(path).write_text("\n".join(lines) + "\n")


def mitsuba_bsdf(materials, m):
    """Mitsuba BSDF dict of material m (see the module docstring)."""
    from ptrace.scene import BSDF_NAMES, DIFFUSE, EMISSION, GLASS, MIRROR
    rgb = lambda values: {"type": "rgb", "value": [float(c) for c in values]}
    kind = materials.kind[m]
    if kind == DIFFUSE:
        return {"type": "twosided", "bsdf": {"type": "diffuse",
                                             "reflectance": rgb(materials.albedo[m])}}
    if kind == EMISSION:   # ptrace: f = 0, a path ends on an emitter
        return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": rgb((0, 0, 0))}}
    if kind == MIRROR:
        return {"type": "twosided", "bsdf": {"type": "conductor", "material": "none",
                                             "specular_reflectance": rgb(materials.albedo[m])}}
    if kind == GLASS:
        return {"type": "dielectric", "int_ior": float(materials.ior[m]), "ext_ior": 1.0,
                "specular_reflectance": rgb(materials.albedo[m]),
                "specular_transmittance": rgb(materials.transmittance[m])}
    raise SystemExit(f"material {m} ({BSDF_NAMES[kind]}) is not mapped to Mitsuba: only "
                     "diffuse, mirror, glass and (with emissive=True) emission are")


def register_schlick_glass(mi):
    """Register `schlick_glass`, a Python Mitsuba BSDF that is ptrace's glass (docs/course.md#bsdfs,
    ptrace.bsdf): Schlick's Fresnel R = R0 + (1 - R0)(1 - |cos theta_o|)^5 on the side the ray
    comes from, inside or out, total internal reflection where sin^2 theta_t >= 1; reflect with
    probability R (weight = reflectance), else refract (weight = transmittance / eta^2). Used
    only to measure what Mitsuba's exact-Fresnel `dielectric` changes (--glass schlick)."""
    import drjit as dr

    class SchlickGlass(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.ior = float(props["ior"])
            # an {"type": "rgb"} value arrives as a constant colour
            self.reflectance = [float(c) for c in props["specular_reflectance"]]
            self.transmittance = [float(c) for c in props["specular_transmittance"]]
            both = mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            reflection = mi.BSDFFlags.DeltaReflection | both
            transmission = mi.BSDFFlags.DeltaTransmission | both | mi.BSDFFlags.NonSymmetric
            self.m_components = [reflection, transmission]
            self.m_flags = reflection | transmission

        def sample(self, ctx, si, sample1, sample2, active):
            ior = self.ior
            cos_o = mi.Frame3f.cos_theta(si.wi)
            entering = cos_o > 0
            eta_ratio = dr.select(entering, 1.0 / ior, ior)     # n_incident / n_transmitted
            abs_cos = dr.abs(cos_o)
            sin2_t = eta_ratio * eta_ratio * dr.maximum(0.0, 1.0 - abs_cos * abs_cos)
            cos_t = dr.safe_sqrt(1.0 - sin2_t)
            r0 = ((1.0 - ior) / (1.0 + ior)) ** 2
            fresnel = dr.select(sin2_t >= 1.0, 1.0, r0 + (1.0 - r0) * (1.0 - abs_cos) ** 5)
            reflect = sample1 < fresnel
            bs = dr.zeros(mi.BSDFSample3f)
            transmitted = mi.Vector3f(-eta_ratio * si.wi.x, -eta_ratio * si.wi.y,
                                      dr.select(entering, -cos_t, cos_t))
            bs.wo = dr.select(reflect, mi.reflect(si.wi), transmitted)
            bs.pdf = dr.select(reflect, fresnel, 1.0 - fresnel)
            bs.eta = dr.select(reflect, 1.0, 1.0 / eta_ratio)
            bs.sampled_type = dr.select(reflect, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                                        mi.UInt32(+mi.BSDFFlags.DeltaTransmission))
            bs.sampled_component = dr.select(reflect, mi.UInt32(0), mi.UInt32(1))
            weight = dr.select(reflect, mi.Color3f(*self.reflectance),
                               mi.Color3f(*self.transmittance) * eta_ratio * eta_ratio)
            return bs, dr.select(active & (cos_o != 0), weight, 0.0)

        def eval(self, ctx, si, wo, active):
            return 0.0

        def pdf(self, ctx, si, wo, active):
            return 0.0

        def eval_pdf(self, ctx, si, wo, active):
            return 0.0, 0.0

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"SchlickGlass[ior={self.ior}]"

    mi.register_bsdf("schlick_glass", lambda props: SchlickGlass(props))


def mitsuba_scene(scene, camera, max_depth, spp, seed, workdir, emissive=False,
                  hide_emitters=True, glass="dielectric", integrator="path"):
    """Mitsuba scene dict of a ptrace Scene (see the module docstring). glass="schlick" maps
    glass to register_schlick_glass's BSDF (register it first) instead of `dielectric`;
    integrator "volpath" does not count the light rectangle's null BSDF as a bounce."""
    import mitsuba as mi

    from ptrace.scene import AREA, EMISSION, LIGHT_NAMES
    materials = scene.materials
    used = np.unique(scene.material_index)
    if not emissive and np.any(materials.kind[used] == EMISSION):
        raise SystemExit("emissive materials are mapped to Mitsuba only with emissive=True "
                         "(two-sided area emitters)")
    bsdfs = {int(m): mitsuba_bsdf(materials, m) for m in used}   # refuses unmapped kinds
    if glass == "schlick":
        for m, bsdf in bsdfs.items():
            if bsdf["type"] == "dielectric":
                bsdfs[m] = {"type": "schlick_glass", "ior": bsdf["int_ior"],
                            "specular_reflectance": bsdf["specular_reflectance"],
                            "specular_transmittance": bsdf["specular_transmittance"]}
    description = {
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": max_depth + 1,
                       "hide_emitters": hide_emitters},
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
        if materials.kind[m] != EMISSION:
            _write_obj(path, geometry.vertices, scene.vertex_normals, faces)
            description[f"mesh_{m}"] = {"type": "obj", "filename": path, "bsdf": bsdfs[int(m)]}
            continue
        radiance = {"type": "rgb", "value": materials.emission[m].tolist()}
        _write_obj(path, geometry.vertices, None, faces)
        # the reversed copy, EMITTER_GAP behind each triangle: a ray from either side meets
        # first the copy that emits toward it
        corners = geometry.vertices[faces]
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        back = (corners - EMITTER_GAP * normal[:, None, :])[:, ::-1].reshape(-1, 3)
        back_path = os.path.join(workdir, f"material_{m}_back.obj")
        _write_obj(back_path, back, None, np.arange(len(back)).reshape(-1, 3))
        for key, file in ((f"emitter_{m}", path), (f"emitter_{m}_back", back_path)):
            description[key] = {"type": "obj", "filename": file, "face_normals": True,
                                "bsdf": bsdfs[int(m)],
                                "emitter": {"type": "area", "radiance": radiance}}
    for s in range(geometry.sphere_count):
        m = int(scene.material_index[geometry.triangle_count + s])
        description[f"sphere_{s}"] = {"type": "sphere", "center": geometry.centers[s].tolist(),
                                      "radius": float(geometry.radii[s]), "bsdf": bsdfs[m]}
        if materials.kind[m] == EMISSION:     # (emissive=True was checked above)
            # seen from outside only, so one-sided emission is ptrace's two-sided emission
            radiance = {"type": "rgb", "value": materials.emission[m].tolist()}
            description[f"sphere_{s}"]["emitter"] = {"type": "area", "radiance": radiance}
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


def pixel_reference(name, spp, batches, variant, threads, glass="dielectric"):
    """Render per-pixel case `name` in Mitsuba: (arrays to save, seconds)."""
    import drjit as dr

    from .paths_per_second import import_mitsuba, set_variant
    mi, libllvm, note = import_mitsuba()
    if mi is None:
        raise SystemExit(note)
    problem = set_variant(mi, variant, threads, libllvm)
    if problem:
        raise SystemExit(problem)
    if spp % batches:
        raise SystemExit(f"--spp {spp} is not a multiple of --batches {batches}")
    per_batch = spp // batches
    if glass == "schlick":
        register_schlick_glass(mi)
    scene, camera, options = pixel_case(name)
    with tempfile.TemporaryDirectory() as workdir:
        loaded = mi.load_dict(mitsuba_scene(scene, camera, PIXEL_DEPTH, per_batch, 0, workdir,
                                            glass=glass, integrator="volpath", **options))
    height, width = camera.height, camera.width
    sum_rgb = np.zeros((height, width, 3))
    sum_l, sum_l2 = np.zeros((height, width)), np.zeros((height, width))
    start = time.perf_counter()
    for k in range(batches):
        image = mi.render(loaded, seed=k, spp=per_batch)
        dr.eval(image)
        image = np.array(image, dtype=np.float64)[..., :3]
        sum_rgb += image
        lum = image @ LUMINANCE
        sum_l += lum
        sum_l2 += lum * lum
        print(f"  {name}: batch {k + 1}/{batches}", flush=True, end="\r")
    seconds = time.perf_counter() - start
    mean_l = sum_l / batches
    batch_var = np.maximum(sum_l2 - batches * mean_l ** 2, 0.0) / (batches - 1)
    arrays = dict(
        mean=(sum_rgb / batches).astype(np.float32),          # (H, W, 3), top row first
        var_mean_luminance=(batch_var / batches).astype(np.float32),   # (H, W)
        spp=np.int64(spp), batches=np.int64(batches), max_depth=np.int64(PIXEL_DEPTH),
        scene=np.str_(PIXEL_CASES[name][0]), change=np.str_(PIXEL_CASES[name][1]),
        camera_position=camera.position.astype(np.float64),
        camera_screen_dist=np.float64(camera.screen_dist),
        hide_emitters=np.bool_(options["hide_emitters"]), glass=np.str_(glass),
        integrator=np.str_("volpath"),
        mitsuba=np.str_(f"Mitsuba {mi.__version__} {variant}"))
    return arrays, seconds


def main(argv=None):
    import ptrace
    from ptrace.camera import course_camera
    from ptrace.image import write_image
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="variants_sp23/sky/CBspheres_lambertian.dae")
    parser.add_argument("--spp", type=int, default=None,
                        help="samples per pixel (default 512; with --pixels 16384 in all)")
    parser.add_argument("--max-depth", type=int, default=5, help="ptrace's -m")
    parser.add_argument("--resolution", type=int, nargs=2, default=(480, 360))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--integrator", choices=("volpath", "path"), default="volpath",
                        help="without --pixels (with --pixels: volpath)")
    parser.add_argument("--pixels", nargs="+", metavar="CASE",
                        help=f"per-pixel references instead: 'all' or any of "
                             f"{', '.join(PIXEL_CASES)}")
    parser.add_argument("--batches", type=int, default=32,
                        help="with --pixels: independent renders the spp is split into")
    parser.add_argument("--variant", default="llvm_ad_rgb", help="with --pixels")
    parser.add_argument("--threads", type=int, default=2, help="with --pixels")
    parser.add_argument("--glass", choices=("dielectric", "schlick"), default="dielectric",
                        help="with --pixels: glass as Mitsuba's exact-Fresnel dielectric, or "
                             "as ptrace's Schlick glass (register_schlick_glass; the file "
                             "gets a _schlick suffix)")
    args = parser.parse_args(argv)
    if args.pixels:
        names = list(PIXEL_CASES) if args.pixels == ["all"] else args.pixels
        unknown = [n for n in names if n not in PIXEL_CASES]
        if unknown:
            raise SystemExit(f"unknown cases {unknown}; known: {list(PIXEL_CASES)}")
        spp = args.spp or 16384
        REFERENCES.mkdir(exist_ok=True)
        for name in names:
            arrays, seconds = pixel_reference(name, spp, args.batches, args.variant,
                                              args.threads, args.glass)
            suffix = "_schlick" if args.glass == "schlick" else ""
            output = REFERENCES / f"{name}_m{PIXEL_DEPTH}_pixels{suffix}.npz"
            np.savez_compressed(output, **arrays)
            mean, var = arrays["mean"], arrays["var_mean_luminance"]
            lum = mean.astype(np.float64) @ LUMINANCE
            kept = ~(mean > 1).any(axis=-1)
            w, h = PIXEL_RESOLUTION
            note = (report.header(f"Mitsuba 3 per-pixel reference: {name}")
                    + f"- scene: `{PIXEL_CASES[name][0]}`, {PIXEL_CASES[name][1]} "
                    f"(benchmarks.mitsuba_reference.pixel_case)\n"
                    f"- {arrays['mitsuba']}, `volpath` max_depth {PIXEL_DEPTH + 1} (ptrace -m "
                    f"{PIXEL_DEPTH}), hide_emitters {bool(arrays['hide_emitters'])}, "
                    f"box filter, independent sampler; glass as {args.glass}\n"
                    f"- {w}x{h}: the course's {PIXEL_VIEW[0]}x{PIXEL_VIEW[1]} view at 1/"
                    f"{PIXEL_SCALE} (pixel_camera: focal length "
                    f"{float(arrays['camera_screen_dist']):.1f} px)\n"
                    f"- {spp} spp as {args.batches} renders of {spp // args.batches} spp "
                    f"(seeds 0..{args.batches - 1}), {seconds:.0f} s on {args.threads} "
                    f"threads\n"
                    f"- stored (float32): `mean` (H, W, 3) RGB, top row first; "
                    f"`var_mean_luminance` (H, W), the variance of the pixel's mean luminance "
                    f"from the spread of the batch means\n"
                    f"- mean luminance {lum.mean():.5f}; {int((~kept).sum())} pixels over 1 in "
                    f"a channel; median relative s.d. of a pixel's mean (others) "
                    f"{np.median(np.sqrt(var[kept]) / np.maximum(lum[kept], 1e-12)):.4f}; "
                    f"file {output.stat().st_size / 1024:.0f} KB\n")
            output.with_suffix(".md").write_text(note)
            print(f"wrote {output} ({seconds:.0f} s, {output.stat().st_size / 1024:.0f} KB); "
                  f"mean luminance {lum.mean():.5f}")
        return
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    spp = args.spp or 512
    scene = ptrace.load(os.path.join(scenes_dir(), args.scene))
    camera = course_camera(scene, *args.resolution)
    with tempfile.TemporaryDirectory() as workdir:
        loaded = mi.load_dict(mitsuba_scene(scene, camera, args.max_depth, spp, args.seed,
                                            workdir, integrator=args.integrator))
        start = time.perf_counter()
        image = np.array(mi.render(loaded), dtype=np.float32)
        seconds = time.perf_counter() - start
    name = Path(args.scene).stem
    REFERENCES.mkdir(exist_ok=True)
    output = REFERENCES / f"{name}_m{args.max_depth}_mitsuba.exr"
    write_image(output, image)
    note = (report.header(f"Mitsuba 3 reference: {args.scene}, ptrace -m {args.max_depth}")
            + f"Mitsuba {mi.__version__} (scalar_rgb, `{args.integrator}`), {spp} spp, "
            f"{args.resolution[0]}x{args.resolution[1]}, {seconds:.0f} s. Mapping: see the "
            f"docstring of benchmarks/mitsuba_reference.py.\n")
    output.with_suffix(".md").write_text(note)
    print(f"wrote {output} ({seconds:.0f} s); mean RGB {image.reshape(-1, 3).mean(axis=0)}")


if __name__ == "__main__":
    main()
