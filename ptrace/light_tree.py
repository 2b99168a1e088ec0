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
tree is walked from the root, each child chosen in proportion to its importance, with one
uniform number rescaled from level to level.

Lights at infinity are not entries: the caller chooses between them and the tree. n is one-sided
(lights below p's tangent plane get nothing, as light sampling there counts nothing); pass a zero
normal where light may come from every side (a medium, a surface lit through).

Build with build_light_tree (ptrace.light_tree_build, re-exported here: numpy arrays in, a
LightTree of flat arrays out); sample with
tree_sample and evaluate with tree_pmf from numba code (or Python): both compile with
_nrt=False and allocate nothing, and tree_pmf returns exactly the product of probabilities that
tree_sample multiplied to reach the entry.
"""
import math

from numba import njit

from .light_tree_build import (  # noqa: F401 - LightTree and build_light_tree, re-exported
    ONE_MINUS_EPSILON,
    LightTree,
    build_light_tree,
)

# -- importance and traversal ------------------------------------------------------------------

@njit(cache=True, _nrt=False, forceinline=True)
def node_importance(tree, k, px, py, pz, nx, ny, nz):
    """Node k's estimated contribution at p (pbrt-v4's LightBounds::Importance); (nx, ny, nz)
    a unit normal or zero. Zero only where none of the node's entries can light p."""
    lo, hi, axis = tree.lower, tree.upper, tree.axis
    if nx != 0.0 or ny != 0.0 or nz != 0.0:
        # the whole box on or below p's tangent plane: no light from above it
        if (max(lo[k, 0] * nx, hi[k, 0] * nx) + max(lo[k, 1] * ny, hi[k, 1] * ny)
                + max(lo[k, 2] * nz, hi[k, 2] * nz) <= px * nx + py * ny + pz * nz):
            return 0.0
    if tree.cos_o[k] >= 1.0 and tree.cos_e[k] >= 0.0 and not tree.two_sided[k]:
        # flat one-sided emitters, all facing along axis: p on or behind every plane of the box
        ax, ay, az = axis[k, 0], axis[k, 1], axis[k, 2]
        if (px * ax + py * ay + pz * az <= min(lo[k, 0] * ax, hi[k, 0] * ax)
                + min(lo[k, 1] * ay, hi[k, 1] * ay) + min(lo[k, 2] * az, hi[k, 2] * az)):
            return 0.0
    cx, cy, cz = tree.center[k, 0], tree.center[k, 1], tree.center[k, 2]
    dx, dy, dz = px - cx, py - cy, pz - cz        # from the node's centre toward p
    d2 = dx * dx + dy * dy + dz * dz
    r2 = tree.radius2[k]
    if d2 <= r2 or d2 < 1e-300:   # p inside the bounding sphere: every direction is possible
        return tree.power[k] / max(r2, 1e-300)
    inv = 1.0 / math.sqrt(d2)
    wx, wy, wz = dx * inv, dy * inv, dz * inv
    sin2_b = r2 * inv * inv
    cos_b = math.sqrt(1.0 - sin2_b)
    cos_w = axis[k, 0] * wx + axis[k, 1] * wy + axis[k, 2] * wz
    if tree.two_sided[k]:
        cos_w = abs(cos_w)
    cos_o = tree.cos_o[k]
    # theta_x = max(0, theta_w - theta_o), then theta' = max(0, theta_x - theta_b)
    cos_p = 1.0
    if not cos_w > cos_o:
        sin_w = math.sqrt(max(0.0, 1.0 - cos_w * cos_w))
        sin_o = tree.sin_o[k]
        cos_x = cos_w * cos_o + sin_w * sin_o
        if not cos_x > cos_b:
            sin_x = sin_w * cos_o - cos_w * sin_o
            cos_p = cos_x * cos_b + sin_x * math.sqrt(sin2_b)
    if cos_p <= tree.cos_e[k]:
        return 0.0
    importance = tree.power[k] * cos_p * (inv * inv)
    if nx != 0.0 or ny != 0.0 or nz != 0.0:
        cos_i = -(nx * wx + ny * wy + nz * wz)    # n against the direction toward the light
        if cos_i < cos_b:      # else the light's sphere straddles n's axis: bound 1
            sin_i = math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
            cos_pi = cos_i * cos_b + sin_i * math.sqrt(sin2_b)   # cos(max(0, theta_i - theta_b))
            if cos_pi <= 0.0:
                return 0.0
            importance *= cos_pi
    return max(importance, 0.0)


@njit(cache=True, _nrt=False, forceinline=True)
def _walk(tree, px, py, pz, nx, ny, nz, u, leaf):
    """From the root to a leaf, each child taken with probability in proportion to its
    importance at p: by u (uniform in [0, 1), rescaled from level to level) when leaf is -1,
    else toward that leaf. (the leaf reached, or -1 at a dead end; the path's probability)."""
    if tree.child.shape[0] == 0:
        return -1, 0.0
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    if length > 0.0:
        nx, ny, nz = nx / length, ny / length, nz / length
    else:
        nx = ny = nz = 0.0
    u = min(max(u, 0.0), ONE_MINUS_EPSILON)
    k, pmf = 0, 1.0
    while tree.child[k] >= 0:
        right = tree.child[k]
        c0 = node_importance(tree, k + 1, px, py, pz, nx, ny, nz)
        c1 = node_importance(tree, right, px, py, pz, nx, ny, nz)
        total = c0 + c1
        if not total > 0.0:
            return -1, 0.0
        p0 = c0 / total
        if (leaf < right) if leaf >= 0 else (u < p0):   # (nodes are in depth-first order)
            pmf *= p0
            if leaf < 0:
                u = min(u / p0, ONE_MINUS_EPSILON)
            k = k + 1
        else:
            pmf *= c1 / total
            if leaf < 0:
                u = min((u - p0) / (1.0 - p0), ONE_MINUS_EPSILON)
            k = right
        if pmf == 0.0:
            return -1, 0.0
    if k == 0 and not node_importance(tree, 0, px, py, pz, nx, ny, nz) > 0.0:
        return -1, 0.0
    return k, pmf


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
