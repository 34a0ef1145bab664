"""Compiled inner loops of the general hand's decoding (numba, cached on disk, GIL released).

Batched over particles and fingers, for arbitrary chains, from the flat tables of
:mod:`.any_hand_tables` (passed as the tuple :func:`kin`): forward kinematics of a
finger's links (revolute and prismatic motions, couplings through ``full = A q + b``),
the clearance of its collision spheres from the object's signed-distance grid (groups of
spheres whose bounding sphere is farther than ``cutoff`` are skipped: their clearance is
then a lower bound above ``cutoff``), the closing sweep (GraspIt!'s auto-grasp: a coarse
sweep of the common closing parameter ``s`` then bisection), the overlap of spheres of
different fingers and the palm's clearance.

Conventions as :mod:`grasp_apso.geometry.kernels`: float64 C-contiguous arrays, inputs
validated by the caller, outputs written in place.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..model.hands.fk_kernel import apply_motion
from . import kernels as _kernels

_jit = numba.njit(cache=True, nogil=True)
#: Helpers that take the kinematic tuple are inlined into their callers: a call passing the
#: tuple's 30 arrays costs their reference counting, more than the helper's arithmetic.
_inline = numba.njit(cache=True, nogil=True, inline="always")
#: The grid's trilinear look-up (:func:`.kernels._grid_value`) inlined here: a compiled
#: call passing the grid array costs its reference counting, about as much as the look-up.
_grid_value = _inline(_kernels._grid_value.py_func)
#: The grid's unit gradient (:func:`.kernels._unit_gradient`, inlined there too).
_unit_gradient = _kernels._unit_gradient


@_inline
def _grid_distance(values, ox, oy, oz, inv, spacing, x, y, z):
    """:func:`.kernels._grid_distance`, inlined."""
    value, outside = _grid_value(values, ox, oy, oz, inv, spacing, x, y, z)
    return value + outside

# indices into the kinematic tuple (see kin())
_AS, _AC, _AV, _B, _NL, _PAR, _PRE, _MS, _MC, _MK, _MAX, _MAN, _MI, _MR = range(14)
_GS, _GC, _GRS, _GRC, _GRCEN, _GRR, _SC, _SR, _PADL, _PADC, _PADR, _JC, _JI, _JT, _LC, _LR, _MOV, _PADS, _PADB = range(14, 33)


def kin(t) -> tuple:
    """The kinematic tuple the kernels take, from a :class:`.any_hand_tables.HandTables`.

    The coupling matrix ``full_a`` (m, n) goes in by rows of its non-zero entries (row k's
    are ``a_val[a_start[k]:a_start[k + 1]]`` at columns ``a_col``, in column order): a full
    joint follows one or two actuated joints, and the forward kinematics sums only those
    (the same sum as the whole row: the zeros add nothing)."""
    a = np.asarray(t.full_a, dtype=np.float64)
    rows, cols = np.nonzero(a)  # row-major: each row's columns ascending
    a_start = np.concatenate([[0], np.cumsum(np.count_nonzero(a, axis=1))]).astype(np.int64)
    return (a_start, np.ascontiguousarray(cols, dtype=np.int64), np.ascontiguousarray(a[rows, cols]),
            t.full_b, t.n_links, t.parent, t.pre, t.m_start, t.m_count, t.m_kind, t.m_axis,
            t.m_anchor, t.m_index, t.m_ref, t.g_start, t.g_count, t.grp_start, t.grp_count, t.grp_center,
            t.grp_radius, t.sph_center, t.sph_radius, t.pad_local, t.pad_center, t.pad_radius, t.j_count,
            t.j_index, t.j_target, t.lnk_center, t.lnk_radius, t.moving, t.pad_slack, t.pad_body)


@_inline
def finger_poses(q, f, K, poses, tmp, local, moving_only=False):
    """Poses (root frame) of finger ``f``'s links at actuated positions q (n,) -> poses (Lmax, 4, 4).

    Written out on the tables' elements (no array views: a view per element costs more
    than the arithmetic): each link's constant pose composed onto its parent's, then each
    joint motion (revolute about an axis through an anchor, prismatic along an axis)
    composed onto it. ``moving_only``: only the links the finger's closing moves (the
    closing sweep: the others, and so their poses, stay as the last call at the sweep's
    pre-shape left them). ``tmp`` and ``local`` are unused (kept for the callers)."""
    full_b, pre, parent, mov = K[_B], K[_PRE], K[_PAR], K[_MOV]
    a_start, a_col, a_val = K[_AS], K[_AC], K[_AV]
    m_start, m_count, m_kind, m_axis, m_anchor, m_index, m_ref = K[_MS], K[_MC], K[_MK], K[_MAX], K[_MAN], K[_MI], K[_MR]
    for l in range(K[_NL][f]):
        if moving_only and mov[f, l] == 0:
            continue
        pl = parent[f, l]
        if pl < 0:
            for i in range(4):
                for j in range(4):
                    poses[l, i, j] = pre[f, l, i, j]
        else:
            for i in range(3):
                a0, a1, a2, a3 = poses[pl, i, 0], poses[pl, i, 1], poses[pl, i, 2], poses[pl, i, 3]
                for j in range(4):
                    v = a0 * pre[f, l, 0, j] + a1 * pre[f, l, 1, j] + a2 * pre[f, l, 2, j]
                    if j == 3:
                        v += a3
                    poses[l, i, j] = v
            poses[l, 3, 0] = 0.0
            poses[l, 3, 1] = 0.0
            poses[l, 3, 2] = 0.0
            poses[l, 3, 3] = 1.0
        start = m_start[f, l]
        for m in range(start, start + m_count[f, l]):
            k = m_index[m]
            value = full_b[k] - m_ref[m]
            for e in range(a_start[k], a_start[k + 1]):
                value += a_val[e] * q[a_col[e]]
            apply_motion(poses, l, m_kind[m], m_axis[m, 0], m_axis[m, 1], m_axis[m, 2], m_anchor[m, 0],
                         m_anchor[m, 1], m_anchor[m, 2], value)


@_inline
def _point(rot, trans, pose, p, out):
    """out = rot @ (pose @ p) + trans (object frame)."""
    _point_xyz(rot, trans, pose, p[0], p[1], p[2], out)


@_inline
def _point_xyz(rot, trans, pose, px, py, pz, out):
    """:func:`_point` of the point (px, py, pz): callers pass a table's elements, not a view of its row."""
    for i in range(3):
        out[i] = pose[i, 0] * px + pose[i, 1] * py + pose[i, 2] * pz + pose[i, 3]
    x, y, z = out[0], out[1], out[2]
    for i in range(3):
        out[i] = rot[i, 0] * x + rot[i, 1] * y + rot[i, 2] * z + trans[i]


