"""Our hand-written BVH: the course's suggested mean-centroid split, built and walked iteratively.

`split="sah"` chooses instead, among 16 bins of the centroid bounds on each axis, the plane of
least surface-area cost (n_left * area_left + n_right * area_right); everything else is shared.

Traversal (this module) walks not the binary tree of the build (accel.bvh_build) but the
8-wide rows accel.bvh_wide folds it into, laid out as described there: the slab test of a
node's children is one vector operation (accel.simd, in float32, its planes and each ray
(accel.bvh_slab) rounded outward so that rounding can only keep a box, never lose one); which
primitive is hit, and its t, come from the leaves' float64 tests alone, four triangles at a
time, bit for bit the scalar
test of accel.kernels.
"""
import time
from collections import namedtuple

import numpy as np
from numba import njit, uint64
from numba.cpython.unsafe.numbers import trailing_zeros  # numba's llvm.cttz

from . import compiled, interpreted
from .bvh_build import (  # noqa: F401 - the build's names, re-exported as before
    BUILDS,
    MEAN_SPLIT_DEPTH,
    SPLITS,
    STACK_SIZE,
    _primitive_boxes,
)
from .bvh_slab import _hi32, _ray_planes  # noqa: F401 - _ray_planes re-exported as before
from .bvh_wide import (  # noqa: F401 - the rows' names, re-exported as before
    MAX_LEAF_SIZE,
    PAYLOAD,
    WIDTH,
    _collapse,
    _fill_rows,
    _float32_down,
    _float32_exact,
    _float32_up,
    _node_rows,
    _traversal_rows,
    _wide_rows,
)
from .kernels import (
    NO_HIT,
    MollerTrumbore,
    better,
    shear_setup,
    sphere_hit,
    triangle_test,
)
from .simd import BLOCK, make_slab_test, moller_trumbore_block, watertight_block

WIDE_STACK = (WIDTH - 1) * STACK_SIZE + WIDTH   # each pop pushes at most WIDTH - 1 more
slab_test = make_slab_test(WIDTH)
# the root's payload and the miss's primitive as int64 values, not literals: a literal argument
# compiles each traversal helper once more for it (_blocks_closest three times, not once)
ROOT, MISS = np.int64(0), np.int64(NO_HIT)
BINARY_FIELDS = ("lower", "upper", "child_or_first", "count", "order")


# blocks: the leaves' triangles, float32 where every coordinate is a float32 value (_fill_rows),
# else float64; the record of the watertight test, and of Möller–Trumbore
# (accel.kernels.MollerTrumbore). The blocks' dtype and the class are the record's numba type:
# a traversal compiles for the one leaf test its record has.
BVHRecord = namedtuple("BVHRecord", ["nodes", "payloads", "blocks", "prims", "n_tri", "centers",
                                     "radii"])


class BVHRecordMT(BVHRecord, MollerTrumbore):
    __slots__ = ()


RECORDS = (BVHRecord, BVHRecordMT)   # by accel.kernels.triangle_test


@njit(cache=True)
def new_scratch(record):
    """Traversal stack for one block of rays: payloads and the t where the ray enters each."""
    return np.empty(WIDE_STACK, dtype=np.int64), np.empty(WIDE_STACK, dtype=np.float32)


@njit(cache=True, inline="always")
def _watertight_block(record, block, shear, ray, lo, hi):
    return watertight_block(record.blocks, block, shear, lo, hi)


@njit(cache=True, inline="always")
def _moller_trumbore_block(record, block, shear, ray, lo, hi):
    return moller_trumbore_block(record.blocks, block, ray, lo, hi)


# the record's triangle test on one block: (mask, t's, u's, v's) of its BLOCK lanes
_block_test = compiled.by_class(MollerTrumbore, _moller_trumbore_block, _watertight_block)


