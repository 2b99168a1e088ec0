"""What each kept change of the BVH traversal bought (issue 14.3): bvh rays per second at several
commits, side by side with Embree, in one run.

    python -m benchmarks.bvh_changes [--rays 1000000] [--repeats 5] [--threads 2]
        [--meshes meshedit/cow.dae ...] [--splits mean sah] [--leaf-sizes 2 8]
        [--revisions COMMIT=LABEL ... tree=LABEL] [--output bvh_changes.md]

Each revision (REVISIONS: the traversal before the change, then one commit per kept change; the
last is this tree) runs in a process of its own, from a `git worktree` of that commit (this tree
for the last) with its own numba cache, so each times its own code. The processes stay alive and
take turns: for every mesh, ray kind and split, each repeat asks every revision in turn to trace
the same batch once (and this tree's process to trace it with Embree, and with the BVH built
with other leaf sizes, --leaf-sizes), so a slow spell of
the machine touches all of them alike. Rays are accel_rays' (`benchmarks.accel_rays.make_rays`:
random, camera, secondary and shadow rays, the last with any hit (`occluded`), the others closest
hit through the compiled face (`accel.compiled.run_intersect`, what every backend's `intersect`
is today: the same call at every revision and for Embree, where older revisions' bvh.intersect
also counted its work per ray);
kernels are compiled, and each batch traced once, before timing. Rates are medians of the
repeats. Then the same revisions render course scenes (RENDERS), in turns as well, and the
report says whether their images are bit for bit the same (bvh's answers are naive's exactly at
every revision, so they must be). Compile times are not measured here (accel_rays does). Run
time: about 25 minutes for the defaults, a few of them compiling four revisions' kernels into
empty caches.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from . import report

ROOT = Path(__file__).resolve().parents[1]
# (commit, label); None is this tree
REVISIONS = [
    ("11fa26c", "4-wide, scalar (before)"),
    ("e7e8a2d", "8-wide, vector tests"),
    ("6e6ee83", "+ float32 planes"),
    ("bd6c4cc", "+ unsigned indices"),
    (None, "+ one-hit shortcut (this tree)"),
]
MESHES = ["meshedit/cow.dae", "sky/CBbunny.dae", "keenan/building.dae", "meshedit/maxplanck.dae"]
KINDS = ("random", "camera", "secondary", "shadow")


def _default_leaf_size():
    import inspect

    from accel.bvh import BVHAccelerator
    return inspect.signature(BVHAccelerator).parameters["max_leaf_size"].default


DEFAULT_LEAF = _default_leaf_size()

# Runs inside each revision's process: reads one JSON request per line, answers with seconds.
WORKER = r"""
import hashlib, json, sys, time
import numba
import accel, ptrace
from accel.compiled import run_intersect
from accel.types import Hits, Rays
from benchmarks.accel_rays import make_rays, scene_light
numba.set_num_threads(int(sys.argv[1]))
print(json.dumps({"accel": accel.__file__}), flush=True)
loaded, backends, batches = None, {}, {}
scenes = {}
for line in sys.stdin:
    request = json.loads(line)
    if "render" in request:
        path = request["render"]
        if path not in scenes:
            scenes[path] = ptrace.load(path)
            ptrace.render(scenes[path], threads=int(sys.argv[1]),
                          **dict(request["options"], resolution=(8, 6)))
        stats = {}
        start = time.perf_counter()
        image = ptrace.render(scenes[path], threads=int(sys.argv[1]), stats=stats,
                              **request["options"])
        seconds = time.perf_counter() - start
        print(json.dumps({"seconds": seconds, "rays": stats["rays"],
                          "image": hashlib.sha256(image.tobytes()).hexdigest()}), flush=True)
        continue
    if request["mesh"] != loaded:
        loaded, backends, batches = request["mesh"], {}, {}
        scene = ptrace.load(request["mesh"])
        geometry, light = scene.geometry, scene_light(scene)
    key = (request["backend"], request["split"], request.get("leaf"))
    if key not in backends:
        options = {} if request["backend"] == "embree" else {"split": request["split"]}
        if request.get("leaf"):
            options["max_leaf_size"] = request["leaf"]
        backends[key] = accel.build(request["backend"], geometry, **options)
    if request["kind"] not in batches:
        rays = make_rays(request["kind"], geometry, request["rays"], light)
        part = slice(0, max(1, len(rays) // 8))
        batches[request["kind"]] = rays, Rays(rays.origins[part], rays.directions[part],
                                              rays.tmin[part], rays.tmax[part])
    rays, head = batches[request["kind"]]
    backend = backends[key]
    if request["kind"] == "shadow":
        query = backend.occluded
    else:   # the compiled face, as the path loop calls it: until 7da9a05, bvh.intersect also
        # counted its work per ray (the plain face ran 1.11-1.22x its rays per second)
        def query(rays, record=backend.compiled):
            rays.validate()
            return run_intersect(record, rays, Hits)
    if request.get("warm"):
        query(rays)
    # Untimed: another process's OpenMP threads spin for a few milliseconds after its batch (the
    # first batch after one measured a few percent slower, camera rays up to 20%), so wait that
    # out, then trace an eighth of the batch to bring this tree back into the caches.
    time.sleep(0.05)
    query(head)
    start = time.perf_counter()
    query(rays)
    print(json.dumps({"seconds": time.perf_counter() - start}), flush=True)
"""


class Revision:
    """A process running WORKER at one commit's tree."""

    def __init__(self, commit, label, threads, scratch):
        self.commit, self.label = commit, label
        if commit is None:
            tree = ROOT
        else:
            tree = Path(scratch) / commit
            subprocess.run(["git", "worktree", "add", "--detach", str(tree), commit], cwd=ROOT,
                           check=True, capture_output=True)
        self.tree = tree
        env = dict(os.environ, PYTHONPATH=str(tree),
                   NUMBA_CACHE_DIR=str(Path(scratch) / f"cache-{commit or 'tree'}"))
        self.process = subprocess.Popen([sys.executable, "-c", WORKER, str(threads)], cwd=tree,
                                        env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        text=True)
        found = json.loads(self.process.stdout.readline())["accel"]
        if not Path(found).resolve().is_relative_to(Path(tree).resolve()):
            raise RuntimeError(f"{label}: imported accel from {found}, not from {tree}")

    def ask(self, **request):
        self.process.stdin.write(json.dumps(request) + "\n")
        self.process.stdin.flush()
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError(f"{self.label}: the worker stopped")
        return json.loads(line)

    def seconds(self, **request):
        return self.ask(**request)["seconds"]

    def close(self):
        self.process.stdin.close()
        self.process.wait()
        if self.commit is not None:
            subprocess.run(["git", "worktree", "remove", "--force", str(self.tree)], cwd=ROOT,
                           check=True, capture_output=True)


def measure(args, revisions, scenes):
    """rates[(mesh, kind, split, label)], rates[(mesh, kind, None, "embree")] and, for this
    tree's other leaf sizes, rates[(mesh, kind, split, f"leaf {n}")], rays/s."""
    rates = {}
    for mesh in args.meshes:
        path = str(Path(scenes) / mesh)
        for kind in KINDS:
            for split in args.splits:
                times = {r.label: [] for r in revisions}
                times.update({f"leaf {n}": [] for n in args.leaf_sizes})
                embree = []
                for repeat in range(args.repeats):
                    request = dict(mesh=path, kind=kind, split=split, rays=args.rays,
                                   warm=repeat == 0)
                    for revision in revisions:
                        times[revision.label].append(revision.seconds(backend="bvh", **request))
                    for n in args.leaf_sizes:
                        times[f"leaf {n}"].append(revisions[-1].seconds(backend="bvh", leaf=n,
                                                                        **request))
                    if split == args.splits[0]:
                        embree.append(revisions[-1].seconds(backend="embree", **request))
                for label, seconds in times.items():
                    rates[mesh, kind, split, label] = args.rays / statistics.median(seconds)
                if embree:
                    rates[mesh, kind, None, "embree"] = args.rays / statistics.median(embree)
                print(mesh, kind, split, ", ".join(
                    f"{label} {rates[mesh, kind, split, label]:,.0f}" for label in times)
                    + f", embree {rates[mesh, kind, None, 'embree']:,.0f} rays/s", flush=True)
    return rates


# renders timed in turns as the rays are: (scene, ptrace.render options)
RENDERS = [
    ("sky/CBbunny.dae", dict(spp=16, light_samples=4, max_depth=5, resolution=(480, 360))),
    ("sky/CBspheres.dae", dict(spp=16, light_samples=4, max_depth=5, resolution=(480, 360))),
    ("sky/CBcoil.dae", dict(spp=16, light_samples=4, max_depth=5, resolution=(480, 360))),
]


def measure_renders(args, revisions, scenes):
    """{scene: {label: (median seconds, rays, image digest)}} for RENDERS (bvh, mean split)."""
    results = {}
    for scene, options in RENDERS[:args.renders]:
        path = str(Path(scenes) / scene)
        runs = {r.label: [] for r in revisions}
        for _ in range(args.render_repeats):
            for revision in revisions:
                runs[revision.label].append(revision.ask(render=path, options=options))
        results[scene] = {label: (statistics.median(run["seconds"] for run in found),
                                  found[0]["rays"], {run["image"] for run in found})
                          for label, found in runs.items()}
        print(scene, ", ".join(f"{label} {value[0]:.2f} s"
                               for label, value in results[scene].items()), flush=True)
    return results


def render_table(labels, renders):
    lines = ["### Renders", "",
             "Seconds of `ptrace.render` (bvh, mean split, 2 threads, kernels compiled "
             "beforehand; median of the runs taken in turns), the first revision's time over each "
             "later one's (*speed-up*), the last revision's rays per second, and whether every "
             "revision's image is bit for bit the same (SHA-256 of the float32 pixels).", "",
             "| scene | options | " + " | ".join(f"{label} s" for label in labels) + " | "
             + " | ".join(f"speed-up: {label}" for label in labels[1:])
             + " | rays/s (last) | same image |",
             "|---|---|" + "---:|" * (2 * len(labels) - 1 + 1) + "---|"]
    for scene, options in RENDERS:
        if scene not in renders:
            continue
        found = renders[scene]
        seconds = [found[label][0] for label in labels]
        digests = set().union(*(found[label][2] for label in labels))
        shown = ", ".join(f"{k}={v}" for k, v in options.items())
        lines.append(f"| {scene} | {shown} | " + " | ".join(f"{s:.2f}" for s in seconds) + " | "
                     + " | ".join(f"{seconds[0] / s:.2f}x" for s in seconds[1:]) + " | "
                     + f"{found[labels[-1]][1] / seconds[-1]:,.0f} | "
                     + ("yes" if len(digests) == 1 else f"NO ({len(digests)} images)") + " |")
    lines.append("")
    return "\n".join(lines)


def tables(args, labels, rates):
    lines = []
    for split in args.splits:
        lines += [f"### bvh {split} split", "",
                  "Rays per second of bvh at each revision, Embree's, then each revision's rate "
                  "over the one before it (*step*) and over Embree's (*/ embree*).", "",
                  "| mesh | rays | " + " | ".join(labels) + " | embree | "
                  + " | ".join(f"step: {label}" for label in labels[1:]) + " | "
                  + " | ".join(f"/ embree: {label}" for label in labels) + " |",
                  "|---|---|" + "---:|" * (2 * len(labels) + 1 + len(labels) - 1)]
        for mesh in args.meshes:
            for kind in KINDS:
                rate = [rates[mesh, kind, split, label] for label in labels]
                embree = rates[mesh, kind, None, "embree"]
                lines.append(
                    f"| {mesh} | {kind}{' (any hit)' if kind == 'shadow' else ''} | "
                    + " | ".join(f"{r:,.0f}" for r in rate) + f" | {embree:,.0f} | "
                    + " | ".join(f"{b / a:.2f}x" for a, b in zip(rate, rate[1:])) + " | "
                    + " | ".join(f"{r / embree:.2f}" for r in rate) + " |")
        lines.append("")
        if args.leaf_sizes:
            sizes = sorted(args.leaf_sizes + [DEFAULT_LEAF])
            columns = [f"leaf {n}" if n != DEFAULT_LEAF else labels[-1] for n in sizes]
            lines += [f"Leaf size, bvh {split} split, this tree: rays per second with max_leaf_size "
                      f"{', '.join(map(str, sizes))} ({DEFAULT_LEAF}, the default, is the column "
                      "above), and each over the default's.", "",
                      "| mesh | rays | " + " | ".join(f"leaf {n}" for n in sizes) + " | "
                      + " | ".join(f"leaf {n} / leaf {DEFAULT_LEAF}" for n in args.leaf_sizes)
                      + " |", "|---|---|" + "---:|" * (len(sizes) + len(args.leaf_sizes))]
            for mesh in args.meshes:
                for kind in KINDS:
                    rate = {n: rates[mesh, kind, split, c] for n, c in zip(sizes, columns)}
                    lines.append(f"| {mesh} | {kind} | "
                                 + " | ".join(f"{rate[n]:,.0f}" for n in sizes) + " | "
                                 + " | ".join(f"{rate[n] / rate[DEFAULT_LEAF]:.2f}x"
                                              for n in args.leaf_sizes) + " |")
            lines.append("")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--meshes", nargs="+", default=MESHES)
    parser.add_argument("--splits", nargs="+", default=["mean", "sah"], choices=["mean", "sah"])
    parser.add_argument("--revisions", nargs="+", metavar="COMMIT=LABEL",
                        help="the revisions to compare, oldest first; COMMIT 'tree' is this tree "
                             "(default: REVISIONS, the kept changes of issue 14.3)")
    parser.add_argument("--leaf-sizes", type=int, nargs="*", default=[8],
                        help="other max_leaf_size values to time in this tree (default 8)")
    parser.add_argument("--renders", type=int, default=len(RENDERS),
                        help=f"how many of the {len(RENDERS)} renders to time (0: none)")
    parser.add_argument("--render-repeats", type=int, default=3)
    parser.add_argument("--output", default="bvh_changes.md")
    args = parser.parse_args(argv)
    revisions_wanted = REVISIONS if not args.revisions else [
        (None if commit == "tree" else commit, label)
        for commit, _, label in (spec.partition("=") for spec in args.revisions)]
    scenes = os.environ.get("PTRACE_SCENES", str(ROOT.parent / "shared" / "scenes" / "cs184"))
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as scratch:
        revisions = []
        try:
            for commit, label in revisions_wanted:
                revisions.append(Revision(commit, label, args.threads, scratch))
            rates = measure(args, revisions, scenes)
            renders = measure_renders(args, revisions, scenes)
        finally:
            for revision in revisions:
                revision.close()
    labels = [label for _, label in revisions_wanted]
    commits = ", ".join(f"{label}: {commit or 'this tree'}" for commit, label in revisions_wanted)
    text = report.header("BVH traversal changes side by side (issue 14.3)") + (
        f"{args.rays:,} rays per batch, {args.threads} threads, median of {args.repeats} runs "
        f"taken in turns (each revision's process, then Embree's, per repeat); closest hit "
        f"through the compiled face (`accel.compiled.run_intersect`) at every revision and for "
        f"Embree, any hit through `occluded`. Revisions: "
        f"{commits}. Load average (1 min) before the run {load:.1f}, after it "
        f"{os.getloadavg()[0]:.1f}.\n\n" + tables(args, labels, rates)
        + render_table(labels, renders))
    path = report.destination(args.output)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