@_inline
def _point_at(rot, trans, poses, l, px, py, pz, out):
    """:func:`_point_xyz` with the pose ``poses[l]`` read in place (no view of it)."""
    for i in range(3):
        out[i] = poses[l, i, 0] * px + poses[l, i, 1] * py + poses[l, i, 2] * pz + poses[l, i, 3]
    x, y, z = out[0], out[1], out[2]
    for i in range(3):
        out[i] = rot[i, 0] * x + rot[i, 1] * y + rot[i, 2] * z + trans[i]


@_inline
def _groups_clearance(values, origin, spacing, rot, trans, poses, l, g0, g1, K, cutoff, c, first_touch=False):
    """Least clearance (sdf - radius, m) of the spheres of groups g0..g1-1 of a link at
    ``poses[l]``; ``first_touch``: returns at the first sphere at or below 0 (only the sign is
    wanted: the closing sweep)."""
    ox, oy, oz = origin[0], origin[1], origin[2]
    inv = 1.0 / spacing
    # The tables bound once: each read of a tuple's item in a loop costs a reference count.
    grc, sc, grr, grs, grn, sr = K[_GRCEN], K[_SC], K[_GRR], K[_GRS], K[_GRC], K[_SR]
    best = np.inf
    for g in range(g0, g1):
        _point_at(rot, trans, poses, l, grc[g, 0], grc[g, 1], grc[g, 2], c)
        d = _grid_distance(values, ox, oy, oz, inv, spacing, c[0], c[1], c[2]) - grr[g]
        if d > cutoff:
            best = min(best, d)
            continue
        s0 = grs[g]
        for s in range(s0, s0 + grn[g]):
            _point_at(rot, trans, poses, l, sc[s, 0], sc[s, 1], sc[s, 2], c)
            d = _grid_distance(values, ox, oy, oz, inv, spacing, c[0], c[1], c[2]) - sr[s]
            best = min(best, d)
            if first_touch and best <= 0.0:
                return best
    return best


