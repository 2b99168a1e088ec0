"""Error against time, as a user would compare: ptrace's estimators and Mitsuba 3 on full frames.

    python -m benchmarks.error_vs_time [--quick] [--scenes CBspheres_lambertian CBbunny ...]

Scenes: the course's CBspheres_lambertian, CBbunny and CBspheres (mirror and glass) at -m 5, the
whole 480x360 frame, 2 threads. Each is rendered WITHOUT its emissive quad, by both renderers
(benchmarks.mitsuba_reference.without_emissive_primitives: the quad is the <light>'s visible
face in ptrace, which Mitsuba cannot reproduce; docs/course.md#light-faces), so both see one
scene: the <light> as a one-sided area light hidden from camera rays. Mapping:
benchmarks.mitsuba_reference.mitsuba_scene with ptrace's Schlick glass (register_schlick_glass;
Mitsuba's `dielectric` has the exact Fresnel equations). The timed Mitsuba curves use its `path`
integrator (its standard one, the issue's), the references `volpath`: `path` counts crossing
the light's null-BSDF rectangle as a bounce, 0.6 % dark at -m 5, a bias far below these
curves' noise (a relative MSE near 4e-5), while volpath is about half as fast here.

Reference per scene: Mitsuba 3 llvm_ad_rgb at REFERENCE_SPP samples per pixel (made once, kept
in benchmarks/.cache/, which git ignores; the report gives its mean). Relative MSE = mean over
pixels whose reference is at most 1 in every channel (directly seen lights are left out) of
(x - ref)^2 / (ref^2 + 0.01), as the issue measured it.

Curves (points at doubling -s; seconds = wall time of the render call, compiled kernels, BVH
build included; Mitsuba's = its render call after an untimed JIT warm-up):
- ptrace with multiple importance sampling or light sampling alone (--direct), with the Sobol'
  or the independent sampler (--sampler), -l 1 / 4 / 16, three roulette rules (ptrace's default,
  Mitsuba's: from vertex 5, continue with min(0.95, max throughput); ptrace's rule before: the
  same from vertex 2; pbrt-v4's: from vertex 2, min(1, max throughput)) and roulette off, the
  embree backend; and, as a separate biased estimator, the default's image denoised by Intel Open
  Image Denoise (pyoidn) with the albedo and normal AOVs as its guides;
- Mitsuba 3 llvm_ad_rgb's `path` integrator with its independent and multijitter samplers.

Measuring (measure(): plain data, written as error_vs_time.json) is apart from writing
(write_report(): the Markdown from a template with named fields, and one chart per scene).
"""
import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from ptrace.scene import LUMINANCE

from . import report
from .rays import scenes_dir

SCENES = {"CBspheres_lambertian": "sky/CBspheres_lambertian.dae",
          "CBbunny": "sky/CBbunny.dae",
          "CBspheres": "sky/CBspheres.dae"}
FULL = (480, 360)
DEPTH = 5
THREADS = 2
REFERENCE_SPP = 1024   # volpath at 0.7 M paths/s here: 4 min a scene (4096 would be 17)
CACHE = Path(__file__).resolve().parent / ".cache"
DEFAULT = "ptrace mis sobol (default)"
DENOISED = "ptrace mis sobol + Open Image Denoise (biased)"
PTRACE_METHODS = {
    DEFAULT: {},
    "ptrace mis independent": dict(sampler="independent"),
    "ptrace light sobol": dict(direct="light"),
    "ptrace light independent (the course's estimator)": dict(direct="light",
                                                              sampler="independent"),
    "ptrace -l 4": dict(light_samples=4),
    "ptrace -l 16": dict(light_samples=16),
    "roulette from vertex 2 (ptrace's rule before)": dict(rr_depth=2),
    "roulette from vertex 2, uncapped (pbrt-v4's rule)": dict(rr_depth=2, rr_cap=1.0),
    "roulette off": dict(roulette=False),
    "ptrace embree": dict(accel="embree"),
    # a separate, biased estimator: the default's image denoised by Open Image Denoise with the
    # albedo and normal AOVs as guides (their extra ray per sample and the denoiser timed too)
    DENOISED: dict(denoise=True),
}
MITSUBA_SAMPLERS = ("independent", "multijitter")
MITSUBA_VARIANT = "llvm_ad_rgb"


