"""The BVH's build: a binary tree by the mean-centroid split (or a binned SAH), which
accel.bvh_wide folds into the 8-wide rows that the traversal in accel.bvh reads.

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

Memory. The primitives' boxes come in as float32, rounded outward (_primitive_boxes): the traversal
rounds every box outward to float32 anyway, and the least float32 at or below a set's minimum is
the minimum of the least float32s at or below each, so the rows it walks are the same as from
float64 boxes. The nodes' boxes are therefore float32 too. The node arrays are made for the worst
case of 2n - 1 nodes with np.empty and returned as views of the nodes used: the pages of nodes
never written are never touched, so they cost address space, not memory.
"""
import numpy as np
from numba import njit

from .bvh_wide import _float32_down, _float32_up, _half_area

STACK_SIZE = 128
MEAN_SPLIT_DEPTH = 64   # below this depth only count splits: depth <= 64 + log2(n) < STACK_SIZE
# the mean-centroid split the course suggests (its staff build uses the midpoint of the centroid
# bounds); a binned surface-area heuristic
SPLITS = ("mean", "sah")
SAH_BINS = 16


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


def _make_build(sah):
    """The build of one split, the SAH or the mean (a constant of its code, so that the mean
    split's build never compiles the SAH's partition):

        lower, upper, child_or_first, count, order, max_depth = build(
            prim_lower, prim_upper, centroid, max_leaf_size, mean_split_depth)
    """
    SAH = sah

    @njit(cache=True)
    def build(prim_lower, prim_upper, centroid, max_leaf_size, mean_split_depth):
        n = prim_lower.shape[0]
        max_nodes = max(2 * n - 1, 1)
        # every node used gets all four written; np.empty leaves the pages of the rest untouched
        lower = np.empty((max_nodes, 3), dtype=prim_lower.dtype)
        upper = np.empty((max_nodes, 3), dtype=prim_upper.dtype)
        child_or_first = np.empty(max_nodes, dtype=np.int64)
        count = np.empty(max_nodes, dtype=np.int64)
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
            if SAH:
                if depth < mean_split_depth:
                    mid = _sah_partition(prim_lower, prim_upper, centroid, order, start, end, c_lo,
                                         c_hi)
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
    return build


# the build of each split (SPLITS)
BUILDS = {"mean": _make_build(False), "sah": _make_build(True)}


@njit(cache=True)
def _primitive_boxes(vertices, faces, centers, radii, pad):
    """(lower, upper, centroid) of every primitive for the build, in one pass without temporaries:
    the box of its corners (a sphere's centre -+ radius) widened by `pad`, rounded outward to
    float32, and the float64 centroid of the box before widening (as accel.Geometry's
    primitive_bounds computes them)."""
    n_tri = faces.shape[0]
    n = n_tri + centers.shape[0]
    lower = np.empty((n, 3), dtype=np.float32)
    upper = np.empty((n, 3), dtype=np.float32)
    centroid = np.empty((n, 3))
    for p in range(n):
        for a in range(3):
            if p < n_tri:
                x0 = vertices[faces[p, 0], a]
                x1 = vertices[faces[p, 1], a]
                x2 = vertices[faces[p, 2], a]
                lo = min(min(x0, x1), x2)
                hi = max(max(x0, x1), x2)
            else:
                lo = centers[p - n_tri, a] - radii[p - n_tri]
                hi = centers[p - n_tri, a] + radii[p - n_tri]
            centroid[p, a] = 0.5 * (lo + hi)
            lower[p, a] = _float32_down(lo - pad)
            upper[p, a] = _float32_up(hi + pad)
    return lower, upper, centroid