@_inline
def _finger_clearance(values, origin, spacing, rot, trans, poses, f, K, cutoff, link_out, c, moving_only=False):
    """Least clearance over finger f's links (posed), per link into link_out (Lmax,);
    ``moving_only``: only the links the closing moves (the others keep link_out)."""
    best = np.inf
    ox, oy, oz = origin[0], origin[1], origin[2]
    inv = 1.0 / spacing
    mov, lr, lc, gs, gc, padb = K[_MOV], K[_LR], K[_LC], K[_GS], K[_GC], K[_PADB]
    for l in range(K[_NL][f]):
        if moving_only and mov[f, l] == 0:
            continue
        if lr[f, l] < 0.0:
            link_out[l] = np.inf
            continue
        _point_at(rot, trans, poses, l, lc[f, l, 0], lc[f, l, 1], lc[f, l, 2], c)
        d = _grid_distance(values, ox, oy, oz, inv, spacing, c[0], c[1], c[2]) - lr[f, l]
        if d > cutoff:
            link_out[l] = d
            best = min(best, d)
            continue
        g0 = gs[f, l]
        d = _groups_clearance(values, origin, spacing, rot, trans, poses, l, g0, g0 + gc[f, l], K, cutoff, c,
                              moving_only and padb[f, l] == 0)
        if padb[f, l]:
            # The pad link's cover (and that of links fixed to it: one body) may enter by
            # its stray (it lies outside the exact surface); the pad sphere (the exact
            # surface at the pad) may not.
            d = min(d + K[_PADS][f], _pad(values, origin, spacing, rot, trans, poses, f, K, c))
        link_out[l] = d
        best = min(best, d)
        if moving_only and best <= 0.0:  # the sweep needs only the first touch
            return best
    return best


@_inline
def _set_closing(q, q0, f, K, s):
    jt, ji = K[_JT], K[_JI]
    for k in range(K[_JC][f]):
        target = jt[f, k]
        if not math.isnan(target):
            j = ji[f, k]
            q[j] = q0[j] + s * (target - q0[j])


@_inline
def _pad(values, origin, spacing, rot, trans, poses, f, K, pad_pos):
    """Pad sphere's centre (object frame) into pad_pos (3,); returns its clearance (sdf -
    pad radius, m): 0 when the pad touches the surface."""
    _point_at(rot, trans, poses, K[_PADL][f], K[_PADC][f, 0], K[_PADC][f, 1], K[_PADC][f, 2], pad_pos)
    return _grid_distance(values, origin[0], origin[1], origin[2], 1.0 / spacing, spacing,
                          pad_pos[0], pad_pos[1], pad_pos[2]) - K[_PADR][f]


@_inline
def _facing(values, origin, spacing, point, centre):
    """Cosine between a pad's normal (its sphere's ``centre`` (3,) to its pad ``point``
    (3,)) and the inward surface normal at the centre (the grid's unit gradient,
    normalised once more as unit vectors are): 1 when the pad point faces the surface, 0
    when the fingertip touches with its side."""
    nx, ny, nz = point[0] - centre[0], point[1] - centre[1], point[2] - centre[2]
    norm = max(math.sqrt(nx * nx + ny * ny + nz * nz), 1e-12)
    nx, ny, nz = nx / norm, ny / norm, nz / norm
    gx, gy, gz = _unit_gradient(values, origin[0], origin[1], origin[2], 1.0 / spacing, spacing, centre[0],
                                centre[1], centre[2])
    norm = max(math.sqrt(gx * gx + gy * gy + gz * gz), 1e-12)
    return -(nx * (gx / norm) + ny * (gy / norm) + nz * (gz / norm))


@_jit
def pad_facings(values, origin, spacing, points, centres, out):
    """:func:`_facing` of pads given by their points and sphere centres (N, 3) -> out (N,)."""
    for n in range(points.shape[0]):
        out[n] = _facing(values, origin, spacing, points[n], centres[n])


