"""Compiled inner loops of the optimiser's hot path (numba, no Python objects).

Decoding a swarm is a closing sweep per finger that stops at the first touch of the
surface, then a refinement and a check of the closed pose: about 120 signed-distance
look-ups per finger, 36,000 per batch of 60 particles. In numpy every step of the sweep had to be evaluated
for every finger (no early exit), each through a dozen temporaries and ~1 us of call
overhead per operation; these loops run once per finger row, stop where the finger
stops, and keep their intermediates in registers. Measured by ``bench/bench_decode.py``
(the numbers are in the README).

Conventions: float64, C-contiguous arrays; a finger *row* ``f`` is finger ``f % 5`` of
particle ``f // 5`` (F = P * 5 rows). The kernels release the GIL (the ROS node's
executor keeps serving while a plan runs in its worker thread) and are cached on disk,
so they are compiled once per installation (``NUMBA_CACHE_DIR`` moves the cache when
the package directory is read-only). The semantics are those documented in
:mod:`grasp_apso.geometry.decoder`, :mod:`grasp_apso.geometry.sdf` and :mod:`grasp_apso.geometry.collision`,
which call them; the callers validate their inputs.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True)

#: Fingers per particle (rows of a particle are consecutive).
N_FINGERS = 5
#: Cells inside the grid's last cell used when clamping (safe for the index cast).
_CELL_MARGIN = 1e-3


# --------------------------------------------------------------------------------------
# signed-distance grid: trilinear look-up
# --------------------------------------------------------------------------------------
@_jit
def _grid_value(values, ox, oy, oz, inv, spacing, x, y, z):
    """(trilinear value at the nearest point c of the grid's box, |p - c| m): the two
    parts of a look-up. ``inv`` = 1 / spacing."""
    nx, ny, nz = values.shape
    gx = (x - ox) * inv
    gy = (y - oy) * inv
    gz = (z - oz) * inv
    cx = min(max(gx, 0.0), nx - 1 - _CELL_MARGIN)
    cy = min(max(gy, 0.0), ny - 1 - _CELL_MARGIN)
    cz = min(max(gz, 0.0), nz - 1 - _CELL_MARGIN)
    out2 = (gx - cx) ** 2 + (gy - cy) ** 2 + (gz - cz) ** 2
    outside = math.sqrt(out2) * spacing if out2 > 0.0 else 0.0
    i = int(cx)
    j = int(cy)
    k = int(cz)
    fx = cx - i
    fy = cy - j
    fz = cz - k
    c00 = values[i, j, k] + (values[i, j, k + 1] - values[i, j, k]) * fz
    c01 = values[i, j + 1, k] + (values[i, j + 1, k + 1] - values[i, j + 1, k]) * fz
    c10 = values[i + 1, j, k] + (values[i + 1, j, k + 1] - values[i + 1, j, k]) * fz
    c11 = values[i + 1, j + 1, k] + (values[i + 1, j + 1, k + 1] - values[i + 1, j + 1, k]) * fz
    c0 = c00 + (c01 - c00) * fy
    c1 = c10 + (c11 - c10) * fy
    return c0 + (c1 - c0) * fx, outside


@_jit
def _grid_distance(values, ox, oy, oz, inv, spacing, x, y, z):
    """Signed distance at one point: trilinear inside the grid box, plus the distance to
    the box outside it (an over-estimate far from the object). ``inv`` = 1 / spacing."""
    value, outside = _grid_value(values, ox, oy, oz, inv, spacing, x, y, z)
    return value + outside


@_jit
def grid_distances(values, origin, spacing, x, y, z, out):
    """Signed distances of points given as flat coordinate arrays.

    values : (nx, ny, nz) float, m; origin : (3,) float, m; spacing : float, m
    x, y, z, out : (N,) float, m (out is written)
    """
    ox, oy, oz = origin[0], origin[1], origin[2]
    inv = 1.0 / spacing
    for n in range(x.shape[0]):
        out[n] = _grid_distance(values, ox, oy, oz, inv, spacing, x[n], y[n], z[n])


@_jit
def grid_values(values, origin, spacing, points, out):
    """Trilinear interpolation of a grid of any quantity, clamped to the grid box (no
    distance term: the normal-spread grid, :mod:`grasp_apso.geometry.normal_spread`).

    values : (nx, ny, nz) float; origin : (3,) float, m; spacing : float, m
    points : (N, 3) float, m; out : (N,) float (written; 0 at a non-finite point)
    """
    ox, oy, oz = origin[0], origin[1], origin[2]
    inv = 1.0 / spacing
    for n in range(points.shape[0]):
        x, y, z = points[n, 0], points[n, 1], points[n, 2]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            out[n] = 0.0
            continue
        # spacing 0: the distance-to-box term of _grid_distance vanishes (clamped value)
        out[n] = _grid_distance(values, ox, oy, oz, inv, 0.0, x, y, z)


@_jit
def normal_spreads(dist, index, normals, reference, radius, back_cos, out):
    """Weighted RMS angle of sample normals around their weighted mean, per node.

    dist, index : (N, K) float m, int: the K nearest surface samples of each node's
    closest surface point (``cKDTree.query`` with ``distance_upper_bound``: missing ones
    are inf / ``len(normals)``); normals : (S, 3) unit sample normals; reference : (N, 3)
    unit, samples whose normal's cosine to it is <= back_cos are left out; the others
    within ``radius`` weigh 1 (area-weighted samples: the area of the disc, as
    ``quality.robustness.normal_uncertainty``); out : (N,) rad (written; 0 without a
    neighbour).
    """
    n_samples = normals.shape[0]
    for n in range(dist.shape[0]):
        mx = my = mz = 0.0
        total = 0.0
        for k in range(dist.shape[1]):
            j = index[n, k]
            if j >= n_samples or not dist[n, k] < radius:
                continue
            if (normals[j, 0] * reference[n, 0] + normals[j, 1] * reference[n, 1]
                    + normals[j, 2] * reference[n, 2]) <= back_cos:
                continue
            w = 1.0
            mx += w * normals[j, 0]
            my += w * normals[j, 1]
            mz += w * normals[j, 2]
            total += w
        norm = math.sqrt(mx * mx + my * my + mz * mz)
        if total <= 0.0 or norm <= 1e-12:
            out[n] = 0.0
            continue
        mx /= norm
        my /= norm
        mz /= norm
        acc = 0.0
        for k in range(dist.shape[1]):
            j = index[n, k]
            if j >= n_samples or not dist[n, k] < radius:
                continue
            c = normals[j, 0] * reference[n, 0] + normals[j, 1] * reference[n, 1] + normals[j, 2] * reference[n, 2]
            if c <= back_cos:
                continue
            w = 1.0
            a = math.acos(min(max(normals[j, 0] * mx + normals[j, 1] * my + normals[j, 2] * mz, -1.0), 1.0))
            acc += w * a * a
        out[n] = math.sqrt(acc / total)


@numba.njit(cache=True, nogil=True, inline="always")
def _unit_gradient(values, ox, oy, oz, inv, spacing, x, y, z):
    """The signed distance's unit gradient at one point, a tuple (gx, gy, gz): central
    differences over half a cell (inlined where called; ``inv`` = 1 / spacing)."""
    h = 0.5 * spacing
    gx = (_grid_distance(values, ox, oy, oz, inv, spacing, x + h, y, z)
          - _grid_distance(values, ox, oy, oz, inv, spacing, x - h, y, z))
    gy = (_grid_distance(values, ox, oy, oz, inv, spacing, x, y + h, z)
          - _grid_distance(values, ox, oy, oz, inv, spacing, x, y - h, z))
    gz = (_grid_distance(values, ox, oy, oz, inv, spacing, x, y, z + h)
          - _grid_distance(values, ox, oy, oz, inv, spacing, x, y, z - h))
    norm = max(math.sqrt(gx * gx + gy * gy + gz * gz), 1e-12)
    return gx / norm, gy / norm, gz / norm


@_jit
def grid_distances_gradients(values, origin, spacing, points, distance, gradient):
    """Signed distance and its unit gradient (central differences over half a cell).

    points : (N, 3) float, m; distance : (N,) and gradient : (N, 3) float (written)
    """
    ox, oy, oz = origin[0], origin[1], origin[2]
    inv = 1.0 / spacing
    for n in range(points.shape[0]):
        x, y, z = points[n, 0], points[n, 1], points[n, 2]
        distance[n] = _grid_distance(values, ox, oy, oz, inv, spacing, x, y, z)
        gradient[n, 0], gradient[n, 1], gradient[n, 2] = _unit_gradient(values, ox, oy, oz, inv, spacing, x, y, z)


@_jit
def support_function(points, directions, out, argmax):
    """Support function of a point set: max over points of (point . direction) and the
    point that attains it, per direction (a compiled loop: a BLAS product of this shape
    wakes OpenBLAS's threads, which then spin on the other core).

    points : (H, 3) float; directions : (P, 3) float
    out : (P,) float, argmax : (P,) int (written)
    """
    for p in range(directions.shape[0]):
        dx, dy, dz = directions[p, 0], directions[p, 1], directions[p, 2]
        best = -np.inf
        best_h = 0
        for h in range(points.shape[0]):
            v = points[h, 0] * dx + points[h, 1] * dy + points[h, 2] * dz
            if v > best:
                best = v
                best_h = h
        out[p] = best
        argmax[p] = best_h


# --------------------------------------------------------------------------------------
# closing the fingers
# --------------------------------------------------------------------------------------
@_jit
def _world_plane(rot, trans, planes_palm, p, f, plane):
    """Finger row f's flexion plane (base, ex, ey; palm frame, planes_palm (F, 3, 3)) moved
    into the object frame by particle p's wrist (rot (P, 3, 3), trans (P, 3)): plane (3, 3)."""
    for a in range(3):
        for i in range(3):
            acc = trans[p, i] if a == 0 else 0.0
            for j in range(3):
                acc += rot[p, i, j] * planes_palm[f, a, j]
            plane[a, i] = acc


@_jit
def _segments(lengths, finger, ratio, distal, proximal, seg):
    """Planar link vectors (u, v) of a finger at flexions (distal, proximal): seg (3, 2)."""
    phi0 = proximal
    phi1 = proximal + ratio * distal
    phi2 = proximal + (ratio + 1.0) * distal
    seg[0, 0] = lengths[finger, 0] * math.cos(phi0)
    seg[0, 1] = lengths[finger, 0] * math.sin(phi0)
    seg[1, 0] = lengths[finger, 1] * math.cos(phi1)
    seg[1, 1] = lengths[finger, 1] * math.sin(phi1)
    seg[2, 0] = lengths[finger, 2] * math.cos(phi2)
    seg[2, 1] = lengths[finger, 2] * math.sin(phi2)


@_jit
def _link_point(coeff, m, seg, plane):
    """Link point m (coeff (3, K): a combination of the planar segments seg (3, 2)) in
    the object frame through the flexion plane (3, 3: base, ex, ey): (x, y, z) m."""
    u = coeff[0, m] * seg[0, 0] + coeff[1, m] * seg[1, 0] + coeff[2, m] * seg[2, 0]
    v = coeff[0, m] * seg[0, 1] + coeff[1, m] * seg[1, 1] + coeff[2, m] * seg[2, 1]
    return (plane[0, 0] + u * plane[1, 0] + v * plane[2, 0],
            plane[0, 1] + u * plane[1, 1] + v * plane[2, 1],
            plane[0, 2] + u * plane[1, 2] + v * plane[2, 2])


@_jit
def _link_clearances(values, grid_origin, spacing, plane, seg, coeff, radii, points, clearance, k):
    """Link points of a finger (object frame) and their clearance, written to points[k]
    (K, 3) and clearance[k] (K,); returns the smallest clearance (m).

    plane : (3, 3) -- base, ex, ey of the finger's flexion plane in the object frame
    seg : (3, 2) -- planar link vectors; coeff (3, K), radii (K,) -- the link spheres
    """
    ox, oy, oz = grid_origin[0], grid_origin[1], grid_origin[2]
    inv = 1.0 / spacing
    best = np.inf
    for m in range(coeff.shape[1]):
        x, y, z = _link_point(coeff, m, seg, plane)
        points[k, m, 0] = x
        points[k, m, 1] = y
        points[k, m, 2] = z
        c = _grid_distance(values, ox, oy, oz, inv, spacing, x, y, z) - radii[m]
        clearance[k, m] = c
        if c < best:
            best = c
    return best


@_jit
def close_fingers(values, grid_origin, spacing, rot, trans, planes, lengths, ratio,
                  distal0, proximal0, distal_span, proximal_span,
                  sweep_coeff, sweep_radii, final_coeff, final_radii,
                  coarse_steps, refine_steps, max_penetration, tolerance,
                  rows, slots, s_out, blocked, contact, points, clearance, tip_gap):
    """Close finger rows onto the surface and check their closed pose.

    Each finger moves ``theta(s) = pre + s * span`` for s in [0, 1]; a coarse sweep of
    ``coarse_steps`` samples finds the first touch of a sweep sphere, regula falsi
    (Illinois, ``refine_steps``) the last free s before it. A finger whose fingertip pad
    is then within ``tolerance`` of the surface, not blocked, and with no link deeper
    than ``max_penetration`` is a fingertip contact; the others are re-opened to their
    pre-shape (s = 0).

    values, grid_origin, spacing : the signed-distance grid
    rot (P, 3, 3), trans (P, 3) : palm frame in the object frame
    planes : (F, 3, 3) float -- flexion plane of each row in the palm frame: base (m),
        ex (the straight finger), ey (the direction flexion curls toward)
    lengths : (5, 3) float, m; ratio : float -- link lengths, distal coupling ratio
    distal0, proximal0, distal_span, proximal_span : (F,) float, rad
    sweep_coeff (3, Ks), sweep_radii (Ks,), final_coeff (3, Kf), final_radii (Kf,):
        link points as combinations of the three planar segments, and their radii;
        the last final point is the fingertip pad
    rows : (R,) int -- the rows to close (all F, or the fingers GRG regenerated)
    slots : (R,) int -- where each row's results go in the outputs
    Outputs (written at ``slots``, the others untouched): s_out closing parameter of the
    returned pose; blocked (bool), deeper than max_penetration at the pre-shape; contact
    (bool); points (., Kf, 3) and clearance (., Kf) of the returned pose; tip_gap, the
    clearance of the pad where the closing stopped (before a finger without contact is
    re-opened).
    """
    seg = np.empty((3, 2))
    plane = np.empty((3, 3))
    sweep_points = np.empty((1, sweep_coeff.shape[1], 3))  # scratch
    sweep_clearance = np.empty((1, sweep_coeff.shape[1]))
    pad_point = np.empty((1, 1, 3))
    pad_clearance = np.empty((1, 1))
    last = final_coeff.shape[1] - 1
    inv_steps = 1.0 / (coarse_steps - 1)
    for row in range(rows.shape[0]):
        f = rows[row]
        k = slots[row]
        p = f // N_FINGERS
        finger = f % N_FINGERS
        _world_plane(rot, trans, planes, p, f, plane)  # base, ex, ey into the object frame
        d0 = distal0[f]
        p0 = proximal0[f]
        dspan = distal_span[f]
        pspan = proximal_span[f]
        # The sweep's link angles advance by a fixed step: rotate (cos, sin) by it instead
        # of calling cos and sin at every step.
        c0, s0 = math.cos(p0), math.sin(p0)
        c1, s1 = math.cos(p0 + ratio * d0), math.sin(p0 + ratio * d0)
        c2, s2 = math.cos(p0 + (ratio + 1.0) * d0), math.sin(p0 + (ratio + 1.0) * d0)
        w0 = pspan * inv_steps
        w1 = (pspan + ratio * dspan) * inv_steps
        w2 = (pspan + (ratio + 1.0) * dspan) * inv_steps
        cw0, sw0 = math.cos(w0), math.sin(w0)
        cw1, sw1 = math.cos(w1), math.sin(w1)
        cw2, sw2 = math.cos(w2), math.sin(w2)
        l0, l1, l2 = lengths[finger, 0], lengths[finger, 1], lengths[finger, 2]
        first = -1
        c_first = 0.0
        c_prev = 0.0
        is_blocked = False
        for step in range(coarse_steps):
            seg[0, 0] = l0 * c0
            seg[0, 1] = l0 * s0
            seg[1, 0] = l1 * c1
            seg[1, 1] = l1 * s1
            seg[2, 0] = l2 * c2
            seg[2, 1] = l2 * s2
            c = _link_clearances(values, grid_origin, spacing, plane, seg, sweep_coeff, sweep_radii,
                                 sweep_points, sweep_clearance, 0)
            if step == 0:
                is_blocked = c < -max_penetration
            if c <= 0.0:
                first = step
                c_first = c
                break
            c_prev = c
            c0, s0 = c0 * cw0 - s0 * sw0, s0 * cw0 + c0 * sw0
            c1, s1 = c1 * cw1 - s1 * sw1, s1 * cw1 + c1 * sw1
            c2, s2 = c2 * cw2 - s2 * sw2, s2 * cw2 + c2 * sw2
        blocked[k] = is_blocked
        if first < 0:
            s_stop = 1.0
        elif first == 0:
            s_stop = 0.0
        else:
            lo = (first - 1) * inv_steps
            hi = first * inv_steps
            c_lo = c_prev
            c_hi = c_first
            side = 0
            for _ in range(refine_steps):
                denom = c_lo - c_hi
                frac = c_lo / (denom if abs(denom) > 1e-12 else 1.0)
                frac = min(max(frac, 0.05), 0.95)
                mid = lo + frac * (hi - lo)
                _segments(lengths, finger, ratio, d0 + mid * dspan, p0 + mid * pspan, seg)
                c_mid = _link_clearances(values, grid_origin, spacing, plane, seg, sweep_coeff, sweep_radii,
                                         sweep_points, sweep_clearance, 0)
                if c_mid > 0.0:  # Illinois: halve the stale end's value when a side repeats
                    if side > 0:
                        c_hi *= 0.5
                    lo = mid
                    c_lo = c_mid
                    side = 1
                else:
                    if side < 0:
                        c_lo *= 0.5
                    hi = mid
                    c_hi = c_mid
                    side = -1
            s_stop = lo
        _segments(lengths, finger, ratio, d0 + s_stop * dspan, p0 + s_stop * pspan, seg)
        # The pad first: a finger whose pad is not within the tolerance is no contact, and
        # its pose at the stop is not needed (it is re-opened).
        gap = _link_clearances(values, grid_origin, spacing, plane, seg, final_coeff[:, last:],
                               final_radii[last:], pad_point, pad_clearance, 0)
        tip_gap[k] = gap
        touching = False
        at_stop = False
        if gap <= tolerance and not is_blocked:
            lowest = _link_clearances(values, grid_origin, spacing, plane, seg, final_coeff, final_radii,
                                      points, clearance, k)
            at_stop = True
            touching = lowest >= -max_penetration
        contact[k] = touching
        if touching:
            s_out[k] = s_stop
        else:
            s_out[k] = 0.0
            if s_stop != 0.0 or not at_stop:
                _segments(lengths, finger, ratio, d0, p0, seg)
                _link_clearances(values, grid_origin, spacing, plane, seg, final_coeff, final_radii,
                                 points, clearance, k)


@_jit
def open_fingers(values, grid_origin, spacing, rot, trans, planes, lengths, ratio, distal0, proximal0,
                 final_coeff, rows, slots, s_out, blocked, contact, points, clearance, tip_gap):
    """Finger rows left at their pre-shape, not closed: the decoder found them illegal
    before closing (their open hand comes too close to the scene). Outputs as
    :func:`close_fingers`: s_out 0, no contact; the points of the pre-shape; the tip gap
    (the pad's clearance there); the other clearances, not needed for an illegal
    finger, are written +inf (no penetration, no link contact, not blocked).

    Arguments as :func:`close_fingers`.
    """
    seg = np.empty((3, 2))
    plane = np.empty((3, 3))
    last = final_coeff.shape[1] - 1
    inv = 1.0 / spacing
    for row in range(rows.shape[0]):
        f = rows[row]
        k = slots[row]
        _world_plane(rot, trans, planes, f // N_FINGERS, f, plane)
        _segments(lengths, f % N_FINGERS, ratio, distal0[f], proximal0[f], seg)
        for m in range(final_coeff.shape[1]):
            points[k, m, 0], points[k, m, 1], points[k, m, 2] = _link_point(final_coeff, m, seg, plane)
            clearance[k, m] = np.inf
        tip_gap[k] = _grid_distance(values, grid_origin[0], grid_origin[1], grid_origin[2], inv, spacing,
                                    points[k, last, 0], points[k, last, 1], points[k, last, 2])
        s_out[k] = 0.0
        contact[k] = False
        blocked[k] = False


@_jit
def palm_depths(points, first, stop, rows, rot, trans, center, half_extents, out):
    """Deepest penetration of link points into the palm box, per finger row.

    points : (R, K, 3) float, m, object frame, of the finger rows ``rows`` (R,) --
        points first..stop-1 are checked
    rot : (P, 3, 3), trans : (P, 3) -- palm frame in the object frame
    center, half_extents : (3,) float, m -- the palm box in the palm frame
    out : (R,) float, m (written; 0 when no point is inside)
    """
    for k in range(points.shape[0]):
        p = rows[k] // N_FINGERS
        deepest = 0.0
        for m in range(first, stop):
            dx = points[k, m, 0] - trans[p, 0]
            dy = points[k, m, 1] - trans[p, 1]
            dz = points[k, m, 2] - trans[p, 2]
            inside = -np.inf
            for a in range(3):  # palm coordinate a = column a of rot . (p - t)
                local = rot[p, 0, a] * dx + rot[p, 1, a] * dy + rot[p, 2, a] * dz
                q = abs(local - center[a]) - half_extents[a]
                if q > inside:
                    inside = q
            if inside < 0.0 and -inside > deepest:
                deepest = -inside
        out[k] = deepest


# --------------------------------------------------------------------------------------
# capsules
# --------------------------------------------------------------------------------------
@_jit
def _segment_distance(p0x, p0y, p0z, p1x, p1y, p1z, q0x, q0y, q0z, q1x, q1y, q1z):
    """Closest distance between segments [p0, p1] and [q0, q1] (Ericson, Real-Time
    Collision Detection, 5.1.9, with its degenerate cases)."""
    d1x, d1y, d1z = p1x - p0x, p1y - p0y, p1z - p0z
    d2x, d2y, d2z = q1x - q0x, q1y - q0y, q1z - q0z
    rx, ry, rz = p0x - q0x, p0y - q0y, p0z - q0z
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    f = d2x * rx + d2y * ry + d2z * rz
    eps = 1e-15
    if a <= eps and e <= eps:
        s = 0.0
        t = 0.0
    elif a <= eps:
        s = 0.0
        t = min(max(f / e, 0.0), 1.0)
    else:
        c = d1x * rx + d1y * ry + d1z * rz
        if e <= eps:
            t = 0.0
            s = min(max(-c / a, 0.0), 1.0)
        else:
            b = d1x * d2x + d1y * d2y + d1z * d2z
            denom = a * e - b * b
            s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = min(max(-c / a, 0.0), 1.0)
            elif t > 1.0:
                t = 1.0
                s = min(max((b - c) / a, 0.0), 1.0)
    gx = rx + s * d1x - t * d2x
    gy = ry + s * d1y - t * d2y
    gz = rz + s * d1z - t * d2z
    return math.sqrt(gx * gx + gy * gy + gz * gz)


@_jit
def segment_distances(p0, p1, q0, q1, out):
    """Row-wise segment distances: p0, p1, q0, q1 (N, 3) float -> out (N,) (written)."""
    for n in range(p0.shape[0]):
        out[n] = _segment_distance(p0[n, 0], p0[n, 1], p0[n, 2], p1[n, 0], p1[n, 1], p1[n, 2],
                                   q0[n, 0], q0[n, 1], q0[n, 2], q1[n, 0], q1[n, 1], q1[n, 2])


@_jit
def _link_distance(joints, p, i, a, j, b):
    """Distance between link a of finger i and link b of finger j of particle p."""
    return _segment_distance(
        joints[p, i, a, 0], joints[p, i, a, 1], joints[p, i, a, 2],
        joints[p, i, a + 1, 0], joints[p, i, a + 1, 1], joints[p, i, a + 1, 2],
        joints[p, j, b, 0], joints[p, j, b, 1], joints[p, j, b, 2],
        joints[p, j, b + 1, 0], joints[p, j, b + 1, 1], joints[p, j, b + 1, 2],
    )


@_jit
def finger_collisions(joints, radii, allowed_overlap, out):
    """Fingers colliding with another finger or folded into themselves.

    joints : (P, Fn, 4, 3) float, m -- base, PIP, DIP, tip of each finger
    radii : (3,) float, m; allowed_overlap : float, m
    out : (P, Fn) bool (written)
    """
    n_p, n_f = joints.shape[0], joints.shape[1]
    for p in range(n_p):
        for i in range(n_f):
            out[p, i] = _link_distance(joints, p, i, 0, i, 2) < radii[0] + radii[2] - allowed_overlap
        for i in range(n_f):
            for j in range(i + 1, n_f):
                if out[p, i] and out[p, j]:
                    continue  # nothing left to flag for this pair
                hit = False
                for a in range(3):
                    for b in range(3):
                        if _link_distance(joints, p, i, a, j, b) < radii[a] + radii[b] - allowed_overlap:
                            hit = True
                            break
                    if hit:
                        break
                if hit:
                    out[p, i] = True
                    out[p, j] = True