def relative_mse(image, reference):
    """Mean of (x - ref)^2 / (ref^2 + 0.01) over the pixels whose reference is <= 1."""
    mask = reference.max(axis=-1) <= 1.0
    error = ((image - reference) ** 2 / (reference ** 2 + 1e-2)).mean(axis=-1)
    return float(error[mask].mean())


def test_scene(name):
    """The loaded course scene without its emissive quad: what both renderers render."""
    import ptrace

    from .mitsuba_reference import without_emissive_primitives
    return without_emissive_primitives(ptrace.load(os.path.join(scenes_dir(), SCENES[name])))


class Mitsuba:
    """Mitsuba 3 renders of a ptrace scene in one variant (None if it cannot run here)."""

    def __init__(self, variant=MITSUBA_VARIANT, threads=THREADS):
        from .paths_per_second import import_mitsuba, set_variant
        self.mi, libllvm, note = import_mitsuba()
        self.note = note or (set_variant(self.mi, variant, threads, libllvm)
                             if self.mi is not None else None)
        self.variant = variant
        self.schlick = False

    @property
    def available(self):
        return self.mi is not None and self.note is None

    def render(self, scene, spp, sampler="independent", seed=0, repeats=1, integrator="path",
               **mapping):
        """(image, seconds of the fastest of `repeats` timed renders, actual spp)."""
        import drjit as dr

        from ptrace.camera import course_camera

        from .mitsuba_reference import mitsuba_scene, register_schlick_glass
        mi = self.mi
        if not self.schlick:
            register_schlick_glass(mi)
            self.schlick = True
        with tempfile.TemporaryDirectory() as workdir:
            # Schlick glass: ptrace's (and the course's) Fresnel
            description = mitsuba_scene(scene, course_camera(scene, *FULL), DEPTH, spp, seed,
                                        workdir, glass="schlick", integrator=integrator,
                                        **mapping)
            description["sensor"]["sampler"]["type"] = sampler
            loaded = mi.load_dict(description)
        actual = loaded.sensors()[0].sampler().sample_count()

        def once(s):
            image = mi.render(loaded, seed=s)
            dr.eval(image)
            dr.sync_thread()
            return image

        once(seed + 1000)          # JIT compilation, untimed
        best, image = float("inf"), None
        for r in range(repeats):
            start = time.perf_counter()
            image = once(seed + r)
            best = min(best, time.perf_counter() - start)
        return np.array(image, dtype=np.float32)[..., :3], best, actual


def reference(name, mitsuba, spp, scene=None, **mapping):
    """The scene's Mitsuba reference image, made once and cached (`scene`: what `name` names,
    when it is not one of SCENES; `mapping`: mitsuba_scene's emissive and hide_emitters)."""
    from ptrace.image import read_image, write_image
    path = CACHE / f"{name}_m{DEPTH}_{mitsuba.variant}_{spp}spp.exr"
    if path.exists():
        return read_image(path)[..., :3], path
    CACHE.mkdir(exist_ok=True)
    print(f"{name}: rendering the {spp}-spp Mitsuba reference ...", flush=True)
    # volpath: Mitsuba's path integrator counts crossing the light rectangle's null BSDF as a
    # bounce, which leaves it 0.6 % dark at this depth (benchmarks/mitsuba_reference.py)
    image, seconds, _ = mitsuba.render(test_scene(name) if scene is None else scene, spp,
                                       seed=12345, integrator="volpath", **mapping)
    write_image(path, image)
    print(f"{name}: reference in {seconds:.0f} s -> {path}", flush=True)
    return image, path