@_jit
def close_fingers(values, origin, spacing, rot, trans, q0, K, coarse, refine, cutoff, pad_point,
                  q_out, s_out, start_clear, stopped, link_clear, pad_pos, pad_gap, pads, facing, pad_dist,
                  open_clear, open_pad, open_gap):
    """Close every finger of every particle from its pre-shape q0 (P, n).

    Each joint of finger f with a closing limit moves ``q0 + s (limit - q0)``; ``s`` is the
    first sample of ``coarse`` steps at which a sphere of the finger meets the surface
    (clearance <= 0; these steps cull at 0: only the sign matters), refined by ``refine`` bisections to the last free ``s`` (1 when nothing
    is met). Writes q_out (P, n) closed, s_out (P, F), start_clear (P, F) the finger's
    clearance at its pre-shape, stopped (P, F) bool something met, link_clear (P, F, Lmax)
    per link at the stop, pad_pos (P, F, 3) and pad_gap (P, F) the pad's clearance; and
    at the closed posture q_out, pads (P, F, 3) the pad points (``pad_point`` (F, 3) on
    the pad links) in the object frame, facing (P, F) each pad's :func:`_facing` at its
    sphere's centre pad_pos, pad_dist (P, F) the signed distance at the pad point; and at
    the pre-shape q0 (where a finger that makes no contact goes back to), open_clear (P, F,
    Lmax) per link, open_pad (P, F, 3) and open_gap (P, F) as link_clear, pad_pos and
    pad_gap (what :func:`finger_clearances` computes there).
    """
    n_p, n_f, lmax = q0.shape[0], K[_NL].shape[0], link_clear.shape[2]
    n_links, mov, jc, ji = K[_NL], K[_MOV], K[_JC], K[_JI]
    poses = np.empty((lmax, 4, 4))
    tmp = np.empty((4, 4))
    local = np.empty((4, 4))
    lc = np.empty(lmax)
    c = np.empty(3)
    q = np.empty(q0.shape[1])
    qp = np.empty(q0.shape[1])  # the particle's pre-shape (a copy: a row view per use costs more)
    used = np.empty((n_f, ji.shape[1]))  # each finger's joint values at its closing
    for p in range(n_p):
        r, t = rot[p], trans[p]
        for j in range(q0.shape[1]):
            q_out[p, j] = q0[p, j]
            qp[j] = q0[p, j]
        for f in range(n_f):
            for j in range(q0.shape[1]):
                q[j] = qp[j]
            finger_poses(q, f, K, poses, tmp, local)
            c0 = _finger_clearance(values, origin, spacing, r, t, poses, f, K, cutoff, open_clear[p, f], c)
            open_gap[p, f] = _pad(values, origin, spacing, r, t, poses, f, K, open_pad[p, f])
            start_clear[p, f] = c0
            fixed = np.inf  # the links the closing does not move keep their clearance
            for l in range(n_links[f]):
                if mov[f, l] == 0:
                    fixed = min(fixed, open_clear[p, f, l])
            s = 0.0
            posed = 0.0  # the closing parameter the moving links' poses are at
            met = c0 <= 0.0
            if not met:
                lo, hi = 0.0, -1.0
                for k in range(1, coarse + 1):
                    sk = k / coarse
                    _set_closing(q, qp, f, K, sk)
                    finger_poses(q, f, K, poses, tmp, local, True)
                    posed = sk
                    if min(fixed, _finger_clearance(values, origin, spacing, r, t, poses, f, K, 0.0, lc, c,
                                                    True)) <= 0.0:
                        hi = sk
                        break
                    lo = sk
                if hi < 0.0:
                    s = 1.0
                else:
                    met = True
                    for _ in range(refine):
                        mid = 0.5 * (lo + hi)
                        _set_closing(q, qp, f, K, mid)
                        finger_poses(q, f, K, poses, tmp, local, True)
                        posed = mid
                        if min(fixed, _finger_clearance(values, origin, spacing, r, t, poses, f, K, 0.0, lc,
                                                        c, True)) <= 0.0:
                            hi = mid
                        else:
                            lo = mid
                    s = lo
            _set_closing(q, qp, f, K, s)
            if posed != s:  # (the sweep's last step already posed the links at s: the same poses)
                finger_poses(q, f, K, poses, tmp, local, True)
            _finger_clearance(values, origin, spacing, r, t, poses, f, K, cutoff, link_clear[p, f], c)
            pad_gap[p, f] = _pad(values, origin, spacing, r, t, poses, f, K, pad_pos[p, f])
            _point_at(r, t, poses, K[_PADL][f], pad_point[f, 0], pad_point[f, 1], pad_point[f, 2], pads[p, f])
            s_out[p, f] = s
            stopped[p, f] = met
            for k in range(jc[f]):
                j = ji[f, k]
                q_out[p, j] = q[j]
                used[f, k] = q[j]
        ox, oy, oz, inv = origin[0], origin[1], origin[2], 1.0 / spacing
        for f in range(n_f):
            # A joint another finger closes too (one closing several fingers) ends where the
            # last of them left it: the pad point at the closed posture then moves with it.
            for k in range(jc[f]):
                if q_out[p, ji[f, k]] != used[f, k]:
                    for j in range(q0.shape[1]):
                        q[j] = q_out[p, j]
                    finger_poses(q, f, K, poses, tmp, local)
                    _point_at(r, t, poses, K[_PADL][f], pad_point[f, 0], pad_point[f, 1], pad_point[f, 2],
                              pads[p, f])
                    break
            facing[p, f] = _facing(values, origin, spacing, pads[p, f], pad_pos[p, f])
            pad_dist[p, f] = _grid_distance(values, ox, oy, oz, inv, spacing, pads[p, f, 0], pads[p, f, 1],
                                            pads[p, f, 2])


