"""Compiled distances to convex primitives (boxes and cylinders) along straight paths:
the scene kernels' obstacle check (:mod:`grasp_apso.geometry.scene_kernels`).

The signed distance to a convex set is a convex function, so along a straight path it
lies above each of its tangents; :func:`convex_path_least` brackets the least with the
tangents at the bracket's ends (a certified lower bound within CONVEX_TOLERANCE in a
few evaluations, where sampling every few millimetres needs dozens).
"""

from __future__ import annotations

import math

import numba

_jit = numba.njit(cache=True, nogil=True)


@_jit
def convex_value_slope(is_box, inv, hx, hy, hz, radius, half_height, x, y, z, wx, wy, wz):
    """Signed distance (m) of a point to a box (half sizes ``hx, hy, hz``) or a cylinder
    (``radius``, ``half_height``, axis = local z), and its slope along ``w`` (local
    frame, m per unit of the path parameter): the gradient (a subgradient inside) dot w."""
    lx = inv[0, 0] * x + inv[0, 1] * y + inv[0, 2] * z + inv[0, 3]
    ly = inv[1, 0] * x + inv[1, 1] * y + inv[1, 2] * z + inv[1, 3]
    lz = inv[2, 0] * x + inv[2, 1] * y + inv[2, 2] * z + inv[2, 3]
    sx = 1.0 if lx >= 0.0 else -1.0
    sy = 1.0 if ly >= 0.0 else -1.0
    sz = 1.0 if lz >= 0.0 else -1.0
    if is_box:
        qx = abs(lx) - hx
        qy = abs(ly) - hy
        qz = abs(lz) - hz
        ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
        d = math.sqrt(ox * ox + oy * oy + oz * oz)
        if d > 0.0:
            return d, (sx * ox * wx + sy * oy * wy + sz * oz * wz) / d
        if qx >= qy and qx >= qz:
            return qx, sx * wx
        if qy >= qz:
            return qy, sy * wy
        return qz, sz * wz
    rho = math.sqrt(lx * lx + ly * ly)
    ux, uy = (lx / rho, ly / rho) if rho > 1e-12 else (1.0, 0.0)
    qr = rho - radius
    qz = abs(lz) - half_height
    o_r, o_z = max(qr, 0.0), max(qz, 0.0)
    d = math.sqrt(o_r * o_r + o_z * o_z)
    if d > 0.0:
        return d, (o_r * (ux * wx + uy * wy) + o_z * sz * wz) / d
    if qr >= qz:
        return qr, ux * wx + uy * wy
    return qz, sz * wz


#: Sub-steps of :func:`convex_path_least`, and the width (m) of the bracket at which it stops.
CONVEX_ITERATIONS = 8
CONVEX_TOLERANCE = 1e-4


@_jit
def convex_path_least(is_box, inv, hx, hy, hz, radius, half_height, qx, qy, qz, dx, dy, dz, wx, wy, wz, stop):
    """A lower bound (m) of the least signed distance from the path q + t d, t in [0, 1]
    (object frame; ``w`` = d in the obstacle's frame), to a box or a cylinder, within
    CONVEX_TOLERANCE of it, or any value >= ``stop`` once the least is known to be >= stop.

    The distance to a convex set is convex along a line, so it lies above each of its
    tangents: where the tangents at the two ends of a bracket meet bounds the least from
    below; the bracket shrinks to the side where the slope changes sign.
    """
    fa, ga = convex_value_slope(is_box, inv, hx, hy, hz, radius, half_height, qx, qy, qz, wx, wy, wz)
    if ga >= 0.0:
        return fa
    fb, gb = convex_value_slope(is_box, inv, hx, hy, hz, radius, half_height, qx + dx, qy + dy, qz + dz, wx, wy, wz)
    if gb <= 0.0:
        return fb
    a, b = 0.0, 1.0
    lower = min(fa, fb)
    for _ in range(CONVEX_ITERATIONS):
        # ga < 0 < gb: the tangents at a and b meet inside [a, b]
        tm = (fb - gb * b - fa + ga * a) / (ga - gb)
        tm = min(max(tm, a), b)
        lower = fa + ga * (tm - a)
        if lower >= stop or min(fa, fb) - lower <= CONVEX_TOLERANCE:
            return lower
        fm, gm = convex_value_slope(is_box, inv, hx, hy, hz, radius, half_height,
                                     qx + tm * dx, qy + tm * dy, qz + tm * dz, wx, wy, wz)
        if gm == 0.0:
            return fm
        if gm > 0.0:
            b, fb, gb = tm, fm, gm
        else:
            a, fa, ga = tm, fm, gm
    return min(lower, fa + ga * ((fb - gb * b - fa + ga * a) / (ga - gb) - a))


@_jit
def path_least(is_box, inv, hx, hy, hz, radius, half_height, qx, qy, qz, length, dx, dy, dz, wx, wy, wz, stop):
    """:func:`convex_path_least`, or the distance at q alone when ``length`` is 0."""
    if length > 0.0:
        return convex_path_least(is_box, inv, hx, hy, hz, radius, half_height, qx, qy, qz, dx, dy, dz, wx, wy, wz, stop)
    return convex_value_slope(is_box, inv, hx, hy, hz, radius, half_height, qx, qy, qz, 0.0, 0.0, 0.0)[0]


@_jit
def _least_abs(lo, span):
    """Least |lo + t span| over t in [0, 1]."""
    hi = lo + span
    if (lo <= 0.0 <= hi) or (hi <= 0.0 <= lo):
        return 0.0
    return min(abs(lo), abs(hi))


@_jit
def path_slab_bound(is_box, inv, hx, hy, hz, radius, half_height, qx, qy, qz, wx, wy, wz):
    """A cheap lower bound (m) of the least signed distance from the path q + t d, t in
    [0, 1] (``w`` = d in the obstacle's frame), to a box or a cylinder: the distance is at
    least the one to each slab between two opposite faces (and, for a cylinder, to its
    infinite tube), which is easy to minimise along a line. Screens paths far from an
    obstacle before :func:`convex_path_least`."""
    lx = inv[0, 0] * qx + inv[0, 1] * qy + inv[0, 2] * qz + inv[0, 3]
    ly = inv[1, 0] * qx + inv[1, 1] * qy + inv[1, 2] * qz + inv[1, 3]
    lz = inv[2, 0] * qx + inv[2, 1] * qy + inv[2, 2] * qz + inv[2, 3]
    if is_box:
        return max(_least_abs(lx, wx) - hx, _least_abs(ly, wy) - hy, _least_abs(lz, wz) - hz)
    # the tube: the least distance of the 2-D segment (lx, ly) + t (wx, wy) from the axis
    w2 = wx * wx + wy * wy
    t = 0.0 if w2 <= 1e-18 else min(max(-(lx * wx + ly * wy) / w2, 0.0), 1.0)
    return max(_least_abs(lz, wz) - half_height, math.sqrt((lx + t * wx) ** 2 + (ly + t * wy) ** 2) - radius)
