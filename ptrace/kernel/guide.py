"""The path guide's compiled side: where a point falls in the guide's spatial tree, a direction
drawn from the directional quadtree of that leaf, the density of any direction, and the two
stages that turn a training wave's vertices into records for ptrace.guiding.

The guide (GuideArrays) is flat arrays. The spatial tree: node j is a leaf where axis[j] < 0,
else its children are child[j] (below split[j] on that axis) and child[j] + 1; a leaf's root[j]
is its quadtree's root node (or, in the tree being filled, the leaf's number). The directional
quadtrees share q_child (N, 4, int32) and q_density (N, 4): quadrant q = 2 iy + ix of a node
covers [ix/2, ix/2 + 1/2) x [iy/2, iy/2 + 1/2) of the node's square, q_child -1 where the
quadrant is not divided, and q_density is 4 x the quadrant's share of the node's energy (the
factor by which it scales the density of the node's square: all 1 for a uniform node), so a
density lookup is a product of one number per level, without sums or divisions. The square
maps to the sphere by the equal-area map cos theta = 2 x - 1, phi = 2 pi y, so a density on
the square is a density in solid angle times 4 pi. A sample warps one 2D random point down the
quadtree, rescaled at each level, and guide_pdf is exactly the density of that warp. No
recursion; nothing allocates.
"""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from .layout import MAT, VERTEX, R

GuideArrays = namedtuple("GuideArrays", ["axis", "split", "child", "root", "q_child",
                                         "q_density", "share", "alpha", "record"])
# share: per quadtree root node (what guide_leaf returns), the guide's learnt share of that
# spatial leaf's bounces; a vertex draws from the guide with probability alpha * share[leaf],
# and alpha 0 turns the guide off (the kernels then skip it: no lookup, no pdf).

# the rows of a wave's vertex history (one column per path slot and recorded vertex): the
# vertex, the unit direction it left by, the mixture pdf of that direction, the throughput after
# the bounce, the path's radiance when the bounce ray left, whether the column is set, the
# bounce's f cos / pdf (R, G, B), the BSDF's own pdf of the direction and the shading normal
(H_PX, H_PY, H_PZ, H_DX, H_DY, H_DZ, H_PDF, H_TR, H_TG, H_TB, H_LR, H_LG, H_LB,
 H_VALID, H_MR, H_MG, H_MB, H_BSDF, H_NX, H_NY, H_NZ) = range(21)
HISTORY_ROWS = 21
# a record: position (3), unit direction (3), luminance of Li / pdf (the guide's energy), the
# bounce's contribution over its pdf F / p (luminance), the mixture pdf p, the BSDF's pdf, and
# the shading normal (3): the last five learn the guide's share (ptrace.guiding.learn_share)
(R_PX, R_PY, R_PZ, R_DX, R_DY, R_DZ, R_ENERGY, R_F, R_PDF, R_BSDF, R_NX, R_NY,
 R_NZ) = range(13)
RECORD_ROWS = 13
INV_FOUR_PI = 0.25 / math.pi


def uniform_guide(alpha=0.0, record=False):
    """A guide of one spatial leaf whose quadtree is uniform over the sphere."""
    return GuideArrays(np.full(1, -1, dtype=np.int64), np.zeros(1), np.zeros(1, dtype=np.int64),
                       np.zeros(1, dtype=np.int64), np.full((1, 4), -1, dtype=np.int32),
                       np.ones((1, 4)), np.ones(1), float(alpha), int(bool(record)))


@njit(cache=True, _nrt=False, forceinline=True)
def guide_leaf(axis, split, child, root, px, py, pz):
    """root[] of the spatial leaf holding point p."""
    node = 0
    while axis[node] >= 0:
        a = axis[node]
        c = px if a == 0 else (py if a == 1 else pz)
        node = child[node] + (0 if c < split[node] else 1)
    return root[node]


@njit(cache=True, _nrt=False, forceinline=True)
def square_to_sphere(x, y):
    """The unit direction of point (x, y) of the unit square (equal-area map). One cosine: the
    sine is its complement's square root, negative from y = 1/2 on (phi from pi)."""
    z = 2.0 * x - 1.0
    r = math.sqrt(max(0.0, 1.0 - z * z))
    c = math.cos(2.0 * math.pi * y)
    s = math.sqrt(max(0.0, (1.0 - c) * (1.0 + c)))
    return r * c, (r * s if y < 0.5 else -(r * s)), z