@_jit
def finger_clearances(values, origin, spacing, rot, trans, q, rows, K, cutoff, link_clear, pad_pos, pad_gap):
    """Per-link clearance and pad of the finger rows (R, 2: particle, finger) at postures
    q (P, n): link_clear (P, F, Lmax), pad_pos (P, F, 3), pad_gap (P, F) written for them."""
    lmax = link_clear.shape[2]
    poses = np.empty((lmax, 4, 4))
    tmp = np.empty((4, 4))
    local = np.empty((4, 4))
    c = np.empty(3)
    qp = np.empty(q.shape[1])
    for i in range(rows.shape[0]):
        p, f = rows[i, 0], rows[i, 1]
        for j in range(q.shape[1]):
            qp[j] = q[p, j]
        finger_poses(qp, f, K, poses, tmp, local)
        _finger_clearance(values, origin, spacing, rot[p], trans[p], poses, f, K, cutoff, link_clear[p, f], c)
        pad_gap[p, f] = _pad(values, origin, spacing, rot[p], trans[p], poses, f, K, pad_pos[p, f])


@_jit
def link_poses(q, K, out):
    """Every finger link's pose in the root frame: q (P, n) -> out (P, F, Lmax, 4, 4)."""
    tmp = np.empty((4, 4))
    local = np.empty((4, 4))
    qp = np.empty(q.shape[1])
    for p in range(q.shape[0]):
        for j in range(q.shape[1]):
            qp[j] = q[p, j]
        for f in range(K[_NL].shape[0]):
            finger_poses(qp, f, K, out[p, f], tmp, local)


@_inline
def _posed(poses, p, f, l, x, y, z):
    """The point (x, y, z) of link l of finger f placed by ``poses[p, f, l]``: a tuple."""
    return (poses[p, f, l, 0, 0] * x + poses[p, f, l, 0, 1] * y + poses[p, f, l, 0, 2] * z + poses[p, f, l, 0, 3],
            poses[p, f, l, 1, 0] * x + poses[p, f, l, 1, 1] * y + poses[p, f, l, 1, 2] * z + poses[p, f, l, 1, 3],
            poses[p, f, l, 2, 0] * x + poses[p, f, l, 2, 1] * y + poses[p, f, l, 2, 2] * z + poses[p, f, l, 2, 3])


@_inline
def _apart(a, b, limit):
    """True when the points a and b (tuples) are at least ``limit`` apart."""
    return math.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2) >= limit


