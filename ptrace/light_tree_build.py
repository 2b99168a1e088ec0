"""The light BVH's layout (LightTree) and its build: bounded light entries in, a tree of flat
arrays out, each node's box, power and emission cone, split where pbrt-v4's surface-area and
orientation cost is least.

Separate from ptrace.light_tree, which samples and evaluates the tree at a shading point from
numba code; this is the one-off construction, run once per render, and that module re-exports
LightTree and build_light_tree.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

LightTree = namedtuple("LightTree", [
    "lower", "upper",        # (M, 3) float64: each node's box
    "center", "radius2",     # (M, 3), (M,): its bounding sphere (centre, squared radius)
    "power",                 # (M,): its entries' power, as a fraction of the whole tree's
    "axis", "cos_o", "sin_o", "cos_e",   # (M, 3), (M,) x 3: its emission cone
    "two_sided",             # (M,) bool: the cone also holds its mirror image (-axis)
    "child",                 # (M,) int64: an interior node's second child (its first is the
                             # next node), -1 for a leaf
    "entry",                 # (M,) int64: a leaf's entry index, -1 for an interior node
    "entry_node",            # (L,) int64: each entry's leaf, -1 for an entry left out
    # the same tree four levels at a time, as the walk reads it (_wide): W nodes of LANES
    # lanes, each lane one of the binary tree's nodes
    "lanes",                 # (W, FIELDS, LANES) float64: each lane's node, field by field
    "kid",                   # (W, LANES) int64: a lane's wide node, or -1 - its binary leaf
    "span",                  # (W, LANES, 2) int64: the binary nodes [first, end) of its subtree
])

BUCKETS = 12
SAMPLE = 1024
ONE_MINUS_EPSILON = 1.0 - 2.0 ** -53


LANES = 16        # a wide node's lanes: the binary tree's nodes four levels down
LEVELS = 4
# a lane's fields in LightTree.lanes: box, bounding sphere, power, emission cone, and flags
F_LO, F_HI, F_CENTER, F_R2, F_POWER, F_AXIS = 0, 3, 6, 9, 10, 11
F_COS_O, F_SIN_O, F_COS_E, F_TWO, F_FLAT = 14, 15, 16, 17, 18
FIELDS = 19

# -- building ----------------------------------------------------------------------------------

@njit(cache=True, _nrt=False, inline="always")
def _cone_cos(ax, ay, az, wx, wy, wz, cos_o, sin_o):
    """cos(min(pi, angle(a, w) + theta_o)): the widest angle from axis a that a cone about w
    of half-angle theta_o reaches."""
    cd = min(1.0, max(-1.0, ax * wx + ay * wy + az * wz))
    if cos_o <= -cd:
        return -1.0
    return cd * cos_o - math.sqrt(max(0.0, 1.0 - cd * cd)) * sin_o


# columns of the entries' and the nodes' packed rows while building
LO, HI, AX, PW, CO, SO, CE, TW, ID = 0, 3, 6, 9, 10, 11, 12, 13, 14
WIDTH = 15


@njit(cache=True)
def _entries_cone(rec, start, end, two):
    """A tight cone holding the cones of entries rec[start:end]: their mean axis (turned toward
    the first one's where two-sided) and the widest angle any of them reaches from it; the first
    axis itself, exactly, when all are the same (so flat emitters keep cos_o 1).
    (ax, ay, az, cos_o)."""
    fx, fy, fz = rec[start, AX], rec[start, AX + 1], rec[start, AX + 2]
    sx = sy = sz = 0.0
    same = True
    for j in range(start, end):
        wx, wy, wz = rec[j, AX], rec[j, AX + 1], rec[j, AX + 2]
        if two and wx * fx + wy * fy + wz * fz < 0.0:
            wx, wy, wz = -wx, -wy, -wz
        sx, sy, sz = sx + wx, sy + wy, sz + wz
        same = same and wx == fx and wy == fy and wz == fz
    length = math.sqrt(sx * sx + sy * sy + sz * sz)
    if same:
        ax, ay, az, c = fx, fy, fz, 1.0
    elif length > 1e-6 * (end - start):
        ax, ay, az, c = sx / length, sy / length, sz / length, ONE_MINUS_EPSILON
    else:
        return 0.0, 0.0, 1.0, -1.0
    for j in range(start, end):
        wx, wy, wz = rec[j, AX], rec[j, AX + 1], rec[j, AX + 2]
        if two and ax * wx + ay * wy + az * wz < 0.0:
            wx, wy, wz = -wx, -wy, -wz
        c = min(c, rec[j, CO] if same else _cone_cos(ax, ay, az, wx, wy, wz, rec[j, CO],
                                                     rec[j, SO]))
    return ax, ay, az, c


@njit(cache=True, inline="always")
def _acos(x):
    """acos within 1e-4 (Abramowitz and Stegun 4.4.45): enough for a cost estimate."""
    a = min(abs(x), 1.0)
    r = math.sqrt(1.0 - a) * (1.5707288 + a * (-0.2121144 + a * (0.0742610 - 0.0187293 * a)))
    return r if x >= 0.0 else math.pi - r


@njit(cache=True)
def _cost(power, cos_o, cos_e, lower, upper, kr):
    """pbrt-v4's surface-area-orientation cost of a set of lights: power times the solid-angle
    measure of its cone of emission times its box's surface area (times kr, which penalises
    thin slabs cut along their short side)."""
    theta_o, theta_e = _acos(cos_o), _acos(cos_e)
    theta_w = min(theta_o + theta_e, math.pi)
    sin_o = math.sqrt(max(0.0, 1.0 - cos_o * cos_o))
    m_omega = 2.0 * math.pi * (1.0 - cos_o) + 0.5 * math.pi * (
        2.0 * theta_w * sin_o - math.cos(theta_o - 2.0 * theta_w) - 2.0 * theta_o * sin_o
        + cos_o)
    ex, ey, ez = upper[0] - lower[0], upper[1] - lower[1], upper[2] - lower[2]
    # a flat box counts by its area; a line's or a point's, barely, by its length
    area = max(2.0 * (ex * ey + ey * ez + ez * ex), 1e-9 * (ex + ey + ez) ** 2)
    return power * m_omega * kr * area


@njit(cache=True)
def _bucket(c, lo, scale):
    b = int((c - lo) * scale)
    return min(max(b, 0), BUCKETS - 1)


@njit(cache=True, inline="always")
def _absorb(acc, i, src, j, count):
    """Fold row j of src (an entry, or a bucket of `count` entries, with the same columns) into
    row i of acc: their box, power, cos_e, two-sidedness, count (column ID) and a cone about
    the axis of acc's first row folded in (a rough bound, for the cost alone)."""
    if acc[i, ID] == 0.0:
        acc[i, AX], acc[i, AX + 1], acc[i, AX + 2] = src[j, AX], src[j, AX + 1], src[j, AX + 2]
    for e in range(3):
        acc[i, LO + e] = min(acc[i, LO + e], src[j, LO + e])
        acc[i, HI + e] = max(acc[i, HI + e], src[j, HI + e])
    acc[i, PW] += src[j, PW]
    acc[i, CE] = min(acc[i, CE], src[j, CE])
    acc[i, TW] = max(acc[i, TW], src[j, TW])
    acc[i, ID] += count
    s = -1.0 if acc[i, TW] > 0.0 and (acc[i, AX] * src[j, AX] + acc[i, AX + 1] * src[j, AX + 1]
                                       + acc[i, AX + 2] * src[j, AX + 2]) < 0.0 else 1.0
    acc[i, CO] = min(acc[i, CO], _cone_cos(acc[i, AX], acc[i, AX + 1], acc[i, AX + 2],
                                           s * src[j, AX], s * src[j, AX + 1], s * src[j, AX + 2],
                                           src[j, CO], math.sqrt(max(0.0, 1.0 - src[j, CO] ** 2))))


