"""The forward kinematics of a whole hand, compiled: every link's pose in the root frame.

:meth:`.model.HandModel.link_transforms_batch` walks the tree link by link; done in numpy
that costs a few hundred microseconds per posture (a dozen small array operations per
link and motion), and the python-fcl verification of a general hand's candidates poses the
hand a hundred times and more per plan. Here the tree is flattened once per hand
(:class:`FlatTree`) and walked in one compiled loop (numba, cached on disk, GIL released).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["FlatTree", "flat_tree", "link_poses", "apply_motion", "REVOLUTE", "PRISMATIC"]

_jit = numba.njit(cache=True, nogil=True)
_inline = numba.njit(cache=True, nogil=True, inline="always")
#: Motion kinds in :attr:`FlatTree.kind`.
REVOLUTE, PRISMATIC = 0, 1


@dataclass(frozen=True, eq=False)
class FlatTree:
    """A hand's kinematic tree as flat arrays (L links, M motions, parents before children).

    parents : (L,) int64, -1 for the top link; origins : (L, 4, 4) float
    start : (L + 1,) int64
        Motions of link i: ``start[i]:start[i + 1]``, applied in order.
    kind : (M,) int64 (:data:`REVOLUTE`, :data:`PRISMATIC`); axis, anchor : (M, 3) float
    index : (M,) int64, into the full joint vector; ref : (M,) float, rad or m
    root_inverse : (4, 4) float
    """

    parents: np.ndarray
    origins: np.ndarray
    start: np.ndarray
    kind: np.ndarray
    axis: np.ndarray
    anchor: np.ndarray
    index: np.ndarray
    ref: np.ndarray
    root_inverse: np.ndarray


def flat_tree(link_parents, origins, motions, root_inverse) -> FlatTree:
    """The :class:`FlatTree` of a hand's ``link_parents``, ``origins``, ``motions`` (per link,
    a tuple of :class:`.model.Motion`) and ``root_inverse``."""
    flat = [m for ms in motions for m in ms]
    start = np.zeros(len(link_parents) + 1, dtype=np.int64)
    start[1:] = np.cumsum([len(ms) for ms in motions])

    def arr(values, dtype=np.float64, shape=None):
        out = np.ascontiguousarray(np.array(values, dtype=dtype))
        out = out.reshape(shape) if shape else out
        out.flags.writeable = False
        return out

    return FlatTree(
        parents=arr(link_parents, np.int64), origins=arr(origins, shape=(-1, 4, 4)), start=arr(start, np.int64),
        kind=arr([REVOLUTE if m.kind == "revolute" else PRISMATIC for m in flat], np.int64),
        axis=arr([m.axis for m in flat], shape=(-1, 3)), anchor=arr([m.anchor for m in flat], shape=(-1, 3)),
        index=arr([m.index for m in flat], np.int64), ref=arr([m.ref for m in flat]),
        root_inverse=arr(root_inverse, shape=(4, 4)))


def link_poses(tree: FlatTree, full: np.ndarray) -> np.ndarray:
    """Every link's pose in the root frame: full joint values (P, m) -> (P, L, 4, 4)."""
    full = np.ascontiguousarray(full, dtype=np.float64)
    out = np.empty((full.shape[0], tree.parents.shape[0], 4, 4))
    _walk(full, tree.parents, tree.origins, tree.start, tree.kind, tree.axis, tree.anchor, tree.index, tree.ref,
          tree.root_inverse, out)
    return out


@_inline
def _product(a, b, out):
    """out = a @ b for (4, 4) rigid transforms (the last row kept 0 0 0 1)."""
    for r in range(3):
        for c in range(4):
            out[r, c] = a[r, 0] * b[0, c] + a[r, 1] * b[1, c] + a[r, 2] * b[2, c]
        out[r, 3] += a[r, 3]
    out[3, 0] = 0.0
    out[3, 1] = 0.0
    out[3, 2] = 0.0
    out[3, 3] = 1.0


@_inline
def apply_motion(poses, l, kind, x, y, z, ax, ay, az, value):
    """poses[l] = poses[l] @ the motion's transform, in place, on scalars (no array views):
    a revolute motion turns ``value`` rad about the unit axis (x, y, z) through the anchor
    (ax, ay, az), a prismatic one moves ``value`` m along it. The one implementation of a
    joint motion, shared by :func:`_walk` and the decoder's finger kernel
    (:func:`grasp_apso.geometry.any_hand_kernels.finger_poses`)."""
    if kind == PRISMATIC:
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        t0, t1, t2 = value * x, value * y, value * z
    else:  # Rodrigues, then about the anchor: t = a - R a
        sn, cs = math.sin(value), math.cos(value)
        t = 1.0 - cs
        r00 = cs + x * x * t
        r01 = x * y * t - z * sn
        r02 = x * z * t + y * sn
        r10 = y * x * t + z * sn
        r11 = cs + y * y * t
        r12 = y * z * t - x * sn
        r20 = z * x * t - y * sn
        r21 = z * y * t + x * sn
        r22 = cs + z * z * t
        t0 = ax - (r00 * ax + r01 * ay + r02 * az)
        t1 = ay - (r10 * ax + r11 * ay + r12 * az)
        t2 = az - (r20 * ax + r21 * ay + r22 * az)
    for i in range(3):
        a0, a1, a2, a3 = poses[l, i, 0], poses[l, i, 1], poses[l, i, 2], poses[l, i, 3]
        poses[l, i, 0] = a0 * r00 + a1 * r10 + a2 * r20
        poses[l, i, 1] = a0 * r01 + a1 * r11 + a2 * r21
        poses[l, i, 2] = a0 * r02 + a1 * r12 + a2 * r22
        poses[l, i, 3] = a0 * t0 + a1 * t1 + a2 * t2 + a3


@_jit
def _walk(full, parents, origins, start, kind, axis, anchor, index, ref, root_inverse, out):
    tmp = np.empty((4, 4))
    for p in range(full.shape[0]):
        poses = out[p]
        for i in range(parents.shape[0]):
            if parents[i] < 0:
                poses[i] = origins[i]
            else:
                _product(poses[parents[i]], origins[i], poses[i])
            for k in range(start[i], start[i + 1]):
                apply_motion(poses, i, kind[k], axis[k, 0], axis[k, 1], axis[k, 2], anchor[k, 0], anchor[k, 1],
                             anchor[k, 2], full[p, index[k]] - ref[k])
        for i in range(parents.shape[0]):  # into the root frame, once the children are placed
            _product(root_inverse, poses[i], tmp)
            poses[i] = tmp
