"""Path guiding's training: the guide (ptrace.kernel.guide.GuideArrays) learnt from the records of
the training passes, after Müller, Gross and Novák 2017 ("Practical Path Guiding").

A spatial binary tree over the scene's box made cubic, each split at the middle of a node's box
on x, y, z in turn (below first levels that split by which way the surface's normal faces,
NORMALS), and a directional quadtree per leaf over the equal-area square of the
sphere. While an iteration renders, the records (position, direction, luminance of the radiance
the bounce brought back over its pdf) are counted per leaf of the tree being filled and their
energy summed into a fixed RESOLUTION x RESOLUTION grid of directions per leaf (with BOX, the
2019 course's box filter: shared among the leaves that a box the size of the record's leaf,
centred on it, overlaps, by volume). Each leaf has a parallax frame (leaf_frames): the point
its records' rays reached, weighted by their energy (the spot its light mostly comes from), from
the records so far; a record's direction is turned into the frame of each leaf it goes to, as
if seen from the leaf's centre, and the guide turns it back toward the focus from the shading
point (ptrace.kernel.guide.frame_turn), so a leaf's light is not smeared over the views of it
from across the leaf. At the end of an
iteration each leaf's quadtree is made from its grid (the energy of every iteration so far:
each record is an unbiased estimate whatever pdf drew it) (a quadrant is divided while it holds more
than ENERGY_SHARE of the leaf's energy, down to the grid's cells), and that guide samples the
next iteration; then each leaf that counted more than SPLIT_SAMPLES x sqrt(passes of the
iteration) records splits (its children counted as halves, again, up to MAX_LEAVES leaves) for
the next iteration's records.

Records of each block of a chunk of passes are kept by (first sample, first row) and, once the
chunk is over, put in that order and cut into PARTS runs of equal count, each splatted on a
thread of its own into a grid of its own, the grids then added in run order: the guide is the
same whatever the threads, the blocks or the order they finish. Training takes up to
TRAIN_SHARE of the samples; its images are not lost (ptrace.guiding.combine).
Memory: the grids (MAX_LEAVES x RESOLUTION^2 float64, 32 MB at most, and as much again for the
other runs' grids while a chunk is merged), the quadtrees (at most 1 + LEVELS / ENERGY_SHARE
nodes of 48 bytes a leaf, 30 MB) and one chunk's records.
"""
import math
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from .kernel.guide import (
    BUCKETS,
    R_BSDF,
    R_DX,
    R_ENERGY,
    R_F,
    R_NX,
    R_PDF,
    R_T,
    GuideArrays,
    frame_turn,
    guide_node,
    guide_pdf,
    guide_turn,
    normal_bucket,
    sphere_to_square,
    turn,
    uniform_guide,
)

RESOLUTION = 64          # grid cells per side of a leaf's directions: quadtree depth <= 6
LEVELS = 6               # log2(RESOLUTION)
MAX_LEAVES = 1024        # spatial leaves at most
SPLIT_SAMPLES = 1000     # a leaf splits past this many records x sqrt(the iteration's passes)
SPLIT_PIXELS = 4         # ... or past (pixels / SPLIT_PIXELS) x sqrt(passes), if fewer
SPLIT_LEAST = 500        #     but at least this many
ENERGY_SHARE = 0.01      # a quadrant is divided above this share of its leaf's energy
ALPHA = 0.5              # the guide's share of the bounces where it is fixed (learn=False)
SHARES = np.linspace(0.0, 0.9, 10)   # the guide's shares a spatial leaf learns from
SHARE_RECORDS = 256      # a leaf with fewer records takes the share learnt over all records
KEEP_RECORDS = 1 << 17   # records kept per iteration to learn the shares (thinned evenly)
TRAIN_SHARE = 0.25       # training passes take at most this share of -s (0.5: less error
#                           per sample, more per second on the door ajar; guiding.md)
TRAIN_MOST = 32          # ... and at most this many passes (at 256 spp the guide learnt no
#                           more from 63 than from 31; guiding.md)
CHUNK = 4                # training passes traced in one call, their records merged after it
PARTS = 2                # runs of a merge's records splatted on threads of their own
PART_LEAST = 4096        # ... of at least this many records each
LEARN = True             # learn each spatial leaf's share (else ALPHA everywhere)
COSINE = False           # learn incident light times the cosine (accumulate)
BOX = True               # splat records into the leaves a box filter overlaps (accumulate)
CARRY = True             # a new iteration's grids start from the last one's energy
PARALLAX = True          # turn each leaf's directions toward its focus point (leaf_frames)
FOCUS_LEAST = 1.0        # ... where the focus is this many half diagonals from its centre
NORMALS = True           # the spatial tree's first levels split by the normal's bucket
# --guiding auto: an unguided first iteration of PROBE passes (part of the unguided image if
# the guide is turned off), whose records give the bounces' headroom (headroom()): how
# far the BSDF's choice of direction is from the best one, which bounds what any guide can
# gain at a vertex. Below HEADROOM the guide is off for the rest of the render. Above it,
# training goes on, and the guide is off for the final passes if the last training
# iteration's variance per sample is not below the probe's.
PROBE = 2                  # (at most CHUNK: the probe's records are all held until it decides)
AUTO_LEAST = 32            # fewer samples than this: auto is off (the probe's records cost
#                            about as much as an unguided sample)
HEADROOM = 32.0            # measured (six seeds each, 64 spp): the course's diffuse boxes and
#                            cornell.dae 1.9-2.2, CBspheres 11.6-12.8 (mirror, glass),
#                            scenes/mitsuba/envmap.xml 17-25 (no gain per sample); the lamp
#                            facing the ceiling 60-178, the door ajar 53-69, and their glossy
#                            variants 55-176


