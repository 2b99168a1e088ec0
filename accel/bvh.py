"""Our hand-written BVH: the seed's mean-centroid split, built and traversed without recursion.

`split="sah"` chooses instead, among 16 bins of the centroid bounds on each axis, the plane of
least surface-area cost (n_left * area_left + n_right * area_right); everything else is shared.

Build: a node covers a contiguous range of the primitive order array. It becomes a leaf when it
holds at most `max_leaf_size` primitives; otherwise it splits along the longest axis of its
centroid bounds at the mean centroid. When that leaves one side empty (coincident centroids,
rounding), or the node is deeper than `MEAN_SPLIT_DEPTH`, it splits by count instead (the lower
half of the centroids sorted on that axis goes left), which always makes progress and bounds the
depth: a run of bad mean splits cannot make a giant leaf, an endless loop, or a tree deeper than
the traversal stack.

Layout (structure of arrays): lower[n], upper[n] boxes; child_or_first[n] is the left child index
(the right child is the next node) for an interior node, or the first entry in `order` for a leaf;
count[n] is 0 for an interior node and the number of primitives for a leaf.

Traversal does not walk that binary tree: after the build, `_collapse` folds it into a 4-wide
tree (each wide node takes its binary node's two children, then keeps opening the interior child
of largest surface area until it has four), which halves the nodes a ray visits and so the chain
of dependent memory loads (the README's BVH departure gives the side-by-side figures against the
binary traversal, and benchmarks/results/accel_rays.md the rays per second of today's; an 8-wide
tree and float32 boxes were tried and were not faster). A wide node is one row of 32
floats (256 bytes, 64-byte aligned): for each of the six planes lower x, y, z, upper x, y, z the
value of its 4 children, then the 4 children's links, then their counts. A link is a wide node's
row when its count is 0 and the first entry in `order` of a leaf otherwise; an unused slot has an
empty box (lower +inf, upper -inf) that no ray enters. Triangles are stored as (p0, p1, p2) rows
in leaf order (what both triangle tests of accel.kernels read).
"""
import time
from collections import namedtuple

import numpy as np
from numba import njit, prange

from . import compiled
from .kernels import (
    NO_HIT,
    better,
    row_triangle_hit,
    shear_setup,
    slab_setup,
    sphere_hit,
    triangle_test,
)
from .types import Hits

STACK_SIZE = 128
MEAN_SPLIT_DEPTH = 64   # below this depth only count splits: depth <= 64 + log2(n) < STACK_SIZE
SPLITS = ("mean", "sah")   # the seed's mean-centroid split; a binned surface-area heuristic
SAH_BINS = 16
RAY_BLOCK = compiled.RAY_BLOCK   # rays per parallel work item of the batch kernels
WIDTH = 4                # children per node of the traversal's tree
WIDE_STACK = (WIDTH - 1) * STACK_SIZE + WIDTH   # each pop pushes at most WIDTH - 1 more


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


def _aligned_empty(rows, columns):
    """An empty float64 (rows, columns) array whose first row starts on a 64-byte boundary
    (numpy only promises 16), so each wide node row starts a cache line."""
    buffer = np.empty(rows * columns + 8)
    skip = (-buffer.ctypes.data % 64) // 8
    return buffer[skip:skip + rows * columns].reshape(rows, columns)


