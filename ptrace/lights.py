"""Light sampling, sample_L of CS184.md 4.4, as a numba function of one light index.

The course applies no distance falloff to point and directional lights (their colour is used as
the radiance reaching every point): ptrace keeps that so course scenes look as the course made
them. Spot lights are parsed and, like the course's Sp19 stub, contribute nothing.
"""
import math

from numba import njit

from .scene import AMBIENT, AREA, DIRECTIONAL, POINT

INF = math.inf


@njit(cache=True, inline="always")
def light_is_delta(kind):
    return kind == POINT or kind == DIRECTIONAL


@njit(cache=True, _nrt=False, forceinline=True)
def sample_light(kind, radiance, position, direction, edge_x, edge_y, area, i,
                 px, py, pz, u1, u2):
    """Sample light i as seen from point p.

    Returns (Lr, Lg, Lb, wix, wiy, wiz, distance, pdf): wi is the unit direction toward the
    light sample, distance is inf for lights at infinity, pdf is per unit solid angle (1 for
    delta lights), and pdf 0 means "no contribution" (spot lights, the back of an area light).
    """
    if kind == POINT:
        dx, dy, dz = position[i, 0] - px, position[i, 1] - py, position[i, 2] - pz
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        if dist == 0.0:
            return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
        return radiance[i, 0], radiance[i, 1], radiance[i, 2], dx / dist, dy / dist, dz / dist, \
            dist, 1.0
    if kind == DIRECTIONAL:
        return radiance[i, 0], radiance[i, 1], radiance[i, 2], direction[i, 0], \
            direction[i, 1], direction[i, 2], INF, 1.0
    if kind == AREA:
        sx, sy = u1 - 0.5, u2 - 0.5
        qx = position[i, 0] + sx * edge_x[i, 0] + sy * edge_y[i, 0]
        qy = position[i, 1] + sx * edge_x[i, 1] + sy * edge_y[i, 1]
        qz = position[i, 2] + sx * edge_x[i, 2] + sy * edge_y[i, 2]
        dx, dy, dz = qx - px, qy - py, qz - pz
        dist2 = dx * dx + dy * dy + dz * dz
        dist = math.sqrt(dist2)
        if dist == 0.0 or area[i] <= 0.0:
            return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
        wx, wy, wz = dx / dist, dy / dist, dz / dist
        cos_light = wx * direction[i, 0] + wy * direction[i, 1] + wz * direction[i, 2]
        if cos_light >= 0.0:   # the point is behind the one-sided light
            return 0.0, 0.0, 0.0, wx, wy, wz, dist, 0.0
        pdf = dist2 / (area[i] * -cos_light)
        return radiance[i, 0], radiance[i, 1], radiance[i, 2], wx, wy, wz, dist, pdf
    if kind == AMBIENT:
        # uniform over the hemisphere about world +Y, pdf 1 / (2 pi)
        y = u1
        r = math.sqrt(max(0.0, 1.0 - y * y))
        phi = 2.0 * math.pi * u2
        return radiance[i, 0], radiance[i, 1], radiance[i, 2], r * math.cos(phi), y, \
            r * math.sin(phi), INF, 1.0 / (2.0 * math.pi)
    return 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0   # spot: nothing, like the course