@_jit
def finger_overlaps(poses, pairs, K, allowed, out):
    """Fingers whose spheres overlap another finger's by more than ``allowed`` (m).

    poses (P, F, Lmax, 4, 4) root frame; pairs (K, 4) f1, l1, f2, l2; out (P, F) bool.
    Link bounding spheres, then group bounding spheres, then the spheres of two groups.
    """
    lc, lr, gs, gc, grc, grr = K[_LC], K[_LR], K[_GS], K[_GC], K[_GRCEN], K[_GRR]
    grs, grn, sc, sr = K[_GRS], K[_GRC], K[_SC], K[_SR]
    for p in range(poses.shape[0]):
        for f in range(out.shape[1]):
            out[p, f] = False
        for k in range(pairs.shape[0]):
            f1, l1, f2, l2 = pairs[k, 0], pairs[k, 1], pairs[k, 2], pairs[k, 3]
            if out[p, f1] and out[p, f2]:
                continue
            a = _posed(poses, p, f1, l1, lc[f1, l1, 0], lc[f1, l1, 1], lc[f1, l1, 2])
            b = _posed(poses, p, f2, l2, lc[f2, l2, 0], lc[f2, l2, 1], lc[f2, l2, 2])
            if _apart(a, b, lr[f1, l1] + lr[f2, l2] - allowed):
                continue
            hit = False
            for g1 in range(gs[f1, l1], gs[f1, l1] + gc[f1, l1]):
                a = _posed(poses, p, f1, l1, grc[g1, 0], grc[g1, 1], grc[g1, 2])
                for g2 in range(gs[f2, l2], gs[f2, l2] + gc[f2, l2]):
                    b = _posed(poses, p, f2, l2, grc[g2, 0], grc[g2, 1], grc[g2, 2])
                    if _apart(a, b, grr[g1] + grr[g2] - allowed):
                        continue
                    for s1 in range(grs[g1], grs[g1] + grn[g1]):
                        u = _posed(poses, p, f1, l1, sc[s1, 0], sc[s1, 1], sc[s1, 2])
                        for s2 in range(grs[g2], grs[g2] + grn[g2]):
                            v = _posed(poses, p, f2, l2, sc[s2, 0], sc[s2, 1], sc[s2, 2])
                            if not _apart(u, v, sr[s1] + sr[s2] - allowed):
                                hit = True
                                break
                        if hit:
                            break
                    if hit:
                        break
                if hit:
                    break
            if hit:
                out[p, f1] = True
                out[p, f2] = True


@_inline
def _palm(values, origin, spacing, rot, trans, groups, group_pose, palm_bound, K, cutoff, c):
    """Least clearance (m) of the palm's sphere groups with the root at rot, trans: its
    bounding sphere ``palm_bound`` (4,) first (returned when beyond ``cutoff``); then each
    group whose bound is below ``cutoff`` and the least clearance found so far."""
    if palm_bound[3] >= 0.0:
        for i in range(3):
            c[i] = rot[i, 0] * palm_bound[0] + rot[i, 1] * palm_bound[1] + rot[i, 2] * palm_bound[2] + trans[i]
        d = _grid_distance(values, origin[0], origin[1], origin[2], 1.0 / spacing, spacing, c[0], c[1], c[2]) \
            - palm_bound[3]
        if d > cutoff:
            return d
    best = np.inf
    for i in range(groups.shape[0]):
        g = groups[i]
        best = min(best, _groups_clearance(values, origin, spacing, rot, trans, group_pose, i, g, g + 1, K,
                                           min(cutoff, best), c))
    return best


@_jit
def palm_clearance(values, origin, spacing, rot, trans, groups, group_pose, palm_bound, K, cutoff, out):
    """Least clearance (m) of the palm's sphere groups (root-frame poses (Gp, 4, 4)) per
    particle (P,): exact when at most ``cutoff``, else a lower bound above it."""
    c = np.empty(3)
    for p in range(rot.shape[0]):
        out[p] = _palm(values, origin, spacing, rot[p], trans[p], groups, group_pose, palm_bound, K, cutoff, c)