@njit(cache=True)
def _collapse(lower, upper, child_or_first, count, wide):
    """Fold the binary tree into WIDTH-wide rows of `wide` (see the module docstring); row 0
    is the root. Returns the number of rows used (at most the binary tree's node count)."""
    n = lower.shape[0]
    if n == 0:
        return 0
    todo_binary = np.empty(n, dtype=np.int64)   # binary node to become wide row todo_wide
    todo_wide = np.empty(n, dtype=np.int64)
    todo_binary[0], todo_wide[0] = 0, 0
    top = 1
    used = 1
    kids = np.empty(WIDTH, dtype=np.int64)
    while top > 0:
        top -= 1
        b, w = todo_binary[top], todo_wide[top]
        if count[b] > 0:   # a leaf root: one child
            kids[0] = b
            m = 1
        else:
            kids[0], kids[1] = child_or_first[b], child_or_first[b] + 1
            m = 2
        while m < WIDTH:   # open the interior child of largest area
            best, best_area = -1, -1.0
            for j in range(m):
                if count[kids[j]] == 0:
                    c = kids[j]
                    area = _half_area(lower[c, 0], lower[c, 1], lower[c, 2], upper[c, 0],
                                      upper[c, 1], upper[c, 2])
                    if area > best_area:
                        best, best_area = j, area
            if best < 0:
                break
            c = kids[best]
            kids[best], kids[m] = child_or_first[c], child_or_first[c] + 1
            m += 1
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


@njit(cache=True, inline="always")
def _child_entries(nodes, node, ox, oy, oz, ix, iy, iz, nx, ny, nz, fx, fy, fz, tmin, tmax,
                   entries):
    """Slab test of the ray against the WIDTH child boxes of wide node `node`: entries[c] is
    child c's entry t clipped to [tmin, tmax], or inf where the ray misses it.

    ix, iy, iz are inverse_direction() of the ray's direction and nx .. fz from near_columns():
    the planes (0-5 for lower x, y, z, upper x, y, z) nearest and farthest along each axis, so
    no per-box comparison is needed to order the two planes. The test is written so that an
    unused slot's empty box (where t0 = inf and t1 = -inf make the tolerance NaN) is a miss.
    """
    for c in range(WIDTH):
        t0 = max(tmin, (nodes[node, nx * WIDTH + c] - ox) * ix,
                 (nodes[node, ny * WIDTH + c] - oy) * iy, (nodes[node, nz * WIDTH + c] - oz) * iz)
        t1 = min(tmax, (nodes[node, fx * WIDTH + c] - ox) * ix,
                 (nodes[node, fy * WIDTH + c] - oy) * iy, (nodes[node, fz * WIDTH + c] - oz) * iz)
        # The slab t values carry rounding error; widen the far end so a box never rejects a
        # hit the primitive test would accept (boxes are also padded at build time).
        entries[c] = t0 if t0 <= t1 + abs(t1) * 4e-16 else np.inf


@njit(cache=True)
def _pack_triangles(order, vertices, faces):
    """Each triangle's vertices (p0, p1, p2) in leaf order, so a leaf reads its triangles from
    consecutive rows instead of through order -> faces -> vertices."""
    n_tri = faces.shape[0]
    tris = np.zeros((order.shape[0], 9))
    for i in range(order.shape[0]):
        if order[i] < n_tri:
            for j in range(3):
                for a in range(3):
                    tris[i, 3 * j + a] = vertices[faces[order[i], j], a]
    return tris


BVHRecord = namedtuple("BVHRecord", ["nodes", "tris", "order", "n_tri", "centers", "radii",
                                     "triangle"])


@njit(cache=True)
def new_scratch(record):
    """Traversal stacks for one block of rays: links, their counts (0: a wide node, else a leaf
    size), the t where the ray enters each box, and the WIDTH children's entries."""
    return (np.empty(WIDE_STACK, dtype=np.int64), np.empty(WIDE_STACK, dtype=np.int64),
            np.empty(WIDE_STACK), np.empty(WIDTH))


