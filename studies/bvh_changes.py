"""What each kept change of the BVH traversal bought: bvh rays per second at several
commits, side by side with Embree, in one run.

    python studies/bvh_changes.py [--rays 1000000] [--repeats 5] [--threads 2]
        [--meshes meshedit/cow.dae ...] [--splits mean sah] [--leaf-sizes 2 8]
        [--revisions COMMIT=LABEL ... tree=LABEL] [--processes 1] [--output bvh_changes.md]

Each revision (REVISIONS: the traversal before the change, then one commit per kept change; the
last is this tree) runs in a process of its own, from a `git worktree` of that commit (this tree
for the last) with its own numba cache, so each times its own code. The processes stay alive and
take turns: for every mesh, ray kind and split, each repeat asks every revision in turn to trace
the same batch once (and this tree's process to trace it with Embree, and with the BVH built
with other leaf sizes, --leaf-sizes), so a slow spell of the machine touches all of them alike.

With --processes N each revision runs in N processes, asked in turn like the others, and a
revision's rate is the median of its processes' rates. A process can run the same code at a
rate of its own for the whole run: in one run with three processes per revision, the fastest
process of a revision over its slowest was 1.03x in the median cell and up to 1.16x (cow, camera
rays), more than most single changes buy, so an A/B of one change wants N >= 3.

Rays are accel_rays' (`benchmarks.accel_rays.make_rays`:
random, camera, secondary and shadow rays, the last with any hit (`occluded`), the others closest
hit through the compiled face (`accel.compiled.run_intersect`, what every backend's `intersect`
is today: the same call at every revision and for Embree, where older revisions' bvh.intersect
also counted its work per ray);
kernels are compiled, and each batch traced once, before timing. Rates are medians of the
repeats. Then the same revisions render course scenes (RENDERS), in turns as well, and the
report says whether their images are bit for bit the same (bvh's answers are naive's exactly at
every revision, so they must be). Compile times are not measured here (accel_rays does). Run
time: about 25 minutes for the defaults with one process per revision, 36 with --processes 3
(seven revisions), a few of them compiling the revisions' kernels into empty caches.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import report  # noqa: E402
from benchmarks.rays import scenes_dir  # noqa: E402

# (commit, label); None is this tree
REVISIONS = [
    ("11fa26c", "4-wide, scalar (before)"),
    ("e7e8a2d", "8-wide, vector tests"),
    ("6e6ee83", "+ float32 planes"),
    ("bd6c4cc", "+ unsigned indices"),
    ("b55d6cb", "+ one-hit shortcut"),
    ("78772cd", "+ float32 slab"),
    (None, "+ least-cost collapse (this tree)"),
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
    """A process running WORKER at one commit's tree (the first of a commit's processes makes
    its worktree, and closing it removes the worktree)."""

    def __init__(self, commit, label, threads, scratch, first=True):
        self.commit, self.label, self.first = commit, label, first
        if commit is None:
            tree = ROOT
        else:
            tree = Path(scratch) / commit
            if first:
                subprocess.run(["git", "worktree", "add", "--detach", str(tree), commit],
                               cwd=ROOT, check=True, capture_output=True)
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
        if self.commit is not None and self.first:
            subprocess.run(["git", "worktree", "remove", "--force", str(self.tree)], cwd=ROOT,
                           check=True, capture_output=True)


def measure(args, revisions, scenes):
    """rates[(mesh, kind, split, label)], rates[(mesh, kind, None, "embree")] and, for this
    tree's other leaf sizes, rates[(mesh, kind, split, f"leaf {n}")], rays/s; and spreads[(mesh,
    kind, split, label)], the fastest of a revision's processes over its slowest.

    With several processes per revision (--processes), a revision's rate is the median of its
    processes' rates (each the median of its repeats): a process's rate can sit apart from
    another's at the same code for the whole run (where its memory landed, perhaps: not
    measured), so one process per revision can show a step that is not the code's."""
    rates, spreads = {}, {}
    last = [r for r in revisions if r.label == revisions[-1].label]
    for mesh in args.meshes:
        path = str(Path(scenes) / mesh)
        for kind in KINDS:
            for split in args.splits:
                times = {(r.label, i): [] for i, r in enumerate(revisions)}
                times.update({(f"leaf {n}", i): [] for n in args.leaf_sizes
                              for i in range(len(last))})
                embree = {i: [] for i in range(len(last))}
                for repeat in range(args.repeats):
                    request = dict(mesh=path, kind=kind, split=split, rays=args.rays,
                                   warm=repeat == 0)
                    for i, revision in enumerate(revisions):
                        times[revision.label, i].append(revision.seconds(backend="bvh",
                                                                         **request))
                    for i, revision in enumerate(last):
                        for n in args.leaf_sizes:
                            times[f"leaf {n}", i].append(revision.seconds(backend="bvh", leaf=n,
                                                                          **request))
                        if split == args.splits[0]:
                            embree[i].append(revision.seconds(backend="embree", **request))
                per_process = {}
                for (label, _), seconds in times.items():
                    per_process.setdefault(label, []).append(args.rays
                                                             / statistics.median(seconds))
                for label, found in per_process.items():
                    rates[mesh, kind, split, label] = statistics.median(found)
                    spreads[mesh, kind, split, label] = max(found) / min(found)
                if split == args.splits[0]:
                    rates[mesh, kind, None, "embree"] = statistics.median(
                        args.rays / statistics.median(seconds) for seconds in embree.values())
                print(mesh, kind, split, ", ".join(
                    f"{label} {rates[mesh, kind, split, label]:,.0f}" for label in per_process)
                    + f", embree {rates[mesh, kind, None, 'embree']:,.0f} rays/s", flush=True)
    return rates, spreads


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