def split_samples(pixels):
    """The spatial tree's split threshold (times sqrt(passes)) for an image of `pixels`."""
    return max(SPLIT_LEAST, min(SPLIT_SAMPLES, pixels // SPLIT_PIXELS))


def schedule(spp, first=1):
    """The training iterations' passes (first, 2 first, 4 first, ...) while their total stays
    within TRAIN_SHARE of spp and TRAIN_MOST (at least one sample is left for the final
    image)."""
    out, total, n = [], 0, first
    while total + n <= min(TRAIN_SHARE * spp, TRAIN_MOST) and total + n < spp:
        out.append(n)
        total += n
        n *= 2
    return out


class SpatialTree:
    """The spatial binary tree as growing lists: axis (-1 for a leaf), split, first child, and
    each leaf's number (in leaf order) with its box. With `normals` (NORMALS), its first levels
    split on the normal's bucket (axis 3, ptrace.kernel.guide.normal_bucket): a tree over the
    whole box for each of the six, so that a leaf's surfaces face one way (a floor's guide
    does not learn a wall's light, much of which would point below the floor)."""

    def __init__(self, lower, upper, normals=None):
        lower, upper = np.asarray(lower, float), np.asarray(upper, float)
        centre = 0.5 * (lower + upper)
        half = 0.5 * float(np.max(upper - lower)) * 1.001 + 1e-9 * (1.0 + np.abs(centre).max())
        self.axis, self.split, self.child = [-1], [0.0], [0]
        self.lower, self.upper, self.depth = [centre - half], [centre + half], [0]
        if NORMALS if normals is None else normals:
            pending = [(0, 0, BUCKETS)]   # (node, its buckets [low, high))
            while pending:
                j, low, high = pending.pop(0)
                if high - low < 2:
                    continue
                middle = (low + high) // 2
                first = len(self.axis)
                for side in (0, 1):
                    self.axis.append(-1)
                    self.split.append(0.0)
                    self.child.append(0)
                    self.lower.append(self.lower[j].copy())
                    self.upper.append(self.upper[j].copy())
                    self.depth.append(0)
                self.axis[j], self.split[j], self.child[j] = 3, middle - 0.5, first
                pending += [(first, low, middle), (first + 1, middle, high)]

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


@njit(cache=True, nogil=True, forceinline=True)
def frame_cell(frames, leaf, px, py, pz, dx, dy, dz):
    """The grid cell of direction d from point p in leaf's parallax frame (d turned back)."""
    vx, vy, vz, c = frame_turn(frames, leaf, px, py, pz)
    dx, dy, dz = turn(vx, vy, vz, c, -1.0, dx, dy, dz)
    x, y = sphere_to_square(dx, dy, dz)
    return int(y * RESOLUTION) * RESOLUTION + int(x * RESOLUTION)


@njit(cache=True, nogil=True)
def accumulate(axis, split, child, root, lower, upper, records, counts, grid, leaves, cosine,
               box, frames, focus):
    """Each record (column of records) counted in its leaf (written to leaves) and its energy
    added to the grid cell of its direction, in column order: to its leaf's, or with `box` (the
    2019 course's box filter) to every leaf that a box the size of its own leaf centred on the
    record overlaps, each its share of the box's volume within the tree's (lower, upper). With
    `cosine`, its energy times the cosine of its direction to its normal (the guide then learns
    incident light times the cosine, where a leaf's surfaces share a normal). A record's
    direction is turned, for each leaf it goes to, into that leaf's parallax frame (frames, per
    leaf number: ptrace.kernel.guide's frame rows; the inverse of the turn at the record's
    position). Each record's energy, and its energy times the point its ray reached, are added
    to its own leaf's row of focus (x, y, z, energy of points reached, energy of rays that left
    the scene)."""
    nodes = axis.shape[0]
    stack = np.empty(nodes + 1, dtype=np.int64)
    hit = np.empty(nodes, dtype=np.int64)
    weight = np.empty(nodes)
    bounds = np.empty((nodes, 6))   # each node's box (a child's index is past its parent's)
    for j in range(3):
        bounds[0, j], bounds[0, 3 + j] = lower[j], upper[j]
    for node in range(nodes):
        if axis[node] >= 0:
            first = child[node]
            for j in range(6):
                bounds[first, j] = bounds[first + 1, j] = bounds[node, j]
            if axis[node] < 3:   # (a split on the normal's bucket keeps the box)
                bounds[first, 3 + axis[node]] = split[node]    # the lower child
                bounds[first + 1, axis[node]] = split[node]    # the upper child
    for k in range(records.shape[1]):
        px, py, pz = records[0, k], records[1, k], records[2, k]
        bucket = normal_bucket(records[R_NX, k], records[R_NX + 1, k], records[R_NX + 2, k])
        node = guide_node(axis, split, child, px, py, pz, bucket)
        leaf = root[node]
        leaves[k] = leaf
        counts[leaf] += 1
        energy = records[R_ENERGY, k]
        if energy == 0.0:   # (most records: counted, with nothing to add)
            continue
        dx, dy, dz = records[R_DX, k], records[R_DX + 1, k], records[R_DX + 2, k]
        t = records[R_T, k]
        if t < math.inf:
            focus[leaf, 0] += energy * (px + t * dx)
            focus[leaf, 1] += energy * (py + t * dy)
            focus[leaf, 2] += energy * (pz + t * dz)
            focus[leaf, 3] += energy
        else:
            focus[leaf, 4] += energy
        if cosine:
            energy *= abs(dx * records[R_NX, k] + dy * records[R_NX + 1, k]
                          + dz * records[R_NX + 2, k])
        if not box:
            grid[leaf, frame_cell(frames, leaf, px, py, pz, dx, dy, dz)] += energy
            continue
        # the box of the record's leaf, centred on the record; the leaves it overlaps
        h0 = 0.5 * (bounds[node, 3] - bounds[node, 0])
        h1 = 0.5 * (bounds[node, 4] - bounds[node, 1])
        h2 = 0.5 * (bounds[node, 5] - bounds[node, 2])
        b = (px - h0, py - h1, pz - h2, px + h0, py + h1, pz + h2)
        stack[0] = 0
        top, found, total = 1, 0, 0.0
        while top:
            top -= 1
            node = stack[top]
            w = 1.0
            for j in range(3):
                w *= max(min(bounds[node, 3 + j], b[3 + j]) - max(bounds[node, j], b[j]), 0.0)
            if not w > 0.0:
                continue
            if axis[node] < 0:
                hit[found], weight[found] = root[node], w
                found += 1
                total += w
                continue
            if axis[node] == 3:   # (the record's own bucket only)
                stack[top] = child[node] + (0 if bucket < split[node] else 1)
                top += 1
                continue
            stack[top] = child[node]
            stack[top + 1] = child[node] + 1
            top += 2
        if not total > 0.0:
            grid[leaf, frame_cell(frames, leaf, px, py, pz, dx, dy, dz)] += energy
            continue
        for j in range(found):
            cell = frame_cell(frames, hit[j], px, py, pz, dx, dy, dz)
            grid[hit[j], cell] += energy * (weight[j] / total)


@njit(cache=True, nogil=True)
def keep_rows(records, leaves, first, stride):
    """learn_share's rows (leaf, F / p, p, the BSDF's pdf, direction, normal, position) of
    every stride-th record from `first`."""
    count = max(0, (records.shape[1] - first + stride - 1) // stride)
    out = np.empty((13, count))
    for j in range(count):
        k = first + j * stride
        out[0, j] = leaves[k]
        out[1, j], out[2, j], out[3, j] = records[R_F, k], records[R_PDF, k], records[R_BSDF, k]
        for c in range(3):
            out[4 + c, j] = records[R_DX + c, k]
            out[7 + c, j] = records[R_NX + c, k]
            out[10 + c, j] = records[c, k]
    return out


@njit(cache=True)
def learn_share(guide, leaves, kept, shares, least):
    """Each of `leaves` spatial leaves' share of the guide: of `shares`, the one whose mixture
    share g + (1 - share) b has the least estimated second moment of the bounce's estimate F / p
    over the leaf's kept records (rows: leaf, F / p under the pdf p that drew it, p, the BSDF's
    pdf b, direction, normal, position), mean of (F / p)^2 p / mixture; g is the pdf of
    `guide`, the guide that drew the records (so the records did not make it: no in-sample
    optimism). A leaf of fewer than `least` records takes the choice over all records."""
    k = shares.shape[0]
    moments = np.zeros((leaves + 1, k))
    counts = np.zeros(leaves + 1, dtype=np.int64)
    for r in range(kept.shape[1]):
        leaf = int(kept[0, r])
        counts[leaf] += 1
        counts[leaves] += 1
        x = kept[1, r]
        if not x > 0.0:
            continue
        node = guide_node(guide.axis, guide.split, guide.child, kept[10, r], kept[11, r],
                          kept[12, r], normal_bucket(kept[7, r], kept[8, r], kept[9, r]))
        vx, vy, vz, c = guide_turn(guide, node, kept[10, r], kept[11, r], kept[12, r])
        g = guide_pdf(guide, guide.root[node], kept[4, r], kept[5, r], kept[6, r], vx, vy, vz,
                      c)
        b, p = kept[3, r], kept[2, r]
        for a in range(k):
            q = shares[a] * g + (1.0 - shares[a]) * b
            m = x * x * p / q if q > 0.0 else math.inf
            moments[leaf, a] += m
            moments[leaves, a] += m
    out = np.zeros(leaves)
    best = shares[np.argmin(moments[leaves])] if counts[leaves] > 0 else 0.0
    for leaf in range(leaves):
        out[leaf] = shares[np.argmin(moments[leaf])] if counts[leaf] >= least else best
    return out


@njit(cache=True)
def build_quadtrees(grid, share):
    """The quadtrees of each leaf's grid: (q_child, q_density, roots). A quadrant is divided
    while its energy is above `share` of its leaf's total and above a grid cell; its density is
    4 x its share of its node's energy (ptrace.kernel.guide), and a leaf without energy gets a
    uniform root (densities 1)."""
    leaves = grid.shape[0]
    capacity = leaves * (1 + int(math.ceil(1.0 / share)) * LEVELS) + 1
    q_child = np.full((capacity, 4), -1, dtype=np.int32)
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
    for node in range(nodes):   # energies to densities (4 x e / total, as the walks used)
        total = q_energy[node, 0] + q_energy[node, 1] + q_energy[node, 2] + q_energy[node, 3]
        for q in range(4):
            q_energy[node, q] = 4.0 * q_energy[node, q] / total if total > 0.0 else 1.0
    return q_child[:nodes].copy(), q_energy[:nodes].copy(), roots


class Trainer:
    """The records of a training iteration, summed per leaf of the tree being filled, and the
    guides made from them. Blocks hand their records in through add (from any thread); merge,
    after a pass, sums them in (first sample, first row) order."""

    def __init__(self, lower, upper, split_samples=SPLIT_SAMPLES, learn=None, normals=None):
        self.tree = SpatialTree(lower, upper, normals)
        self.split_samples = split_samples
        self.learn = LEARN if learn is None else learn
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
        self.kept, self.seen, self.count = [], 0, 0
        self.stride = getattr(self, "stride", 1)   # (the last iteration's, a good first guess)
        self.keep = origin is not None   # (the first iteration's guide learns no share)
        if origin is None or not CARRY:
            self.grid = np.zeros((leaves, RESOLUTION * RESOLUTION))
        else:
            self.grid = np.array([self.grid[k] * share for k, share in origin])
        if origin is None:
            self.focus = np.zeros((leaves, 5))
        else:   # (every iteration's: the focus points settle as the records come in)
            self.focus = np.array([self.focus[k] * share for k, share in origin])
        self.frames = self.leaf_frames()
        self._arrays = self.tree.arrays()

    def leaf_frames(self):
        """Each leaf's parallax frame (ptrace.kernel.guide) for this iteration's records and the
        guide made from them: its box's centre and the mean of the points its records' rays
        reached, weighted by their energy, from the records so far. On (with PARALLAX) where
        most of the leaf's energy reached a point (not the sky), and that focus is more than
        FOCUS_LEAST half diagonals of the leaf's box from its centre."""
        leaves = self.tree.leaves()
        frames = np.zeros((len(leaves), 7))
        for k, j in enumerate(leaves):
            low, high = self.tree.lower[j], self.tree.upper[j]
            centre = 0.5 * (low + high)
            frames[k, 0:3] = centre
            sums = self.focus[k]
            if not (PARALLAX and sums[3] > sums[4] and sums[3] > 0.0):
                continue
            focus = sums[0:3] / sums[3]
            frames[k, 3:6] = focus
            reach = FOCUS_LEAST * 0.5 * float(np.linalg.norm(high - low))
            frames[k, 6] = float(np.linalg.norm(focus - centre) > reach)
        return frames

    def node_frames(self):
        """leaf_frames by spatial tree node (what guide_node returns)."""
        out = np.zeros((len(self.tree.axis), 7))
        out[self.tree.leaves()] = self.frames
        return out

    def add(self, key, records):
        """One block's records (RECORD_ROWS, n), keyed by its place in the pass."""
        with self._lock:
            self._blocks[key] = records

    def merge(self):
        """Sum the blocks handed in so far, in key order, and forget them: their records, in
        that order, cut into PARTS runs of equal count (by record, not by block, so the cut is
        the same whatever the blocks), each run counted and splatted by its own thread into
        its own grid (the first run's into the iteration's grid), the grids then added in run
        order. The guide is the same whatever the threads or the blocks."""
        with self._lock:
            blocks, self._blocks = self._blocks, {}
        if not blocks:
            return
        ordered = [np.asarray(blocks[key]) for key in sorted(blocks)]
        total = sum(b.shape[1] for b in ordered)
        if total == 0:
            return
        self.records += total
        parts = max(1, min(PARTS, total // PART_LEAST))
        cuts = [total * j // parts for j in range(parts + 1)]
        runs = []
        for j in range(parts):   # the records of run j: [cuts[j], cuts[j + 1]) in key order
            pieces, at = [], 0
            for b in ordered:
                n = b.shape[1]
                lo, hi = max(cuts[j] - at, 0), min(cuts[j + 1] - at, n)
                if hi > lo:
                    pieces.append(b[:, lo:hi])
                at += n
            runs.append(np.ascontiguousarray(np.concatenate(pieces, axis=1)))
        leaves = self.grid.shape[0]
        grids = [self.grid] + [np.zeros_like(self.grid) for _ in range(parts - 1)]
        focus = [self.focus] + [np.zeros_like(self.focus) for _ in range(parts - 1)]
        counts = [self.counts] + [np.zeros(leaves, dtype=np.int64) for _ in range(parts - 1)]
        found = [np.empty(r.shape[1], dtype=np.int64) for r in runs]
        axis, split, child, root = self._arrays
        lower, upper = self.tree.lower[0], self.tree.upper[0]

        def splat(j):
            accumulate(axis, split, child, root, lower, upper, runs[j], counts[j], grids[j],
                       found[j], COSINE, BOX, self.frames, focus[j])

        if parts == 1:
            splat(0)
        else:
            with ThreadPoolExecutor(parts) as pool:
                list(pool.map(splat, range(parts)))
        for j in range(1, parts):   # (in run order: the same sums whatever finished first)
            self.grid += grids[j]
            self.counts += counts[j]
            self.focus += focus[j]
        if self.learn and self.keep:
            for j in range(parts):
                self._keep(runs[j], found[j])

    def pending_headroom(self):
        """The headroom of the records handed in since the last merge, without merging them:
        --guiding auto's probe decides on it before anything is splatted (train). Their order
        is merge's, so the sums are the same whatever the blocks."""
        with self._lock:
            ordered = [np.asarray(self._blocks[key]) for key in sorted(self._blocks)]
        leaves = self.grid.shape[0]
        if not ordered or not sum(b.shape[1] for b in ordered):
            return headroom(np.zeros(leaves), np.zeros((2, leaves)))
        records = np.ascontiguousarray(np.concatenate(ordered, axis=1))
        found = np.empty(records.shape[1], dtype=np.int64)
        record_leaves(*self._arrays, records, found)
        f = records[R_F]
        moments = np.array([np.bincount(found, weights=f, minlength=leaves),
                            np.bincount(found, weights=f * f, minlength=leaves)])
        return headroom(np.bincount(found, minlength=leaves), moments)

    def _keep(self, records, leaves):
        """Keep every stride-th record of the iteration (by its place in merge order) for
        learn_share, doubling the stride while more than KEEP_RECORDS are kept."""
        first = (-self.seen) % self.stride
        self.seen += records.shape[1]
        pick = keep_rows(records, leaves, first, self.stride)
        self.kept.append(pick)
        self.count += pick.shape[1]
        if self.count > KEEP_RECORDS:   # (the same records whatever the blocks: by index)
            kept = np.concatenate(self.kept, axis=1)[:, ::2]
            self.kept, self.count, self.stride = [kept], kept.shape[1], 2 * self.stride

    def finish(self, passes, sampled=None, alpha=ALPHA):
        """End an iteration of `passes` passes: the guide made from its records (to sample the
        next iteration), and the tree refined for the next one's records. The guide's share in
        each spatial leaf is learnt from the records against `sampled`, the guide that drew
        them (learn_share), or is `alpha` everywhere where there is none (the first iteration)
        or without learning."""
        self.merge()
        q_child, q_density, roots = build_quadtrees(self.grid, ENERGY_SHARE)
        axis, split, child, root = self.tree.arrays(roots)
        share = np.ones(q_child.shape[0])
        guide = GuideArrays(axis, split, child, root, q_child, q_density, share, 1.0, 1,
                            self.node_frames())
        self.shares = np.full(roots.shape[0], float(alpha))
        if self.learn and sampled is not None:
            kept = np.concatenate(self.kept, axis=1) if self.kept else np.zeros((13, 0))
            kept = np.ascontiguousarray(kept)
            self.shares = learn_share(sampled, roots.shape[0], kept, SHARES, SHARE_RECORDS)
            share[roots] = self.shares
        else:
            guide = guide._replace(alpha=float(alpha))
        self.begin(self.tree.refine(self.counts, self.split_samples * math.sqrt(passes)))
        return guide


def headroom(counts, moments):
    """The bounces' headroom in records counted per leaf (counts) with their sums of F / p and
    of its square (moments): over each leaf, the second moment of the bounce's estimate F / p
    of the light it reflects over its mean squared, E[(F/p)^2] / E[F/p]^2, averaged over the
    leaves by their light (sum of F / p). That is the factor by which the bounce's second
    moment would fall if its directions were drawn in proportion to F (a perfect guide; no
    guide does better, so 1 leaves nothing to gain), where the records' directions were drawn
    by the BSDF. 1.0 where nothing was lit."""
    n = np.asarray(counts, dtype=np.float64)
    first, second = moments
    lit = first > 0.0
    total = float(np.sum(first[lit]))
    if not total > 0.0:
        return 1.0
    return float(np.sum(n[lit] * second[lit] / first[lit])) / total


@njit(cache=True, nogil=True)
def record_leaves(axis, split, child, root, records, leaves):
    """Each record's leaf number (the root[] of its leaf node, as accumulate finds it) into
    leaves."""
    for k in range(records.shape[1]):
        bucket = normal_bucket(records[R_NX, k], records[R_NX + 1, k], records[R_NX + 2, k])
        leaves[k] = root[guide_node(axis, split, child, records[0, k], records[1, k],
                                    records[2, k], bucket)]


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


def auto_schedule(spp):
    """--guiding auto's iterations: PROBE unguided passes, then guided ones of PROBE, 2 PROBE,
    ... while the total stays within TRAIN_SHARE of spp and TRAIN_MOST (none, auto off, below
    AUTO_LEAST samples)."""
    if spp < AUTO_LEAST:
        return []
    out, total, n = [PROBE], PROBE, PROBE
    while total + n <= min(TRAIN_SHARE * spp, TRAIN_MOST) and total + n < spp:
        out.append(n)
        total += n
        n *= 2
    return out


def train(job, pixel_x, pixel_y, spp, mode="on", on_chunk=None):
    """Train job's guide (its wavefront must be guided) on the pixels: the iterations of
    schedule(spp) (under mode "auto", auto_schedule(spp)), the first unguided, on the samples
    from spp down (the last iteration's lowest), so the final passes render the first ones.
    Each iteration's records make the guide the next one samples (its share per spatial leaf
    learnt, Trainer.finish). Under "auto", the unguided first iteration's records give the
    bounces' headroom (headroom()): below HEADROOM, training stops and the guide is off
    for the rest of the render, whose final passes with the first iteration's are then the
    unguided render of spp samples (its samples 0 .. spp - 1). Above it, training goes on; if
    the last training iteration's variance per sample (relative_variance) is not below the
    first's, the final passes are unguided (the training images still combine). Returns
    (training samples, figures, images): images, for combine, holds each iteration's samples,
    relative variance and mean radiance per pixel, or the first iteration's sums to add."""
    from .rendering.tiles import new_sums
    wavefront = job.wavefront
    plan = auto_schedule(spp) if mode == "auto" else schedule(spp)
    bounds = job.scene.geometry.bounds()
    figures = dict(iterations=plan, training_samples=sum(plan), records=0, guide_bytes=0,
                   variance=[], guided=True)
    images = []
    if not plan or bounds is None:
        if mode == "auto":
            wavefront.guide = uniform_guide()
            figures.update(guided=False, iterations=[], training_samples=0)
        return 0, figures, images
    trainer = Trainer(*bounds, split_samples=split_samples(pixel_x.shape[0]))
    rows = np.arange(pixel_x.shape[0])
    top = spp
    wavefront.guide = uniform_guide(0.0, True)
    wavefront.trainer = trainer
    done, guide = [], None
    try:
        for passes in plan:
            sums = new_sums(pixel_x.shape[0])
            top -= passes
            probe = mode == "auto" and not done   # (its records merged only if it says on)
            for s in range(0, passes, CHUNK):   # (CHUNK passes' records held at once)
                job.trace(pixel_x, pixel_y, top + s, min(CHUNK, passes - s), sums, rows,
                          on_chunk)
                if not probe:
                    trainer.merge()
            done.append(passes)
            variance = relative_variance(*sums[1:])
            figures["variance"].append(variance)
            if math.isfinite(variance):
                images.append((passes, variance, sums[0] / np.maximum(sums[3], 1)[:, None]))
            if probe:
                room = trainer.pending_headroom()
                figures["decision"] = dict(headroom=room, probe_variance=variance)
                if not room >= HEADROOM:   # the unguided render, with these samples
                    guide = uniform_guide()
                    figures["guided"] = False
                    images = [sums]
                    break
                trainer.merge()
            guide = trainer.finish(passes, guide if len(done) > 1 else None)
            wavefront.guide = guide
    finally:
        wavefront.trainer = None
    total = sum(done)
    figures.update(records=trainer.records, guide_bytes=guide_bytes(guide),
                   leaves=len(trainer.tree.leaves()), iterations=done, training_samples=total)
    if figures["guided"] and mode == "auto":   # (the probe's variance against the last's)
        figures["guided"] = bool(variance < figures["variance"][0])
    if figures["guided"]:
        wavefront.guide = guide._replace(record=0)
        figures["share_mean"] = float(np.mean(trainer.shares))
    else:
        wavefront.guide = guide._replace(alpha=0.0, record=0)
    return total, figures, images


def combine(sums, images):
    """The unguided first iteration's sums added to the final passes' (when --guiding auto
    turned the guide off), or else the final passes' sums (rgb, l, l2, count) rescaled in
    place so that their mean per pixel is the combination of their image with the training
    iterations' images, each weighted by its samples over its relative_variance (the 2019
    course's inverse-variance combination); the counts stay the final passes'. Returns the
    weights, the final image's last."""
    sum_rgb, sum_l, sum_l2, count = sums
    if len(images) == 1 and len(images[0]) == 4:   # the unguided first iteration's sums
        for total, part in zip(sums, images[0]):
            total += part
        return []
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
