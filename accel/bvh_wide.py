"""The BVH's traversal rows: the binary tree of accel.bvh_build folded into 8-wide nodes
and written out as the float32 rows and triangle blocks that accel.bvh walks.

Separate from the build because it is a second, independent step with its own cost model
and layout: the build only decides which primitives share a leaf; this module decides how
the tree is laid out for the vector slab test.

Traversal does not walk the binary tree: `_collapse` folds it into an 8-wide tree, so a ray
visits fewer nodes and the slab test of a node's children is one vector operation (accel.simd:
one AVX2 instruction per step, in float32). Which binary nodes become wide nodes is chosen for
the least sum of wide-node surface areas (the expected nodes a ray visits; _slot_costs, after
Ylitie, Karras and Laine 2017), leaves as built. A wide node is
one 256-byte row (_node_rows): its children's six box planes as float32, rounded outward so a
box never shrinks, and an int64 payload per child: a row for an interior child, or a leaf's
first triangle block and its triangle and sphere counts. The slab test computes in float32, from
the ray's origin moved outward and its inverse direction scaled outward per axis (accel.bvh_slab),
so that rounding can only keep a box, never lose one; which primitive is hit, and its t, come
from the leaves' float64 tests alone.
A leaf's triangles are stored by _fill_rows in blocks of four, as the mesh's own coordinates
(each lane of accel.simd's block test computes what the scalar test of accel.kernels computes on
those values, bit for bit, so bvh and naive agree exactly), and tested four at a time. They are
float32 when every coordinate of the mesh is a float32 value (a float PLY's, a glTF's: widened
as they are loaded, they are the same float64 values in half the memory), else float64. What
each of these choices bought is measured side by side in benchmarks/results/bvh_changes.md:
8-wide with vector slab and block tests over the earlier 4-wide scalar traversal, float32
planes over float64 ones, unsigned stack indices, entering a node's only child hit directly,
float32 slab arithmetic over float64.
"""
import numpy as np
from numba import njit
from numba.cpython.unsafe.numbers import viewer  # numba's bitcast

from .simd import BLOCK, BLOCK_COLUMNS

WIDTH = 8                # children per node of the traversal's tree (_closest's tournament: 8)
NODE_COLUMNS = 64        # float32 columns of a wide node's row: 6 * WIDTH planes, WIDTH payloads
PAYLOAD = 6 * WIDTH // 2   # the first payload's column in the row's int64 view
MAX_LEAF_SIZE = 0xffff   # a leaf payload holds its triangle and sphere counts in 16 bits each


@njit(cache=True, inline="always")
def _half_area(lx, ly, lz, hx, hy, hz):
    """Half the surface area of a box, in float64 (of float32 corners too)."""
    dx, dy, dz = (np.float64(hx) - np.float64(lx), np.float64(hy) - np.float64(ly),
                  np.float64(hz) - np.float64(lz))
    return dx * dy + dy * dz + dz * dx


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
def _collapse(lower, upper, child_or_first, count, planes, links, link_column):
    """Fold the binary tree into WIDTH-wide rows; row 0 is the root. Row w of `planes` holds in
    its first 6 * WIDTH columns the six planes lower x, y, z, upper x, y, z of its WIDTH
    children (their binary boxes as they are: float32 values when written to the traversal's
    float32 rows), and row w of `links`, from column `link_column`, each child's link: a wide
    row for an interior child, or first | count << 32 for a leaf (its first `order` entry and
    its primitive count, so nonzero above bit 31, as a leaf's traversal payload is); an unused
    slot has an empty box (lower +inf, upper -inf) and link 0. Which binary nodes become wide
    nodes is _slot_costs' least-cost choice; a row's children are in the binary tree's
    left-to-right order. _fill_rows then lays out the leaves. Returns the number of rows used
    (at most the binary tree's interior node count, or 1 for a leaf root)."""
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
                    planes[w, a * WIDTH + k] = np.inf
                    planes[w, (3 + a) * WIDTH + k] = -np.inf
                links[w, link_column + k] = 0
                continue
            c = kids[k]
            for a in range(3):
                planes[w, a * WIDTH + k] = lower[c, a]
                planes[w, (3 + a) * WIDTH + k] = upper[c, a]
            if count[c] > 0:
                links[w, link_column + k] = child_or_first[c] | (count[c] << 32)
            else:
                links[w, link_column + k] = used
                todo_binary[top], todo_wide[top] = c, used
                top += 1
                used += 1
    return used


def _traversal_rows(lower, upper, child_or_first, count, collapse=_collapse):
    """(nodes, payloads) of _node_rows with the collapse written straight into them (a leaf's
    payload still first | count << 32, for _fill_rows). The rows are made for the worst case (a
    row per interior binary node; untouched pages cost nothing) and, where fewer are used, the
    used ones copied into rows of their own. The boxes must be float32 (the build's): the rows
    hold them as they are. `collapse` is _collapse, compiled or interpreted (accel.bvh)."""
    if lower.dtype != np.float32 or upper.dtype != np.float32:
        raise TypeError("the traversal rows take the build's float32 boxes")
    interior = max(1, int(np.count_nonzero(count == 0))) if count.shape[0] else 0
    nodes, payloads = _node_rows(interior)
    used = collapse(lower, upper, child_or_first, count, nodes, payloads, PAYLOAD)
    if used == interior:
        return nodes, payloads
    kept, kept_payloads = _node_rows(used)
    kept[:] = nodes[:used]
    return kept, kept_payloads


