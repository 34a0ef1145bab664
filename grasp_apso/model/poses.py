"""Poses: ``geometry_msgs/Pose``-like position + quaternion and 4x4 transforms.

A pose is a position (3,) in metres and an orientation quaternion (x, y, z, w) in ROS
order; a transform is the matching 4x4 homogeneous matrix ``T`` with ``T[:3, :3]`` the
rotation and ``T[:3, 3]`` the position. The planner works in the object frame; the
object pose (object -> planning frame) is applied to its results only.

- :func:`pose_to_matrix` -- pose -> transform; a quaternion whose norm is not 1 within
  :data:`QUATERNION_NORM_TOLERANCE` is rejected (:class:`~grasp_apso.errors.ObjectError`
  naming the request field), not silently normalised.
- :func:`matrix_to_pose` -- rigid transform -> pose (quaternion with w >= 0).
- :func:`transform_points` / :func:`transform_vectors` -- apply a transform to points
  (rotation and translation) or to directions (rotation only).

All are also importable from :mod:`grasp_apso.model.objects`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import ObjectError

__all__ = [
    "QUATERNION_NORM_TOLERANCE",
    "pose_to_matrix",
    "matrix_to_pose",
    "transform_points",
    "transform_vectors",
]

#: Tolerance on the quaternion norm: |norm - 1| above this is rejected, not normalised.
QUATERNION_NORM_TOLERANCE: float = 1e-3


def _as_vector(values: Any, size: int, what: str) -> np.ndarray:
    """A finite float vector of length ``size`` or ObjectError naming ``what``."""
    try:
        vec = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ObjectError(f"{what} must be {size} numbers") from None
    if vec.shape != (size,):
        raise ObjectError(f"{what} must have shape ({size},), got {vec.shape}")
    if not np.isfinite(vec).all():
        raise ObjectError(f"{what} is not finite: {vec.tolist()}")
    return vec


def pose_to_matrix(position: Any, quaternion: Any, field: str = "object_pose") -> np.ndarray:
    """Homogeneous transform of a pose.

    Parameters
    ----------
    position : array_like, (3,) float, m
    quaternion : array_like, (4,) float
        Orientation as (x, y, z, w) (ROS order). Its norm must be 1 within
        :data:`QUATERNION_NORM_TOLERANCE` (1e-3); such a quaternion is normalised, any
        other is rejected, not silently normalised.
    field : str
        Request field named in error messages.

    Returns
    -------
    (4, 4) float
        ``T`` with ``T[:3, :3]`` the rotation and ``T[:3, 3]`` the position.

    Raises
    ------
    ObjectError
        ``object_pose: ...`` for wrong shapes, non-finite values, a zero quaternion or a
        quaternion that is not unit.
    """
    pos = _as_vector(position, 3, f"{field}: position")
    quat = _as_vector(quaternion, 4, f"{field}: quaternion")
    norm = float(np.linalg.norm(quat))
    if norm < 1e-12:
        raise ObjectError(f"{field}: zero quaternion")
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise ObjectError(f"{field}: quaternion is not unit (norm {norm:.4g})")
    transform = np.eye(4)
    transform[:3, :3] = Rotation.from_quat(quat / norm).as_matrix()
    transform[:3, 3] = pos
    return transform


def _check_transform(transform: Any) -> np.ndarray:
    """A (4, 4) finite float array, or ValueError naming ``T``."""
    mat = np.asarray(transform, dtype=np.float64)
    if mat.shape != (4, 4):
        raise ValueError(f"T: expected shape (4, 4), got {mat.shape}")
    if not np.isfinite(mat).all():
        raise ValueError("T: not finite")
    return mat


def matrix_to_pose(transform: Any) -> tuple[np.ndarray, np.ndarray]:
    """Position and quaternion of a rigid homogeneous transform.

    Parameters
    ----------
    transform : array_like, (4, 4) float
        Rigid transform: rotation block orthonormal with determinant +1 (within 1e-6),
        last row (0, 0, 0, 1).

    Returns
    -------
    position : (3,) float, m
    quaternion : (4,) float
        Unit (x, y, z, w) with w >= 0.

    Raises
    ------
    ValueError
        ``T: ...`` when the matrix is not a finite rigid transform.
    """
    mat = _check_transform(transform)
    if not np.allclose(mat[3], (0.0, 0.0, 0.0, 1.0), atol=1e-9):
        raise ValueError(f"T: last row must be (0, 0, 0, 1), got {mat[3].tolist()}")
    rot = mat[:3, :3]
    if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) <= 0.0:
        raise ValueError("T: rotation block is not a proper rotation")
    quat = Rotation.from_matrix(rot).as_quat()
    if quat[3] < 0.0:
        quat = -quat
    return mat[:3, 3].copy(), quat


def transform_points(transform: Any, points: Any) -> np.ndarray:
    """Apply a homogeneous transform to points.

    Parameters
    ----------
    transform : array_like, (4, 4) float
    points : array_like, (..., 3) float, m

    Returns
    -------
    (..., 3) float, m
        ``R @ p + t`` for every point.
    """
    mat = _check_transform(transform)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 0 or pts.shape[-1] != 3:
        raise ValueError(f"points: expected shape (..., 3), got {pts.shape}")
    return pts @ mat[:3, :3].T + mat[:3, 3]


def transform_vectors(transform: Any, vectors: Any) -> np.ndarray:
    """Rotate vectors (directions, normals, forces) by a transform's rotation only.

    Parameters
    ----------
    transform : array_like, (4, 4) float
    vectors : array_like, (..., 3) float

    Returns
    -------
    (..., 3) float
        ``R @ v`` for every vector.
    """
    mat = _check_transform(transform)
    vecs = np.asarray(vectors, dtype=np.float64)
    if vecs.ndim == 0 or vecs.shape[-1] != 3:
        raise ValueError(f"vectors: expected shape (..., 3), got {vecs.shape}")
    return vecs @ mat[:3, :3].T
