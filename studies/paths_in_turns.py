"""Study: ptrace bvh/embree and Mitsuba llvm_ad_rgb in turns in one process: TURNS rounds, each one
render of each (repeats=1), 480x360 16 spp -m 5 -l 1, 2 threads. Prints per-turn paths/s and
the medians.

    python studies/paths_in_turns.py [TURNS] [SCENE]
"""
import os
import statistics
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import ptrace  # noqa: E402
from benchmarks import paths_per_second as pps  # noqa: E402
from benchmarks.accel_rays import scenes_dir  # noqa: E402

TURNS = int(sys.argv[1]) if len(sys.argv) > 1 else 5
name = sys.argv[2] if len(sys.argv) > 2 else "sky/CBspheres_lambertian.dae"
scene = ptrace.load(os.path.join(scenes_dir(), name))
pps.warm_up(scene, ("bvh", "embree"))
mi, libllvm, note = pps.import_mitsuba()
assert not note, note
print(pps.set_variant(mi, "llvm_ad_rgb", 2, libllvm))
spp, res = pps.FULL["spp"], pps.FULL["resolution"]
mask = pps.lamp_mask(scene, pps.FULL["resolution"], pps.FULL["spp"])
pps.measure_mitsuba(mi, "llvm_ad_rgb", scene, name, spp, res, 1, mask)   # JIT
rates = {"bvh": [], "embree": [], "mitsuba": []}
for t in range(TURNS):
    for kind in ("bvh", "embree"):
        r = pps.measure_ptrace(scene, name, kind, spp, res, 2, 1, mask)
        rates[kind].append(r["paths_per_second"] if "paths_per_second" in r else None)
    m = pps.measure_mitsuba(mi, "llvm_ad_rgb", scene, name, spp, res, 1, mask)
    rates["mitsuba"].append(m.get("paths_per_second"))
    print(t, {k: f"{v[-1]:,.0f}" if v[-1] else v[-1] for k, v in rates.items()}, flush=True)
med = {k: statistics.median(v) for k, v in rates.items()}
print("median", {k: f"{v:,.0f}" for k, v in med.items()},
      "bvh/mitsuba %.2f embree/mitsuba %.2f" % (med["bvh"] / med["mitsuba"],
                                                med["embree"] / med["mitsuba"]))
