"""Where a backend's compiled traversal spends its time, instruction by instruction: samples a
process tracing one batch of rays over and over with `perf record -e cpu-clock` (no hardware
counters needed), and writes the disassembly of the JIT code the samples fell in, each
instruction with its share of the samples.

    python -m benchmarks.sample_kernel [--mesh meshedit/cow.dae] [--kind random] [--backend bvh]
        [--seconds 15] [--threads 1] [--output sample_kernel.txt]

Why by hand: numba's JIT code has no symbols for perf (it writes no perf map), so `perf report`
shows only addresses. The traced process, once sampled, copies its executable anonymous
mappings (from /proc/self/maps, where numba's code lives) to files; the mapping holding the
most samples is disassembled with `objdump -b binary --adjust-vma`, and the samples are counted
per instruction address. Which lines are the slab test, the leaf tests or the ray setup is left
to the reader of the listing. cpu-clock samples skid: a stall is charged to the instruction
after the one that waits (the first use of a load, for example). Needs perf and objdump.
"""
import argparse
import collections
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from . import report
from .rays import scenes_dir

ROOT = Path(__file__).resolve().parents[1]

# Runs in the sampled process: trace for `seconds`, then copy the executable anonymous mappings.
WORKER = r"""
import ctypes, json, os, sys, time
import numba
import accel, ptrace
from benchmarks.rays import make_rays, scene_light
mesh, kind, backend, seconds, threads, folder = sys.argv[1:7]
numba.set_num_threads(int(threads))
scene = ptrace.load(mesh)
rays = make_rays(kind, scene.geometry, 1_000_000, scene_light(scene))
built = accel.build(backend, scene.geometry)
query = built.occluded if kind == "shadow" else built.intersect
query(rays)
print(json.dumps({"pid": os.getpid()}), flush=True)
start, batches = time.perf_counter(), 0
while time.perf_counter() - start < float(seconds):
    query(rays)
    batches += 1
rate = batches * len(rays) / (time.perf_counter() - start)
mappings = []
for line in open("/proc/self/maps"):
    fields = line.split()
    if "x" in fields[1] and len(fields) == 5:   # executable and anonymous: JIT code
        low, high = (int(a, 16) for a in fields[0].split("-"))
        path = os.path.join(folder, f"{low:x}.bin")
        with open(path, "wb") as out:
            out.write(ctypes.string_at(low, high - low))
        mappings.append((low, high, path))
print(json.dumps({"rate": rate, "mappings": mappings}), flush=True)
"""


def sample(args, folder):
    """(rays per second while sampled, {address: samples}, [(low, high, file)])."""
    worker = subprocess.Popen(
        [sys.executable, "-c", WORKER, args.mesh, args.kind, args.backend, str(args.seconds + 4),
         str(args.threads), folder], cwd=ROOT, stdout=subprocess.PIPE, text=True,
        env=dict(os.environ, PYTHONPATH=str(ROOT)))
    pid = json.loads(worker.stdout.readline())["pid"]
    data = os.path.join(folder, "perf.data")
    subprocess.run(["perf", "record", "-F", "5000", "-e", "cpu-clock", "-p", str(pid), "-o",
                    data, "--", "sleep", str(args.seconds)], check=True, capture_output=True)
    done = json.loads(worker.stdout.readline())
    worker.wait()
    ips = subprocess.run(["perf", "script", "-i", data, "-F", "ip"], check=True,
                         capture_output=True, text=True).stdout.split()
    return done["rate"], collections.Counter(int(ip, 16) for ip in ips), done["mappings"]


def listing(counts, low, path):
    """[(address, share of all samples, instruction text)] of the mapping at `low`."""
    text = subprocess.run(["objdump", "-D", "-b", "binary", "-mi386:x86-64",
                           f"--adjust-vma={low:#x}", path], check=True, capture_output=True,
                          text=True).stdout
    total = sum(counts.values())
    lines = []
    for line in text.splitlines():
        found = re.match(r"\s*([0-9a-f]+):\s*(?:[0-9a-f]{2} )+\s*(.*)", line)
        if found and found.group(2):
            address = int(found.group(1), 16)
            lines.append((address, counts.get(address, 0) / total, found.group(2).strip()))
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default="meshedit/cow.dae")
    parser.add_argument("--kind", default="random",
                        choices=["random", "camera", "secondary", "shadow"])
    parser.add_argument("--backend", default="bvh")
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--output", default="sample_kernel.txt")
    args = parser.parse_args(argv)
    args.mesh = str(Path(scenes_dir()) / args.mesh)
    with tempfile.TemporaryDirectory() as folder:
        rate, counts, mappings = sample(args, folder)
        low, high, path = max(mappings, key=lambda m: sum(n for a, n in counts.items()
                                                          if m[0] <= a < m[1]))
        lines = listing(counts, low, path)
    inside = sum(n for a, n in counts.items() if low <= a < high) / sum(counts.values())
    command = " ".join(["python -m benchmarks.sample_kernel", *(argv or sys.argv[1:])])
    head = (f"# {command}\n# {args.backend}, {args.kind} rays on {args.mesh}, {args.threads} "
            f"thread(s): {rate:,.0f} rays/s while sampled; {sum(counts.values())} samples, "
            f"{inside:.1%} of them in the mapping {low:#x}-{high:#x} listed here (share of all "
            f"samples per instruction)\n")
    body = "".join(f"{share:6.1%}  {address:x}  {text}\n" for address, share, text in lines)
    destination = report.write(args.output, head + body)
    print(head, end="")
    for address, share, text in sorted(lines, key=lambda line: -line[1])[:15]:
        print(f"{share:6.1%}  {address:x}  {text}")
    print(f"wrote {destination}")


if __name__ == "__main__":
    main()
