"""Which area lights a ray crosses: a small bounding-volume tree over the scene's area-light
rectangles, so that a bounce ray's search for the lights it passes through (the integrator's
emission_found) visits the lights near its path, not every light of the scene.

Area lights are not geometry: a ray passes on through them (the course's rule) and may cross
several before its hit, so the search wants every crossing, not the closest. The tree is
stackless, for numba code compiled without the runtime: its nodes are in depth-first order, a
node's first child is the next node, and `skip[k]` is the first node after k's subtree. A walk
(next_light) enters an inner node whose box the ray crosses (k + 1) and else jumps over it
(skip[k]); each leaf holds one light, handed to the caller's exact rectangle test
(ptrace.lights.area_light_hit) without a box test of its own, so the lights are visited in the
tree's depth-first order, which depends on the scene alone. The boxes are padded outward, so
that no ray the rectangle test accepts is turned away by an inner node's box.
"""
import numpy as np
from numba import njit

from .scene import AREA

PAD = 1e-6      # each box grows by this fraction of its largest coordinate and of its size


def build_light_hits(kind, position, edge_x, edge_y):
    """(lower, upper, skip, light) of the area lights among a scene's lights (light kind,
    centre, full edges), one leaf per light: lower and upper (nodes, 3) float64, skip and light
    (nodes,) int64, light -1 at inner nodes. No area light: empty arrays."""
    kind = np.asarray(kind)
    lights = np.nonzero(kind == AREA)[0]
    position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    edge_x = np.asarray(edge_x, dtype=np.float64).reshape(-1, 3)
    edge_y = np.asarray(edge_y, dtype=np.float64).reshape(-1, 3)
    corners = (position[lights, None, :]
               + np.array([-0.5, 0.5, 0.5, -0.5])[None, :, None] * edge_x[lights, None, :]
               + np.array([-0.5, -0.5, 0.5, 0.5])[None, :, None] * edge_y[lights, None, :])
    low, high = corners.min(axis=1), corners.max(axis=1)
    pad = PAD * (np.abs(corners).max(axis=(1, 2)) + (high - low).max(axis=1, initial=0.0))
    low, high = low - pad[:, None], high + pad[:, None]
    lower, upper, skip, leaf = [], [], [], []

    def node(members):
        k = len(skip)
        lower.append(low[members].min(axis=0))
        upper.append(high[members].max(axis=0))
        skip.append(-1)
        leaf.append(-1)
        if len(members) == 1:
            leaf[k] = lights[members[0]]
        else:   # halves by the centres along the widest axis of the centres
            centres = 0.5 * (low[members] + high[members])
            axis = int(np.argmax(np.ptp(centres, axis=0)))
            order = members[np.argsort(centres[:, axis], kind="stable")]
            half = len(order) // 2
            node(order[:half])
            node(order[half:])
        skip[k] = len(skip)

    if lights.shape[0]:
        node(np.arange(lights.shape[0]))
    return (np.array(lower, dtype=np.float64).reshape(-1, 3),
            np.array(upper, dtype=np.float64).reshape(-1, 3),
            np.array(skip, dtype=np.int64), np.array(leaf, dtype=np.int64))


def no_light_hits():
    """LightArrays' fields of a record built by hand without them: no light at infinity (sky)
    and no area light to cross."""
    return (np.zeros(0, dtype=np.int64),) + build_light_hits(np.zeros(0), np.zeros((0, 3)),
                                                             np.zeros((0, 3)),
                                                             np.zeros((0, 3)))


@njit(cache=True, _nrt=False, forceinline=True)
def _slab(o, d, lo, hi, near, far):
    """(near, far) narrowed to where o + t d lies in [lo, hi]; empty (near > far) if nowhere."""
    if d == 0.0:
        return (near, far) if lo <= o <= hi else (1.0, 0.0)
    t0, t1 = (lo - o) / d, (hi - o) / d
    if t0 > t1:
        t0, t1 = t1, t0
    return max(near, t0), min(far, t1)


@njit(cache=True, _nrt=False, forceinline=True)
def box_crossed(lower, upper, k, ox, oy, oz, dx, dy, dz, t_max):
    """Whether the ray o + t d, 0 <= t <= t_max, meets node k's box (its faces included); a
    direction component of zero meets it where the origin lies within that slab."""
    near, far = _slab(ox, dx, lower[k, 0], upper[k, 0], 0.0, t_max)
    if near > far:
        return False
    near, far = _slab(oy, dy, lower[k, 1], upper[k, 1], near, far)
    if near > far:
        return False
    near, far = _slab(oz, dz, lower[k, 2], upper[k, 2], near, far)
    return near <= far


@njit(cache=True, _nrt=False, forceinline=True)
def next_light(lower, upper, skip, leaf, k, ox, oy, oz, dx, dy, dz, t_max):
    """The walk from node k: (the next light whose box's parents the ray o + t d, 0 <= t <=
    t_max, meets, the node to go on from), or (-1, end) when there is none. Start at 0."""
    while k < skip.shape[0]:
        light = leaf[k]
        if light >= 0:
            return light, k + 1
        k = k + 1 if box_crossed(lower, upper, k, ox, oy, oz, dx, dy, dz, t_max) else skip[k]
    return -1, k
