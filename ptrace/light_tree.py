"""A light BVH: choose one of many bounded lights at a shading point by an estimate of its
contribution there, and the probability of that choice, in time proportional to the tree's depth.

After pbrt-v4's BVHLightSampler (Conty Estevez and Kulla 2018): every node bounds its light
entries by a box, their total power and a cone of emission (an axis, the spread cos_theta_o of
the entries' normals about it, the spread cos_theta_e of emission about each normal, and whether
emission leaves both faces). At a point p with normal n, a node's importance is its power over
the squared distance to its centre (clamped below by its bounding sphere's squared radius),
times the cosine of the smallest angle its cone can make with p's direction, times the cosine
bound toward n; it is zero where its box lies on or below p's tangent plane, or p lies on or
behind a box of flat one-sided emitters, and only where no entry of the node can light p. The
tree is walked from the root four levels at a time: a wide node's LANES lanes are the binary
nodes four levels below it, their importances are computed together on vector registers, and
one lane is chosen in proportion to its importance, with one uniform number rescaled from step
to step.

Lights at infinity are not entries: the caller chooses between them and the tree. n is one-sided
(lights below p's tangent plane get nothing, as light sampling there counts nothing); pass a zero
normal where light may come from every side (a medium, a surface lit through).

Build with ptrace.light_tree_build's build_light_tree (numpy arrays in, a LightTree of flat
arrays out); sample with
tree_sample and evaluate with tree_pmf from numba code (or Python): both compile with
_nrt=False and allocate nothing, and tree_pmf returns exactly the product of probabilities that
tree_sample multiplied to reach the entry.
"""
import math

from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from .light_tree_build import (
    F_AXIS,
    F_CENTER,
    F_COS_E,
    F_COS_O,
    F_FLAT,
    F_HI,
    F_LO,
    F_POWER,
    F_R2,
    F_SIN_O,
    F_TWO,
    LANES,
    ONE_MINUS_EPSILON,
)

# -- importance and traversal ------------------------------------------------------------------

@intrinsic
def _lane_buffer(typingctx):
    """An array of LANES float64 on the calling function's stack (for code compiled without
    numba's runtime, which cannot allocate one)."""
    array_type = types.Array(types.float64, 1, "C")

    def codegen(context, builder, signature, args):
        data = cgutils.alloca_once(builder, ir.DoubleType(), size=LANES)
        array = context.make_array(array_type)(context, builder)
        intp = lambda value: context.get_constant(types.intp, value)
        context.populate_array(array, data=data, shape=[intp(LANES)], strides=[intp(8)],
                               itemsize=intp(8), meminfo=None)
        return array._getvalue()
    return array_type(), codegen


@njit(cache=True, _nrt=False, inline="always")
def lane_importance(lanes, w, i, px, py, pz, nx, ny, nz, has_n):
    """Lane i of wide node w: its node's estimated contribution at p (pbrt-v4's
    LightBounds::Importance); (nx, ny, nz) a unit normal when has_n. Zero only where none of the
    node's entries can light p. Written without branches (each condition is a select), so that a
    loop over the lanes runs on vector registers."""
    lo0, lo1, lo2 = lanes[w, F_LO, i], lanes[w, F_LO + 1, i], lanes[w, F_LO + 2, i]
    hi0, hi1, hi2 = lanes[w, F_HI, i], lanes[w, F_HI + 1, i], lanes[w, F_HI + 2, i]
    ax, ay, az = lanes[w, F_AXIS, i], lanes[w, F_AXIS + 1, i], lanes[w, F_AXIS + 2, i]
    # the whole box on or below p's tangent plane: no light from above it
    below = has_n & (max(lo0 * nx, hi0 * nx) + max(lo1 * ny, hi1 * ny)
                     + max(lo2 * nz, hi2 * nz) <= px * nx + py * ny + pz * nz)
    # flat one-sided emitters, all facing along axis: p on or behind every plane of the box
    behind = (lanes[w, F_FLAT, i] != 0.0) & (px * ax + py * ay + pz * az <= min(
        lo0 * ax, hi0 * ax) + min(lo1 * ay, hi1 * ay) + min(lo2 * az, hi2 * az))
    dx = px - lanes[w, F_CENTER, i]      # from the node's centre toward p
    dy = py - lanes[w, F_CENTER + 1, i]
    dz = pz - lanes[w, F_CENTER + 2, i]
    d2 = dx * dx + dy * dy + dz * dz
    r2 = lanes[w, F_R2, i]
    power = lanes[w, F_POWER, i]
    inside = (d2 <= r2) | (d2 < 1e-300)   # p in the bounding sphere: every direction possible
    inv2 = 1.0 / max(d2, 1e-300)
    inv = math.sqrt(inv2)
    sin2_b = min(r2 * inv2, 1.0)
    cos_b = math.sqrt(1.0 - sin2_b)
    sin_b = math.sqrt(sin2_b)
    wx, wy, wz = dx * inv, dy * inv, dz * inv
    cos_w = ax * wx + ay * wy + az * wz
    cos_w = abs(cos_w) if lanes[w, F_TWO, i] != 0.0 else cos_w
    cos_o, sin_o = lanes[w, F_COS_O, i], lanes[w, F_SIN_O, i]
    # theta_x = max(0, theta_w - theta_o), then theta' = max(0, theta_x - theta_b)
    sin_w = math.sqrt(max(0.0, 1.0 - cos_w * cos_w))
    cos_x = cos_w * cos_o + sin_w * sin_o
    sin_x = sin_w * cos_o - cos_w * sin_o
    cos_p = 1.0 if (cos_w > cos_o) | (cos_x > cos_b) else cos_x * cos_b + sin_x * sin_b
    importance = power * cos_p * inv2
    # n against the direction toward the light: bound 1 where the light's sphere straddles n
    cos_i = -(nx * wx + ny * wy + nz * wz)
    sin_i = math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
    cos_pi = cos_i * cos_b + sin_i * sin_b        # cos(max(0, theta_i - theta_b))
    tilted = has_n & (cos_i < cos_b)
    importance = importance * cos_pi if tilted else importance
    importance = 0.0 if (cos_p <= lanes[w, F_COS_E, i]) | (tilted & (cos_pi <= 0.0)) \
        else importance
    importance = power / max(r2, 1e-300) if inside else importance
    importance = 0.0 if below | behind else importance
    return max(importance, 0.0)


