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
import threading
from itertools import combinations

import fcl
import numpy as np
import trimesh

from ..cache import PerThreadCache, cached
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


#: Approximate bytes of a python-fcl BVH per triangle (OBBRSS nodes, vertices, faces).
BVH_BYTES_PER_TRIANGLE = 300


def object_bvh(obj) -> fcl.BVHModel:
    """The BVH of an object's mesh (object frame), built once per mesh: the named cache
    ``"mesh_bvh"`` of :mod:`grasp_apso.cache`, keyed by ``obj.mesh_hash``. Shared between
    threads (only geometry; the moved collision objects are per thread)."""
    mesh = obj.mesh
    return cached("mesh_bvh", obj.mesh_hash, lambda: mesh_bvh(mesh),
                  nbytes=BVH_BYTES_PER_TRIANGLE * len(mesh.faces) + 24 * len(mesh.vertices))


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


#: Link pairs of different fingers (indices into the 15 links, finger-major).
_LINK_PAIRS = tuple(np.array(v, dtype=np.int64) for v in zip(*[
    (3 * i + a, 3 * j + b) for i, j in FINGER_PAIRS for a in range(3) for b in range(3)]))
#: Segment-distance margin (m) within which fcl decides whether two finger capsules collide.
_PAIR_MARGIN = 0.001
_LOCAL = threading.local()


def _cached_capsule(radius: float, length: float, tf: fcl.Transform, slot: int) -> fcl.CollisionObject:
    """A per-thread cached fcl capsule object of this size (created once, then moved
    with ``setTransform``); ``slot`` separates objects used at the same time."""
    cache = getattr(_LOCAL, "capsules", None)
    if cache is None:
        cache = _LOCAL.capsules = {}
    key = (round(radius, 9), round(length, 9), slot)
    obj = cache.get(key)
    if obj is None:
        if len(cache) > 512:
            cache.clear()
        obj = cache[key] = fcl.CollisionObject(fcl.Capsule(radius, length), tf)
    else:
        obj.setTransform(tf)
    return obj


_MESH_OBJECTS: "PerThreadCache[fcl.CollisionObject]" = PerThreadCache(max_entries=8)


def _mesh_object(bvh: fcl.BVHModel) -> fcl.CollisionObject:
    """The per-thread cached fcl object of a BVH at the identity."""
    return _MESH_OBJECTS.get(bvh, lambda b: fcl.CollisionObject(b, fcl.Transform()))


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
    joints = np.asarray(joints, dtype=float)
    radii = np.asarray(radii, dtype=float)
    rot, centre, length = capsule_frames(joints[:, :3], joints[:, 1:])  # (5, 3, ...) in one batch
    mesh_obj = _mesh_object(bvh)
    dist = np.zeros((5, 3))
    penetrates = np.zeros((5, 3), dtype=bool)
    for f in range(5):
        for k in range(3):
            tf = fcl.Transform(rot[f, k], centre[f, k])
            full = _cached_capsule(float(radii[k]), float(length[f, k]), tf, 0)
            # one distance query: fcl answers -1 (<= 0) for a pair in collision
            d = fcl.distance(full, mesh_obj, fcl.DistanceRequest(), fcl.DistanceResult())
            if d > 1e-6:
                dist[f, k] = d
            elif _collide(full, mesh_obj):
                shrunk = _cached_capsule(float(radii[k]) - penetration_tolerance, float(length[f, k]), tf, 1)
                penetrates[f, k] = _collide(shrunk, mesh_obj)
            else:
                dist[f, k] = max(d, 0.0)
    # Finger pairs: fcl decides for the link pairs whose segments come within the sum of
    # the shrunk radii plus a margin (the compiled segment distances, one batch); pairs
    # farther apart cannot collide.
    shrink = 0.5 * allowed_overlap
    ia, ib = _LINK_PAIRS
    p0, p1 = joints[:, :3].reshape(15, 3), joints[:, 1:].reshape(15, 3)
    seg = segment_distances(p0[ia], p1[ia], p0[ib], p1[ib])
    link_r = np.tile(radii, 5) - shrink
    near = seg < link_r[ia] + link_r[ib] + _PAIR_MARGIN
    colliding = set()
    for n in np.flatnonzero(near):
        a, b = int(ia[n]), int(ib[n])
        fa, fb = a // 3, b // 3
        if (fa, fb) in colliding:
            continue
        oa = _cached_capsule(float(link_r[a]), float(length[fa, a % 3]),
                             fcl.Transform(rot[fa, a % 3], centre[fa, a % 3]), 2)
        ob = _cached_capsule(float(link_r[b]), float(length[fb, b % 3]),
                             fcl.Transform(rot[fb, b % 3], centre[fb, b % 3]), 3)
        if _collide(oa, ob):
            colliding.add((fa, fb))
    pairs = tuple((finger_names[i], finger_names[j]) for i, j in FINGER_PAIRS if (i, j) in colliding)
    return FclReport(link_distance=dist, link_penetrates=penetrates, finger_pairs_colliding=pairs)
