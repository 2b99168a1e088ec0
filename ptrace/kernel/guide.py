"""The path guide's compiled side: where a point falls in the guide's spatial tree, a direction
drawn from the directional quadtree of that leaf, the density of any direction, and the two
stages that turn a training wave's vertices into records for ptrace.guiding.

The guide (GuideArrays) is flat arrays. The spatial tree: node j is a leaf where axis[j] < 0,
else its children are child[j] (below split[j] on that axis: x, y, z, or 3, the bucket of the
way the surface's normal faces, normal_bucket) and child[j] + 1; a leaf's root[j]
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

from .layout import MAT, VERTEX, R, T

GuideArrays = namedtuple("GuideArrays", ["axis", "split", "child", "root", "q_child",
                                         "q_density", "share", "alpha", "record", "frame"])
# share: per quadtree root node (what guide_leaf returns), the guide's learnt share of that
# spatial leaf's bounces; a vertex draws from the guide with probability alpha * share[leaf],
# and alpha 0 turns the guide off (the kernels then skip it: no lookup, no pdf).
# frame: per spatial tree node (what guide_node returns), its leaf's parallax frame: the
# centre c of the leaf's box (3), its focus f (3), the point its light mostly comes from, and
# whether the frame is on (1). A leaf's quadtree holds directions as seen from c; at a point x,
# the guide turns them by the rotation that takes the direction c -> f to x -> f (guide_turn),
# so the bright spot its light comes from is aimed at from x, not from c. A rotation keeps
# solid angle: the density at a direction is the quadtree's at the direction turned back.

# the rows of a wave's vertex history (one column per path slot and recorded vertex): the
# vertex, the unit direction it left by, the mixture pdf of that direction, the throughput after
# the bounce, the path's radiance when the bounce ray left, whether the column is set, the
# bounce's f cos / pdf (R, G, B), the BSDF's own pdf of the direction, the shading normal and
# the distance its ray went to the next vertex
(H_PX, H_PY, H_PZ, H_DX, H_DY, H_DZ, H_PDF, H_TR, H_TG, H_TB, H_LR, H_LG, H_LB,
 H_VALID, H_MR, H_MG, H_MB, H_BSDF, H_NX, H_NY, H_NZ, H_T) = range(22)
HISTORY_ROWS = 22
# a record: position (3), unit direction (3), luminance of Li / pdf (the guide's energy), the
# bounce's contribution over its pdf F / p (luminance), the mixture pdf p, the BSDF's pdf, and
# the shading normal (3): those five learn the guide's share (ptrace.guiding.learn_share); the
# distance to the next vertex (inf if the ray left the scene: the leaves' focus points)
(R_PX, R_PY, R_PZ, R_DX, R_DY, R_DZ, R_ENERGY, R_F, R_PDF, R_BSDF, R_NX, R_NY,
 R_NZ, R_T) = range(14)
RECORD_ROWS = 14
INV_FOUR_PI = 0.25 / math.pi
BUCKETS = 6   # the ways a normal faces (normal_bucket)


def uniform_guide(alpha=0.0, record=False):
    """A guide of one spatial leaf whose quadtree is uniform over the sphere."""
    return GuideArrays(np.full(1, -1, dtype=np.int64), np.zeros(1), np.zeros(1, dtype=np.int64),
                       np.zeros(1, dtype=np.int64), np.full((1, 4), -1, dtype=np.int32),
                       np.ones((1, 4)), np.ones(1), float(alpha), int(bool(record)),
                       np.zeros((1, 7)))


@njit(cache=True, _nrt=False, forceinline=True)
def normal_bucket(nx, ny, nz):
    """Which of BUCKETS ways unit normal n faces: 2 x its largest component's axis, plus 1
    where that component is negative."""
    ax, ay, az = abs(nx), abs(ny), abs(nz)
    if ax >= ay and ax >= az:
        return 0 if nx >= 0.0 else 1
    if ay >= az:
        return 2 if ny >= 0.0 else 3
    return 4 if nz >= 0.0 else 5


@njit(cache=True, _nrt=False, forceinline=True)
def guide_node(axis, split, child, px, py, pz, bucket):
    """The spatial tree's leaf node holding point p on a surface whose normal is in `bucket`
    (normal_bucket; axis 3 splits on it)."""
    node = 0
    while axis[node] >= 0:
        a = axis[node]
        c = px if a == 0 else (py if a == 1 else (pz if a == 2 else bucket))
        node = child[node] + (0 if c < split[node] else 1)
    return node


@njit(cache=True, _nrt=False, forceinline=True)
def frame_turn(frame, node, px, py, pz):
    """The rotation of spatial node `node`'s parallax frame at point p, as (v, c): the cross and
    dot products of the unit directions a (centre to focus) and b (p to focus); (0, 0, 0, 1),
    no turn, where the frame is off or b is not defined. turn() applies it."""
    if frame[node, 6] == 0.0:
        return 0.0, 0.0, 0.0, 1.0
    fx, fy, fz = frame[node, 3], frame[node, 4], frame[node, 5]
    ax, ay, az = fx - frame[node, 0], fy - frame[node, 1], fz - frame[node, 2]
    bx, by, bz = fx - px, fy - py, fz - pz
    la = math.sqrt(ax * ax + ay * ay + az * az)
    lb = math.sqrt(bx * bx + by * by + bz * bz)
    if not (la > 0.0 and lb > 0.0):
        return 0.0, 0.0, 0.0, 1.0
    s = 1.0 / (la * lb)
    c = (ax * bx + ay * by + az * bz) * s
    if not c > -0.5:   # (a turn past 120 degrees: p is about as far from the focus as c)
        return 0.0, 0.0, 0.0, 1.0
    return (ay * bz - az * by) * s, (az * bx - ax * bz) * s, (ax * by - ay * bx) * s, c


@njit(cache=True, _nrt=False, forceinline=True)
def turn(vx, vy, vz, c, sign, dx, dy, dz):
    """Direction d turned by the rotation (v, c) of frame_turn (sign 1), or by its inverse
    (sign -1): Rodrigues' formula d c + (v x d) + v (v . d) / (1 + c)."""
    vx, vy, vz = sign * vx, sign * vy, sign * vz
    k = (vx * dx + vy * dy + vz * dz) / (1.0 + c)
    return (dx * c + (vy * dz - vz * dy) + vx * k, dy * c + (vz * dx - vx * dz) + vy * k,
            dz * c + (vx * dy - vy * dx) + vz * k)