@njit(cache=True, _nrt=False, forceinline=True)
def _importances(lanes, w, px, py, pz, nx, ny, nz, has_n, out):
    """out[i] = lane_importance of every lane of wide node w. The loop's count is read from the
    array, not a constant: LLVM would unroll a constant count of 8 before its loop vectoriser
    saw the loop, and numba leaves the SLP vectoriser off."""
    for i in range(lanes.shape[2]):
        out[i] = lane_importance(lanes, w, i, px, py, pz, nx, ny, nz, has_n)


@njit(cache=True, _nrt=False, forceinline=True)
def _walk(tree, px, py, pz, nx, ny, nz, u, leaf):
    """From the root to a leaf, each wide node's lane taken with probability in proportion to
    its importance at p: by u (uniform in [0, 1), rescaled from level to level) when leaf is -1,
    else toward binary leaf node `leaf`. (the leaf reached, or -1 at a dead end; the path's
    probability)."""
    if tree.kid.shape[0] == 0:
        return -1, 0.0
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    has_n = length > 0.0
    if has_n:
        nx, ny, nz = nx / length, ny / length, nz / length
    else:
        nx = ny = nz = 0.0
    u = min(max(u, 0.0), ONE_MINUS_EPSILON)
    c = _lane_buffer()
    w, pmf = 0, 1.0
    while True:
        _importances(tree.lanes, w, px, py, pz, nx, ny, nz, has_n, c)
        total = 0.0
        for i in range(LANES):
            total += c[i]
        if not total > 0.0:
            return -1, 0.0
        j = -1
        if leaf >= 0:     # the lane whose subtree holds the leaf
            for i in range(LANES):
                if tree.span[w, i, 0] <= leaf < tree.span[w, i, 1]:
                    j = i
            if j < 0 or not c[j] > 0.0:
                return -1, 0.0
        else:             # the lane u falls in, among those of importance > 0
            x = u * total
            low = 0.0
            for i in range(LANES):
                if c[i] > 0.0:
                    if j >= 0 and x < low:
                        break
                    j = i
                    low += c[i]
            low -= c[j]
            u = min(max((x - low) / c[j], 0.0), ONE_MINUS_EPSILON)
        pmf *= c[j] / total
        if pmf == 0.0:
            return -1, 0.0
        k = tree.kid[w, j]
        if k < 0:
            return -1 - k, pmf
        w = k


@njit(cache=True, _nrt=False)
def tree_sample(tree, px, py, pz, nx, ny, nz, u):
    """(entry, pmf): an entry chosen at p (normal n, or zero) with u uniform in [0, 1), and the
    probability of choosing it; (-1, 0.0) when the walk meets a node neither of whose children
    can light p (none can, or the node's looser bounds let it be chosen where none of its
    entries gives light: as in pbrt-v4, that chance is lost, and the entries' probabilities at
    p sum to 1 less it), or the tree is empty."""
    k, pmf = _walk(tree, px, py, pz, nx, ny, nz, u, -1)
    return (tree.entry[k], pmf) if k >= 0 else (-1, 0.0)


@njit(cache=True, _nrt=False)
def tree_pmf(tree, px, py, pz, nx, ny, nz, entry):
    """The probability that tree_sample chooses this entry at p (normal n, or zero), the very
    number tree_sample returns with it: 0 for an entry that is not in the tree or cannot light
    p."""
    if entry < 0 or entry >= tree.entry_node.shape[0] or tree.entry_node[entry] < 0:
        return 0.0
    k, pmf = _walk(tree, px, py, pz, nx, ny, nz, 0.0, tree.entry_node[entry])
    return pmf if k >= 0 else 0.0