@njit(cache=True, inline="always")
def _clear(acc, i):
    acc[i, LO:LO + 3], acc[i, HI:HI + 3] = np.inf, -np.inf
    acc[i, PW], acc[i, CO], acc[i, CE], acc[i, TW], acc[i, ID] = 0.0, 1.0, 1.0, 0.0, 0.0


@njit(cache=True)
def _build(rec):
    """Nodes over the packed entries rec (reordered in place), in depth-first order: a node's
    first child is the next node, its second child[node]. (nodes (M, WIDTH), child (M,))."""
    m = rec.shape[0]
    nodes = np.empty((2 * m - 1, WIDTH))
    child = np.full(2 * m - 1, -1, dtype=np.int64)
    spare = np.empty((m, WIDTH))
    bucket = np.empty((3 * BUCKETS, WIDTH))    # the buckets along x, y and z
    side, side_cost = np.empty((1, WIDTH)), np.empty(BUCKETS)
    c_lo, c_hi, scale = np.empty(3), np.empty(3), np.empty(3)
    stack = np.empty((m + 1, 3), dtype=np.int64)   # start, end, the node it is second child of
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, m, -1
    top, count = 1, 0
    while top > 0:
        top -= 1
        start, end, parent = stack[top, 0], stack[top, 1], stack[top, 2]
        k = count
        count += 1
        if parent >= 0:
            child[parent] = k
        if end - start == 1:
            for e in range(WIDTH):
                nodes[k, e] = rec[start, e]
            continue
        total, ce, two = 0.0, 1.0, 0.0
        lx = ly = lz = cx = cy = cz = np.inf
        hx = hy = hz = dx = dy = dz = -np.inf
        for j in range(start, end):
            total, ce, two = total + rec[j, PW], min(ce, rec[j, CE]), max(two, rec[j, TW])
            lx, ly, lz = min(lx, rec[j, LO]), min(ly, rec[j, LO + 1]), min(lz, rec[j, LO + 2])
            hx, hy, hz = max(hx, rec[j, HI]), max(hy, rec[j, HI + 1]), max(hz, rec[j, HI + 2])
            x, y, z = rec[j, LO] + rec[j, HI], rec[j, LO + 1] + rec[j, HI + 1], \
                rec[j, LO + 2] + rec[j, HI + 2]
            cx, cy, cz, dx, dy, dz = min(cx, x), min(cy, y), min(cz, z), max(dx, x), \
                max(dy, y), max(dz, z)
        lo, hi = nodes[k, LO:LO + 3], nodes[k, HI:HI + 3]
        lo[0], lo[1], lo[2], hi[0], hi[1], hi[2] = lx, ly, lz, hx, hy, hz
        c_lo[0], c_lo[1], c_lo[2] = 0.5 * cx, 0.5 * cy, 0.5 * cz    # the centres' box
        c_hi[0], c_hi[1], c_hi[2] = 0.5 * dx, 0.5 * dy, 0.5 * dz
        ax, ay, az, co = _entries_cone(rec, start, end, two > 0.0)
        nodes[k, AX], nodes[k, AX + 1], nodes[k, AX + 2], nodes[k, PW] = ax, ay, az, total
        nodes[k, CO], nodes[k, CE], nodes[k, TW], nodes[k, ID] = co, ce, two, -1.0
        # the split: pbrt-v4's surface-area-orientation heuristic over BUCKETS buckets per axis,
        # binning every entry of a node or, of a large one, an even stride of about SAMPLE
        splits = end - start > 2      # (every split of two is the same)
        for d in range(3):
            scale[d] = BUCKETS / (c_hi[d] - c_lo[d]) if splits and c_hi[d] > c_lo[d] else 0.0
        for i in range(3 * BUCKETS if splits else 0):
            _clear(bucket, i)
        for j in range(start if splits else end, end, max(1, (end - start) // SAMPLE)):
            for d in range(3):
                if scale[d] > 0.0:
                    b = _bucket(0.5 * (rec[j, LO + d] + rec[j, HI + d]), c_lo[d], scale[d])
                    _absorb(bucket, d * BUCKETS + b, rec, j, 1.0)
        best, best_dim, best_bucket = np.inf, -1, -1
        longest = max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2])
        for d in range(3):
            if scale[d] == 0.0:
                continue
            kr = longest / (hi[d] - lo[d])
            # side_cost[s]: the cost of buckets s+1.. (the second side of a split after s),
            # -1 where they are empty; a split is tried after each nonempty bucket
            for first_side in (False, True):
                _clear(side, 0)
                cost = -1.0
                for step in range(BUCKETS - 1):
                    b = step if first_side else BUCKETS - 1 - step
                    i = d * BUCKETS + b
                    if bucket[i, ID] > 0.0:
                        _absorb(side, 0, bucket, i, bucket[i, ID])
                        cost = _cost(side[0, PW], side[0, CO], side[0, CE], side[0, LO:LO + 3],
                                     side[0, HI:HI + 3], kr)
                    if not first_side:
                        side_cost[b - 1] = cost
                    elif bucket[i, ID] > 0.0 and side_cost[b] >= 0.0 \
                            and cost + side_cost[b] < best:
                        best, best_dim, best_bucket = cost + side_cost[b], d, b
        mid = (start + end) // 2
        if best_dim >= 0:     # a stable partition: the first side's buckets first
            d, n_first, n_second = best_dim, 0, 0
            for j in range(start, end):
                if _bucket(0.5 * (rec[j, LO + d] + rec[j, HI + d]), c_lo[d],
                           scale[d]) <= best_bucket:
                    for e in range(WIDTH):
                        rec[start + n_first, e] = rec[j, e]
                    n_first += 1
                else:
                    for e in range(WIDTH):
                        spare[n_second, e] = rec[j, e]
                    n_second += 1
            rec[start + n_first:end] = spare[:n_second]
            mid = start + n_first
        stack[top, 0], stack[top, 1], stack[top, 2] = mid, end, k
        stack[top + 1, 0], stack[top + 1, 1], stack[top + 1, 2] = start, mid, -1
        top += 2
    return nodes, child