@njit(cache=True, _nrt=False, forceinline=True)
def sphere_to_square(dx, dy, dz):
    """The point of the unit square of unit direction d (the inverse of square_to_sphere), both
    coordinates in [0, 1)."""
    x = min(max(0.5 * (dz + 1.0), 0.0), 0.9999999999999999)
    phi = math.atan2(dy, dx)
    if phi < 0.0:
        phi += 2.0 * math.pi
    y = min(max(phi / (2.0 * math.pi), 0.0), 0.9999999999999999)
    return x, y


@njit(cache=True, _nrt=False, forceinline=True)
def _rescale(u, low, share):
    """u in [low, low + share) rescaled to [0, 1)."""
    return min((u - low) / share, 0.9999999999999999)


@njit(cache=True, _nrt=False, forceinline=True)
def quadtree_sample(q_child, q_density, node, u1, u2):
    """A point of the unit square drawn from quadtree `node` with the 2D random point (u1, u2):
    (x, y, density on the square). At each node the first number picks the left or right
    half by their densities, the second the lower or upper quadrant of that half, each then
    rescaled to [0, 1) for the next level; a quadrant that is not divided is uniform. The
    density is the product of the chosen quadrants' q_density, as quadtree_pdf's."""
    ox = oy = 0.0
    size = 1.0
    pdf = 1.0
    while True:
        d0, d1, d2, d3 = (q_density[node, 0], q_density[node, 1], q_density[node, 2],
                          q_density[node, 3])
        left = (d0 + d2) / (d0 + d1 + d2 + d3)
        if u1 < left:
            ix = 0
            u1 = _rescale(u1, 0.0, left)
            low, high = d0, d2
        else:
            ix = 1
            u1 = _rescale(u1, left, 1.0 - left)
            low, high = d1, d3
        lower = low / (low + high)
        if u2 < lower:
            iy = 0
            u2 = _rescale(u2, 0.0, lower)
            pdf *= low
        else:
            iy = 1
            u2 = _rescale(u2, lower, 1.0 - lower)
            pdf *= high
        size *= 0.5
        ox += ix * size
        oy += iy * size
        node = q_child[node, 2 * iy + ix]
        if node < 0:
            return ox + size * u1, oy + size * u2, pdf


@njit(cache=True, _nrt=False, forceinline=True)
def quadtree_pdf(q_child, q_density, node, x, y):
    """The density on the unit square of quadtree_sample at point (x, y)."""
    pdf = 1.0
    while True:
        ix = 1 if x >= 0.5 else 0
        iy = 1 if y >= 0.5 else 0
        x = min(2.0 * x - ix, 0.9999999999999999)
        y = min(2.0 * y - iy, 0.9999999999999999)
        q = 2 * iy + ix
        pdf *= q_density[node, q]
        node = q_child[node, q]
        if node < 0:
            return pdf


# cos and sin of phi = 2 pi j / 2^MID_LEVELS: the middles of the quadtrees' first MID_LEVELS
# levels in y, against which direction_pdf tells a direction's half without an arctangent
MID_LEVELS = 6
MID_COS = np.cos(2.0 * np.pi * np.arange(1 << MID_LEVELS) / (1 << MID_LEVELS))
MID_SIN = np.sin(2.0 * np.pi * np.arange(1 << MID_LEVELS) / (1 << MID_LEVELS))


@njit(cache=True, _nrt=False, forceinline=True)
def direction_pdf(q_child, q_density, node, dx, dy, dz):
    """quadtree_pdf at the point of the square of direction d (sphere_to_square's), found
    without the arctangent: at level l < MID_LEVELS the y half (phi at or past the middle of
    the node's phi interval) is the sign of the sine of phi minus that middle, dy cos - dx sin
    (the interval is at most pi wide from level 1 on; level 0's half is phi >= pi, dy < 0); past
    them, from sphere_to_square's y. The same cells as quadtree_pdf's but where d is within
    rounding of a cell's edge."""
    mids = 1 << MID_LEVELS
    x = min(max(0.5 * (dz + 1.0), 0.0), 0.9999999999999999)
    if dx == 0.0 and dy == 0.0:   # a pole: phi 0, as atan2(0, 0)
        dx = 1.0
    y = 0.0
    low = 0        # the node's phi interval starts at 2 pi low / mids (levels < MID_LEVELS)
    level = 0
    pdf = 1.0
    while True:
        ix = 1 if x >= 0.5 else 0
        x = min(2.0 * x - ix, 0.9999999999999999)
        if level == 0:
            iy = 1 if (dy < 0.0 or (dy == 0.0 and dx < 0.0)) else 0
            low = iy * (mids >> 1)
        elif level < MID_LEVELS:
            half = mids >> (level + 1)
            j = low + half
            iy = 1 if dy * MID_COS[j] - dx * MID_SIN[j] >= 0.0 else 0
            low += iy * half
        else:
            if level == MID_LEVELS:   # (deeper than the guides ptrace.guiding builds)
                y = min(max(sphere_to_square(dx, dy, dz)[1] * mids - low, 0.0),
                        0.9999999999999999)
            iy = 1 if y >= 0.5 else 0
            y = min(2.0 * y - iy, 0.9999999999999999)
        q = 2 * iy + ix
        pdf *= q_density[node, q]
        node = q_child[node, q]
        if node < 0:
            return pdf
        level += 1