def spread_text(args, labels, spreads):
    """A sentence on how far apart one revision's processes were (--processes > 1)."""
    if args.processes < 2:
        return ""
    cells = {key: value for key, value in spreads.items() if key[3] in labels}
    worst = max(cells, key=cells.get)
    return (f"Each revision ran in {args.processes} processes; a cell is the median of their "
            f"rates. The fastest process of a revision over its slowest, over all cells: median "
            f"{statistics.median(cells.values()):.2f}x, largest {cells[worst]:.2f}x ({worst[0]}, "
            f"{worst[1]}, {worst[2]} split, {worst[3]}).\n\n")


def tables(args, labels, rates):
    lines = []
    for split in args.splits:
        lines += [f"### bvh {split} split", "",
                  "Rays per second of bvh at each revision, Embree's, then each revision's rate "
                  "over the one before it (*step*) and over Embree's (*/ embree*).", "",
                  "| " + " | ".join(["mesh", "rays", *labels, "embree",
                                     *(f"step: {label}" for label in labels[1:]),
                                     *(f"/ embree: {label}" for label in labels)]) + " |",
                  "|---|---|" + "---:|" * (2 * len(labels) + 1 + len(labels) - 1)]
        for mesh in args.meshes:
            for kind in KINDS:
                rate = [rates[mesh, kind, split, label] for label in labels]
                embree = rates[mesh, kind, None, "embree"]
                lines.append("| " + " | ".join([
                    mesh, kind + (" (any hit)" if kind == "shadow" else ""),
                    *(f"{r:,.0f}" for r in rate), f"{embree:,.0f}",
                    *(f"{b / a:.2f}x" for a, b in zip(rate, rate[1:])),
                    *(f"{r / embree:.2f}" for r in rate)]) + " |")
        lines.append("")
        if args.leaf_sizes:
            sizes = sorted(args.leaf_sizes + [DEFAULT_LEAF])
            columns = [f"leaf {n}" if n != DEFAULT_LEAF else labels[-1] for n in sizes]
            lines += [f"Leaf size, bvh {split} split, this tree: rays per second with "
                      f"max_leaf_size {', '.join(map(str, sizes))} ({DEFAULT_LEAF}, the default, "
                      "is the column above), and each over the default's.", "",
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
                             "(default: REVISIONS, the kept changes)")
    parser.add_argument("--leaf-sizes", type=int, nargs="*", default=[8],
                        help="other max_leaf_size values to time in this tree (default 8)")
    parser.add_argument("--renders", type=int, default=len(RENDERS),
                        help=f"how many of the {len(RENDERS)} renders to time (0: none)")
    parser.add_argument("--render-repeats", type=int, default=3)
    parser.add_argument("--processes", type=int, default=1,
                        help="worker processes per revision (default 1; see measure())")
    parser.add_argument("--output", default="bvh_changes.md")
    args = parser.parse_args(argv)
    revisions_wanted = REVISIONS if not args.revisions else [
        (None if commit == "tree" else commit, label)
        for commit, _, label in (spec.partition("=") for spec in args.revisions)]
    scenes = scenes_dir()
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as scratch:
        revisions = []
        try:
            for commit, label in revisions_wanted:
                for i in range(args.processes):
                    revisions.append(Revision(commit, label, args.threads, scratch, i == 0))
            rates, spreads = measure(args, revisions, scenes)
            renders = measure_renders(args, revisions, scenes)
        finally:
            for revision in reversed(revisions):   # a commit's first process last: its worktree
                revision.close()
    labels = [label for _, label in revisions_wanted]
    commits = ", ".join(f"{label}: {commit or 'this tree'}" for commit, label in revisions_wanted)
    text = report.header("BVH traversal changes side by side") + (
        f"{args.rays:,} rays per batch, {args.threads} threads, median of {args.repeats} runs "
        f"taken in turns (each revision's process, then Embree's, per repeat); closest hit "
        f"through the compiled face (`accel.compiled.run_intersect`) at every revision and for "
        f"Embree, any hit through `occluded`. Revisions: "
        f"{commits}. Load average (1 min) before the run {load:.1f}, after it "
        f"{os.getloadavg()[0]:.1f}.\n\n" + spread_text(args, labels, spreads)
        + tables(args, labels, rates)
        + render_table(labels, renders))
    print(f"wrote {report.write(args.output, text)}")


if __name__ == "__main__":
    main()
