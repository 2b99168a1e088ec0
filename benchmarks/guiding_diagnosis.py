"""Path guiding's diagnosis: how close the learnt guide comes, at a few points, to the incident
radiance brute-forced there by ptrace's own unguided wavefront.

    python -m benchmarks.guiding_diagnosis [--scene ceiling|door] [--spp 64] [--size 128]
                                           [--paths 64]

Renders the scene guided (--spp, -m as benchmarks.guiding) and keeps the guide it trained.
Then, from each point, traces --paths unguided paths through each of 32 x 32 equal-area cells
of directions (depth -m minus 1: the point is a path's first vertex) and prints the relative
variance of a one-sample estimate of the light the point reflects diffusely (the integral of
L cos, the later path's noise included) under: cosine sampling; the learnt mixture (the leaf's
share of its guide, the rest cosine); the ideal guide (density proportional to the
brute-forced L above the surface, half and half with the cosine); and the product L cos (what
the later path's noise alone leaves). Also: the share of the light in the top 2% of the cells,
and the learnt guide's mass there. Prints only; nothing is written.
"""
import argparse

import numpy as np

from .guiding import CASES, SCENES

POINTS = {"guiding_ceiling.xml": [((-0.5, -0.999, 0.6), (0, 1, 0)),
                                  ((0.5, -0.999, -0.5), (0, 1, 0)),
                                  ((0.0, -0.999, 0.0), (0, 1, 0)),
                                  ((-0.999, 0.0, 0.5), (1, 0, 0))],
          "guiding_door.xml": [((-0.5, -0.999, 0.0), (0, 1, 0)),
                               ((-1.999, 0.0, 0.0), (1, 0, 0)),
                               ((0.0, 0.999, -0.5), (0, -1, 0))]}
RES = 32


def brute(wavefront, point, paths, rng, pixels):
    """Each cell's paths' luminance (cells, paths): unguided paths leaving `point` through
    jittered directions of the cell."""
    from accel.compiled import new_scratch
    from ptrace.kernel import layout as L
    cells = RES * RES
    n = cells * paths
    c = np.repeat(np.arange(cells), paths)
    x = ((c % RES) + rng.random(n)) / RES
    y = ((c // RES) + rng.random(n)) / RES
    z = 2 * x - 1
    r = np.sqrt(np.maximum(0, 1 - z * z))
    d = np.stack([r * np.cos(2 * np.pi * y), r * np.sin(2 * np.pi * y), z], 1)
    out = np.zeros(n)
    wave, scratch = wavefront.new_wave(), new_scratch(wavefront.accel)
    f, i, q = wave.floats, wave.ints, wave.queue
    for s in range(0, n, wave.size):
        m = min(wave.size, n - s)
        for k in range(3):
            f[L.OX + k, :m] = point[k]
            f[L.DX + k, :m] = d[s:s + m, k]
        f[L.TMIN, :m], f[L.TMAX, :m] = 1e-4, np.inf
        f[L.TR, :m] = f[L.TG, :m] = f[L.TB, :m] = 1.0
        f[L.R, :m] = f[L.G, :m] = f[L.B, :m] = 0.0
        i[L.PIXEL, :m] = (np.arange(s, s + m) // paths) % pixels
        i[L.SAMPLE, :m] = np.arange(s, s + m) % paths + 1000
        i[L.VERTEX, :m] = 0
        i[L.RAYS, :m] = 1
        i[L.DELTA, :m] = i[L.KEY, :m] = 0
        q[:m] = np.arange(m)
        wavefront.paths(wave, scratch, m)
        out[s:s + m] = (f[L.R, :m] + f[L.G, :m] + f[L.B, :m]) / 3
    return out.reshape(cells, paths)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.guiding_diagnosis")
    parser.add_argument("--scene", choices=("ceiling", "door"), default="ceiling")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--paths", type=int, default=64)
    args = parser.parse_args(argv)
    import ptrace
    import ptrace.rendering.executors as executors
    from ptrace.kernel.guide import guide_node, guide_pdf, guide_turn, normal_bucket, uniform_guide
    name = f"guiding_{args.scene}.xml"
    depth = dict(CASES)[name]
    kept = {}
    train = executors.train

    def keep(job, *a, **k):   # the guided render's job, with the guide it trained
        result = train(job, *a, **k)
        kept["job"] = job
        return result

    executors.train = keep
    try:
        scene = ptrace.load(str(SCENES / name), defines={"res": str(args.size)})
        stats = {}
        ptrace.render(scene, spp=args.spp, max_depth=depth, resolution=(args.size, args.size),
                      threads=2, guiding="on", stats=stats, seed=1)
    finally:
        executors.train = train
    wavefront = kept["job"].wavefront
    guide = wavefront.guide
    figures = stats["guiding"]
    print(f"{name} {args.size}x{args.size} -s {args.spp} -m {depth}: leaves "
          f"{int((guide.axis < 0).sum())}, quadtree nodes {guide.q_child.shape[0]}, records "
          f"{figures['records']}, training samples {figures['training_samples']}")
    wavefront.trainer, wavefront.guide = None, uniform_guide()
    wavefront.options = wavefront.options._replace(max_depth=depth - 1)
    cells = RES * RES
    cx = ((np.arange(cells) % RES) + 0.5) / RES
    cy = ((np.arange(cells) // RES) + 0.5) / RES
    z = 2 * cx - 1
    r = np.sqrt(1 - z * z)
    centres = np.stack([r * np.cos(2 * np.pi * cy), r * np.sin(2 * np.pi * cy), z], 1)
    solid = 4 * np.pi / cells
    rng = np.random.default_rng(5)
    print("| point | cosine | learnt mixture (share) | ideal 50/50 | product | light in top 2% "
          "| learnt mass there |")
    print("|---|---|---|---|---|---|---|")
    for point, normal in POINTS[name]:
        values = brute(wavefront, np.array(point), args.paths, rng, args.size * args.size)
        mean, square = values.mean(1), (values ** 2).mean(1)
        cos = np.maximum(centres @ np.array(normal, float), 0.0)
        up = cos > 0
        light = (mean * cos).sum() * solid

        def relvar(pdf):
            return (square[up] * cos[up] ** 2 / np.maximum(pdf[up], 1e-30)).sum() * solid \
                / light ** 2 - 1

        node = guide_node(guide.axis, guide.split, guide.child, *point,
                          normal_bucket(*normal))
        leaf, turned = guide.root[node], guide_turn(guide, node, *point)
        share = guide.alpha * guide.share[leaf]
        learnt = np.array([guide_pdf(guide, leaf, *centres[k], *turned) for k in range(cells)])
        ideal = mean * up / ((mean * up).sum() * solid)
        top = np.argsort(-(mean * cos))[:cells // 50]
        print(f"| {point} | {relvar(cos / np.pi):.1f} | "
              f"{relvar(share * learnt + (1 - share) * cos / np.pi):.1f} ({share:.2f}) | "
              f"{relvar(0.5 * ideal + 0.5 * cos / np.pi):.1f} | "
              f"{relvar(mean * cos / light):.1f} | "
              f"{(mean * cos)[top].sum() / (mean * cos).sum():.2f} | "
              f"{(learnt[top] * solid).sum():.2f} |", flush=True)


if __name__ == "__main__":
    main()
