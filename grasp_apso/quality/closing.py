"""The closing of a grasp: do the fingers' squeezing forces balance, and the squeezed
posture that exerts them (DexGraspBench / BODex: ``q_squeeze = q_grasp + K^-1 J^T f``).

Why: a position servo squeezes the object with a force along each contact's inward normal.
When those forces do not cancel (net force and torque about the centre of mass far from
zero) the object is shoved or rolled while the hand closes until the palm or another link
stops it, and the grasp is judged on that shoved state. A uniform extra flexion of every
closing joint (the former 8 degree squeeze) also moves each fingertip along its curl, not
into the surface, and by an amount that depends on the finger's length: the fingers press
with unequal forces in tangential directions, and spheres roll.

- :func:`closing_forces`: contact force magnitudes (N,) >= a floor that minimise the net
  wrench of the normal forces, their mean fixed; ``imbalance`` is that least net wrench
  relative to the total force. Friction can absorb an imbalance up to about mu.
- :func:`balanced_forces`: contact force *vectors* inside a narrowed friction cone that
  cancel the net wrench where those cones can (to within about 1 %: the tangential parts
  are weighed against it, kept to what the balance needs). The normal forces alone leave
  a net wrench that friction must absorb while the servos press; with the squeeze aiming
  at them the object is shoved and turned in the closing (the Shadow hand's four grasps of
  the mustard bottle on a table, seed 0: the squeeze along the normals turned it 15 and 11
  degrees in two of them, these forces 9 and 8; three of the four held instead of none).
- :func:`squeeze_toward_forces`: the posture whose servo error exerts those forces at the
  pads: ``q + (J^T f) / kp`` (J: numerical Jacobian of each contacting finger's pad point
  over the actuated joints, couplings applied), clipped to the limits.
"""

from __future__ import annotations

import numpy as np

from .bounded_lsq import bounded_lsq

__all__ = ["closing_forces", "balanced_forces", "squeeze_toward_forces"]

#: Force magnitudes may range from FLOOR to CEILING times the mean: a servo presses with
#: some force wherever it touches, and a finger cannot carry the whole grasp alone.
FLOOR, CEILING = 0.3, 3.0
#: :func:`balanced_forces` uses this share of mu (the cone narrowed so that a contact whose
#: force or normal is a little off still sticks), with CONE_EDGES edges, and weighs the
#: tangential parts by TANGENTIAL_WEIGHT against the net wrench (friction only as needed).
CONE_SHARE, CONE_EDGES, TANGENTIAL_WEIGHT = 0.6, 8, 0.2


def closing_forces(points: np.ndarray, normals: np.ndarray, center: np.ndarray, radius: float,
                   mean_force: float = 1.0) -> tuple[np.ndarray, float]:
    """Normal force magnitudes that balance the closing best, and the imbalance left.

    Parameters
    ----------
    points, normals : (N, 3) float, m / unit
        Contacts and the object's OUTWARD normals there (the fingers push along ``-n``).
    center : (3,) float, m
        The object's centre of mass.
    radius : float, m
        Torque scale (the object's characteristic radius): torques / radius are forces.
    mean_force : float, N
        The mean of the magnitudes.

    Returns
    -------
    forces : (N,) float, N, in [FLOOR, CEILING] * mean_force
    imbalance : float
        ``|(net force, net torque / radius)| / sum(forces)``: 0 when the squeeze cancels,
        1 when every finger pushes the same way.
    """
    p = np.asarray(points, float).reshape(-1, 3)
    u = -np.asarray(normals, float).reshape(-1, 3)
    n = len(p)
    if n == 0:
        return np.zeros(0), 1.0
    torque = np.cross(p - np.asarray(center, float), u) / float(radius)
    a = np.vstack([u.T, torque.T])  # (6, N): wrench per unit force
    weight = 1.0  # keeps the mean at mean_force (the trivial all-zero answer is excluded by the floor anyway)
    a_full = np.vstack([a, weight * np.ones((1, n)) / n])
    b = np.zeros(7)
    b[6] = weight * mean_force
    if n == 1:
        f = np.array([mean_force])
    else:
        f = bounded_lsq(a_full, b, FLOOR * mean_force, CEILING * mean_force)
    imbalance = float(np.linalg.norm(a @ f) / max(f.sum(), 1e-12))
    return f, imbalance