def denoised_render(**options):
    """ptrace.render with the AOVs, then Open Image Denoise guided by them."""
    import ptrace
    from ptrace.features import denoise
    aovs = {}
    image = ptrace.render(aovs=aovs, **options)
    return denoise(image, aovs["albedo"], aovs["normal"])


def measure_scene(name, mitsuba, spps, repeats, reference_spp):
    """{method: [point, ...]} for one scene; a point is {spp, seconds, rel_mse, luminance}."""
    import ptrace
    ref, ref_path = reference(name, mitsuba, reference_spp)
    scene = test_scene(name)
    curves = {}

    def point(spp, seconds, image):
        return {"spp": int(spp), "seconds": seconds, "rel_mse": relative_mse(image, ref),
                "luminance": float((image @ LUMINANCE).mean())}

    for label, options in PTRACE_METHODS.items():
        options = dict(options)
        denoised = options.pop("denoise", False)
        render = lambda **kw: denoised_render(**kw) if denoised else ptrace.render(**kw)  # noqa: E731
        render(scene=scene, spp=1, resolution=(8, 6), max_depth=DEPTH, **options)   # compile
        points = []
        for spp in (spps if options.get("light_samples", 1) < 16 else spps[:-1] or spps):
            best, image = float("inf"), None
            for r in range(repeats):
                start = time.perf_counter()
                image = render(scene=scene, spp=spp, resolution=FULL, max_depth=DEPTH,
                               threads=THREADS, seed=r, **options)
                best = min(best, time.perf_counter() - start)
            points.append(point(spp, best, image))
            print(name, label, points[-1], flush=True)
        curves[label] = points
    for sampler in MITSUBA_SAMPLERS:
        label = f"Mitsuba {mitsuba.variant} {sampler}"
        points = []
        for spp in spps:
            image, seconds, actual = mitsuba.render(scene, spp, sampler=sampler,
                                                    repeats=repeats)
            points.append(point(actual, seconds, image))
            print(name, label, points[-1], flush=True)
        curves[label] = points
    return {"scene": SCENES[name], "reference": {
        "file": str(ref_path.relative_to(Path(__file__).resolve().parents[1])),
        "spp": reference_spp, "variant": mitsuba.variant,
        "luminance": float((ref @ LUMINANCE).mean()),
        "masked_fraction": float((ref.max(axis=-1) > 1.0).mean())}, "curves": curves}


def measure(names, spps, repeats, reference_spp=REFERENCE_SPP):
    """Everything the report says, as plain data."""
    mitsuba = Mitsuba()
    if not mitsuba.available:
        raise SystemExit(f"error_vs_time needs Mitsuba 3 {MITSUBA_VARIANT}: {mitsuba.note}")
    return {"resolution": list(FULL), "max_depth": DEPTH, "threads": THREADS,
            "spp": list(spps), "repeats": repeats, "mitsuba": mitsuba.mi.__version__,
            "reference_spp": reference_spp,
            "scenes": {name: measure_scene(name, mitsuba, spps, repeats, reference_spp)
                       for name in names}}


# -- what the numbers say --------------------------------------------------------------------------

def at_spp(points, spp):
    return next((p for p in points if p["spp"] == spp), None)


def efficiency(points):
    """Lowest relative MSE x seconds along a curve (lower is better)."""
    return min(p["rel_mse"] * p["seconds"] for p in points)


def target_spp(data):
    """The -s the targets compare at: 16, or the largest measured."""
    return 16 if 16 in data["spp"] else max(data["spp"])