@njit(cache=True)
def _wide_rows(lower, upper, child_or_first, count):
    """The collapse as float64 rows of 8 * WIDTH columns, for tests and studies: the planes,
    then each child's link (a wide row, or its first `order` entry for a leaf), then its count
    (0 for an interior child or an unused slot)."""
    interior = max(1, int((count == 0).sum()))
    planes = np.empty((interior, 6 * WIDTH))
    links = np.empty((interior, WIDTH), dtype=np.int64)
    used = _collapse(lower, upper, child_or_first, count, planes, links, 0)
    wide = np.empty((used, 8 * WIDTH))
    for r in range(used):
        for k in range(6 * WIDTH):
            wide[r, k] = planes[r, k]
        for k in range(WIDTH):
            link = links[r, k]
            wide[r, 6 * WIDTH + k] = link & 0xffffffff if link >> 32 else link
            wide[r, 7 * WIDTH + k] = link >> 32
    return wide


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
def _float32_exact(vertices):
    """True when every coordinate is a float32 value (a float PLY's, a glTF's): the leaves'
    blocks can then hold float32 coordinates, widened to exactly the same float64 values."""
    for i in range(vertices.shape[0]):
        for a in range(3):
            if np.float64(np.float32(vertices[i, a])) != vertices[i, a]:
                return False
    return True


@njit(cache=True)
def _fill_rows(nodes, payloads, order, n_tri, vertices, faces, single):
    """The leaves as blocks of BLOCK triangles, in the order the rows reach them, and each leaf
    slot's traversal payload (_node_rows) in place of _collapse's first | count << 32.

    For each leaf slot of each row: its triangles fill ceil(triangles / BLOCK) consecutive
    blocks (NaN in unused lanes, which every triangle test misses), then its spheres take
    ceil(spheres / BLOCK) more block rows of `prims` (their block rows stay NaN), so every leaf
    starts on a block. Returns (blocks, blocks32, prims): the (blocks, BLOCK_COLUMNS) vertex
    coordinates, float64 in `blocks`, or float32 in `blocks32` where `single` (every coordinate a
    float32 value: _float32_exact), the other array empty; and the int64 primitive id of each
    lane (-1 unused)."""
    rows = nodes.shape[0]
    n_blocks = 0
    for r in range(rows):
        for c in range(WIDTH):
            link = payloads[r, PAYLOAD + c]
            if link >> 32:
                first, size = link & 0xffffffff, link >> 32
                n_tri_leaf = 0
                for i in range(first, first + size):
                    n_tri_leaf += order[i] < n_tri
                n_sph = size - n_tri_leaf
                n_blocks += (n_tri_leaf + BLOCK - 1) // BLOCK + (n_sph + BLOCK - 1) // BLOCK
    blocks = np.full((0 if single else n_blocks, BLOCK_COLUMNS), np.nan)
    blocks32 = np.full((n_blocks if single else 0, BLOCK_COLUMNS), np.nan, dtype=np.float32)
    prims = np.full(n_blocks * BLOCK, -1, dtype=np.int64)
    block = 0
    for r in range(rows):
        for c in range(WIDTH):
            link = payloads[r, PAYLOAD + c]
            if link >> 32 == 0:
                continue
            first_entry, size = link & 0xffffffff, link >> 32
            first = block
            lane = 0
            for i in range(first_entry, first_entry + size):   # triangles first
                p = order[i]
                if p < n_tri:
                    for j in range(3):
                        for a in range(3):
                            column = (3 * j + a) * BLOCK + lane
                            if single:
                                blocks32[block, column] = vertices[faces[p, j], a]
                            else:
                                blocks[block, column] = vertices[faces[p, j], a]
                    prims[block * BLOCK + lane] = p
                    lane += 1
                    if lane == BLOCK:
                        block, lane = block + 1, 0
            n_tri_leaf = (block - first) * BLOCK + lane
            if lane > 0:
                block, lane = block + 1, 0
            spheres = block * BLOCK
            for i in range(first_entry, first_entry + size):
                if order[i] >= n_tri:
                    prims[spheres] = order[i]
                    spheres += 1
            n_sph = spheres - block * BLOCK
            block += (n_sph + BLOCK - 1) // BLOCK
            payloads[r, PAYLOAD + c] = first | (n_tri_leaf << 32) | (n_sph << 48)
    return blocks, blocks32, prims


def _node_rows(rows):
    """An empty node array of `rows` 256-byte rows, one per wide node, each starting a cache line,
    and its int64 view (filled by _fill_rows).

    Columns 0-47 (float32): the six planes lower x, y, z, upper x, y, z, WIDTH children each,
    rounded outward; columns 48-63, read as int64 columns PAYLOAD.. PAYLOAD + 7: each child's
    payload. A payload is a row for an interior child, or for a leaf first_block | n_triangles
    << 32 | n_spheres << 48 (n_triangles + n_spheres > 0, so payload >> 32 is not 0), its
    triangles in blocks first_block.. and its spheres' ids in the `prims` entries after them
    (_fill_rows). Made with np.empty: the pages of rows never written cost no memory."""
    nodes = _aligned_empty(rows, NODE_COLUMNS, np.float32)
    return nodes, nodes.view(np.int64)
