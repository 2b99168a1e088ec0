"""A mutation check: plant known bugs one at a time and see which tests catch them.

    python tests/mutants.py                 # every mutant, report to benchmarks/results/mutants.md
    python tests/mutants.py rr-cap-half     # only the named ones (report printed, not written)
    python tests/mutants.py --check         # each mutant's text is found exactly once, run nothing

Each mutant is a list of (file, text, replacement) edits, each text found exactly once, and the
tests that should catch it. For each, the working tree (tracked and untracked files, as they are
on disk) is copied to a scratch directory, the edits are applied there, and the tests run in a
fresh process with a fresh numba cache (numba's cache would not notice an edit in a callee's
module) and the scratch copy first on sys.path. A mutant is *killed* when those tests fail. The
unmutated copy must pass the same tests first, or the run stops: a mutant killed by a broken
suite proves nothing.
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REPORT = ROOT / "benchmarks" / "results" / "mutants.md"

INTEGRATOR, KERNELS, BVH = "ptrace/integrator.py", "accel/kernels.py", "accel/bvh.py"
SIMD = "accel/simd.py"
SHADING = "ptrace/kernel/shading.py"
RR_TEST = "tests/ptrace/test_roulette_rule.py"
PROMISES = "tests/ptrace/test_hostile_promises.py"
ALPHA_TEST = "tests/ptrace/test_gltf_alpha_normals.py"
GUIDE, GUIDE_TEST = "ptrace/kernel/guide.py", "tests/ptrace/test_guiding.py"

# name -> (what the bug is, [(file, text, replacement)], [pytest arguments])
MUTANTS = {
    "rr-survives-1-minus-q": (
        "roulette continues with probability 1 - q while still dividing by q",
        [(SHADING, "base + DIM_RR) < q:", "base + DIM_RR) >= q:")],
        [RR_TEST]),
    "rr-cap-half": (
        "the default roulette cap is 0.5 instead of 0.95",
        [("ptrace/codes.py", "RR_CAP = 0.95 ", "RR_CAP = 0.5 ")],
        [RR_TEST]),
    "tie-highest-id": (
        "between hits at the same t the higher primitive id wins (the shared better())",
        [(KERNELS, "(best_prim == NO_HIT or prim < best_prim)",
          "(best_prim == NO_HIT or prim > best_prim)")],
        ["tests/accel/test_backends.py", "-k", "tie"]),
    "glass-leaves-with-entering-scale": (
        "light leaving glass is scaled by the entering radiance scale 1 / ior^2",
        [("ptrace/bsdf.py", "-eta_ratio * woy, tz, eta_ratio * eta_ratio",
          "-eta_ratio * woy, tz, 1.0 / (ior_m * ior_m)")],
        ["tests/ptrace/test_bsdf.py"]),
    "image-written-in-place": (
        "the output image is written straight to its target, not through a temporary file",
        [("ptrace/image.py", "_write_temporary(temporary, pixels, pixel_type, names,   #",
          "_write_temporary(path, pixels, pixel_type, names,   #"),
         ("ptrace/image.py", "temporary = entry[0] = _link(unnamed, directory, path)",
          "temporary = entry[0] = None"),
         ("ptrace/image.py", "                    os.replace(temporary, path)\n",
          "                    pass\n")],
        ["tests/ptrace/test_image.py"]),
    "dropped-cosine": (
        "the path throughput drops the cosine of the sampled direction",
        [(SHADING, "weight = abs(wiz) / pdf", "weight = 1.0 / pdf")],
        ["tests/ptrace/test_light_transport.py", "-k", "furnace"]),
    "swapped-barycentrics": (
        "the watertight test returns (v, u) for (u, v)",
        [(KERNELS, "return t, e1 * inv, e2 * inv", "return t, e2 * inv, e1 * inv")],
        ["tests/accel/test_backends.py", "-k", "barycentrics"]),
    "no-tmax-shrink": (
        "BVH traversal opens boxes beyond the nearest hit found so far",
        [(BVH, "            if entry[uint64(top)] <= best_s:\n",
          "            if True:\n"),
         (BVH, "            hi32 = _hi32(best_t, shift)\n", "")],
        ["tests/accel/test_bvh.py", "-k", "nearest"]),
    "slab-inverses-not-scaled": (
        "the float32 slab test's inverses are not scaled outward",
        [("accel/bvh_slab.py", "SLAB_SCALE = 4.0 * 2.0 ** -24", "SLAB_SCALE = 0.0")],
        ["tests/accel/test_simd.py", "-k", "slab"]),
    "one-child-shortcut-for-several": (
        "BVH closest hit enters the first child hit and drops the others whenever any is hit",
        [(BVH, "if mask != 0 and mask & (mask - 1) == 0:   # one child hit",
          "if mask != 0:   # one child hit")],
        ["tests/accel/test_bvh.py"]),
    "collapse-not-least-cost": (
        "the BVH's collapse opens a node into its children where keeping it costs less",
        [("accel/bvh_wide.py", "if opened < value:", "if opened > value:")],
        ["tests/accel/test_bvh.py", "-k", "least_cost"]),
    "block-swapped-barycentrics": (
        "the BVH's four-lane watertight test returns (v, u) for (u, v)",
        [(SIMD, "b.fmul(e1, inv), b.fmul(e2, inv),", "b.fmul(e2, inv), b.fmul(e1, inv),")],
        ["tests/accel/test_backends.py", "-k", "barycentrics"]),
    "light-pdf-doubled": (
        "an area light sample reports twice its solid-angle pdf",
        [("ptrace/solid_angle.py", "kz + a * xz + b * yz, 1.0 / omega",
          "kz + a * xz + b * yz, 2.0 / omega")],
        ["tests/ptrace/test_bsdf.py", "-k", "area_light"]),
    "seed-in-dimension-slot": (
        "the Sobol sampler's key takes the seed where the dimension belongs",
        [("ptrace/sampling.py", "+ _mix(np.uint64(pixel) * _K_PIXEL + np.uint64(dim) * _K_DIM) "
          "+ salt)", "+ _mix(np.uint64(pixel) * _K_PIXEL + np.uint64(seed) * _K_DIM) + salt)")],
        ["tests/ptrace/test_sampler.py"]),
    "adaptive-batch-off-by-one": (
        "adaptive sampling's passes take one sample more than the batch",
        [("ptrace/rendering/tiles.py", "self.batch = adaptive[0] if",
          "self.batch = adaptive[0] + 1 if")],
        ["tests/ptrace/test_passes.py"]),
    "adaptive-one-batch-of-zeros": (
        "a pixel of equal samples stops after one batch",
        [("ptrace/rendering/tiles.py", "(n >= 2 * batch)", "(n >= batch)")],
        ["tests/ptrace/test_passes.py"]),
    "spawn-on-the-wrong-side": (
        "spawned rays leave on the side opposite their direction (self-intersection)",
        [(INTEGRATOR, "e = offset if wx * gx + wy * gy + wz * gz >= 0.0 else -offset",
          "e = -offset if wx * gx + wy * gy + wz * gz >= 0.0 else offset")],
        ["tests/ptrace/test_stability.py", "-k", "spawned"]),
    "mis-weight-one": (
        "multiple importance sampling gives every technique weight 1 (light counted twice)",
        [(INTEGRATOR, "return a / (a + b) if a > 0.0 else 0.0", "return 1.0 if a > 0.0 else 0.0")],
        ["tests/ptrace/test_estimators.py", "-k", "agree or analytic"]),
    "dask-forces-roulette": (
        "Dask workers render with roulette on whatever the settings say",
        [("ptrace/rendering/distributed.py", 'settings = request["settings"]',
          'settings = type(request["settings"])(**{**vars(request["settings"]), '
          '"roulette": True})')],
        ["tests/ptrace/test_distributed.py", "-k", "option"]),
    "last-vertex-delta-only-under-mis": (
        "at the last vertex a mirror's or glass's ray is traced only under MIS, so under "
        "--direct light, -H or with point lights the mirror shows no light",
        [(SHADING, "if vertex == max_depth and not (DELTA_KIND or MIXED_KIND or mis):",
          "if vertex == max_depth and not (MIXED_KIND or mis):")],
        [PROMISES, "-k", "last_vertex"]),
    "face-anywhere-in-the-plane": (
        "an emissive panel anywhere in a light's plane is taken for the light's face (the "
        "light's centre need not lie on it)",
        [("ptrace/emitters.py",
          "if np.any(p < lower - tolerance) or np.any(p > upper + tolerance):", "if False:")],
        [PROMISES, "-k", "sideways"]),
    "gltf-wrap-t-for-s": (
        "a glTF sampler's wrapT is read for the texture's u wrap as well as its v wrap",
        [("ptrace/io/gltf_materials.py",
          'return (GLTF_WRAP.get(sampler.get("wrapS", 10497), REPEAT),',
          'return (GLTF_WRAP.get(sampler.get("wrapT", 10497), REPEAT),')],
        ["tests/ptrace/test_hostile_gltf_wrap.py"]),
    "embree-grazing-refines-t-only": (
        "on a grazing hit the embree backend recomputes t in float64 but keeps float32 u and v",
        [("accel/embree.py", "best_t, best_u, best_v = t, u, v", "best_t = t")],
        [PROMISES, "-k", "embree"]),
    "bvh-prim-pmf-constant": (
        "the MIS density of an emissive primitive a BSDF ray finds under the light BVH takes a "
        "constant selection probability instead of the tree's pmf at that vertex",
        [("ptrace/light_bvh.py", "    return lights.bvh_pmf[lights.bvh_pmf.shape[0] - 1] * "
          "tree_pmf(lights.tree, px, py, pz, nx,", "    return 0.5 + 0.0 * tree_pmf(lights.tree, "
          "px, py, pz, nx,")],
        ["tests/ptrace/test_light_bvh.py"]),
    "instances-counted-once": (
        "the glTF budget counts each instanced mesh's triangles once, not once per node placing it",
        [("ptrace/io/gltf.py", "            triangles += per_mesh[mesh]\n",
          "            triangles += 0 if mesh in used else per_mesh[mesh]\n")],
        ["tests/ptrace/test_budgets.py", "-k", "instancing"]),
    "blend-passes-with-alpha": (
        "a BLEND surface passes rays with probability alpha instead of 1 - alpha",
        [("ptrace/cutouts.py", "return alpha <= uniform(", "return alpha > uniform(")],
        [ALPHA_TEST, "-k", "blend"]),
    "shadow-ignores-cutouts": (
        "shadow rays stop at cut-out surfaces",
        [("ptrace/cutouts.py", "    if materials.cutoff.shape[0] == 0:\n        return True\n",
          "    return True\n")],
        [ALPHA_TEST, "-k", "occluder"]),
    "bitangent-keeps-handedness": (
        "the normal texture's bitangent is n x t whatever side dP/dv is on (mirrored UVs)",
        [("ptrace/textures.py", "        cx, cy, cz = -cx, -cy, -cz\n", "        pass\n")],
        [ALPHA_TEST, "-k", "mirrored"]),
    "light-hits-slab-unordered": (
        "the area-light tree's slab test takes (lo - o) / d as the near end even for d < 0",
        [("ptrace/light_hits.py", "    if t0 > t1:\n        t0, t1 = t1, t0\n", "")],
        ["tests/ptrace/test_light_hits.py"]),
    "light-hits-never-enters": (
        "the walk over the area-light tree jumps past every inner node, so a BSDF ray under MIS "
        "finds none of many area lights",
        [("ptrace/light_hits.py", "        k = k + 1 if box_crossed(lower, upper, k, ox, oy, oz, "
          "dx, dy, dz, t_max) else skip[k]\n", "        k = skip[k]\n")],
        ["tests/ptrace/test_light_bvh.py", "-k", "through_the_tree"]),
    "guide-u-not-rescaled": (
        "the guide's quadtree warp passes u1 down unrescaled after choosing the left half",
        [(GUIDE, "u1 = _rescale(u1, 0.0, left)", "u1 = u1")],
        [GUIDE_TEST, "-k", "chi_square or sphere"]),
    "guide-left-out-of-bsdf-bounce-pdf": (
        "a bounce the BSDF draws is weighted by the BSDF's pdf alone, not the mixture's",
        [(SHADING, "pdf = (1.0 - mix) * pdf + mix * guide_pdf(guide, leaf, wx / length,",
          "pdf = pdf + 0.0 * guide_pdf(guide, leaf, wx / length,")],
        [GUIDE_TEST, "-k", "means_agree"]),
    "guide-chosen-at-half-alpha": (
        "the guide is chosen with probability alpha / 2 while the pdf mixes at alpha",
        [(SHADING, "                if u1 < mix:", "                if u1 < 0.5 * mix:")],
        [GUIDE_TEST, "-k", "means_agree"]),
    "guide-runs-cut-by-block": (
        "a merge's records are cut into the splatting threads' runs at a block's edge, not by "
        "record count, so the guide depends on how the blocks cut the records",
        [("ptrace/guiding.py", "        cuts = [total * j // parts for j in range(parts + 1)]\n",
          "        cuts = [total * j // parts for j in range(parts + 1)]\n        if parts == 2:\n"
          "            cuts[1] = sum(b.shape[1] for b in ordered[:max(1, len(ordered) // 2)])\n")],
        [GUIDE_TEST, "-k", "order_or_cut"]),
    "guide-run-grids-dropped": (
        "the splatting threads' other runs are counted but their energy is never added",
        [("ptrace/guiding.py", "            self.grid += grids[j]\n", "")],
        [GUIDE_TEST, "-k", "splatting_on_threads"]),
    "guide-splat-turned-the-wrong-way": (
        "records are splatted into a leaf's parallax frame turned by the frame's rotation, not "
        "by its inverse",
        [("ptrace/guiding.py", "    dx, dy, dz = turn(vx, vy, vz, c, -1.0, dx, dy, dz)\n",
          "    dx, dy, dz = turn(vx, vy, vz, c, 1.0, dx, dy, dz)\n")],
        [GUIDE_TEST, "-k", "parallax"]),
    "guide-pdf-not-turned-back": (
        "the guide's pdf looks a direction up in the leaf's quadtree without turning it back "
        "into the leaf's frame (the samples are turned)",
        [(GUIDE, "    ax, ay, az = turn(vx, vy, vz, vc, -1.0, dx, dy, dz)\n",
          "    ax, ay, az = dx, dy, dz\n")],
        [GUIDE_TEST, "-k", "turned"]),
    "guide-box-filter-across-normals": (
        "the box filter splats a record into the leaves of every normal's tree, not only its "
        "own normal's",
        [("ptrace/guiding.py",
          "            if axis[node] == 3:   # (the record's own bucket only)\n",
          "            if axis[node] == 99:\n")],
        [GUIDE_TEST, "-k", "facing"]),
    "guide-headroom-unweighted": (
        "auto's headroom averages the leaves' second moments over their mean squared with equal "
        "weights, not by their light",
        [("ptrace/guiding.py",
          "    return float(np.sum(n[lit] * second[lit] / first[lit])) / total\n",
          "    return float(np.mean(n[lit] * second[lit] / first[lit] ** 2))\n")],
        [GUIDE_TEST, "-k", "headroom"]),
    "light-tree-u-not-rescaled": (
        "the light tree's walk reuses u at every step instead of rescaling it within the "
        "chosen lane's interval",
        [("ptrace/light_tree.py", "            u = min(max((x - low) / c[j], 0.0), "
          "ONE_MINUS_EPSILON)\n", "")],
        ["tests/ptrace/test_light_tree.py", "-k", "frequency or interval"]),
}


def tree_files():
    """Tracked and untracked (not ignored) files of the working tree, as paths under ROOT."""
    out = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, check=True,
                         capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if (ROOT / line).is_file()]


def scratch_copy(files, directory):
    for name in files:
        target = directory / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, target)


def apply(directory, edits):
    for name, text, replacement in edits:
        path = directory / name
        source = path.read_text()
        if source.count(text) != 1:
            raise SystemExit(f"{name}: the mutant's text is found {source.count(text)} times, "
                             f"not once: {text!r}")
        path.write_text(source.replace(text, replacement))


def check(names):
    for name in names:
        for file, text, _ in MUTANTS[name][1]:
            count = (ROOT / file).read_text().count(text)
            if count != 1:
                raise SystemExit(f"{name}: {file}: text found {count} times: {text!r}")
    print(f"{len(names)} mutants: every text found exactly once")


def run_tests(directory, args):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(directory / ".numba-cache"),
               PYTHONDONTWRITEBYTECODE="1", PYTHONPATH=str(directory))
    env.setdefault("PTRACE_SCENES", str((ROOT.parent / "shared" / "scenes" / "cs184").resolve()))
    probe = subprocess.run([sys.executable, "-c", "import ptrace, accel; print(ptrace.__file__,"
                            " accel.__file__)"], cwd=directory, env=env, capture_output=True,
                           text=True)
    if not all(p.startswith(str(directory)) for p in probe.stdout.split()):
        raise SystemExit(f"the scratch copy is not what gets imported: {probe.stdout}"
                         f"{probe.stderr}")
    start = time.perf_counter()
    # one process (-n 0): xdist reports -x's stop as an interruption (exit 2), not a failure
    result = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-n", "0", "-p",
                             "no:cacheprovider", *args], cwd=directory, env=env,
                            capture_output=True, text=True)
    lines = [line for line in result.stdout.splitlines() if line.strip()] or [""]
    return result.returncode, time.perf_counter() - start, lines[-1], lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="mutants to run (default: all)")
    parser.add_argument("--check", action="store_true", help="only check the mutants' texts")
    args = parser.parse_args(argv)
    names = args.names or list(MUTANTS)
    unknown = [n for n in names if n not in MUTANTS]
    if unknown:
        raise SystemExit(f"unknown mutant(s): {', '.join(unknown)}; known: {', '.join(MUTANTS)}")
    check(names)
    if args.check:
        return 0
    files = tree_files()
    rows = []
    started = time.strftime("%Y-%m-%d %H:%M")
    with tempfile.TemporaryDirectory(prefix="ptrace-mutants-") as temp:
        base = Path(temp) / "unmutated"
        scratch_copy(files, base)
        tests = sorted({a for n in names for a in MUTANTS[n][2] if a.endswith(".py")})
        code, seconds, tail, lines = run_tests(base, tests)
        print(f"unmutated: {tail} ({seconds:.0f} s)", flush=True)
        if code != 0:
            print("\n".join(lines[-30:]))
            raise SystemExit("the unmutated copy fails its tests: fix the suite first")
        for name in names:
            what, edits, test_args = MUTANTS[name]
            directory = Path(temp) / name
            scratch_copy(files, directory)
            apply(directory, edits)
            code, seconds, tail, _ = run_tests(directory, test_args)
            verdict = "killed" if code == 1 else "SURVIVED" if code == 0 else f"error ({code})"
            print(f"{name}: {verdict} in {seconds:.0f} s: {tail}", flush=True)
            rows.append((name, what, " ".join(test_args), verdict, seconds, tail))
            shutil.rmtree(directory, ignore_errors=True)
    survivors = [r[0] for r in rows if r[3] != "killed"]
    if not args.names:
        lines = ["# Mutation check", "",
                 f"- date: {started}; command: `python tests/mutants.py`",
                 f"- {len(rows)} mutants, {len(rows) - len(survivors)} killed"
                 + (f"; not killed: {', '.join(survivors)}" if survivors else ""), "",
                 "Each mutant is planted alone in a scratch copy of the working tree, run with a "
                 "fresh numba cache against the tests that should catch it (`pytest -x`); the "
                 "unmutated copy passed the same test files first. Killed: those tests failed.", "",
                 "| mutant | planted bug | tests | result | seconds | pytest's last line |",
                 "|---|---|---|---|---:|---|"]
        lines += [f"| {n} | {w} | `{t}` | {v} | {s:.0f} | {tail} |"
                  for n, w, t, v, s, tail in rows]
        REPORT.write_text("\n".join(lines) + "\n")
        print(f"report: {REPORT}")
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main())
