"""Compiled grasp-quality terms per particle (numba): the fitness's inner loops.

The fitness of a batch needs, for every particle, the contact polygon's regularity
(eq. 8-10), the antipodality of a pinch, the force balance (eq. 11-12) and the distance
from the origin to the hull of the normal wrenches. Each is a handful of operations on at
most five contacts, which numpy could only batch through some forty array operations
per call; here one loop over the particles computes them all
(:func:`fitness_terms`, used by :func:`grasp_apso.quality.fitness.evaluate`), and the public,
validating functions of :mod:`grasp_apso.quality.measures` run the same per-particle functions
through their ``*_batch`` loops, so each formula exists once. The formulas, and what they
return for degenerate input, are documented in :mod:`grasp_apso.quality.measures`.

Conventions as in :mod:`grasp_apso.geometry.kernels`: float64 C-contiguous arrays, inputs already
validated (finite in-contact values, unit normals), the GIL released, cached on disk.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True)


# --------------------------------------------------------------------------------------
# per particle
# --------------------------------------------------------------------------------------
@_jit
def _contacts(mask_row, members):
    """Indices of the in-contact slots into members; returns their count."""
    n = 0
    for i in range(mask_row.shape[0]):
        if mask_row[i]:
            members[n] = i
            n += 1
    return n


@_jit
def _polygon_q(points, members, n, rtol, atol):
    """Q of eq. 8-10 for the n >= 3 contacts points[members[:n]] (m).

    The contacts are centred, projected on their best-fit plane (the two largest principal
    directions of their scatter) and ordered by angle around the centroid; the internal
    angle at vertex i is the counter-clockwise angle from edge (i -> i+1) to edge
    (i -> i-1), in [0, 360) degrees. With theta_bar = 180 (n - 2) / n and
    theta_max = (n - 2)(180 - theta_bar) + 2 theta_bar,
    Q = clip(sum |theta_i - theta_bar| / theta_max, 0, 1); contacts that coincide in the
    plane (closer than ``rtol`` times the polygon radius, or a radius below ``atol``) give 1.
    """
    centroid = np.zeros(3)
    for k in range(n):
        for a in range(3):
            centroid[a] += points[members[k], a]
    centroid /= n
    centred = np.empty((n, 3))
    for k in range(n):
        for a in range(3):
            centred[k, a] = points[members[k], a] - centroid[a]
    scatter = centred.T @ centred
    _, vecs = np.linalg.eigh(scatter)  # ascending eigenvalues
    xy = np.empty((n, 2))
    angle = np.empty(n)
    order = np.empty(n, dtype=np.int64)
    r2 = 0.0
    for k in range(n):
        x = centred[k, 0] * vecs[0, 2] + centred[k, 1] * vecs[1, 2] + centred[k, 2] * vecs[2, 2]
        y = centred[k, 0] * vecs[0, 1] + centred[k, 1] * vecs[1, 1] + centred[k, 2] * vecs[2, 1]
        xy[k, 0] = x
        xy[k, 1] = y
        r2 = max(r2, x * x + y * y)
        a = math.atan2(y, x)
        j = k  # insertion sort by angle (stable, as numpy's sort of so few)
        while j > 0 and angle[j - 1] > a:
            angle[j] = angle[j - 1]
            order[j] = order[j - 1]
            j -= 1
        angle[j] = a
        order[j] = k
    theta_bar = 180.0 * (n - 2.0) / n
    theta_max = (n - 2.0) * (180.0 - theta_bar) + 2.0 * theta_bar
    dev = 0.0
    min_d2 = np.inf
    for k in range(n):
        cur, nxt, prv = order[k], order[(k + 1) % n], order[(k - 1) % n]
        bx, by = xy[nxt, 0] - xy[cur, 0], xy[nxt, 1] - xy[cur, 1]
        ax, ay = xy[prv, 0] - xy[cur, 0], xy[prv, 1] - xy[cur, 1]
        theta = math.degrees(math.atan2(bx * ay - by * ax, bx * ax + by * ay)) % 360.0
        dev += abs(theta - theta_bar)
        for m in range(k + 1, n):
            d2 = (xy[order[m], 0] - xy[cur, 0]) ** 2 + (xy[order[m], 1] - xy[cur, 1]) ** 2
            min_d2 = min(min_d2, d2)
    if min_d2 <= rtol * rtol * r2 or r2 <= atol * atol:
        return 1.0
    return min(max(dev / theta_max, 0.0), 1.0)


@_jit
def _antipodal(points, normals, i, j, atol):
    """Antipodality A in [0, 1] of the contacts i, j (slot order):
    ((1 - n1.n2) / 2 + max(0, -n1.u) + max(0, n2.u)) / 3, u the unit vector from contact
    i to contact j; normals re-normalised; coincident contacts (no line) give 0."""
    n1 = normals[i] / math.sqrt(normals[i, 0] ** 2 + normals[i, 1] ** 2 + normals[i, 2] ** 2)
    n2 = normals[j] / math.sqrt(normals[j, 0] ** 2 + normals[j, 1] ** 2 + normals[j, 2] ** 2)
    line = points[j] - points[i]
    length = math.sqrt(line[0] ** 2 + line[1] ** 2 + line[2] ** 2)
    if not length > atol:
        return 0.0
    u = line / length
    opposed = 0.5 * (1.0 - (n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]))
    along1 = max(0.0, -(n1[0] * u[0] + n1[1] * u[1] + n1[2] * u[2]))
    along2 = max(0.0, n2[0] * u[0] + n2[1] * u[1] + n2[2] * u[2])
    return min(max((opposed + along1 + along2) / 3.0, 0.0), 1.0)


@_jit
def _balance_residual(points, members, n, com):
    """|sum of the unit forces (com - p) / |com - p|| / n, in [0, 1] (eq. 11-12); a contact
    on the centre of mass pushes nowhere; 1 for no contact."""
    if n == 0:
        return 1.0
    tx = ty = tz = 0.0
    for k in range(n):
        dx = com[0] - points[members[k], 0]
        dy = com[1] - points[members[k], 1]
        dz = com[2] - points[members[k], 2]
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        if dist > 0.0:
            tx += dx / dist
            ty += dy / dist
            tz += dz / dist
    return min(max(math.sqrt(tx * tx + ty * ty + tz * tz) / n, 0.0), 1.0)


@_jit
def _solve_in_place(a, b, n):
    """Solve a[:n, :n] x = b[:n] by Gaussian elimination with partial pivoting; x in b.
    Returns False for a (numerically) singular matrix."""
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(a[r, col]) > abs(a[piv, col]):
                piv = r
        if abs(a[piv, col]) < 1e-300:
            return False
        if piv != col:
            for c in range(n):
                a[col, c], a[piv, c] = a[piv, c], a[col, c]
            b[col], b[piv] = b[piv], b[col]
        for r in range(col + 1, n):
            factor = a[r, col] / a[col, col]
            if factor != 0.0:
                for c in range(col, n):
                    a[r, c] -= factor * a[col, c]
                b[r] -= factor * b[col]
    for r in range(n - 1, -1, -1):
        acc = b[r]
        for c in range(r + 1, n):
            acc -= a[r, c] * b[c]
        b[r] = acc / a[r, r]
    return True


@_jit
def _wrench_residual(points, normals, members, n, com, torque_scale, min_share):
    """Distance from the origin to the convex hull of the n contacts' unit normal wrenches
    ``w = [-n, (p - com) x (-n) / torque_scale]``, each contact carrying at least
    ``min_share / n`` of the squeeze (the points shifted to ``(1 - min_share) w_i +
    (min_share / n) sum_j w_j``); inf for no contact.

    Exact for so few points: the min-norm point lies on the face spanned by some subset of
    them, so every subset of two or more is tried: its affine min-norm point (KKT system of
    ``min |a W|`` s.t. ``sum a = 1``, regularised by 1e-12) counts when its weights are all
    >= -1e-9. A single point is never nearer than 1 (unit wrenches), the starting value.
    """
    if n == 0:
        return np.inf
    wrench = np.empty((n, 6))
    for k in range(n):
        p = points[members[k]]
        fx, fy, fz = -normals[members[k], 0], -normals[members[k], 1], -normals[members[k], 2]
        ax, ay, az = p[0] - com[0], p[1] - com[1], p[2] - com[2]
        wrench[k, 0] = fx
        wrench[k, 1] = fy
        wrench[k, 2] = fz
        wrench[k, 3] = (ay * fz - az * fy) / torque_scale
        wrench[k, 4] = (az * fx - ax * fz) / torque_scale
        wrench[k, 5] = (ax * fy - ay * fx) / torque_scale
    if min_share > 0.0:
        delta = min_share / n
        total = np.zeros(6)
        for k in range(n):
            total += wrench[k]
        for k in range(n):
            wrench[k] = (1.0 - n * delta) * wrench[k] + delta * total
    best = 1.0
    kkt = np.empty((n + 1, n + 1))
    rhs = np.empty(n + 1)
    chosen = np.empty(n, dtype=np.int64)
    for subset in range(1, 1 << n):
        k = 0
        for i in range(n):
            if subset >> i & 1:
                chosen[k] = i
                k += 1
        if k < 2:
            continue
        for r in range(k):
            for c in range(r, k):
                g = 0.0
                for d in range(6):
                    g += wrench[chosen[r], d] * wrench[chosen[c], d]
                kkt[r, c] = g
                kkt[c, r] = g
            kkt[r, r] += 1e-12
            kkt[r, k] = 1.0
            kkt[k, r] = 1.0
            rhs[r] = 0.0
        kkt[k, k] = 0.0
        rhs[k] = 1.0
        if not _solve_in_place(kkt, rhs, k + 1):
            continue
        feasible = True
        for r in range(k):
            if rhs[r] < -1e-9:
                feasible = False
                break
        if not feasible:
            continue
        norm2 = 0.0
        for d in range(6):
            acc = 0.0
            for r in range(k):
                acc += rhs[r] * wrench[chosen[r], d]
            norm2 += acc * acc
        best = min(best, math.sqrt(norm2))
    return best


# --------------------------------------------------------------------------------------
# batches
# --------------------------------------------------------------------------------------
@_jit
def polygon_batch(points, mask, rtol, atol, out):
    """:func:`_polygon_q` per particle; NaN where fewer than 3 contacts.
    points (P, F, 3), mask (P, F) -> out (P,) (written)."""
    members = np.empty(mask.shape[1], dtype=np.int64)
    for p in range(mask.shape[0]):
        n = _contacts(mask[p], members)
        out[p] = _polygon_q(points[p], members, n, rtol, atol) if n >= 3 else np.nan


@_jit
def antipodal_batch(points, normals, mask, atol, out):
    """:func:`_antipodal` per particle; NaN where not exactly 2 contacts."""
    members = np.empty(mask.shape[1], dtype=np.int64)
    for p in range(mask.shape[0]):
        n = _contacts(mask[p], members)
        out[p] = _antipodal(points[p], normals[p], members[0], members[1], atol) if n == 2 else np.nan


@_jit
def balance_batch(points, mask, com, out):
    """:func:`_balance_residual` per particle."""
    members = np.empty(mask.shape[1], dtype=np.int64)
    for p in range(mask.shape[0]):
        out[p] = _balance_residual(points[p], members, _contacts(mask[p], members), com)


@_jit
def wrench_batch(points, normals, mask, com, torque_scale, min_share, out):
    """:func:`_wrench_residual` per particle."""
    members = np.empty(mask.shape[1], dtype=np.int64)
    for p in range(mask.shape[0]):
        n = _contacts(mask[p], members)
        out[p] = _wrench_residual(points[p], normals[p], members, n, com, torque_scale, min_share)


@_jit
def fitness_terms(points, normals, mask, active, com, torque_scale, min_share, rtol, atol,
                  shape, balance, residual):
    """The fitness's per-particle terms for the active particles (the others get NaN).

    shape : 1 - Q (eq. 8-10) for 3 or more contacts, half the antipodality for 2;
    balance : 1 - the force-balance residual; residual : the wrench-hull distance.
    points, normals (P, F, 3), mask (P, F), active (P,) bool -> shape, balance, residual
    (P,) float (written).
    """
    members = np.empty(mask.shape[1], dtype=np.int64)
    for p in range(mask.shape[0]):
        n = _contacts(mask[p], members)
        if not active[p] or n < 2:
            shape[p] = np.nan
            balance[p] = np.nan
            residual[p] = np.nan
            continue
        if n >= 3:
            shape[p] = 1.0 - _polygon_q(points[p], members, n, rtol, atol)
        else:
            shape[p] = 0.5 * _antipodal(points[p], normals[p], members[0], members[1], atol)
        balance[p] = 1.0 - _balance_residual(points[p], members, n, com)
        residual[p] = _wrench_residual(points[p], normals[p], members, n, com, torque_scale, min_share)
