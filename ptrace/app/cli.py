"""`ptrace [options] SCENE`: the course's command line over ptrace.load and ptrace.render.

Anything a user can cause (a PtraceError, a bad flag) ends in one line on stderr and exit code
2, never a traceback. Anything else is a bug in ptrace: `ptrace: internal error: ...`, the
traceback, and exit code 1. Ctrl-C writes what was rendered and exits 130.
"""
import contextlib
import dataclasses
import json
import os
import re
import sys

import numpy as np

from .options import (
    EXIT_INTERRUPTED,
    build_parser,
    guarded,
    parse,
    plan,
    scene_and_camera,
)


def scene_info(scene, camera=None):
    """--info's summary of the scene; its camera is `camera`, default the scene's default
    camera at 800x600."""
    from ..pointing import default_camera
    from ..scene import KIND_NAMES, PHYSICAL
    lights = scene.lights
    entries = []
    for i in range(len(lights)):
        kind = KIND_NAMES[lights.kind[i]]
        entry = {"type": kind, "radiance": lights.radiance[i].tolist()}
        if kind in ("point", "spot"):
            physical = lights.model[i] == PHYSICAL
            entry["model"] = ("physical: radiance / distance^2" + (
                ", a cone" if kind == "spot" else "")) if physical else (
                "course: no falloff" if kind == "point" else "course: contributes nothing")
            if kind == "spot" and physical:
                entry["cone_degrees"] = [
                    float(np.degrees(np.arccos(np.clip(lights.cos_inner[i], -1, 1)))),
                    float(np.degrees(np.arccos(np.clip(lights.cos_outer[i], -1, 1))))]
        if kind in ("point", "spot", "area"):
            entry["position"] = lights.position[i].tolist()
        if kind in ("directional", "spot", "area"):
            entry["direction"] = lights.direction[i].tolist()
        if kind == "area":
            entry.update(edge_x=lights.edge_x[i].tolist(), edge_y=lights.edge_y[i].tolist(),
                         area=float(lights.area[i]))
        entries.append(entry)
    camera = default_camera(scene) if camera is None else camera
    bounds = scene.bounds()
    return {
        "file": os.path.abspath(scene.path),
        "triangles": int(scene.triangle_count),
        "spheres": int(scene.sphere_count),
        "lights": entries,
        "bsdfs": scene.bsdf_kinds(),
        "textures": [f"{name} ({w}x{h})" for name, w, h in zip(
            scene.textures.names, scene.textures.width.tolist(), scene.textures.height.tolist())],
        "camera": {"position": camera.position.tolist(), "target": camera.target.tolist(),
                   "hfov": camera.hfov, "vfov": camera.vfov, "screen_dist": camera.screen_dist,
                   "znear": camera.znear, "zfar": camera.zfar},
        "bounds": None if bounds is None else [bounds[0].tolist(), bounds[1].tolist()],
        "notes": scene_notes(scene),
    }


MESH_FILE = "mesh file: "   # how the mesh files' loader starts a note about the file as a whole


def scene_notes(scene):
    """grouped_notes of the scene's notes, a note on a mesh file as a whole naming the file."""
    name = os.path.basename(scene.path)
    return [f"{name}: {line[len(MESH_FILE):]}" if line.startswith(MESH_FILE) else line
            for line in grouped_notes(scene.notes)]


def grouped_notes(notes):
    """The loader's notes, one line per kind: a note '<element ...>: what' names where, and notes
    that say the same `what` in several places, or the same up to its numbers (fan-triangulated
    1 polygon here, 6 there), become one line with the count of places and the first; where
    one of their numbers differs from place to place, the line gives its sum."""
    kinds = {}
    for note in notes:
        where, _, what = note.partition(": ") if note.startswith("<") else ("", "", note)
        kinds.setdefault(re.sub(r"\d+", "#", what), []).append((where, what))
    lines = []
    for kind, places in kinds.items():
        where, what = places[0]
        if len(places) == 1:
            lines.append(f"{where}: {what}" if where else what)
            continue
        columns = list(zip(*[re.findall(r"\d+", text) for _, text in places]))
        varying = [k for k, column in enumerate(columns) if len(set(column)) > 1]
        if len(varying) == 1:   # one count that differs from place to place: their sum
            values = iter([str(sum(map(int, column))) if k in varying else column[0]
                           for k, column in enumerate(columns)])
            what = re.sub(r"#", lambda _: next(values), kind)
        first = f", the first {where}" if where else ""
        lines.append(f"{what} ({len(places)} places{first})")
    return lines