@njit(cache=True, _nrt=False, forceinline=True)
def _closest(record, scratch, ox, oy, oz, dx, dy, dz, lo, hi):
    """Closest-hit traversal of one ray: (t, prim, u, v, wide nodes visited, triangle tests)."""
    nodes, tris, order, n_tri = record.nodes, record.tris, record.order, record.n_tri
    centers, radii = record.centers, record.radii
    stack, counts, entry, entries = scratch
    test = record.triangle
    ix, iy, iz, nx, ny, nz, fx, fy, fz = slab_setup(dx, dy, dz)
    shear = shear_setup(ox, oy, oz, dx, dy, dz)
    best_t = hi
    best_prim = NO_HIT
    best_u = 0.0
    best_v = 0.0
    visits = 0
    tests = 0
    top = 0
    if nodes.shape[0] > 0:   # the root's children are tested when it is popped
        stack[0], counts[0], entry[0] = 0, 0, lo
        top = 1
    while top > 0:
        top -= 1
        if entry[top] > best_t:
            continue
        link = stack[top]
        k = counts[top]
        if k > 0:
            for i in range(link, link + k):
                p = order[i]
                if p < n_tri:
                    tests += 1
                    t, u, v = row_triangle_hit(tris, i, test, ox, oy, oz, dx, dy, dz, shear)
                    if t >= lo and t <= best_t and better(t, p, best_t, best_prim):
                        best_t, best_prim, best_u, best_v = t, p, u, v
                else:
                    t = sphere_hit(centers, radii, p - n_tri, ox, oy, oz, dx, dy, dz, lo, best_t)
                    if t <= best_t and better(t, p, best_t, best_prim):
                        best_t, best_prim, best_u, best_v = t, p, 0.0, 0.0
            continue
        visits += 1
        _child_entries(nodes, link, ox, oy, oz, ix, iy, iz, nx, ny, nz, fx, fy, fz, lo, best_t,
                       entries)
        # push the children hit, farthest deepest, so the nearest is popped first
        # (an insertion sort of at most WIDTH entries above `base`)
        base = top
        for c in range(WIDTH):
            t = entries[c]
            if t == np.inf:
                continue
            j = top
            while j > base and entry[j - 1] < t:
                stack[j], counts[j], entry[j] = stack[j - 1], counts[j - 1], entry[j - 1]
                j -= 1
            stack[j] = int(nodes[link, 6 * WIDTH + c])
            counts[j] = int(nodes[link, 7 * WIDTH + c])
            entry[j] = t
            top += 1
    if best_prim == NO_HIT:
        best_t = np.inf
    return best_t, best_prim, best_u, best_v, visits, tests


@njit(cache=True, _nrt=False, forceinline=True)
def closest_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    t, prim, u, v, _, _ = _closest(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax)
    return t, prim, u, v


@njit(cache=True, _nrt=False, forceinline=True)
def any_hit(record, scratch, ox, oy, oz, dx, dy, dz, lo, hi):
    """Any-hit traversal of one ray: children are tested before they are pushed, leaves stop at
    the first primitive hit."""
    nodes, tris, order, n_tri = record.nodes, record.tris, record.order, record.n_tri
    centers, radii = record.centers, record.radii
    stack, counts, _, entries = scratch
    test = record.triangle
    ix, iy, iz, nx, ny, nz, fx, fy, fz = slab_setup(dx, dy, dz)
    shear = shear_setup(ox, oy, oz, dx, dy, dz)
    top = 0
    if nodes.shape[0] > 0:
        stack[0], counts[0] = 0, 0
        top = 1
    while top > 0:
        top -= 1
        link = stack[top]
        k = counts[top]
        if k > 0:
            for i in range(link, link + k):
                p = order[i]
                if p < n_tri:
                    t, u, v = row_triangle_hit(tris, i, test, ox, oy, oz, dx, dy, dz, shear)
                    if t >= lo and t <= hi:
                        return True
                elif sphere_hit(centers, radii, p - n_tri, ox, oy, oz, dx, dy, dz, lo, hi) <= hi:
                    return True
            continue
        _child_entries(nodes, link, ox, oy, oz, ix, iy, iz, nx, ny, nz, fx, fy, fz, lo, hi,
                       entries)
        for c in range(WIDTH):
            if entries[c] != np.inf:
                stack[top] = int(nodes[link, 6 * WIDTH + c])
                counts[top] = int(nodes[link, 7 * WIDTH + c])
                top += 1
    return False


