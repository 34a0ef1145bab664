"""Collisions between fingers, and an independent python-fcl check of a grasp.

The optimiser's hot path uses :func:`finger_collisions`, a batched capsule-capsule test
(each link is a capsule: a segment with a radius; compiled loops in
:mod:`grasp_apso.geometry.kernels`). :func:`verify_with_fcl`
checks one final grasp with python-fcl against the real mesh BVH: it is the
"verification test" of the paper done with an independent geometry engine, used on the
returned grasp and in tests to cross-check the grid-based decoding.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import fcl
import numpy as np
import trimesh

from . import kernels

FINGER_PAIRS: tuple[tuple[int, int], ...] = tuple(combinations(range(5), 2))


def segment_distances(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Closest distance between segments [p0, p1] and [q0, q1], batched.

    Parameters
    ----------
    p0, p1, q0, q1 : (..., 3) float, m (broadcast together)

    Returns
    -------
    (...,) float, m
    """
    p0, p1, q0, q1 = np.broadcast_arrays(p0, p1, q0, q1)
    shape = p0.shape[:-1]
    flat = [np.ascontiguousarray(v, dtype=np.float64).reshape(-1, 3) for v in (p0, p1, q0, q1)]
    out = np.empty(len(flat[0]))
    kernels.segment_distances(*flat, out)
    return out.reshape(shape)


def finger_collisions(joints: np.ndarray, radii: np.ndarray, allowed_overlap: float = 0.002) -> np.ndarray:
    """Which fingers collide with another finger.

    Parameters
    ----------
    joints : (P, 5, 4, 3) float, m
        Base, PIP, DIP and tip points of every finger (any common frame).
    radii : (3,) float, m
        Capsule radius of the proximal, middle and distal links.
    allowed_overlap : float, m
        Capsules may interpenetrate this much (soft skin; neighbouring fingers touch).

    Returns
    -------
    (P, 5) bool
        True for each finger in at least one colliding pair (any of its links against
        any link of another finger), or folded into itself (its distal link against its
        proximal link).
    """
    joints = np.ascontiguousarray(joints, dtype=np.float64)
    if joints.ndim != 4 or joints.shape[2:] != (4, 3):
        raise ValueError(f"joints: expected (P, F, 4, 3), got {joints.shape}")
    out = np.empty(joints.shape[:2], dtype=bool)
    kernels.finger_collisions(joints, np.ascontiguousarray(radii, dtype=np.float64), float(allowed_overlap), out)
    return out


@dataclass(frozen=True)
class FclReport:
    """Result of :func:`verify_with_fcl` for one grasp.

    Attributes
    ----------
    link_distance : (5, 3) float, m
        Distance of each link capsule (the distal one ends in the pad) to the mesh; 0 for
        links touching or penetrating it.
    link_penetrates : (5, 3) bool
        The link penetrates the mesh by more than the tolerance: the capsule shrunk by
        the tolerance still collides with the mesh.
    finger_pairs_colliding : tuple[tuple[str, str], ...]
        Finger pairs whose capsules overlap by more than the allowed overlap.
    """

    link_distance: np.ndarray
    link_penetrates: np.ndarray
    finger_pairs_colliding: tuple[tuple[str, str], ...]

    @property
    def legal(self) -> bool:
        """No link penetrates beyond the tolerance and no fingers collide."""
        return not self.link_penetrates.any() and not self.finger_pairs_colliding


def mesh_bvh(mesh: trimesh.Trimesh) -> fcl.BVHModel:
    """python-fcl BVH of a mesh (object frame)."""
    bvh = fcl.BVHModel()
    bvh.beginModel(len(mesh.vertices), len(mesh.faces))
    bvh.addSubModel(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int32))
    bvh.endModel()
    return bvh


def capsule_frames(p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses of fcl capsules along segments [p0, p1], batched.

    fcl capsules lie along their local z, centred on the origin.

    Parameters
    ----------
    p0, p1 : (..., 3) float, m

    Returns
    -------
    rot : (..., 3, 3) float
        Rotation taking +z to the segment direction.
    centre : (..., 3) float, m
        Segment midpoints.
    length : (...,) float, m
        Segment lengths (at least 1e-9).
    """
    p0, p1 = np.broadcast_arrays(np.asarray(p0, dtype=float), np.asarray(p1, dtype=float))
    axis = p1 - p0
    length = np.linalg.norm(axis, axis=-1)
    z = np.where(length[..., None] > 1e-12, axis / np.maximum(length, 1e-300)[..., None], [0.0, 0.0, 1.0])
    helper = np.where(np.abs(z[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1), 0.5 * (p0 + p1), np.maximum(length, 1e-9)


def capsule_transform(p0: np.ndarray, p1: np.ndarray) -> tuple[fcl.Transform, float]:
    """``fcl.Transform`` and length (m) of the capsule along [p0, p1] (3,), see
    :func:`capsule_frames`."""
    rot, centre, length = capsule_frames(p0, p1)
    return fcl.Transform(rot, centre), float(length)


def _capsule(p0: np.ndarray, p1: np.ndarray, radius: float) -> fcl.CollisionObject:
    tf, length = capsule_transform(p0, p1)
    return fcl.CollisionObject(fcl.Capsule(radius, length), tf)


def _collide(a: fcl.CollisionObject, b: fcl.CollisionObject) -> bool:
    return fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult()) > 0


def verify_with_fcl(
    joints: np.ndarray,
    radii: np.ndarray,
    bvh: fcl.BVHModel,
    finger_names: tuple[str, ...],
    penetration_tolerance: float = 0.001,
    allowed_overlap: float = 0.002,
) -> FclReport:
    """Check one grasp against the mesh and between fingers with python-fcl.

    Parameters
    ----------
    joints : (5, 4, 3) float, m, object frame
        Base, PIP, DIP, tip points of each finger.
    radii : (3,) float, m
        Link capsule radii (the distal one is the pad radius).
    bvh : fcl.BVHModel
        The object mesh (object frame), see :func:`mesh_bvh`.
    penetration_tolerance : float, m
        Link penetration accepted (a contact presses this much at most).
    allowed_overlap : float, m
        Finger capsules may overlap this much (as in :func:`finger_collisions`).
    """
    mesh_obj = fcl.CollisionObject(bvh, fcl.Transform())
    dist = np.zeros((5, 3))
    penetrates = np.zeros((5, 3), dtype=bool)
    for f in range(5):
        for k in range(3):
            full = _capsule(joints[f, k], joints[f, k + 1], float(radii[k]))
            if _collide(full, mesh_obj):
                shrunk = _capsule(joints[f, k], joints[f, k + 1], float(radii[k]) - penetration_tolerance)
                penetrates[f, k] = _collide(shrunk, mesh_obj)
            else:
                dist[f, k] = fcl.distance(full, mesh_obj, fcl.DistanceRequest(), fcl.DistanceResult())
    shrunk_links = [
        [_capsule(joints[f, k], joints[f, k + 1], float(radii[k]) - 0.5 * allowed_overlap) for k in range(3)]
        for f in range(5)
    ]
    pairs = tuple(
        (finger_names[i], finger_names[j])
        for i, j in FINGER_PAIRS
        if any(_collide(shrunk_links[i][a], shrunk_links[j][b]) for a in range(3) for b in range(3))
    )
    return FclReport(link_distance=dist, link_penetrates=penetrates, finger_pairs_colliding=pairs)