@_inline
def _finger_bound(poses, f, K, out):
    """A sphere (root frame) enclosing the bounding spheres of finger f's links posed at
    ``poses`` (Lmax, 4, 4): its centre the middle of their centres' box, into out (4,):
    centre, radius. False when no link of the finger has collision geometry."""
    lc, lr = K[_LC], K[_LR]
    lo0 = lo1 = lo2 = np.inf
    hi0 = hi1 = hi2 = -np.inf
    found = False
    for l in range(K[_NL][f]):
        if lr[f, l] < 0.0:
            continue
        found = True
        x, y, z = lc[f, l, 0], lc[f, l, 1], lc[f, l, 2]
        px = poses[l, 0, 0] * x + poses[l, 0, 1] * y + poses[l, 0, 2] * z + poses[l, 0, 3]
        py = poses[l, 1, 0] * x + poses[l, 1, 1] * y + poses[l, 1, 2] * z + poses[l, 1, 3]
        pz = poses[l, 2, 0] * x + poses[l, 2, 1] * y + poses[l, 2, 2] * z + poses[l, 2, 3]
        lo0, lo1, lo2 = min(lo0, px), min(lo1, py), min(lo2, pz)
        hi0, hi1, hi2 = max(hi0, px), max(hi1, py), max(hi2, pz)
    if not found:
        return False
    out[0], out[1], out[2] = 0.5 * (lo0 + hi0), 0.5 * (lo1 + hi1), 0.5 * (lo2 + hi2)
    radius = 0.0
    for l in range(K[_NL][f]):
        if lr[f, l] < 0.0:
            continue
        x, y, z = lc[f, l, 0], lc[f, l, 1], lc[f, l, 2]
        px = poses[l, 0, 0] * x + poses[l, 0, 1] * y + poses[l, 0, 2] * z + poses[l, 0, 3] - out[0]
        py = poses[l, 1, 0] * x + poses[l, 1, 1] * y + poses[l, 1, 2] * z + poses[l, 1, 3] - out[1]
        pz = poses[l, 2, 0] * x + poses[l, 2, 1] * y + poses[l, 2, 2] * z + poses[l, 2, 3] - out[2]
        radius = max(radius, math.sqrt(px * px + py * py + pz * pz) + lr[f, l])
    out[3] = radius
    return True


@_jit
def approach_clearance(values, origin, spacing, rot, trans, approach, backs, q, groups, group_pose, palm_bound, K,
                       cutoff, out):
    """Least clearance (m) of the open hand at q (P, n), root at rot (P, 3, 3), trans (P, 3),
    moved back along ``approach`` (P, 3) by each of ``backs`` (S,) m: its finger links'
    and palm's spheres, per particle into out (P,).

    Each finger posed once for all the retreats; a finger's, link's, group's or the palm's
    bounding sphere farther than the least clearance found so far (or than ``cutoff``) is
    not looked into: the least clearance is exact when at most ``cutoff``, a lower bound
    above it (as :func:`finger_clearances` and :func:`palm_clearance`). The finger's
    bounding sphere (:func:`_finger_bound`, posed once) is read less two grid spacings: it
    encloses its links' bounding spheres, and the grid's trilinear value is within
    sqrt(3)/2 spacings of the distance it samples at both centres, so a finger it skips has
    every link's bound beyond the cut too: the result below the cut is the links' bounds'."""
    n_f, lmax = K[_NL].shape[0], K[_LR].shape[1]
    n_b = backs.shape[0]
    poses = np.empty((lmax, 4, 4))
    tmp = np.empty((4, 4))
    local = np.empty((4, 4))
    lc = np.empty(lmax)
    c = np.empty(3)
    bound = np.empty(4)
    moved = np.empty((n_b, 3))
    qp = np.empty(q.shape[1])
    inv = 1.0 / spacing
    for p in range(rot.shape[0]):
        r = rot[p]
        for j in range(q.shape[1]):
            qp[j] = q[p, j]
        for b in range(n_b):
            for i in range(3):
                moved[b, i] = trans[p, i] - backs[b] * approach[p, i]
        best = np.inf
        for f in range(n_f):
            finger_poses(qp, f, K, poses, tmp, local)
            if not _finger_bound(poses, f, K, bound):
                continue  # no collision geometry on the finger
            for b in range(n_b):
                for i in range(3):
                    c[i] = r[i, 0] * bound[0] + r[i, 1] * bound[1] + r[i, 2] * bound[2] + moved[b, i]
                d = _grid_distance(values, origin[0], origin[1], origin[2], inv, spacing, c[0], c[1], c[2]) \
                    - bound[3] - 2.0 * spacing
                if d > min(cutoff, best):
                    best = min(best, d)
                    continue
                best = min(best, _finger_clearance(values, origin, spacing, r, moved[b], poses, f, K,
                                                   min(cutoff, best), lc, c))
        for b in range(n_b):
            best = min(best, _palm(values, origin, spacing, r, moved[b], groups, group_pose, palm_bound, K,
                                   min(cutoff, best), c))
        out[p] = best
