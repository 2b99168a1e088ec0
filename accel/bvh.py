"""Our hand-written BVH: the course's suggested mean-centroid split, built and walked iteratively.

`split="sah"` chooses instead, among 16 bins of the centroid bounds on each axis, the plane of
least surface-area cost (n_left * area_left + n_right * area_right); everything else is shared.

Build: a node covers a contiguous range of the primitive order array. It becomes a leaf when it
holds at most `max_leaf_size` primitives (the course's 4 by default, one block of the vector
triangle test; leaves of 8 measured neither clearly faster nor slower:
benchmarks/results/bvh_changes.md); otherwise it splits along the longest axis of its
centroid bounds at the mean centroid. When that leaves one side empty (coincident centroids,
rounding), or the node is deeper than `MEAN_SPLIT_DEPTH`, it splits by count instead (the lower
half of the centroids sorted on that axis goes left), which always makes progress and bounds the
depth: a run of bad mean splits cannot make a giant leaf, an endless loop, or a tree deeper than
the traversal stack.

Layout of that binary tree (structure of arrays): lower[n], upper[n] boxes; child_or_first[n] is
the left child index (the right child is the next node) for an interior node, or the first entry
in `order` for a leaf; count[n] is 0 for an interior node and the number of primitives for a leaf.

Traversal does not walk the binary tree: `_collapse` folds it into an 8-wide tree, so a ray
visits fewer nodes and the slab test of a node's children is one vector operation (accel.simd:
one AVX2 instruction per step, in float32). Which binary nodes become wide nodes is chosen for
the least sum of wide-node surface areas (the expected nodes a ray visits; _slot_costs, after
Ylitie, Karras and Laine 2017), leaves as built. A wide node is
one 256-byte row (_node_rows): its children's six box planes as float32, rounded outward so a
box never shrinks, and an int64 payload per child: a row for an interior child, or a leaf's
first triangle block and its triangle and sphere counts. The slab test computes in float32, from
the ray's origin moved outward and its inverse direction scaled outward per axis (_ray_planes),
so that rounding can only keep a box, never lose one; which primitive is hit, and its t, come
from the leaves' float64 tests alone.
A leaf's triangles are stored by _fill_rows in blocks of four, as float64 coordinates (the
mesh's own values: each lane of accel.simd's block test computes what the scalar test of
accel.kernels computes on those values, bit for bit, so bvh and naive agree exactly), and
tested four at a time. What each of these
choices bought is measured side by side in benchmarks/results/bvh_changes.md: 8-wide with
vector slab and block tests over the earlier 4-wide scalar traversal, float32 planes over
float64 ones, unsigned stack indices, entering a node's only child hit directly, float32 slab
arithmetic over float64.
"""
import time
from collections import namedtuple

import numpy as np
from numba import njit, prange, uint64
from numba.cpython.unsafe.numbers import trailing_zeros, viewer  # numba's llvm.cttz, bitcast

from . import compiled
from .kernels import (
    NO_HIT,
    WATERTIGHT,
    better,
    near_columns,
    shear_setup,
    sphere_hit,
    spheres_any,
    spheres_closest,
    triangle_test,
)
from .simd import BLOCK, BLOCK_COLUMNS, make_slab_test, moller_trumbore_block, watertight_block
from .types import Hits

STACK_SIZE = 128
MEAN_SPLIT_DEPTH = 64   # below this depth only count splits: depth <= 64 + log2(n) < STACK_SIZE
# the mean-centroid split the course suggests (its staff build uses the midpoint of the centroid
# bounds); a binned surface-area heuristic
SPLITS = ("mean", "sah")
SAH_BINS = 16
RAY_BLOCK = compiled.RAY_BLOCK   # rays per parallel work item of the batch kernels
WIDTH = 8                # children per node of the traversal's tree (_closest's tournament: 8)
WIDE_STACK = (WIDTH - 1) * STACK_SIZE + WIDTH   # each pop pushes at most WIDTH - 1 more
NODE_COLUMNS = 64        # float32 columns of a wide node's row: 6 * WIDTH planes, WIDTH payloads
PAYLOAD = 6 * WIDTH // 2   # the first payload's column in the row's int64 view
MAX_LEAF_SIZE = 0xffff   # a leaf payload holds its triangle and sphere counts in 16 bits each
# The float32 slab test's margins (see _ray_planes). Float32 rounds a plane's difference from the
# origin, its product with the inverse and the inverse itself (2^-24 each, relative), so near
# inverses are shrunk and far ones grown by SLAB_SCALE: a near t can only come out smaller than
# the exact one, a far t larger. The origins are moved ahead (near) and behind (far) by
# SLAB_SHIFT * |o| (plus 2^-40), more than rounding them to float32 (and float64's rounding of
# o + lo d, for a negative lo) can move them.
SLAB_SCALE = 4.0 * 2.0 ** -24
SLAB_SHIFT = 2.0 * 2.0 ** -24 + 2.0 ** -52
slab_test = make_slab_test(WIDTH)


@njit(cache=True, inline="always")
def _half_area(lx, ly, lz, hx, hy, hz):
    dx, dy, dz = hx - lx, hy - ly, hz - lz
    return dx * dy + dy * dz + dz * dx