def build_light_tree(bounds_lower, bounds_upper, power, axis, cos_theta_o, cos_theta_e,
                     two_sided):
    """A LightTree over L bounded light entries, one row each: their boxes (L, 3) x 2, power
    (L,) (an importance weight >= 0: an entry of power 0 is left out and never chosen), unit
    emission axis (L, 3), the spread of their normals about it cos_theta_o (L,) (1 for a flat
    one-sided emitter, -1 for one that faces every way: a sphere, a point), the spread of their
    emission about each normal cos_theta_e (L,) (0 for a Lambertian emitter; a spot light's
    outer cone with cos_theta_o 1) and two_sided (L,) (emission leaves both faces: the cone
    holds -axis too). The same arrays give the same tree. Raises ValueError on arrays of the
    wrong shape, or values that are not finite, a negative power, a zero axis where
    cos_theta_o > -1, or a box whose lower corner is above its upper one."""
    f64 = lambda array: np.array(array, dtype=np.float64)
    power, lower, upper, axis = f64(power), f64(bounds_lower), f64(bounds_upper), f64(axis)
    cos_o, cos_e = np.clip(f64(cos_theta_o), -1, 1), np.clip(f64(cos_theta_e), -1, 1)
    two = np.array(two_sided, dtype=np.bool_)
    count = power.shape[0] if power.ndim == 1 else -1
    for name, array in (("bounds_lower", lower), ("bounds_upper", upper), ("axis", axis),
                        ("cos_theta_o", cos_o), ("cos_theta_e", cos_e), ("two_sided", two)):
        shape = (count, 3) if name in ("bounds_lower", "bounds_upper", "axis") else (count,)
        if count < 0 or array.shape != shape:
            raise ValueError(f"light tree: {name} has shape {array.shape}, not {shape} "
                             f"(power must be one value per entry)")
        if not np.all(np.isfinite(array)):
            raise ValueError(f"light tree: {name} holds values that are not finite")
    if not np.isfinite(power.sum()) or np.any(power < 0.0):
        raise ValueError("light tree: power must be >= 0 and sum to a finite number")
    if np.any(lower > upper):
        raise ValueError("light tree: a box's bounds_lower is above its bounds_upper")
    length = np.linalg.norm(axis, axis=1)
    if np.any((length == 0.0) & (cos_o > -1.0)):
        raise ValueError("light tree: an axis is zero where cos_theta_o > -1")
    axis[length > 0.0] /= length[length > 0.0, None]
    axis[length == 0.0] = (0.0, 0.0, 1.0)
    kept = np.nonzero(power > 0.0)[0]
    rec = np.empty((kept.shape[0], WIDTH))
    rec[:, LO:LO + 3], rec[:, HI:HI + 3], rec[:, AX:AX + 3] = lower[kept], upper[kept], axis[kept]
    rec[:, PW], rec[:, CO], rec[:, CE], rec[:, TW] = power[kept], cos_o[kept], cos_e[kept], \
        two[kept]
    rec[:, SO], rec[:, ID] = np.sqrt(np.maximum(0.0, 1.0 - rec[:, CO] ** 2)), kept
    nodes, child = _build(rec) if kept.shape[0] else (rec, np.zeros(0, dtype=np.int64))
    entry = nodes[:, ID].astype(np.int64)
    leaves = np.nonzero(entry >= 0)[0]
    entry_node = np.full(count, -1, dtype=np.int64)
    entry_node[entry[leaves]] = leaves
    half = 0.5 * (nodes[:, HI:HI + 3] - nodes[:, LO:LO + 3])
    c = lambda column: np.ascontiguousarray(nodes[:, column])
    root = nodes[0, PW] if nodes.shape[0] else 1.0
    binary = (c(slice(LO, LO + 3)), c(slice(HI, HI + 3)), nodes[:, LO:LO + 3] + half,
              np.einsum("ij,ij->i", half, half), nodes[:, PW] / root, c(slice(AX, AX + 3)),
              c(CO), np.sqrt(np.maximum(0.0, 1.0 - nodes[:, CO] ** 2)), c(CE),
              nodes[:, TW] > 0.0, child, entry, entry_node)
    return LightTree(*binary, *_wide(*binary[:11]))