@njit(cache=True, inline="always")
def _nearer(ta, a, tb, b):
    """The pair (t, slot) nearer first: a compare-exchange of the nearest-child tournament."""
    if tb < ta:
        return tb, b, ta, a
    return ta, a, tb, b


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
def _blocks_any(record, first, n_blocks, shear, ray, lo, hi):
    """True if a triangle of blocks first.. first + n_blocks is hit with lo <= t <= hi."""
    for block in range(first, first + n_blocks):
        if _block_test(record, block, shear, ray, lo, hi)[0] != 0:
            return True
    return False


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
def _every_child(payloads, row):
    """The mask of a wide node's children (an unused slot's link is 0, the root's row): the
    traversal's for a ray with a direction component float32 cannot invert (_ray_planes), which
    visits every node and leaf instead of slab testing them."""
    mask = 0
    for c in range(WIDTH):
        mask |= (payloads[uint64(row), uint64(PAYLOAD + c)] != 0) << c
    return mask


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
    best_t = hi
    best_prim = MISS
    best_u = 0.0
    best_v = 0.0
    best_s = hi - shift   # best_t on the slab's scale: a pushed entry t is compared with it
    visits = 0
    tests = 0
    top = 0
    payload = ROOT   # the root, row 0
    while nodes.shape[0] > 0:
        if payload >> 32 == 0:   # a wide node
            visits += 1
            row = payload
            mask, ts = slab_test(nodes, row, planes, slab_ray, lo32, hi32)
            if wild:   # no slab test for this ray: every child, pushed to be entered in turn
                every = _every_child(payloads, row)
                for c in range(WIDTH):
                    stack[uint64(top)] = payloads[uint64(row), uint64(PAYLOAD + c)]
                    entry[uint64(top)] = -np.inf
                    top += (every >> c) & 1
                mask = 0
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
def any_hit(record, scratch, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Any-hit traversal of one ray: every child hit is pushed (in slot order, unsorted: entering
    the nearest first measured slower for shadow rays), and the first primitive hit ends it."""
    lo, hi = tmin, tmax
    nodes, payloads = record.nodes, record.payloads
    stack = scratch[0]
    planes, slab_ray, lo32, hi32, _, wild = _ray_planes(ox, oy, oz, dx, dy, dz, lo, hi)
    shear = shear_setup(ox, oy, oz, dx, dy, dz)
    ray = (ox, oy, oz, dx, dy, dz)
    top = 0
    payload = ROOT
    while nodes.shape[0] > 0:
        if payload >> 32 == 0:
            row = payload
            mask = slab_test(nodes, row, planes, slab_ray, lo32, hi32)[0]
            if wild:   # no slab test for this ray: every child
                mask = _every_child(payloads, row)
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


for _record in RECORDS:
    compiled.register(_record, new_scratch, closest_hit, any_hit)


@njit(cache=True, nogil=True)
def _count_work(record, origins, directions, tmin, tmax, out_visits, out_tests, start, end):
    """Rays start .. end - 1's wide-node visits and primitive tests in a closest-hit trace
    (traversal_work)."""
    scratch = new_scratch(record)
    for r in range(start, end):
        out_visits[r], out_tests[r] = _closest(
            record, scratch, origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0],
            directions[r, 1], directions[r, 2], tmin[r], tmax[r])[4:]


def _mean(values):
    return float(values.mean()) if values.size else 0.0


class BVHAccelerator(compiled.CompiledFace):
    kind = "bvh"
    record_class = BVHRecord

    def __init__(self, geometry, max_leaf_size=4, split="mean", triangle="watertight"):
        record = RECORDS[triangle_test(triangle)]
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
        lower, upper, child_or_first, count, order, self.max_depth = self._binary_tree()
        self._tree_stats = (int(count.shape[0]), int((count > 0).sum()),
                            int(count.max(initial=0)))
        run = self._run
        self._nodes, payloads = _traversal_rows(lower, upper, child_or_first, count,
                                                run(_collapse))
        # the binary tree goes before the leaves' blocks are made (it is rebuilt if asked for:
        # __getattr__); only the order of its primitives is needed for them
        del lower, upper, child_or_first, count
        blocks, blocks32, self._prims = run(_fill_rows)(
            self._nodes, payloads, order, geometry.triangle_count, geometry.vertices,
            geometry.faces, run(_float32_exact)(geometry.vertices))
        del order
        self._blocks = blocks32 if blocks32.shape[0] else blocks
        self._build_seconds = time.perf_counter() - start
        # A wide row at level L comes from a binary node at depth >= L, and popping it leaves
        # at most (WIDTH - 1) L + WIDTH entries on a traversal stack: depth < STACK_SIZE - 1
        # keeps that within WIDE_STACK.
        if self.max_depth >= STACK_SIZE - 1:   # not an assert: it must hold under python -O
            raise RuntimeError("BVH deeper than the traversal stack")
        self.compiled = record(self._nodes, payloads, self._blocks, self._prims,
                               geometry.triangle_count, geometry.centers, geometry.radii)

    def _binary_tree(self):
        """(lower, upper, child_or_first, count, order, max_depth) of the binary tree that the
        wide rows fold, as accel.bvh_build lays it out, its boxes float32 (views of arrays
        made for the worst case: accel.bvh_build). The build is deterministic, so the tree is
        made again from the geometry when asked for rather than kept beside the rows; the
        primitives' boxes and centroids are freed when the build returns."""
        geometry = self.geometry
        # Pad every box by a hair (1e-9 of the scene's largest coordinate) so the slab test's
        # rounding can never reject a hit that the primitive test accepts.
        bounds = geometry.bounds()
        scale = 0.0 if bounds is None else float(max(np.abs(bounds[0]).max(),
                                                     np.abs(bounds[1]).max()))
        run = self._run
        prim_lower, prim_upper, centroid = run(_primitive_boxes)(
            geometry.vertices, geometry.faces, geometry.centers, geometry.radii, 1e-9 * scale)
        return run(BUILDS[self.split])(prim_lower, prim_upper, centroid, self.max_leaf_size,
                                       MEAN_SPLIT_DEPTH)

    def _run(self, function):
        """A build function as this geometry's build runs it: compiled, or for a scene of at
        most accel.interpreted.SMALL primitives as Python, the same tree in well under a second
        where compiling the build costs about a quarter of a small scene's first render."""
        return interpreted.sized(function, self.geometry.primitive_count)

    def __getattr__(self, name):
        """The binary tree's arrays (lower, upper, child_or_first, count, order), for tests
        and studies: made again on first use (_binary_tree), trimmed to the nodes used, the
        boxes as float64, and kept from then on."""
        if name in BINARY_FIELDS and "geometry" in self.__dict__:
            tree = [array.copy() for array in self._binary_tree()[:5]]
            tree[0], tree[1] = tree[0].astype(np.float64), tree[1].astype(np.float64)
            self.__dict__.update(zip(BINARY_FIELDS, tree))
            return self.__dict__[name]
        raise AttributeError(name)

    def wide_tree(self):
        """The traversal's tree as float64 arrays, for tests and studies: (lower, upper) of
        shape (rows, 3, WIDTH), each child's box as traversed (float32, rounded outward), and
        payloads (rows, WIDTH) as described in _node_rows."""
        planes = self._nodes[:, :6 * WIDTH].astype(np.float64).reshape(-1, 6, WIDTH)
        return planes[:, :3], planes[:, 3:], self.compiled.payloads[:, PAYLOAD:].copy()

    def traversal_work(self, rays):
        """(wide nodes visited, primitive tests) per ray, averaged over a closest-hit trace of
        `rays`, for benchmarks and tests: interior wide nodes only (leaves are counted by their
        primitives; a block's unused lanes are not). A trace of its own, counting as it goes,
        so that intersect() counts nothing and pays nothing for it. Not comparable with counts
        from before the 8-wide traversal."""
        rays.validate()
        visits = np.empty(len(rays), dtype=np.int64)
        tests = np.empty(len(rays), dtype=np.int64)
        compiled.in_blocks(_count_work, len(rays), self.compiled, rays.origins, rays.directions,
                           rays.tmin, rays.tmax, visits, tests)
        return _mean(visits), _mean(tests)

    def stats(self):
        nodes, leaves, largest = self._tree_stats
        arrays = (self._nodes, self._blocks, self._prims)   # what traversal reads
        return {**self.geometry_stats(), "split": self.split,
                "triangle": self.triangle, "width": WIDTH,
                "nodes": nodes, "wide_nodes": int(self._nodes.shape[0]),
                "leaves": leaves,
                "triangle_blocks": int(self._blocks.shape[0]),
                "max_depth": int(self.max_depth), "max_leaf_size": self.max_leaf_size,
                "largest_leaf": largest,
                "bytes": int(sum(a.nbytes for a in arrays))}