@njit(cache=True)
def _sah_partition(prim_lower, prim_upper, centroid, order, start, end, c_lo, c_hi):
    """Binned SAH: over SAH_BINS bins of the centroid bounds on each axis, the plane that
    minimises n_left * area_left + n_right * area_right; partition the range by it and return
    the first index of the right side (start or end if no plane separates anything)."""
    best_cost = np.inf
    best_axis = -1
    best_bin = -1
    counts = np.zeros(SAH_BINS, dtype=np.int64)
    lo = np.empty((SAH_BINS, 3))
    hi = np.empty((SAH_BINS, 3))
    right_area = np.empty(SAH_BINS)
    right_count = np.empty(SAH_BINS, dtype=np.int64)
    for axis in range(3):
        extent = c_hi[axis] - c_lo[axis]
        if not extent > 0.0:
            continue
        counts[:] = 0
        lo[:, :] = np.inf
        hi[:, :] = -np.inf
        for i in range(start, end):
            p = order[i]
            b = min(SAH_BINS - 1, int(SAH_BINS * (centroid[p, axis] - c_lo[axis]) / extent))
            counts[b] += 1
            for a in range(3):
                lo[b, a] = min(lo[b, a], prim_lower[p, a])
                hi[b, a] = max(hi[b, a], prim_upper[p, a])
        # sweep from the right: area and count of bins b..end
        bx0, by0, bz0, bx1, by1, bz1 = np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf
        n = 0
        for b in range(SAH_BINS - 1, 0, -1):
            if counts[b] > 0:
                bx0, by0, bz0 = min(bx0, lo[b, 0]), min(by0, lo[b, 1]), min(bz0, lo[b, 2])
                bx1, by1, bz1 = max(bx1, hi[b, 0]), max(by1, hi[b, 1]), max(bz1, hi[b, 2])
            n += counts[b]
            right_count[b] = n
            right_area[b] = _half_area(bx0, by0, bz0, bx1, by1, bz1) if n > 0 else 0.0
        bx0, by0, bz0, bx1, by1, bz1 = np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf
        n = 0
        for b in range(SAH_BINS - 1):   # plane between bin b and b + 1
            if counts[b] > 0:
                bx0, by0, bz0 = min(bx0, lo[b, 0]), min(by0, lo[b, 1]), min(bz0, lo[b, 2])
                bx1, by1, bz1 = max(bx1, hi[b, 0]), max(by1, hi[b, 1]), max(bz1, hi[b, 2])
            n += counts[b]
            if n == 0 or right_count[b + 1] == 0:
                continue
            cost = n * _half_area(bx0, by0, bz0, bx1, by1, bz1) + \
                right_count[b + 1] * right_area[b + 1]
            if cost < best_cost:
                best_cost, best_axis, best_bin = cost, axis, b
    if best_axis < 0:
        return start
    extent = c_hi[best_axis] - c_lo[best_axis]
    left = start
    right = end - 1
    while left <= right:
        p = order[left]
        b = min(SAH_BINS - 1, int(SAH_BINS * (centroid[p, best_axis] - c_lo[best_axis]) / extent))
        if b <= best_bin:
            left += 1
        else:
            order[left], order[right] = order[right], order[left]
            right -= 1
    return left


@njit(cache=True)
def _build(prim_lower, prim_upper, centroid, max_leaf_size, mean_split_depth, use_sah):
    n = prim_lower.shape[0]
    max_nodes = max(2 * n - 1, 1)
    lower = np.empty((max_nodes, 3))
    upper = np.empty((max_nodes, 3))
    child_or_first = np.zeros(max_nodes, dtype=np.int64)
    count = np.zeros(max_nodes, dtype=np.int64)
    order = np.arange(n)
    if n == 0:
        return lower[:0], upper[:0], child_or_first[:0], count[:0], order, 0

    # explicit stack of (node, start, end, depth)
    stack_node = np.empty(STACK_SIZE * 2, dtype=np.int64)
    stack_start = np.empty(STACK_SIZE * 2, dtype=np.int64)
    stack_end = np.empty(STACK_SIZE * 2, dtype=np.int64)
    stack_depth = np.empty(STACK_SIZE * 2, dtype=np.int64)
    top = 0
    stack_node[0], stack_start[0], stack_end[0], stack_depth[0] = 0, 0, n, 0
    top = 1
    used = 1
    max_depth = 0
    keys = np.empty(n)
    while top > 0:
        top -= 1
        node = stack_node[top]
        start = stack_start[top]
        end = stack_end[top]
        depth = stack_depth[top]
        if depth > max_depth:
            max_depth = depth
        # bounds of the primitives and of their centroids
        c_lo = np.full(3, np.inf)
        c_hi = np.full(3, -np.inf)
        for a in range(3):
            lower[node, a] = np.inf
            upper[node, a] = -np.inf
        for i in range(start, end):
            p = order[i]
            for a in range(3):
                if prim_lower[p, a] < lower[node, a]:
                    lower[node, a] = prim_lower[p, a]
                if prim_upper[p, a] > upper[node, a]:
                    upper[node, a] = prim_upper[p, a]
                if centroid[p, a] < c_lo[a]:
                    c_lo[a] = centroid[p, a]
                if centroid[p, a] > c_hi[a]:
                    c_hi[a] = centroid[p, a]
        size = end - start
        if size <= max_leaf_size:
            child_or_first[node] = start
            count[node] = size
            continue
        axis = 0
        for a in range(1, 3):
            if c_hi[a] - c_lo[a] >= c_hi[axis] - c_lo[axis]:   # ties go to the later axis
                axis = a
        mid = start
        if use_sah and depth < mean_split_depth:
            mid = _sah_partition(prim_lower, prim_upper, centroid, order, start, end, c_lo, c_hi)
        elif depth < mean_split_depth and c_hi[axis] > c_lo[axis]:
            mean = 0.0
            for i in range(start, end):
                mean += centroid[order[i], axis]
            mean /= size
            # partition: centroid < mean to the left
            left = start
            right = end - 1
            while left <= right:
                if centroid[order[left], axis] < mean:
                    left += 1
                else:
                    order[left], order[right] = order[right], order[left]
                    right -= 1
            mid = left
        if mid == start or mid == end:
            # count split: the lower half along the axis goes left (stable in primitive id)
            for i in range(start, end):
                keys[i] = centroid[order[i], axis]
            perm = np.argsort(keys[start:end], kind="mergesort")
            segment = order[start:end].copy()
            for i in range(size):
                order[start + i] = segment[perm[i]]
            mid = start + size // 2
        left_child = used
        used += 2
        child_or_first[node] = left_child
        count[node] = 0
        # push right then left so the left subtree is built first
        stack_node[top], stack_start[top], stack_end[top], stack_depth[top] = \
            left_child + 1, mid, end, depth + 1
        top += 1
        stack_node[top], stack_start[top], stack_end[top], stack_depth[top] = \
            left_child, start, mid, depth + 1
        top += 1
    return lower[:used], upper[:used], child_or_first[:used], count[:used], order, max_depth


