"""Path guiding's training: the guide (ptrace.kernel.guide.GuideArrays) learnt from the records of
the training passes, after Müller, Gross and Novák 2017 ("Practical Path Guiding").

A spatial binary tree over the scene's box made cubic, each split at the middle of a node's box
on x, y, z in turn, and a directional quadtree per leaf over the equal-area square of the
sphere. While an iteration renders, the records (position, direction, luminance of the radiance
the bounce brought back over its pdf) are counted per leaf of the tree being filled and their
energy summed into a fixed RESOLUTION x RESOLUTION grid of directions per leaf. At the end of an
iteration each leaf's quadtree is made from its grid (the energy of every iteration so far:
each record is an unbiased estimate whatever pdf drew it) (a quadrant is divided while it holds more
than ENERGY_SHARE of the leaf's energy, down to the grid's cells), and that guide samples the
next iteration; then each leaf that counted more than SPLIT_SAMPLES x sqrt(passes of the
iteration) records splits (its children counted as halves, again, up to MAX_LEAVES leaves) for
the next iteration's records.

Records of each block of a pass are kept by (first sample, first row) and summed in that order
once the pass is over, so the guide is the same whatever the threads or the order they finish.
Memory: the grids (MAX_LEAVES x RESOLUTION^2 float64, 32 MB at most), the quadtrees (at most
1 + LEVELS / ENERGY_SHARE nodes of 64 bytes a leaf, 39 MB) and one pass's records.
"""
import math
import threading

import numpy as np
from numba import njit

from .kernel.guide import GuideArrays, guide_leaf, sphere_to_square

RESOLUTION = 64          # grid cells per side of a leaf's directions: quadtree depth <= 6
LEVELS = 6               # log2(RESOLUTION)
MAX_LEAVES = 1024        # spatial leaves at most
SPLIT_SAMPLES = 4000     # a leaf splits past this many records x sqrt(the iteration's passes)
ENERGY_SHARE = 0.01      # a quadrant is divided above this share of its leaf's energy
ALPHA = 0.5              # the guide's share of the bounces
TRAIN_SHARE = 0.25       # training passes take at most this share of -s


def schedule(spp, first=1):
    """The training iterations' passes (first, 2 first, 4 first, ...) while their total stays
    within TRAIN_SHARE of spp (at least one sample is left for the final image)."""
    out, total, n = [], 0, first
    while total + n <= TRAIN_SHARE * spp and total + n < spp:
        out.append(n)
        total += n
        n *= 2
    return out


class SpatialTree:
    """The spatial binary tree as growing lists: axis (-1 for a leaf), split, first child, and
    each leaf's number (in leaf order) with its box."""

    def __init__(self, lower, upper):
        lower, upper = np.asarray(lower, float), np.asarray(upper, float)
        centre = 0.5 * (lower + upper)
        half = 0.5 * float(np.max(upper - lower)) * 1.001 + 1e-9 * (1.0 + np.abs(centre).max())
        self.axis, self.split, self.child = [-1], [0.0], [0]
        self.lower, self.upper, self.depth = [centre - half], [centre + half], [0]

    def leaves(self):
        """The leaf nodes, in node order (leaf number k is leaves()[k])."""
        return [j for j, a in enumerate(self.axis) if a < 0]

    def arrays(self, root=None):
        """(axis, split, child, root): root[j] of leaf j is `root` of its leaf number (default
        the leaf number itself)."""
        leaves = self.leaves()
        roots = np.zeros(len(self.axis), dtype=np.int64)
        for k, j in enumerate(leaves):
            roots[j] = k if root is None else root[k]
        return (np.array(self.axis, dtype=np.int64), np.array(self.split, dtype=np.float64),
                np.array(self.child, dtype=np.int64), roots)

    def refine(self, counts, threshold):
        """Split each leaf whose count passes threshold, its children counted as halves, until
        none does or the tree has MAX_LEAVES leaves. Returns, for each leaf of the new tree (in
        leaf order), the number of the old leaf it lies in and its share of that leaf's volume."""
        old = self.leaves()
        origin = {j: (k, 1.0) for k, j in enumerate(old)}
        pending = [(j, float(c)) for j, c in zip(old, counts)]
        leaves = len(pending)
        while pending and leaves < MAX_LEAVES:
            j, count = pending.pop(0)
            if count <= threshold:
                continue
            a = self.depth[j] % 3
            middle = 0.5 * (self.lower[j][a] + self.upper[j][a])
            first = len(self.axis)
            for side in (0, 1):
                low, high = self.lower[j].copy(), self.upper[j].copy()
                if side == 0:
                    high[a] = middle
                else:
                    low[a] = middle
                self.axis.append(-1)
                self.split.append(0.0)
                self.child.append(0)
                self.lower.append(low)
                self.upper.append(high)
                self.depth.append(self.depth[j] + 1)
                pending.append((first + side, 0.5 * count))
                origin[first + side] = (origin[j][0], 0.5 * origin[j][1])
            self.axis[j], self.split[j], self.child[j] = a, middle, first
            leaves += 1
        return [origin[j] for j in self.leaves()]