@njit(cache=True, _nrt=False, forceinline=True)
def guide_turn(guide, node, px, py, pz):
    """frame_turn of the guide's spatial node at point p."""
    return frame_turn(guide.frame, node, px, py, pz)


@njit(cache=True, _nrt=False, forceinline=True)
def guide_leaf(axis, split, child, root, px, py, pz, bucket):
    """root[] of the spatial leaf holding point p, normal in `bucket`."""
    return root[guide_node(axis, split, child, px, py, pz, bucket)]


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
def guide_sample(guide, node, u1, u2, vx=0.0, vy=0.0, vz=0.0, vc=1.0):
    """A unit direction drawn from the guide's quadtree `node`, turned by the rotation (v, vc)
    of guide_turn: (dx, dy, dz, pdf in solid angle, the warp's). It may point below the
    surface, where a BSDF that only reflects gives it nothing (mirroring such directions
    above the surface costs a second walk per vertex; with the spatial tree split by normal,
    few point below: benchmarks/results/guiding.md)."""
    x, y, pdf = quadtree_sample(guide.q_child, guide.q_density, node, u1, u2)
    lx, ly, lz = square_to_sphere(x, y)
    dx, dy, dz = turn(vx, vy, vz, vc, 1.0, lx, ly, lz)
    return dx, dy, dz, pdf * INV_FOUR_PI


@njit(cache=True, _nrt=False, forceinline=True)
def guide_pdf(guide, node, dx, dy, dz, vx=0.0, vy=0.0, vz=0.0, vc=1.0):
    """The solid-angle density of guide_sample (turned by (v, vc)) at unit direction d: the
    quadtree's at d turned back into the leaf's frame."""
    ax, ay, az = turn(vx, vy, vz, vc, -1.0, dx, dy, dz)
    return direction_pdf(guide.q_child, guide.q_density, node, ax, ay, az) * INV_FOUR_PI


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
            history[H_T, col] = floats[T, i]   # (inf where the ray left the scene)


@njit(cache=True, nogil=True, _nrt=False)
def record_stage(floats, size, history, depth, out):
    """The records of a finished wave's first `size` slots into out (RECORD_ROWS, at least
    size x depth): for each set history column, the vertex, its bounce direction, and the
    mean over R, G, B of the radiance the bounce brought back (what the path gathered after it,
    divided by the throughput after it) divided by the bounce's pdf, that radiance times the
    bounce's f cos / pdf (the bounce's estimate F / p of the light it reflects), the pdf, the
    BSDF's pdf, the normal and the distance to the next vertex. Clears the columns; returns
    the count, in slot and vertex order."""
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
            out[13, count] = history[H_T, col]
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