def _aligned_empty(rows, columns, dtype=np.float64):
    """An empty (rows, columns) array whose first row starts on a 64-byte boundary (numpy only
    promises 16), so rows whose size is a multiple of 64 bytes each start a cache line."""
    itemsize = np.dtype(dtype).itemsize
    buffer = np.empty(rows * columns + 64 // itemsize, dtype=dtype)
    skip = (-buffer.ctypes.data % 64) // itemsize
    return buffer[skip:skip + rows * columns].reshape(rows, columns)


@njit(cache=True)
def _slot_costs(lower, upper, child_or_first, count):
    """The collapse's choices (Ylitie, Karras and Laine, "Efficient incoherent ray traversal on
    GPUs through compressed wide BVHs", HPG 2017, without their leaf packing: the leaves stay
    the build's). The cost of a wide tree is the sum of the half areas of its nodes: a ray that
    meets the root's box meets a box with the probability of its area over the root's (for rays
    uniform in direction and position), so the sum is the expected wide nodes visited per ray,
    over the root's half area. Bottom up, for every binary node b and i = 1.. WIDTH slots of
    the wide node that holds it: cost[b, i], the least cost of b's subtree laid out in at most i
    slots. A leaf takes one slot and costs nothing; an interior node takes one slot as a wide
    node of its own (its half area, plus its two children's subtrees laid out in WIDTH slots
    between them) or, with i >= 2, is opened: its two children's subtrees laid out in i slots
    between them. Returns (cost, choice, split): choice[b, i] is -1 where b takes one slot, 0
    where b does as well in i - 1 slots, j > 0 where b is opened with j slots for its left child
    and i - j for its right; split[b] is the left child's share of a wide node of b's own."""
    n = lower.shape[0]
    cost = np.zeros((n, WIDTH + 1))
    choice = np.full((n, WIDTH + 1), -1, dtype=np.int8)
    split = np.zeros(n, dtype=np.int8)
    for b in range(n - 1, -1, -1):   # a node's children come after it
        if count[b] > 0:
            continue
        left = child_or_first[b]
        right = left + 1
        best, best_j = np.inf, 1
        for j in range(1, WIDTH):
            value = cost[left, j] + cost[right, WIDTH - j]
            if value < best:
                best, best_j = value, j
        cost[b, 1] = _half_area(lower[b, 0], lower[b, 1], lower[b, 2], upper[b, 0],
                                upper[b, 1], upper[b, 2]) + best
        split[b] = best_j
        for i in range(2, WIDTH + 1):
            value, how = cost[b, i - 1], 0
            for j in range(1, i):
                opened = cost[left, j] + cost[right, i - j]
                if opened < value:
                    value, how = opened, j
            cost[b, i], choice[b, i] = value, how
    return cost, choice, split


@njit(cache=True)
def _collapse(lower, upper, child_or_first, count, wide):
    """Fold the binary tree into WIDTH-wide float64 rows of `wide`; row 0 is the root. A row holds
    the six planes lower x, y, z, upper x, y, z of its WIDTH children, then each child's link (a
    wide row for an interior child, its first `order` entry for a leaf), then its count (0 for
    an interior child); an unused slot has an empty box (lower +inf, upper -inf). Which binary
    nodes become wide nodes is _slot_costs' least-cost choice; a row's children are in the
    binary tree's left-to-right order. _node_rows and _fill_rows turn these rows into the
    traversal's. Returns the number of rows used (at most the binary tree's node count)."""
    n = lower.shape[0]
    if n == 0:
        return 0
    choice, split = _slot_costs(lower, upper, child_or_first, count)[1:]
    todo_binary = np.empty(n, dtype=np.int64)   # binary node to become wide row todo_wide
    todo_wide = np.empty(n, dtype=np.int64)
    todo_binary[0], todo_wide[0] = 0, 0
    top = 1
    used = 1
    kids = np.empty(WIDTH, dtype=np.int64)
    place_node = np.empty(WIDTH + 1, dtype=np.int64)   # subtrees still to lay out, and in
    place_slots = np.empty(WIDTH + 1, dtype=np.int64)  # how many slots (a stack, left on top)
    while top > 0:
        top -= 1
        b, w = todo_binary[top], todo_wide[top]
        m = 0
        if count[b] > 0:   # a leaf root: one child
            kids[0] = b
            m = 1
        else:
            left = child_or_first[b]
            place_node[0], place_slots[0] = left + 1, WIDTH - split[b]
            place_node[1], place_slots[1] = left, split[b]
            k = 2
            while k > 0:
                k -= 1
                c, i = place_node[k], place_slots[k]
                while choice[c, i] == 0:
                    i -= 1
                j = choice[c, i]
                if j < 0:   # c takes one slot
                    kids[m] = c
                    m += 1
                else:       # c is opened: its left child's subtree first
                    left = child_or_first[c]
                    place_node[k], place_slots[k] = left + 1, i - j
                    place_node[k + 1], place_slots[k + 1] = left, j
                    k += 2
        for k in range(WIDTH):
            if k >= m:
                for a in range(3):
                    wide[w, a * WIDTH + k] = np.inf
                    wide[w, (3 + a) * WIDTH + k] = -np.inf
                wide[w, 6 * WIDTH + k] = 0.0
                wide[w, 7 * WIDTH + k] = 0.0
                continue
            c = kids[k]
            for a in range(3):
                wide[w, a * WIDTH + k] = lower[c, a]
                wide[w, (3 + a) * WIDTH + k] = upper[c, a]
            if count[c] > 0:
                wide[w, 6 * WIDTH + k] = child_or_first[c]
                wide[w, 7 * WIDTH + k] = count[c]
            else:
                wide[w, 6 * WIDTH + k] = used
                wide[w, 7 * WIDTH + k] = 0.0
                todo_binary[top], todo_wide[top] = c, used
                top += 1
                used += 1
    return used




@njit(cache=True)
def _wide_rows(lower, upper, child_or_first, count):
    """_collapse into a staging array sized for the worst case (a row per interior binary node,
    or the one row of a leaf root), returned as a copy of the rows used."""
    interior = max(1, int((count == 0).sum()))
    wide = np.empty((interior, 8 * WIDTH))
    used = _collapse(lower, upper, child_or_first, count, wide)
    return wide[:used].copy()


@njit(cache=True, inline="always")
def _float32_down(x):
    """The largest float32 at or below x (inf and -inf stay). Without branches or a libm call
    (the traversal rounds every ray's lo and hi and each nearer hit this way, and which way the
    rounding went is a coin toss a branch would mispredict): where float32(x) is above x, the
    float32 one step below it, by its bits as an integer (a float32 -0.0 steps to the negative
    subnormal, +inf to the largest float32)."""
    f = np.float32(x)
    bits = viewer(f, np.int32)
    below = viewer(np.int32(bits - 1 if f > 0.0 else bits + 1), np.float32)
    return below if np.float64(f) > x else f


@njit(cache=True, inline="always")
def _float32_up(x):
    """The smallest float32 at or above x, as _float32_down."""
    f = np.float32(x)
    bits = viewer(f, np.int32)
    above = viewer(np.int32(bits - 1 if f < 0.0 else bits + 1), np.float32)
    return above if np.float64(f) < x else f


@njit(cache=True)
def _fill_rows(wide, nodes, payloads, order, n_tri, vertices, faces):
    """The traversal's rows (see _node_rows) from _collapse's: the planes rounded outward to
    float32, so a float32 box always contains its float64 box, and each child's payload; and the
    leaves as blocks of BLOCK triangles, in the order the rows reach them.

    For each leaf slot (count > 0) of each row: its triangles fill ceil(triangles / BLOCK)
    consecutive blocks (NaN in unused lanes, which every triangle test misses), then its spheres
    take ceil(spheres / BLOCK) more block rows of `prims` (their `blocks` rows stay NaN), so every
    leaf starts on a block. Returns (blocks, prims): the float64 (blocks, BLOCK_COLUMNS) vertex
    coordinates and the int64 primitive id of each lane (-1 unused)."""
    rows, width = wide.shape[0], WIDTH
    for r in range(rows):
        for k in range(3 * WIDTH):
            nodes[r, k] = _float32_down(wide[r, k])
            nodes[r, 3 * WIDTH + k] = _float32_up(wide[r, 3 * WIDTH + k])
    links = wide[:, 6 * WIDTH:7 * WIDTH].astype(np.int64)
    counts = wide[:, 7 * WIDTH:8 * WIDTH].astype(np.int64)
    n_blocks = 0
    for r in range(rows):
        for c in range(width):
            if counts[r, c] > 0:
                n_tri_leaf = 0
                for i in range(links[r, c], links[r, c] + counts[r, c]):
                    n_tri_leaf += order[i] < n_tri
                n_sph = counts[r, c] - n_tri_leaf
                n_blocks += (n_tri_leaf + BLOCK - 1) // BLOCK + (n_sph + BLOCK - 1) // BLOCK
    blocks = np.full((n_blocks, BLOCK_COLUMNS), np.nan)
    prims = np.full(n_blocks * BLOCK, -1, dtype=np.int64)
    block = 0
    for r in range(rows):
        for c in range(width):
            if counts[r, c] == 0:
                payloads[r, PAYLOAD + c] = links[r, c]
                continue
            first = block
            lane = 0
            for i in range(links[r, c], links[r, c] + counts[r, c]):   # triangles first
                p = order[i]
                if p < n_tri:
                    for j in range(3):
                        for a in range(3):
                            blocks[block, (3 * j + a) * BLOCK + lane] = vertices[faces[p, j], a]
                    prims[block * BLOCK + lane] = p
                    lane += 1
                    if lane == BLOCK:
                        block, lane = block + 1, 0
            n_tri_leaf = (block - first) * BLOCK + lane
            if lane > 0:
                block, lane = block + 1, 0
            spheres = block * BLOCK
            for i in range(links[r, c], links[r, c] + counts[r, c]):
                if order[i] >= n_tri:
                    prims[spheres] = order[i]
                    spheres += 1
            n_sph = spheres - block * BLOCK
            block += (n_sph + BLOCK - 1) // BLOCK
            payloads[r, PAYLOAD + c] = first | (n_tri_leaf << 32) | (n_sph << 48)
    return blocks, prims


def _node_rows(rows):
    """An empty node array of `rows` 256-byte rows, one per wide node, each starting a cache line,
    and its int64 view (filled by _fill_rows).

    Columns 0-47 (float32): the six planes lower x, y, z, upper x, y, z, WIDTH children each,
    rounded outward; columns 48-63, read as int64 columns PAYLOAD.. PAYLOAD + 7: each child's
    payload. A payload is a row for an interior child, or for a leaf first_block | n_triangles
    << 32 | n_spheres << 48 (n_triangles + n_spheres > 0, so payload >> 32 is not 0), its
    triangles in blocks first_block.. and its spheres' ids in the `prims` entries after them
    (_fill_rows)."""
    nodes = _aligned_empty(rows, NODE_COLUMNS, np.float32)
    return nodes, nodes.view(np.int64)


BVHRecord = namedtuple("BVHRecord", ["nodes", "payloads", "blocks", "prims", "n_tri", "centers",
                                     "radii", "triangle"])


@njit(cache=True)
def new_scratch(record):
    """Traversal stack for one block of rays: payloads and the t where the ray enters each."""
    return np.empty(WIDE_STACK, dtype=np.int64), np.empty(WIDE_STACK, dtype=np.float32)


@njit(cache=True, inline="always")
def _inverse32(d):
    """A direction component's near and far inverses for the float32 slab test (1/d shrunk and
    grown by SLAB_SCALE), and whether float32 holds them: +inf for 0 (parallel: each t is then
    +-inf by the sign of plane - origin, or NaN where they are equal, which culls nothing),
    scaled 1/d where |1/d| is within [2^-100, 2^100]."""
    if d == 0.0:
        return np.float32(np.inf), np.float32(np.inf), True
    q = 1.0 / d
    return (np.float32(q * (1.0 - SLAB_SCALE)), np.float32(q * (1.0 + SLAB_SCALE)),
            2.0 ** -100 <= abs(q) <= 2.0 ** 100)


@njit(cache=True, inline="always")
def _origins32(o, d, shift, inverse):
    """A ray origin coordinate's float32 near and far origins for the slab test, the origin
    being o + shift * d: the near one ahead of it along the axis's direction, the far one behind
    it, each by SLAB_SHIFT of |o| + |shift * d| (at least its magnitude, and enough to cover
    float64's rounding of o + shift * d too) plus 2^-40."""
    step = shift * d
    start = o + step
    move = SLAB_SHIFT * (abs(o) + abs(step)) + 2.0 ** -40
    if inverse > 0:
        return np.float32(start + move), np.float32(start - move)
    return np.float32(start - move), np.float32(start + move)


@njit(cache=True, inline="always")
def _ray_planes(ox, oy, oz, dx, dy, dz, lo, hi):
    """What slab_test needs of a ray: its near and far plane columns; its float32 near and far
    origins and inverses; its float32 lo and hi (rounded down and up); the t its slab t's are
    counted from (0, or lo if lo < 0: the slab test's origin is then o + lo d, so that only t's
    >= 0 matter to it); and whether float32
    cannot invert one of the direction's components (0 < |d| < 2^-100 or |d| > 2^100, which no
    renderer makes: the ray is then answered by testing every primitive).

    Why the slab test never misses a box the ray meets within [lo, hi] (tests/accel/test_simd.py
    checks it against exact arithmetic): with lo32 <= the slab's lo (0 or lo) and hi32 >= its hi,
    a box is met exactly when max(lo, near t's) <= min(hi, far t's), and then every far t is
    >= 0. A near or far difference plane - origin errs outward, its sign included (the origins
    are moved by more than their rounding); where it is >= 0 (a far t always, a near t whenever
    it can exceed lo) the shrunk or grown inverse outweighs the three roundings of 2^-24, so the
    computed near t is at most the exact one and the far t at least; a negative near t is below
    lo32 and changes nothing."""
    shift = min(lo, 0.0)
    (nix, fix, x_ok), (niy, fiy, y_ok), (niz, fiz, z_ok) = (
        _inverse32(dx), _inverse32(dy), _inverse32(dz))
    nx, ny, nz, fx, fy, fz = near_columns(nix, niy, niz)
    planes = (nx * WIDTH, ny * WIDTH, nz * WIDTH, fx * WIDTH, fy * WIDTH, fz * WIDTH)
    near_x, far_x = _origins32(ox, dx, shift, nix)
    near_y, far_y = _origins32(oy, dy, shift, niy)
    near_z, far_z = _origins32(oz, dz, shift, niz)
    ray = (near_x, near_y, near_z, far_x, far_y, far_z, nix, niy, niz, fix, fiy, fiz)
    lo32, hi32 = _float32_down(lo - shift), _hi32(hi, shift)
    return planes, ray, lo32, hi32, shift, not (x_ok and y_ok and z_ok)


@njit(cache=True, inline="always")
def _hi32(t, shift):
    """A float32 at or above t - shift, for the slab test's hi (t - shift rounded up)."""
    return _float32_up((t - shift) * (1.0 + 2.0 ** -52))


@njit(cache=True, inline="always")
def _block_test(record, block, shear, ray, lo, hi):
    """The record's triangle test on one block: (mask, t's, u's, v's) of its BLOCK lanes."""
    if record.triangle == WATERTIGHT:
        return watertight_block(record.blocks, block, shear, lo, hi)
    return moller_trumbore_block(record.blocks, block, ray, lo, hi)


@njit(cache=True, inline="always")
def _nearer(ta, a, tb, b):
    """The pair (t, slot) nearer first: a compare-exchange of the nearest-child tournament."""
    if tb < ta:
        return tb, b, ta, a
    return ta, a, tb, b


@njit(cache=True, _nrt=False, forceinline=True)
def _blocks_closest(record, first, n_blocks, shear, ray, lo, best_t, best_prim, best_u, best_v):
    """Fold the triangles of blocks first.. first + n_blocks into the closest hit so far."""
    for block in range(first, first + n_blocks):
        mask, ts, us, vs = _block_test(record, block, shear, ray, lo, best_t)
        if mask != 0:
            for lane in range(BLOCK):
                t = ts[lane]
                if (mask >> lane) & 1 and t <= best_t:
                    p = record.prims[uint64(block * BLOCK + lane)]
                    if better(t, p, best_t, best_prim):
                        best_t, best_prim, best_u, best_v = t, p, us[lane], vs[lane]
    return best_t, best_prim, best_u, best_v


@njit(cache=True, _nrt=False, forceinline=True)
def _leaf_closest(record, payload, shear, ray, lo, best_t, best_prim, best_u, best_v):
    """Fold a leaf's primitives into the closest hit so far."""
    prims, n_tri = record.prims, record.n_tri
    first = payload & 0xffffffff
    n_blocks = (((payload >> 32) & 0xffff) + BLOCK - 1) // BLOCK
    best_t, best_prim, best_u, best_v = _blocks_closest(
        record, first, n_blocks, shear, ray, lo, best_t, best_prim, best_u, best_v)
    ox, oy, oz, dx, dy, dz = ray
    start = (first + n_blocks) * BLOCK
    for i in range(start, start + ((payload >> 48) & 0xffff)):
        p = prims[i]
        t = sphere_hit(record.centers, record.radii, p - n_tri, ox, oy, oz, dx, dy, dz, lo, best_t)
        if t <= best_t and better(t, p, best_t, best_prim):
            best_t, best_prim, best_u, best_v = t, p, 0.0, 0.0
    return best_t, best_prim, best_u, best_v


@njit(cache=True, _nrt=False, forceinline=True)
def _blocks_any(record, first, n_blocks, shear, ray, lo, hi):
    """True if a triangle of blocks first.. first + n_blocks is hit with lo <= t <= hi."""
    for block in range(first, first + n_blocks):
        if _block_test(record, block, shear, ray, lo, hi)[0] != 0:
            return True
    return False


@njit(cache=True, _nrt=False, forceinline=True)
def _leaf_any(record, payload, shear, ray, lo, hi):
    """True if any of a leaf's primitives is hit with lo <= t <= hi."""
    first = payload & 0xffffffff
    n_blocks = (((payload >> 32) & 0xffff) + BLOCK - 1) // BLOCK
    if _blocks_any(record, first, n_blocks, shear, ray, lo, hi):
        return True
    ox, oy, oz, dx, dy, dz = ray
    start = (first + n_blocks) * BLOCK
    for i in range(start, start + ((payload >> 48) & 0xffff)):
        p = record.prims[i] - record.n_tri
        if sphere_hit(record.centers, record.radii, p, ox, oy, oz, dx, dy, dz, lo, hi) <= hi:
            return True
    return False


@njit(cache=True, _nrt=False, forceinline=True)
def _every_closest(record, shear, ray, lo, hi):
    """The closest hit by testing every primitive, for a ray with a direction component float32
    cannot invert (_ray_planes): (t, prim, u, v, 0, tests)."""
    best_t, best_prim, best_u, best_v = _blocks_closest(
        record, 0, record.blocks.shape[0], shear, ray, lo, hi, NO_HIT, 0.0, 0.0)
    ox, oy, oz, dx, dy, dz = ray
    best_t, best_prim, best_u, best_v = spheres_closest(
        record.centers, record.radii, record.n_tri, ox, oy, oz, dx, dy, dz, lo, best_t,
        best_prim, best_u, best_v)
    if best_prim == NO_HIT:
        best_t = np.inf
    return best_t, best_prim, best_u, best_v, 0, record.n_tri + record.centers.shape[0]


@njit(cache=True, _nrt=False, forceinline=True)
def _closest(record, scratch, ox, oy, oz, dx, dy, dz, lo, hi):
    """Closest-hit traversal of one ray: (t, prim, u, v, wide nodes visited, primitive tests).

    Ordered: at each node the nearest child hit is entered next and the others are pushed with their
    entry t (in slot order); a popped entry beyond the nearest hit found is skipped. A node with one
    child hit enters it directly, skipping the nearest-child tournament and the pushes: closest-hit
    rays gain from it, any-hit rays measured no clear gain and any_hit does without it
    (benchmarks/results/bvh_changes.md, "+ one-hit shortcut"). The stack indices are unsigned, so
    numba emits no negative-index wraparound for them."""
    nodes, payloads = record.nodes, record.payloads
    stack, entry = scratch
    planes, slab_ray, lo32, hi32, shift, wild = _ray_planes(ox, oy, oz, dx, dy, dz, lo, hi)
    shear = shear_setup(ox, oy, oz, dx, dy, dz)
    ray = (ox, oy, oz, dx, dy, dz)
    if wild:
        return _every_closest(record, shear, ray, lo, hi)
    best_t = hi
    best_prim = NO_HIT
    best_u = 0.0
    best_v = 0.0
    best_s = hi - shift   # best_t on the slab's scale: a pushed entry t is compared with it
    visits = 0
    tests = 0
    top = 0
    payload = 0   # the root, row 0
    while nodes.shape[0] > 0:
        if payload >> 32 == 0:   # a wide node
            visits += 1
            row = payload
            mask, ts = slab_test(nodes, row, planes, slab_ray, lo32, hi32)
            if mask != 0 and mask & (mask - 1) == 0:   # one child hit: enter it, push nothing
                payload = payloads[uint64(row), uint64(PAYLOAD + trailing_zeros(mask))]
                continue
            if mask != 0:
                # a tournament for the nearest child hit (a missed child's t is inf)
                t0, c0, t1, c1 = _nearer(ts[0], 0, ts[1], 1)
                t2, c2, t3, c3 = _nearer(ts[2], 2, ts[3], 3)
                t4, c4, t5, c5 = _nearer(ts[4], 4, ts[5], 5)
                t6, c6, t7, c7 = _nearer(ts[6], 6, ts[7], 7)
                t0, c0, t2, c2 = _nearer(t0, c0, t2, c2)
                t4, c4, t6, c6 = _nearer(t4, c4, t6, c6)
                t0, c0, t4, c4 = _nearer(t0, c0, t4, c4)
                others = mask & ~(1 << c0)
                for c in range(WIDTH):   # push the other children hit, without branches
                    stack[uint64(top)] = payloads[uint64(row), uint64(PAYLOAD + c)]
                    entry[uint64(top)] = ts[c]
                    top += (others >> c) & 1
                payload = payloads[uint64(row), uint64(PAYLOAD + c0)]
                continue
        else:
            tests += ((payload >> 32) & 0xffff) + ((payload >> 48) & 0xffff)
            best_t, best_prim, best_u, best_v = _leaf_closest(
                record, payload, shear, ray, lo, best_t, best_prim, best_u, best_v)
            hi32 = _hi32(best_t, shift)
            best_s = best_t - shift
        popped = False
        while top > 0:   # pop the next entry that starts before the nearest hit
            top -= 1
            if entry[uint64(top)] <= best_s:
                payload = stack[uint64(top)]
                popped = True
                break
        if not popped:
            break
    if best_prim == NO_HIT:
        best_t = np.inf
    return best_t, best_prim, best_u, best_v, visits, tests


@njit(cache=True, _nrt=False, forceinline=True)
def closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    t, prim, u, v, _, _ = _closest(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)
    return t, prim, u, v


@njit(cache=True, _nrt=False, forceinline=True)
def any_hit(record, scratch, ox, oy, oz, dx, dy, dz, lo, hi):
    """Any-hit traversal of one ray: every child hit is pushed (in slot order, unsorted: entering
    the nearest first measured slower for shadow rays), and the first primitive hit ends it."""
    nodes, payloads = record.nodes, record.payloads
    stack = scratch[0]
    planes, slab_ray, lo32, hi32, _, wild = _ray_planes(ox, oy, oz, dx, dy, dz, lo, hi)
    shear = shear_setup(ox, oy, oz, dx, dy, dz)
    ray = (ox, oy, oz, dx, dy, dz)
    if wild:   # a direction float32 cannot invert: every primitive
        return (_blocks_any(record, 0, record.blocks.shape[0], shear, ray, lo, hi)
                or spheres_any(record.centers, record.radii, ox, oy, oz, dx, dy, dz, lo, hi))
    top = 0
    payload = 0
    while nodes.shape[0] > 0:
        if payload >> 32 == 0:
            row = payload
            mask = slab_test(nodes, row, planes, slab_ray, lo32, hi32)[0]
            for c in range(WIDTH):
                stack[uint64(top)] = payloads[uint64(row), uint64(PAYLOAD + c)]
                top += (mask >> c) & 1
        elif _leaf_any(record, payload, shear, ray, lo, hi):
            return True
        if top == 0:
            break
        top -= 1
        payload = stack[uint64(top)]
    return False


compiled.register(BVHRecord, new_scratch, closest_hit, any_hit)


@njit(cache=True, parallel=True)
def _count_work(record, origins, directions, tmin, tmax, out_visits, out_tests):
    """Each ray's wide-node visits and primitive tests in a closest-hit trace (traversal_work)."""
    n_rays = origins.shape[0]
    for block in prange((n_rays + RAY_BLOCK - 1) // RAY_BLOCK):
        scratch = new_scratch(record)
        for r in range(block * RAY_BLOCK, min(n_rays, (block + 1) * RAY_BLOCK)):
            out_visits[r], out_tests[r] = _closest(
                record, scratch, origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0],
                directions[r, 1], directions[r, 2], tmin[r], tmax[r])[4:]


def _mean(values):
    return float(values.mean()) if values.size else 0.0


class BVHAccelerator:
    kind = "bvh"
    record_class = BVHRecord

    def __init__(self, geometry, max_leaf_size=4, split="mean", triangle="watertight"):
        test = triangle_test(triangle)
        if split not in SPLITS:
            raise ValueError(f"unknown BVH split {split!r}; choose one of {', '.join(SPLITS)}")
        max_leaf_size = int(max_leaf_size)
        if not 1 <= max_leaf_size <= MAX_LEAF_SIZE:
            raise ValueError(f"max_leaf_size must be between 1 and {MAX_LEAF_SIZE}")
        self.geometry = geometry
        self.max_leaf_size = max_leaf_size
        self.split = split
        self.triangle = triangle
        start = time.perf_counter()
        prim_lower, prim_upper = geometry.primitive_bounds()
        centroid = 0.5 * (prim_lower + prim_upper)
        # Pad every box by a hair (1e-9 of the scene's largest coordinate) so the slab test's
        # rounding can never reject a hit that the primitive test accepts.
        scale = max(np.abs(prim_lower).max(initial=0.0), np.abs(prim_upper).max(initial=0.0))
        prim_lower = np.ascontiguousarray(prim_lower - 1e-9 * scale)
        prim_upper = np.ascontiguousarray(prim_upper + 1e-9 * scale)
        (self.lower, self.upper, self.child_or_first, self.count, self.order,
         self.max_depth) = _build(prim_lower, prim_upper, centroid, max_leaf_size,
                                  MEAN_SPLIT_DEPTH, split == "sah")
        # the build returns views of buffers sized for 2n - 1 nodes: copy to free the rest
        self.lower, self.upper = self.lower.copy(), self.upper.copy()
        self.child_or_first, self.count = self.child_or_first.copy(), self.count.copy()
        wide = _wide_rows(self.lower, self.upper, self.child_or_first, self.count)
        self._nodes, payloads = _node_rows(wide.shape[0])
        self._blocks, self._prims = _fill_rows(wide, self._nodes, payloads, self.order,
                                               geometry.triangle_count, geometry.vertices,
                                               geometry.faces)
        del wide
        self._build_seconds = time.perf_counter() - start
        # A wide row at level L comes from a binary node at depth >= L, and popping it leaves
        # at most (WIDTH - 1) L + WIDTH entries on a traversal stack: depth < STACK_SIZE - 1
        # keeps that within WIDE_STACK.
        if self.max_depth >= STACK_SIZE - 1:   # not an assert: it must hold under python -O
            raise RuntimeError("BVH deeper than the traversal stack")
        self.compiled = BVHRecord(self._nodes, payloads, self._blocks, self._prims,
                                  geometry.triangle_count, geometry.centers, geometry.radii, test)

    def wide_tree(self):
        """The traversal's tree as float64 arrays, for tests and studies: (lower, upper) of
        shape (rows, 3, WIDTH), each child's box as traversed (float32, rounded outward), and
        payloads (rows, WIDTH) as described in _node_rows."""
        planes = self._nodes[:, :6 * WIDTH].astype(np.float64).reshape(-1, 6, WIDTH)
        return planes[:, :3], planes[:, 3:], self.compiled.payloads[:, PAYLOAD:].copy()

    def intersect(self, rays):
        """The batch closest hit through the compiled face, as every backend's (and as the path
        loop calls it): nothing counted, so its rays per second compare with Embree's."""
        rays.validate()
        return compiled.run_intersect(self.compiled, rays, Hits)

    def traversal_work(self, rays):
        """(wide nodes visited, primitive tests) per ray, averaged over a closest-hit trace of
        `rays`, for benchmarks and tests: interior wide nodes only (leaves are counted by their
        primitives; a block's unused lanes are not). A trace of its own, counting as it goes,
        so that intersect() counts nothing and pays nothing for it. Not comparable with counts
        from before the 8-wide traversal."""
        rays.validate()
        visits = np.empty(len(rays), dtype=np.int64)
        tests = np.empty(len(rays), dtype=np.int64)
        _count_work(self.compiled, rays.origins, rays.directions, rays.tmin, rays.tmax, visits,
                    tests)
        return _mean(visits), _mean(tests)

    def occluded(self, rays):
        rays.validate()
        return compiled.run_occluded(self.compiled, rays)

    def stats(self):
        nodes = int(self.lower.shape[0])
        arrays = (self._nodes, self._blocks, self._prims)   # what traversal reads
        return {"kind": self.kind, "primitives": self.geometry.primitive_count,
                "triangles": self.geometry.triangle_count, "spheres": self.geometry.sphere_count,
                "build_seconds": self._build_seconds, "split": self.split,
                "triangle": self.triangle, "width": WIDTH,
                "nodes": nodes, "wide_nodes": int(self._nodes.shape[0]),
                "leaves": int((self.count > 0).sum()),
                "triangle_blocks": int(self._blocks.shape[0]),
                "max_depth": int(self.max_depth), "max_leaf_size": self.max_leaf_size,
                "largest_leaf": int(self.count.max(initial=0)),
                "bytes": int(sum(a.nbytes for a in arrays))}