@njit(cache=True, nogil=True)
def accumulate(axis, split, child, root, records, counts, grid):
    """Each record (column of records) counted in its leaf and its energy added to the leaf's
    grid cell of its direction, in column order."""
    for k in range(records.shape[1]):
        leaf = guide_leaf(axis, split, child, root, records[0, k], records[1, k], records[2, k])
        counts[leaf] += 1
        x, y = sphere_to_square(records[3, k], records[4, k], records[5, k])
        cell = int(y * RESOLUTION) * RESOLUTION + int(x * RESOLUTION)
        grid[leaf, cell] += records[6, k]


@njit(cache=True)
def build_quadtrees(grid, share):
    """The quadtrees of each leaf's grid: (q_child, q_energy, roots). A quadrant is divided
    while its energy is above `share` of its leaf's total and above a grid cell; a leaf
    without energy gets a root of zeros (uniform)."""
    leaves = grid.shape[0]
    capacity = leaves * (1 + int(math.ceil(1.0 / share)) * LEVELS) + 1
    q_child = np.full((capacity, 4), -1, dtype=np.int64)
    q_energy = np.zeros((capacity, 4))
    roots = np.zeros(leaves, dtype=np.int64)
    offsets = np.zeros(LEVELS + 2, dtype=np.int64)
    for level in range(LEVELS + 1):
        offsets[level + 1] = offsets[level] + (1 << (2 * level))
    pyramid = np.zeros(offsets[LEVELS + 1])
    stack = np.zeros((capacity, 4), dtype=np.int64)
    nodes = 0
    for leaf in range(leaves):
        top = offsets[LEVELS]
        for c in range(RESOLUTION * RESOLUTION):
            pyramid[top + c] = max(grid[leaf, c], 0.0)
        for level in range(LEVELS - 1, -1, -1):
            side, fine = 1 << level, 1 << (level + 1)
            for cy in range(side):
                for cx in range(side):
                    f = offsets[level + 1] + 2 * cy * fine + 2 * cx
                    pyramid[offsets[level] + cy * side + cx] = (
                        pyramid[f] + pyramid[f + 1] + pyramid[f + fine] + pyramid[f + fine + 1])
        total = pyramid[0]
        roots[leaf] = nodes
        nodes += 1
        if not total > 0.0:
            continue
        stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = roots[leaf], 0, 0, 0
        pending = 1
        while pending:
            pending -= 1
            node, level, cx, cy = stack[pending, 0], stack[pending, 1], stack[pending, 2], \
                stack[pending, 3]
            fine = 1 << (level + 1)
            for q in range(4):
                x, y = 2 * cx + (q & 1), 2 * cy + (q >> 1)
                energy = pyramid[offsets[level + 1] + y * fine + x]
                q_energy[node, q] = energy
                if level + 1 < LEVELS and energy > share * total:
                    q_child[node, q] = nodes
                    stack[pending, 0], stack[pending, 1] = nodes, level + 1
                    stack[pending, 2], stack[pending, 3] = x, y
                    pending += 1
                    nodes += 1
    return q_child[:nodes].copy(), q_energy[:nodes].copy(), roots


class Trainer:
    """The records of a training iteration, summed per leaf of the tree being filled, and the
    guides made from them. Blocks hand their records in through add (from any thread); merge,
    after a pass, sums them in (first sample, first row) order."""

    def __init__(self, lower, upper, split_samples=SPLIT_SAMPLES):
        self.tree = SpatialTree(lower, upper)
        self.split_samples = split_samples
        self._lock = threading.Lock()
        self._blocks = {}
        self.records = 0
        self.begin()

    def begin(self, origin=None):
        """Start an iteration: zero counts, and grids over the tree's leaves that start from
        the last iteration's energy (origin: each leaf's old leaf and share, from
        SpatialTree.refine), or from zero."""
        leaves = len(self.tree.leaves())
        self.counts = np.zeros(leaves, dtype=np.int64)
        if origin is None:
            self.grid = np.zeros((leaves, RESOLUTION * RESOLUTION))
        else:
            self.grid = np.array([self.grid[k] * share for k, share in origin])
        self._arrays = self.tree.arrays()

    def add(self, key, records):
        """One block's records (RECORD_ROWS, n), keyed by its place in the pass."""
        with self._lock:
            self._blocks[key] = records

    def merge(self):
        """Sum the blocks handed in so far, in key order, and forget them."""
        with self._lock:
            blocks, self._blocks = self._blocks, {}
        axis, split, child, root = self._arrays
        for key in sorted(blocks):
            records = np.ascontiguousarray(blocks[key])
            self.records += records.shape[1]
            accumulate(axis, split, child, root, records, self.counts, self.grid)

    def finish(self, passes, alpha=ALPHA):
        """End an iteration of `passes` passes: the guide made from its records (to sample the
        next iteration), and the tree refined for the next one's records."""
        self.merge()
        q_child, q_energy, roots = build_quadtrees(self.grid, ENERGY_SHARE)
        axis, split, child, root = self.tree.arrays(roots)
        guide = GuideArrays(axis, split, child, root, q_child, q_energy, float(alpha), 1)
        self.begin(self.tree.refine(self.counts, self.split_samples * math.sqrt(passes)))
        return guide


