"""The forward kinematics of a whole hand, compiled: every link's pose in the root frame.

:meth:`.model.HandModel.link_transforms_batch` walks the tree link by link; done in numpy
that costs a few hundred microseconds per posture (a dozen small array operations per
link and motion), and the python-fcl verification of a general hand's candidates poses the
hand a hundred times and more per plan. Here the tree is flattened once per hand
(:class:`FlatTree`) and walked in one compiled loop (numba, cached on disk, GIL released).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["FlatTree", "flat_tree", "link_poses"]

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
        out = np.ascontiguousarray(np.array(values, dtype=dtype).reshape(shape) if shape else
                                   np.array(values, dtype=dtype))
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


@_jit
def _walk(full, parents, origins, start, kind, axis, anchor, index, ref, root_inverse, out):
    local = np.empty((4, 4))
    pose = np.empty((4, 4))
    tmp = np.empty((4, 4))
    for p in range(full.shape[0]):
        for i in range(parents.shape[0]):
            if parents[i] < 0:
                pose[:, :] = origins[i]
            else:
                _product(out[p, parents[i]], origins[i], pose)
            for k in range(start[i], start[i + 1]):
                value = full[p, index[k]] - ref[k]
                local[:, :] = 0.0
                local[3, 3] = 1.0
                x, y, z = axis[k, 0], axis[k, 1], axis[k, 2]
                if kind[k] == REVOLUTE:
                    # Rodrigues: R = I + s K + (1 - c) K^2, K the axis' cross-product matrix
                    s, c = np.sin(value), np.cos(value)
                    v = 1.0 - c
                    local[0, 0] = 1.0 - v * (y * y + z * z)
                    local[0, 1] = -s * z + v * x * y
                    local[0, 2] = s * y + v * x * z
                    local[1, 0] = s * z + v * x * y
                    local[1, 1] = 1.0 - v * (x * x + z * z)
                    local[1, 2] = -s * x + v * y * z
                    local[2, 0] = -s * y + v * x * z
                    local[2, 1] = s * x + v * y * z
                    local[2, 2] = 1.0 - v * (x * x + y * y)
                    for r in range(3):  # about the anchor: t = a - R a
                        local[r, 3] = anchor[k, r] - (local[r, 0] * anchor[k, 0] + local[r, 1] * anchor[k, 1]
                                                      + local[r, 2] * anchor[k, 2])
                else:
                    local[0, 0] = 1.0
                    local[1, 1] = 1.0
                    local[2, 2] = 1.0
                    local[0, 3] = value * x
                    local[1, 3] = value * y
                    local[2, 3] = value * z
                _product(pose, local, tmp)
                pose[:, :] = tmp
            out[p, i] = pose
        for i in range(parents.shape[0]):  # into the root frame, once the children are placed
            _product(root_inverse, out[p, i], tmp)
            out[p, i] = tmp