@njit(cache=True, _nrt=False, forceinline=True)
def guide_sample(guide, node, u1, u2):
    """A unit direction drawn from the guide's quadtree `node`: (dx, dy, dz, pdf in solid
    angle)."""
    x, y, pdf = quadtree_sample(guide.q_child, guide.q_density, node, u1, u2)
    dx, dy, dz = square_to_sphere(x, y)
    return dx, dy, dz, pdf * INV_FOUR_PI


@njit(cache=True, _nrt=False, forceinline=True)
def guide_pdf(guide, node, dx, dy, dz):
    """The solid-angle density of guide_sample from quadtree `node` at unit direction d."""
    return direction_pdf(guide.q_child, guide.q_density, node, dx, dy, dz) * INV_FOUR_PI


@njit(cache=True, _nrt=False, forceinline=True)
def _half(dx, dy, level, low):
    """direction_pdf's y half at `level` (< MID_LEVELS) of a node whose phi interval starts at
    2 pi low / 2^MID_LEVELS: (iy, the child's low)."""
    mids = 1 << MID_LEVELS
    if level == 0:
        iy = 1 if (dy < 0.0 or (dy == 0.0 and dx < 0.0)) else 0
        return iy, iy * (mids >> 1)
    half = mids >> (level + 1)
    j = low + half
    iy = 1 if dy * MID_COS[j] - dx * MID_SIN[j] >= 0.0 else 0
    return iy, low + iy * half


@njit(cache=True, _nrt=False, forceinline=True)
def pair_pdf(q_child, q_density, node, ax, ay, az, bx, by, bz):
    """direction_pdf of quadtree `node` at unit directions a and b, the two walks in one loop
    (independent loads and compares side by side): (pdf at a, pdf at b), the same numbers."""
    if ax == 0.0 and ay == 0.0:
        ax = 1.0
    if bx == 0.0 and by == 0.0:
        bx = 1.0
    xa = min(max(0.5 * (az + 1.0), 0.0), 0.9999999999999999)
    xb = min(max(0.5 * (bz + 1.0), 0.0), 0.9999999999999999)
    na = nb = node
    lowa = lowb = 0
    pa = pb = 1.0
    level = 0
    while na >= 0 or nb >= 0:
        if level >= MID_LEVELS:   # (deeper than the guides ptrace.guiding builds)
            return (direction_pdf(q_child, q_density, node, ax, ay, az),
                    direction_pdf(q_child, q_density, node, bx, by, bz))
        if na >= 0:
            ix = 1 if xa >= 0.5 else 0
            xa = min(2.0 * xa - ix, 0.9999999999999999)
            iy, lowa = _half(ax, ay, level, lowa)
            q = 2 * iy + ix
            pa *= q_density[na, q]
            na = q_child[na, q]
        if nb >= 0:
            ix = 1 if xb >= 0.5 else 0
            xb = min(2.0 * xb - ix, 0.9999999999999999)
            iy, lowb = _half(bx, by, level, lowb)
            q = 2 * iy + ix
            pb *= q_density[nb, q]
            nb = q_child[nb, q]
        level += 1
    return pa, pb


@njit(cache=True, _nrt=False, forceinline=True)
def folded_pdf(guide, node, dx, dy, dz, nx, ny, nz):
    """The solid-angle density of folded_sample at unit direction d above the surface of unit
    normal n: the guide's density at d plus at d mirrored through the surface (0 below it)."""
    c = dx * nx + dy * ny + dz * nz
    if c < 0.0:
        return 0.0
    pa, pb = pair_pdf(guide.q_child, guide.q_density, node, dx, dy, dz, dx - 2.0 * c * nx,
                      dy - 2.0 * c * ny, dz - 2.0 * c * nz)
    return pa * INV_FOUR_PI + pb * INV_FOUR_PI