def guide_bytes(guide):
    """The memory a guide's arrays hold."""
    return sum(a.nbytes for a in guide if isinstance(a, np.ndarray))


def relative_variance(sum_l, sum_l2, count):
    """The per-sample variance of each pixel's illuminance over the pixels' mean illuminance
    squared, over pixels of at least two samples (inf when there are none)."""
    n = count.astype(np.float64)
    use = n >= 2
    if not use.any():
        return math.inf
    mean = sum_l[use] / n[use]
    variance = np.maximum(sum_l2[use] - sum_l[use] * mean, 0.0) / (n[use] - 1)
    level = float(np.mean(mean))
    return float(np.mean(variance)) / (level * level) if level > 0 else math.inf


def train(job, pixel_x, pixel_y, spp, mode="on", on_chunk=None):
    """Train job's guide (its wavefront must be guided) on the pixels: the iterations of
    schedule(spp) (under mode "auto", from 2 passes, the first unguided so the guided ones'
    variance can be compared with it), on samples spp - training .. spp - 1. Sets the guide
    the rest of the render samples with (under "auto", alpha 0 when the last guided iteration's
    relative_variance is not below the first's). Returns (training samples, figures, images):
    images, for combine, holds each guided iteration's samples, relative variance and mean
    radiance per pixel."""
    from .rendering.tiles import new_sums
    wavefront = job.wavefront
    plan = schedule(spp, 2 if mode == "auto" else 1)
    total = sum(plan)
    bounds = job.scene.geometry.bounds()
    figures = dict(iterations=plan, training_samples=total, records=0, guide_bytes=0,
                   variance=[], guided=True)
    images = []
    if not plan or bounds is None:
        return 0, figures, images
    trainer = Trainer(*bounds)
    rows = np.arange(pixel_x.shape[0])
    first = spp - total
    wavefront.guide = GuideArrays(*wavefront.guide[:6], 0.0, 1)
    wavefront.trainer = trainer
    try:
        for passes in plan:
            sums = new_sums(pixel_x.shape[0])
            for s in range(passes):
                job.trace(pixel_x, pixel_y, first, 1, sums, rows, on_chunk)
                trainer.merge()
                first += 1
            variance = relative_variance(*sums[1:])
            figures["variance"].append(variance)
            if wavefront.guide.alpha > 0 and math.isfinite(variance):
                images.append((passes, variance, sums[0] / np.maximum(sums[3], 1)[:, None]))
            wavefront.guide = trainer.finish(passes)
    finally:
        wavefront.trainer = None
    guide = wavefront.guide
    if mode == "auto" and len(plan) > 1 and \
            not figures["variance"][-1] < figures["variance"][0]:
        figures["guided"] = False
    wavefront.guide = GuideArrays(*guide[:6], ALPHA if figures["guided"] else 0.0, 0)
    figures.update(records=trainer.records, guide_bytes=guide_bytes(guide),
                   leaves=len(trainer.tree.leaves()))
    return total, figures, images if figures["guided"] else []


def combine(sums, images):
    """The final passes' sums (rgb, l, l2, count) rescaled in place so that their mean per
    pixel is the combination of their image with the training iterations' images, each
    weighted by its samples over its relative_variance (the 2019 course's inverse-variance
    combination); the counts stay the final passes'. Returns the weights, the final image's
    last."""
    sum_rgb, sum_l, sum_l2, count = sums
    variance = relative_variance(sum_l, sum_l2, count)
    if not images or not math.isfinite(variance) or not variance > 0:
        return []
    n = np.maximum(count, 1)[:, None]
    weights = [samples / v for samples, v, _ in images] + [float(np.mean(count)) / variance]
    total = sum(weights)
    mean = sum_rgb / n * (weights[-1] / total)
    for w, (_, _, image) in zip(weights, images):
        mean += image * (w / total)
    sum_rgb[:] = mean * n
    return [w / total for w in weights]