def targets(data):
    """The issue's targets per scene: rows of named values."""
    spp = target_spp(data)
    rows = []
    for name, result in data["scenes"].items():
        curves = result["curves"]
        independent = f"Mitsuba {MITSUBA_VARIANT} independent"
        multijitter = f"Mitsuba {MITSUBA_VARIANT} multijitter"
        ours = at_spp(curves[DEFAULT], spp)
        ours_independent = at_spp(curves["ptrace mis independent"], spp)
        theirs = at_spp(curves[independent], spp)
        theirs_mj = at_spp(curves[multijitter], spp)
        rows.append({
            "scene": name,
            "ptrace_mse": ours["rel_mse"], "ptrace_independent_mse": ours_independent["rel_mse"],
            "mitsuba_independent_mse": theirs["rel_mse"] if theirs else None,
            "mitsuba_multijitter_mse": theirs_mj["rel_mse"] if theirs_mj else None,
            "ptrace_efficiency": efficiency(curves[DEFAULT]),
            "ptrace_independent_efficiency": efficiency(curves["ptrace mis independent"]),
            "mitsuba_independent_efficiency": efficiency(curves[independent]),
            "mitsuba_multijitter_efficiency": efficiency(curves[multijitter]),
            "luminance_ratio": ours["luminance"] / result["reference"]["luminance"],
        })
    return rows


def roulette_rules(data):
    """Efficiency of each roulette rule relative to ptrace's default, per scene."""
    labels = [DEFAULT, "roulette from vertex 2 (ptrace's rule before)",
              "roulette from vertex 2, uncapped (pbrt-v4's rule)", "roulette off"]
    return {name: {label: efficiency(result["curves"][label]) for label in labels}
            for name, result in data["scenes"].items()}


# -- writing ---------------------------------------------------------------------------------------

TEMPLATE = """{header}Full {width}x{height} frames at ptrace's -m {depth} \
(Mitsuba max_depth {mitsuba_depth}), {threads} threads, \
each scene without its emissive quad in both renderers (see the module docstring). Reference: \
Mitsuba {mitsuba} {variant} at {reference_spp} spp per scene. Relative MSE leaves out pixels whose \
reference exceeds 1 (directly seen lights). Seconds: the fastest of {repeats} render call(s) \
(ptrace: kernels compiled, BVH build included; Mitsuba: after an untimed JIT render).

## Targets (at {target_spp} samples per pixel; efficiency = lowest relative MSE x seconds \
on the curve)

| scene | ptrace rel. MSE (mis, sobol) | Mitsuba multijitter | ptrace (mis, independent) \
| Mitsuba independent | ptrace efficiency | Mitsuba multijitter efficiency \
| Mitsuba independent efficiency | ptrace mean / reference |
|---|---:|---:|---:|---:|---:|---:|---:|---:|
{target_rows}

## Roulette rules (efficiency, lower is better; ratio to ptrace's rule)

| scene | {roulette_header} |
|---|{roulette_align}
{roulette_rows}

{roulette_verdict}

## Denoised (a separate, biased estimator)

The default estimator's image denoised by Intel Open Image Denoise (`--denoise`: its RT filter, \
HDR, guided by the albedo and normal AOVs; their extra ray per sample and the denoiser's own time \
are in its seconds). Its error does not go to zero with samples: it keeps the denoiser's bias.

| scene | -s | default rel. MSE | denoised rel. MSE | default seconds | denoised seconds \
| denoised efficiency / default's |
|---|---:|---:|---:|---:|---:|---:|
{denoise_rows}

## Every point

| scene | method | -s | seconds | relative MSE | MSE x s | mean luminance |
|---|---|---:|---:|---:|---:|---:|
{point_rows}

{charts}
"""


def _roulette_section(data):
    rules = roulette_rules(data)
    labels = list(next(iter(rules.values())))
    rows = []
    for name, values in rules.items():
        base = values[DEFAULT]
        rows.append(f"| {name} | " + " | ".join(
            f"{values[label]:.4f} ({values[label] / base:.2f}x)" for label in labels) + " |")
    geometric = {label: float(np.exp(np.mean([np.log(v[label] / v[DEFAULT])
                                              for v in rules.values()]))) for label in labels}
    best = min(geometric, key=geometric.get)
    verdict = ("Geometric mean over the scenes, relative to ptrace's rule: " + "; ".join(
        f"{label} {value:.2f}x" for label, value in geometric.items())
        + f". Most efficient: {best}.")
    return labels, rows, verdict