@njit(cache=True)
def _wide_members(child):
    """The wide nodes of a binary tree (nodes in depth-first order, child its second children):
    (members (W, LANES), kid (W, LANES), end (M,)): each wide node's lanes' binary nodes (-1
    past its last lane), each lane's wide node or -1 - its binary leaf (-1 past the last lane),
    and the end of each binary node's subtree. Wide node 0 is the root's; the others follow in
    the order their lanes are met, so a wide node comes after the one that holds it."""
    count = child.shape[0]
    end = np.arange(1, count + 1)
    for k in range(count - 1, -1, -1):
        if child[k] >= 0:
            end[k] = end[child[k]]
    members = np.full((max(count, 1), LANES), -1, dtype=np.int64)
    kid = np.full((max(count, 1), LANES), -1, dtype=np.int64)
    tops = np.zeros(max(count, 1), dtype=np.int64)
    stack = np.zeros((2 * LEVELS + 2, 2), dtype=np.int64)
    wide, made = 0, 1 if count else 0
    while wide < made:
        lane, top = 0, 1
        stack[0, 0], stack[0, 1] = tops[wide], LEVELS
        while top > 0:        # depth first, left before right: the lanes from left to right
            top -= 1
            k, levels = stack[top, 0], stack[top, 1]
            if child[k] < 0 or levels == 0:
                members[wide, lane] = k
                if child[k] >= 0:
                    tops[made] = k
                    kid[wide, lane] = made
                    made += 1
                else:
                    kid[wide, lane] = -1 - k
                lane += 1
            else:
                stack[top, 0], stack[top, 1] = child[k], levels - 1
                stack[top + 1, 0], stack[top + 1, 1] = k + 1, levels - 1
                top += 2
        wide += 1
    return members[:made], kid[:made], end