def balanced_forces(points: np.ndarray, normals: np.ndarray, center: np.ndarray, radius: float, mu: float,
                    mean_force: float = 1.0) -> tuple[np.ndarray, float]:
    """Contact force vectors, each inside the friction cone narrowed to ``CONE_SHARE * mu``,
    that cancel the net wrench best, the mean of their normal parts near ``mean_force``.

    Parameters
    ----------
    points, normals : (N, 3) float, m / unit
        Contacts and the object's OUTWARD normals there.
    center : (3,) float, m
        The object's centre of mass.
    radius : float, m
        Torque scale (torques / radius are forces).
    mu : float
        Friction coefficient.
    mean_force : float, N
        Mean normal part; each in [FLOOR, CEILING] * mean_force.

    Returns
    -------
    forces : (N, 3) float, N
        The force each finger exerts on the object (into it).
    imbalance : float
        The net wrench left (torques / radius) over the sum of the normal parts: near 0
        (below 0.01) when the narrowed cones can balance the grasp.
    """
    p = np.asarray(points, float).reshape(-1, 3)
    u = -np.asarray(normals, float).reshape(-1, 3)
    n = len(p)
    if n == 0:
        return np.zeros((0, 3)), 1.0
    helper = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(u, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(u, t1)
    angle = 2.0 * np.pi * np.arange(CONE_EDGES) / CONE_EDGES
    tangent = CONE_SHARE * float(mu) * (np.cos(angle)[None, :, None] * t1[:, None, :]
                                        + np.sin(angle)[None, :, None] * t2[:, None, :])  # (N, E, 3)
    edges = u[:, None, :] + tangent
    torque = np.cross((p - np.asarray(center, float))[:, None, :], edges) / float(radius)
    wrench = np.concatenate([edges, torque], axis=2).reshape(n * CONE_EDGES, 6).T  # (6, N E)
    # rows: the net wrench, the tangential part of each contact (weighted), the normals' mean
    tangential = np.zeros((3 * n, n * CONE_EDGES))
    for i in range(n):
        tangential[3 * i:3 * i + 3, i * CONE_EDGES:(i + 1) * CONE_EDGES] = TANGENTIAL_WEIGHT * tangent[i].T
    rows = np.vstack([wrench, tangential, np.ones((1, n * CONE_EDGES)) / n])
    target = np.zeros(rows.shape[0])
    target[-1] = mean_force
    lam = bounded_lsq(rows, target, FLOOR * mean_force / CONE_EDGES, CEILING * mean_force / CONE_EDGES)
    forces = (lam.reshape(n, CONE_EDGES, 1) * edges).sum(axis=1)
    return forces, float(np.linalg.norm(wrench @ lam) / max(lam.sum(), 1e-12))


def squeeze_toward_forces(hand, q: np.ndarray, fingers: np.ndarray, points_root: np.ndarray,
                          normals_root: np.ndarray, forces: np.ndarray, kp: float | np.ndarray,
                          max_torque: float | np.ndarray | None = None, gaps: np.ndarray | None = None,
                          step: float = 1e-4) -> np.ndarray:
    """The squeezed posture: ``q + sum_i [J_i^+ (g_i u_i) + J_i^T f_i / kp]`` within
    the limits, with ``u_i = -n_i`` (into the object) and ``J_i^+ (g u) = J^T u g / |J^T u|^2``
    the least joint motion that moves pad i by its gap ``g_i`` along ``u_i``: a pad that
    already penetrates the exact geometry by 4 mm would otherwise press with the force of
    4 mm of servo error more than the others, and one 4 mm short would touch last.

    Parameters
    ----------
    hand : grasp_apso.model.hands.HandModel
    q : (n,) float, rad or m
        The grasp posture over ``hand.actuated_joints``.
    fingers : (N,) int
        Index in ``hand.fingers`` of each contact's finger (its pad link carries the point).
    points_root, normals_root : (N, 3) float
        Contacts and outward object normals in the hand's root frame.
    forces : (N,) float, N, or (N, 3) float, N
        Magnitudes along ``u_i``, or the force vectors themselves (:func:`balanced_forces`).
    kp : float or (n,) float, N m / rad (N / m for a slide)
        The servos' position gain, or each actuated joint's.
    max_torque : float or (n,) float, N m, optional
        The servos' torque limit, or each actuated joint's: each joint's torque is clipped to it.
    gaps : (N,) float, m, optional
        Each pad's distance to the surface at q (negative: penetrating); 0 when None.
    step : float
        Finite-difference step of the Jacobian (rad or m).
    """
    q = np.asarray(q, float)
    n = q.shape[0]
    batch = np.vstack([q, q + step * np.eye(n)])
    poses = hand.link_transforms_batch(batch)  # (n + 1, L, 4, 4)
    tau = np.zeros(n)
    reach = np.zeros(n)
    normals_root = np.asarray(normals_root, float).reshape(-1, 3)
    forces = np.asarray(forces, float)
    if forces.ndim == 1:
        forces = -forces[:, None] * normals_root
    gaps = np.zeros(len(forces)) if gaps is None else np.asarray(gaps, float)
    for f_index, p, nrm, force, gap in zip(fingers, np.asarray(points_root, float), normals_root, forces, gaps):
        link = hand.link_index(hand.fingers[int(f_index)].pad_link)
        base = poses[0, link]
        local = np.linalg.solve(base, np.append(p, 1.0))  # the point, fixed on its link
        moved = poses[1:, link] @ local  # (n, 4)
        jac = (moved[:, :3] - p) / step  # (n, 3): d point / d q_j
        along = jac @ (-nrm)  # (n,): J^T u
        tau += jac @ force
        norm2 = float(along @ along)
        if norm2 > 1e-12:
            reach += along * (gap / norm2)
    if max_torque is not None:
        limit = np.asarray(max_torque, dtype=float)
        tau = np.clip(tau, -limit, limit)
    return np.clip(q + reach + tau / np.asarray(kp, dtype=float), hand.lower, hand.upper)
