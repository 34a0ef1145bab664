"""The scene check of a general hand's decoding: its collision spheres against the
Scene's planes and obstacles (a compiled loop over particles).

At the grasp (the grasp posture at the root pose) and along the approach (the open
pre-shape at the root pose moved back along the palm normal by
:data:`APPROACH_FRACTIONS` of the approach distance), the least of ``scene distance -
radius - clearance`` over the hand's spheres. A link's bounding sphere, then its groups'
are checked first; only those within :data:`SCENE_CUTOFF` of the clearance are resolved
sphere by sphere (above it the value is a lower bound: the particle is clear anyway).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .any_hand_kernels import _GRC, _GRCEN, _GRR, _GRS, _GS, _GC, _LC, _LR, _NL, _SC, _SR, _point_xyz

__all__ = ["scene_margins", "APPROACH_FRACTIONS"]

#: Where along the approach the open hand is checked (0 = at the grasp pose).
APPROACH_FRACTIONS = (0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0)
#: Margins above this (m, past the clearance) are lower bounds (culled): legality needs
#: only the sign, the fitness's guide only the depth inside the clearance.
SCENE_CUTOFF = 0.0

_jit = numba.njit(cache=True, nogil=True)
#: Helpers that take the kinematic and scene tuples are inlined (see any_hand_kernels._inline).
_inline = numba.njit(cache=True, nogil=True, inline="always")


@_inline
def _scene_distance(c, S):
    """Least signed distance (m) of point c (3,) to the scene's solids (as
    Scene.signed_distance); ``S`` the arrays of :func:`packed_scene`."""
    planes, box_inv, box_half, sphere_center, sphere_radius, cyl_inv, cyl_radius, cyl_half = S
    best = np.inf
    for k in range(planes.shape[0]):
        best = min(best, planes[k, 0] * c[0] + planes[k, 1] * c[1] + planes[k, 2] * c[2] + planes[k, 3])
    for k in range(box_inv.shape[0]):
        out2, inside = 0.0, -np.inf
        for i in range(3):
            v = box_inv[k, i, 0] * c[0] + box_inv[k, i, 1] * c[1] + box_inv[k, i, 2] * c[2] + box_inv[k, i, 3]
            q = abs(v) - box_half[k, i]
            out2 += max(q, 0.0) ** 2
            inside = max(inside, q)
        best = min(best, math.sqrt(out2) + min(inside, 0.0))
    for k in range(sphere_center.shape[0]):
        d = math.sqrt((c[0] - sphere_center[k, 0]) ** 2 + (c[1] - sphere_center[k, 1]) ** 2
                      + (c[2] - sphere_center[k, 2]) ** 2)
        best = min(best, d - sphere_radius[k])
    for k in range(cyl_inv.shape[0]):
        v0 = cyl_inv[k, 0, 0] * c[0] + cyl_inv[k, 0, 1] * c[1] + cyl_inv[k, 0, 2] * c[2] + cyl_inv[k, 0, 3]
        v1 = cyl_inv[k, 1, 0] * c[0] + cyl_inv[k, 1, 1] * c[1] + cyl_inv[k, 1, 2] * c[2] + cyl_inv[k, 1, 3]
        v2 = cyl_inv[k, 2, 0] * c[0] + cyl_inv[k, 2, 1] * c[1] + cyl_inv[k, 2, 2] * c[2] + cyl_inv[k, 2, 3]
        radial = math.sqrt(v0 ** 2 + v1 ** 2) - cyl_radius[k]
        axial = abs(v2) - cyl_half[k]
        best = min(best, math.sqrt(max(radial, 0.0) ** 2 + max(axial, 0.0) ** 2) + min(max(radial, axial), 0.0))
    return best


@_inline
def _groups_margin(rot, trans, pose, g0, g1, K, S, cutoff, c):
    # The tables bound once: each read of a tuple's item in a loop costs a reference count.
    grc, grr, grs, grn, sc, sr = K[_GRCEN], K[_GRR], K[_GRS], K[_GRC], K[_SC], K[_SR]
    best = np.inf
    for g in range(g0, g1):
        _point_xyz(rot, trans, pose, grc[g, 0], grc[g, 1], grc[g, 2], c)
        d = _scene_distance(c, S) - grr[g]
        if d > cutoff:
            best = min(best, d)
            continue
        for s in range(grs[g], grs[g] + grn[g]):
            _point_xyz(rot, trans, pose, sc[s, 0], sc[s, 1], sc[s, 2], c)
            best = min(best, _scene_distance(c, S) - sr[s])
    return best


@_inline
def _hand_margin(rot, trans, poses, K, palm_bound, palm_groups, palm_pose, S, cutoff, c, eye):
    """Least distance - radius (m) of the hand's spheres (finger links posed (F, Lmax, 4, 4));
    ``eye`` the (4, 4) identity (the palm's bound is in the root frame)."""
    best = np.inf
    n_links, lr, lc, gs, gc = K[_NL], K[_LR], K[_LC], K[_GS], K[_GC]
    for f in range(n_links.shape[0]):
        for l in range(n_links[f]):
            if lr[f, l] < 0.0:
                continue
            pose = poses[f, l]
            _point_xyz(rot, trans, pose, lc[f, l, 0], lc[f, l, 1], lc[f, l, 2], c)
            d = _scene_distance(c, S) - lr[f, l]
            if d > cutoff:
                best = min(best, d)
                continue
            g0 = gs[f, l]
            best = min(best, _groups_margin(rot, trans, pose, g0, g0 + gc[f, l], K, S, cutoff, c))
    if palm_bound[3] >= 0.0:
        _point_xyz(rot, trans, eye, palm_bound[0], palm_bound[1], palm_bound[2], c)
        d = _scene_distance(c, S) - palm_bound[3]
        if d > cutoff:
            return min(best, d)
        for i in range(palm_groups.shape[0]):
            g = palm_groups[i]
            best = min(best, _groups_margin(rot, trans, palm_pose[i], g, g + 1, K, S, cutoff, c))
    return best


@_jit
def scene_clearances(rot, trans, approach, backs, grasp_poses, open_poses, K, palm_bound, palm_groups, palm_pose,
                     S, cutoff, out):
    """Least margin (m, before the clearance) per particle (P,): the grasp posture at the
    root, then the open pre-shape moved back by each of ``backs`` (m) along ``approach`` (P, 3)."""
    c = np.empty(3)
    t = np.empty(3)
    eye = np.eye(4)
    for p in range(rot.shape[0]):
        r = rot[p]
        best = _hand_margin(r, trans[p], grasp_poses[p], K, palm_bound, palm_groups, palm_pose, S, cutoff, c, eye)
        for k in range(backs.shape[0]):
            for i in range(3):
                t[i] = trans[p, i] - backs[k] * approach[p, i]
            best = min(best, _hand_margin(r, t, open_poses[p], K, palm_bound, palm_groups, palm_pose, S,
                                          cutoff, c, eye))
        out[p] = best


def packed_scene(scene) -> tuple:
    """The scene's arrays in the order the kernels take them."""
    p = scene.packed()
    return tuple(np.ascontiguousarray(p[k], dtype=np.float64) for k in (
        "planes", "box_inv", "box_half", "sphere_center", "sphere_radius", "cyl_inv", "cyl_radius", "cyl_half_height"))


def scene_margins(model, root: np.ndarray, grasp_poses: np.ndarray, open_poses: np.ndarray) -> np.ndarray:
    """Least ``distance - radius - clearance`` (m) of the hand to the scene, per particle (P,).

    root : (P, 4, 4) object frame; grasp_poses, open_poses : (P, F, Lmax, 4, 4) the finger
    links in the root frame at the grasp posture and the pre-shape.
    """
    t = model.tables
    rot, trans = np.ascontiguousarray(root[:, :3, :3]), np.ascontiguousarray(root[:, :3, 3])
    approach = np.ascontiguousarray(rot @ t.basis[:, 2])
    backs = np.array(APPROACH_FRACTIONS) * model.approach_distance
    out = np.empty(len(root))
    clearance = model.scene_clearance
    scene_clearances(rot, trans, approach, backs, grasp_poses, open_poses, model.kin, t.palm_bound, t.palm_groups,
                     t.palm_pose, model.scene_arrays, clearance + SCENE_CUTOFF, out)
    return out - clearance