def _wide(lower, upper, center, radius2, power, axis, cos_o, sin_o, cos_e, two, child):
    """The binary tree as the walk reads it, LEVELS levels a step (_wide_members): (lanes, kid,
    span). A lane holds its binary node's fields; unused lanes have power 0, so their importance
    is 0 everywhere, and an empty span."""
    if child.shape[0] == 0:   # no lights (every record built without the tree): no compile
        members = kid = np.zeros((0, LANES), dtype=np.int64)
        end = np.zeros(0, dtype=np.int64)
    else:
        members, kid, end = _wide_members(np.ascontiguousarray(child, dtype=np.int64))
    fields = np.zeros((child.shape[0] + 1, FIELDS))     # the last row: an unused lane's
    fields[:-1, F_LO:F_LO + 3], fields[:-1, F_HI:F_HI + 3] = lower, upper
    fields[:-1, F_CENTER:F_CENTER + 3], fields[:-1, F_R2] = center, radius2
    fields[:-1, F_POWER], fields[:-1, F_AXIS:F_AXIS + 3] = power, axis
    fields[:-1, F_COS_O], fields[:-1, F_SIN_O], fields[:-1, F_COS_E] = cos_o, sin_o, cos_e
    fields[:-1, F_TWO] = two
    fields[:-1, F_FLAT] = (cos_o >= 1.0) & (cos_e >= 0.0) & ~two
    lanes = np.ascontiguousarray(fields[members].transpose(0, 2, 1))   # (-1: the last row)
    used = members >= 0
    span = np.zeros(members.shape + (2,), dtype=np.int64)
    span[used, 0], span[used, 1] = members[used], end[members[used]]
    return lanes, kid, span