compiled.register(BVHRecord, new_scratch, closest_hit, any_hit)


@njit(cache=True, parallel=True)
def _intersect(record, origins, directions, tmin, tmax, out_t, out_prim, out_u, out_v,
               out_visits, out_tests):
    """The batch closest hit, with each ray's visit and test counts (for the benchmarks)."""
    n_rays = origins.shape[0]
    for block in prange((n_rays + RAY_BLOCK - 1) // RAY_BLOCK):
        scratch = new_scratch(record)
        for r in range(block * RAY_BLOCK, min(n_rays, (block + 1) * RAY_BLOCK)):
            (out_t[r], out_prim[r], out_u[r], out_v[r], out_visits[r], out_tests[r]) = _closest(
                record, scratch, origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0],
                directions[r, 1], directions[r, 2], tmin[r], tmax[r])


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
        if max_leaf_size < 1:
            raise ValueError("max_leaf_size must be at least 1")
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
        # each wide row takes at least one interior binary node: at most (nodes + 1) / 2 rows
        wide = _aligned_empty(max(1, (self.lower.shape[0] + 1) // 2), 8 * WIDTH)
        used = _collapse(self.lower, self.upper, self.child_or_first, self.count, wide)
        self._nodes = _aligned_empty(used, 8 * WIDTH)
        self._nodes[:] = wide[:used]
        self._tris = _pack_triangles(self.order, geometry.vertices, geometry.faces)
        self._build_seconds = time.perf_counter() - start
        # A wide row at level L comes from a binary node at depth >= L, and popping it leaves
        # at most 3 L + 4 entries on a traversal stack: depth < STACK_SIZE - 1 keeps that
        # within WIDE_STACK.
        if self.max_depth >= STACK_SIZE - 1:   # not an assert: it must hold under python -O
            raise RuntimeError("BVH deeper than the traversal stack")
        self._last_work = None
        self.compiled = BVHRecord(self._nodes, self._tris, self.order, geometry.triangle_count,
                                  geometry.centers, geometry.radii, test)

    def intersect(self, rays):
        rays.validate()
        n = len(rays)
        hits = Hits(np.empty(n), np.empty(n, dtype=np.int64), np.empty(n), np.empty(n))
        visits = np.empty(n, dtype=np.int64)
        tests = np.empty(n, dtype=np.int64)
        _intersect(self.compiled, rays.origins, rays.directions, rays.tmin, rays.tmax, hits.t,
                   hits.prim, hits.u, hits.v, visits, tests)
        self._last_work = (visits, tests)   # averaged only when asked for (see below)
        return hits

    @property
    def last_mean_visits(self):
        """Interior wide nodes visited per ray in the last intersect() (None before the
        first); leaves are counted by last_mean_triangle_tests. Not comparable with figures
        from before the 4-wide traversal, which counted binary nodes, leaves included."""
        return None if self._last_work is None else _mean(self._last_work[0])

    @property
    def last_mean_triangle_tests(self):
        """Ray-triangle tests per ray in the last intersect() (None before the first)."""
        return None if self._last_work is None else _mean(self._last_work[1])

    def occluded(self, rays):
        rays.validate()
        return compiled.run_occluded(self.compiled, rays)

    def stats(self):
        nodes = int(self.lower.shape[0])
        arrays = (self._nodes, self._tris, self.order)   # what traversal reads
        return {"kind": self.kind, "primitives": self.geometry.primitive_count,
                "triangles": self.geometry.triangle_count, "spheres": self.geometry.sphere_count,
                "build_seconds": self._build_seconds, "split": self.split,
                "triangle": self.triangle,
                "nodes": nodes, "wide_nodes": int(self._nodes.shape[0]),
                "leaves": int((self.count > 0).sum()),
                "max_depth": int(self.max_depth), "max_leaf_size": self.max_leaf_size,
                "largest_leaf": int(self.count.max(initial=0)),
                "bytes": int(sum(a.nbytes for a in arrays))}
