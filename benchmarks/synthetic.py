"""Deterministic synthetic meshes of a chosen triangle count, for scaling benchmarks.

displaced_torus(triangles) is a torus (major radius 1, minor radius 0.4) on a rows x 2*rows grid
of quads, two triangles each, so it has exactly 4 * rows**2 triangles (1,024 = 2**10 up to
1,048,576 = 2**20 for rows = 16..512) and no degenerate triangle (a sphere's grid collapses at
the poles). The minor radius is displaced by a fixed sum of sinusoids with integer frequencies
(periodic on the torus) and seeded phases, so every size is the same bumpy shape sampled finer:
rays hit the same surface whatever the count, and only the triangle count changes.
"""
import numpy as np

SERIES = (1024, 4096, 16384, 65536, 262144, 1048576)   # 4 * rows**2 for rows = 16 .. 512
QUICK_SERIES = (1024, 16384, 65536)


def displaced_torus(triangles, seed=0, bumps=0.08):
    """(vertices, faces) of a displaced torus with exactly `triangles` triangles (4 * rows**2)."""
    rows = round(float(np.sqrt(triangles / 4)))
    if rows < 2 or 4 * rows * rows != triangles:
        raise ValueError(f"triangles must be 4 * rows**2 with rows >= 2, not {triangles}")
    cols = 2 * rows
    rng = np.random.default_rng(seed)
    u = 2 * np.pi * np.arange(cols) / cols            # around the major circle
    v = 2 * np.pi * np.arange(rows) / rows            # around the tube
    uu, vv = np.meshgrid(u, v, indexing="ij")         # (cols, rows)
    minor = np.full(uu.shape, 0.4)
    for _ in range(8):
        fu, fv = rng.integers(1, 7, size=2)
        phase_u, phase_v = rng.random(2) * 2 * np.pi
        minor += bumps / 8 * 4 * np.sin(fu * uu + phase_u) * np.sin(fv * vv + phase_v)
    ring = 1.0 + minor * np.cos(vv)
    vertices = np.stack([ring * np.cos(uu), minor * np.sin(vv), ring * np.sin(uu)], axis=-1)
    vertices = vertices.reshape(-1, 3)
    i, j = np.meshgrid(np.arange(cols), np.arange(rows), indexing="ij")
    a = i * rows + j
    b = ((i + 1) % cols) * rows + j
    c = ((i + 1) % cols) * rows + (j + 1) % rows
    d = i * rows + (j + 1) % rows
    faces = np.concatenate([np.stack([a, b, c], axis=-1).reshape(-1, 3),
                            np.stack([a, c, d], axis=-1).reshape(-1, 3)])
    return vertices, faces


def name(triangles):
    """Row label: torus-1k, torus-16k, torus-1M ..."""
    if triangles >= 1 << 20 and triangles % (1 << 20) == 0:
        return f"torus-{triangles >> 20}M"
    if triangles % 1024 == 0:
        return f"torus-{triangles >> 10}k"
    return f"torus-{triangles}"