def write_report(data, output="error_vs_time.md"):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    charts = []
    for name, result in data["scenes"].items():
        fig, axis = plt.subplots(figsize=(7.5, 5))
        for label, points in result["curves"].items():
            axis.loglog([p["seconds"] for p in points], [p["rel_mse"] for p in points],
                        marker="o", ms=3, label=label,
                        ls="--" if label.startswith("Mitsuba") else (
                            ":" if label == DENOISED else "-"),
                        lw=2.5 if label == DEFAULT else 1.2)
        axis.set_xlabel(f"wall seconds ({data['resolution'][0]}x{data['resolution'][1]}, "
                        f"{data['threads']} threads)")
        axis.set_ylabel(f"relative MSE against Mitsuba {result['reference']['spp']} spp")
        axis.set_title(f"{name}, -m {data['max_depth']}")
        axis.grid(True, which="both", alpha=0.3)
        axis.legend(fontsize=7)
        fig.tight_layout()
        chart = f"error_vs_time_{name}.png"
        fig.savefig(report.RESULTS / chart, dpi=100)
        plt.close(fig)
        charts.append(f"![{name}: relative MSE against wall time]({chart})")
    target_rows = [
        f"| {r['scene']} | {r['ptrace_mse']:.4f} | {r['mitsuba_multijitter_mse']:.4f} | "
        f"{r['ptrace_independent_mse']:.4f} | {r['mitsuba_independent_mse']:.4f} | "
        f"{r['ptrace_efficiency']:.4f} | {r['mitsuba_multijitter_efficiency']:.4f} | "
        f"{r['mitsuba_independent_efficiency']:.4f} | {r['luminance_ratio']:.4f} |"
        for r in targets(data)]
    labels, roulette_rows, verdict = _roulette_section(data)
    denoise_rows = [
        f"| {name} | {a['spp']} | {a['rel_mse']:.5f} | {b['rel_mse']:.5f} | {a['seconds']:.2f} "
        f"| {b['seconds']:.2f} "
        f"| {b['rel_mse'] * b['seconds'] / (a['rel_mse'] * a['seconds']):.3f} |"
        for name, result in data["scenes"].items() if DENOISED in result["curves"]
        for a, b in zip(result["curves"][DEFAULT], result["curves"][DENOISED])]
    point_rows = [f"| {name} | {label} | {p['spp']} | {p['seconds']:.2f} | {p['rel_mse']:.5f} | "
                  f"{p['rel_mse'] * p['seconds']:.5f} | {p['luminance']:.4f} |"
                  for name, result in data["scenes"].items()
                  for label, points in result["curves"].items() for p in points]
    text = TEMPLATE.format(
        header=report.header("Error against time: ptrace and Mitsuba 3, full frames"),
        width=data["resolution"][0], height=data["resolution"][1], depth=data["max_depth"],
        mitsuba_depth=data["max_depth"] + 1, threads=data["threads"], mitsuba=data["mitsuba"],
        variant=MITSUBA_VARIANT, repeats=data["repeats"],
        target_spp=target_spp(data), reference_spp=data["reference_spp"],
        target_rows="\n".join(target_rows), roulette_header=" | ".join(labels),
        roulette_align="---:|" * len(labels), roulette_rows="\n".join(roulette_rows),
        roulette_verdict=verdict, point_rows="\n".join(point_rows), charts="\n\n".join(charts),
        denoise_rows="\n".join(denoise_rows) or "| (not measured in this run) | | | | | | |")
    path = report.write(output, text)
    report.write(Path(output).with_suffix(".json").name, json.dumps(data, indent=1))
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1-4 spp, one scene")
    parser.add_argument("--scenes", nargs="+", choices=list(SCENES), default=None)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--output", default="error_vs_time.md")
    args = parser.parse_args(argv)
    names = args.scenes or (["CBspheres_lambertian"] if args.quick else list(SCENES))
    spps = [1, 2, 4] if args.quick else [1, 2, 4, 8, 16]
    data = measure(names, spps, args.repeats, 256 if args.quick else REFERENCE_SPP)
    print(f"wrote {write_report(data, args.output)}")


if __name__ == "__main__":
    main()