@njit(cache=True, _nrt=False, forceinline=True)
def folded_sample(guide, node, u1, u2, nx, ny, nz):
    """A direction of guide_sample, mirrored through the surface of unit normal n when it
    points below it (a BSDF that only reflects would waste it): (dx, dy, dz, folded_pdf). The
    drawn direction's density is the warp's; only its mirror image's is looked up."""
    dx, dy, dz, pdf = guide_sample(guide, node, u1, u2)
    c = dx * nx + dy * ny + dz * nz
    mx, my, mz = dx - 2.0 * c * nx, dy - 2.0 * c * ny, dz - 2.0 * c * nz
    pdf += guide_pdf(guide, node, mx, my, mz)
    if c < 0.0:
        return mx, my, mz, pdf
    return dx, dy, dz, pdf


@njit(cache=True, nogil=True, _nrt=False)
def snapshot_stage(floats, ints, queue, n, history, depth):
    """After the hit stage, for each of the n paths it ran over (those that bounced into it),
    its radiance so far into the history column of the vertex its ray left: the emission that
    ray found is counted as the light samples' (direct light stays with the light sampler), and
    what the path gathers after this is the indirect light the bounce brought back. A path the
    hit stage ended (material -1) is still at that vertex; one that goes on has moved past it."""
    for k in range(n):
        i = queue[k]
        v = ints[VERTEX, i] - (2 if ints[MAT, i] >= 0 else 1)
        if 0 <= v < depth:
            col = i * depth + v
            for c in range(3):
                history[H_LR + c, col] = floats[R + c, i]


@njit(cache=True, nogil=True, _nrt=False)
def record_stage(floats, size, history, depth, out):
    """The records of a finished wave's first `size` slots into out (RECORD_ROWS, at least
    size x depth): for each set history column, the vertex, its bounce direction, and the
    mean over R, G, B of the radiance the bounce brought back (what the path gathered after it,
    divided by the throughput after it) divided by the bounce's pdf, that radiance times the
    bounce's f cos / pdf (the bounce's estimate F / p of the light it reflects), the pdf, the
    BSDF's pdf and the normal. Clears the columns; returns the count, in slot and vertex
    order."""
    count = 0
    for i in range(size):
        for v in range(depth):
            col = i * depth + v
            if history[H_VALID, col] == 0.0:
                continue
            history[H_VALID, col] = 0.0
            li = 0.0
            contribution = 0.0
            for c in range(3):
                t = history[H_TR + c, col]
                if t > 0.0:
                    lc = (floats[R + c, i] - history[H_LR + c, col]) / t
                    li += lc
                    contribution += lc * history[H_MR + c, col]
            weight = li / (3.0 * history[H_PDF, col])
            if not (weight > 0.0 and weight < math.inf):
                weight = 0.0
            contribution /= 3.0
            if not (contribution > 0.0 and contribution < math.inf):
                contribution = 0.0
            out[0, count] = history[H_PX, col]
            out[1, count] = history[H_PY, col]
            out[2, count] = history[H_PZ, col]
            out[3, count] = history[H_DX, col]
            out[4, count] = history[H_DY, col]
            out[5, count] = history[H_DZ, col]
            out[6, count] = weight
            out[7, count] = contribution
            out[8, count] = history[H_PDF, col]
            out[9, count] = history[H_BSDF, col]
            out[10, count] = history[H_NX, col]
            out[11, count] = history[H_NY, col]
            out[12, count] = history[H_NZ, col]
            count += 1
    return count


@njit(cache=True, _nrt=False, forceinline=True)
def remember(history, depth, i, vertex, px, py, pz, dx, dy, dz, pdf, tr, tg, tb, mr, mg, mb,
             bsdf_pdf, nx, ny, nz):
    """Path slot i's bounce at `vertex` (from 1) into its history column, if within depth: m is
    the bounce's f cos / pdf, n the shading normal."""
    v = vertex - 1
    if v < depth:
        col = i * depth + v
        history[H_PX, col], history[H_PY, col], history[H_PZ, col] = px, py, pz
        history[H_DX, col], history[H_DY, col], history[H_DZ, col] = dx, dy, dz
        history[H_PDF, col] = pdf
        history[H_TR, col], history[H_TG, col], history[H_TB, col] = tr, tg, tb
        history[H_MR, col], history[H_MG, col], history[H_MB, col] = mr, mg, mb
        history[H_BSDF, col] = bsdf_pdf
        history[H_NX, col], history[H_NY, col], history[H_NZ, col] = nx, ny, nz
        history[H_VALID, col] = 1.0