def _one_line_warnings():
    import warnings
    seen = set()

    def show(message, category, filename, lineno, file=None, line=None):
        text = str(message)
        if text not in seen:
            seen.add(text)
            print(f"ptrace: warning: {text}", file=sys.stderr)
    warnings.showwarning = show


def _notice(text):
    print(f"ptrace: {text}", file=sys.stderr, flush=True)


def run(argv):
    from .. import render
    from ..errors import PtraceError
    from ..features import denoise, denoised_path
    from ..image import rate_colours, rate_path, write_images
    args = parse(build_parser(), argv)
    _one_line_warnings()
    job = plan(args, lambda output: [output, rate_path(output)] + (
        [denoised_path(output)] if args.denoise else []))
    output, aov_names, budget = job.output, job.aov_names, job.budget
    aovs = {} if (aov_names or args.denoise) else None
    scene, camera = scene_and_camera(args, budget, job)
    width, height = args.resolution
    if args.info:
        print(json.dumps(scene_info(scene, camera), indent=2))
        return 0
    if args.dashboard and args.workers is None:
        raise PtraceError("--dashboard needs --workers (a local cluster)")
    stats = {}
    client = cluster = None
    with contextlib.ExitStack() as scope:   # left after the client's shutdown
        try:
            if args.workers is not None or args.scheduler is not None:
                from ..rendering import distributed
                # the CLI owns the process: keep Dask's Ctrl-C race out of the user's terminal
                # from here until the client is closed (a library render scopes it to itself)
                scope.enter_context(distributed.dropping_the_sync_cancel_race())
                if args.workers is not None:
                    client, cluster = distributed.local_client(args.workers, args.dashboard)
                else:
                    client = distributed.connect(args.scheduler)
                workers = len(client.scheduler_info()["workers"])
                dashboard = f", dashboard {client.dashboard_link}" if args.dashboard else ""
                print(f"ptrace: rendering on {workers} Dask workers at "
                      f"{client.scheduler.address}{dashboard}", file=sys.stderr, flush=True)
            image = render(scene, **dataclasses.asdict(job.settings),
                           resolution=(width, height), threads=args.threads, crop=args.crop,
                           camera=camera, progress=not args.quiet and sys.stderr.isatty(),
                           stats=stats, client=client,
                           notice=None if args.quiet else _notice, aovs=aovs, max_memory=budget)
            images = [dict(path=output, radiance=image,
                           extra=[(name, aovs[name]) for name in aov_names]),
                      dict(path=rate_path(output),
                           eight_bit=rate_colours(stats["samples"] / args.spp))]
            if args.denoise:
                images.append(dict(path=denoised_path(output),
                                   radiance=denoise(image, aovs["albedo"], aovs["normal"])))
            write_images(images)   # all of them or none
        finally:
            if client is not None:
                distributed.shutdown(client, cluster)
    seconds, build_seconds = stats["render_seconds"], stats["build_seconds"]
    phases = stats.get("phases", {})
    if "compile" in phases:   # in-process: the summary's seconds leave numba's compiler out
        seconds = phases["records"] + phases["render"]
        build_seconds = phases["build"]
        if stats["counts"].get("compiled", 0) and not args.quiet:
            print(f"ptrace: compiled kernels in {phases['compile']:.1f} s (cached for the next "
                  f"runs)", file=sys.stderr)
    mean_spp = stats["samples"].mean()
    where = f"workers {stats['workers']} " if "workers" in stats else ""
    split = f" split {args.bvh_split}" if args.bvh_split != "mean" else ""
    print(f"{image.shape[1]}x{image.shape[0]} spp {args.spp} (mean {mean_spp:.1f}) "
          f"{where}accel {args.accel}{split} build {build_seconds:.3f} s render {seconds:.3f} s "
          f"rays {stats['rays']} ({stats['rays'] / max(seconds, 1e-9):,.0f} rays/s) "
          f"non-finite samples dropped {stats['nonfinite']} -> {os.path.abspath(output)}")
    if args.denoise:
        print(f"denoised by Open Image Denoise (biased) -> "
              f"{os.path.abspath(denoised_path(output))}")
    if not args.quiet:   # what the loader ignored, changed or assumed (after the render, so that
        # an error stays the one line it promises to be)
        for line in scene_notes(scene):
            print(f"ptrace: note: {line}", file=sys.stderr)
    if stats["interrupted"]:
        print("ptrace: interrupted: wrote the samples rendered so far", file=sys.stderr)
        return EXIT_INTERRUPTED
    return 0


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "view":   # `ptrace view SCENE [render flags]`: the browser preview
        from . import view
        return view.main(argv[1:])
    return guarded(lambda: run(argv))


if __name__ == "__main__":
    sys.exit(main())
