"""Contact robustness: how well defined the surface normal is under each fingertip, and
the Ferrari-Canny epsilon that survives that uncertainty (issue 13, part 6).

A grasp whose force closure rests on a contact at an edge or a corner is fragile: there
the surface normal is ill defined, the real contact force may point anywhere in the
fan of the adjacent faces' normals, and a fingertip slides off the edge under load.
Two measures, for the few final contacts only (not the swarm's hot path):

- :func:`normal_uncertainty` ``(obj, points (k, 3)) -> (k,) rad``: the spread of the
  mesh's face normals within ``radius`` of each contact. 0 in the middle of a flat face,
  about ``curvature * radius`` on a smooth curved surface, 45 degrees (0.785 rad) on a
  box edge, 54.7 degrees (0.955 rad) at a box corner.
- :func:`robust_epsilon` ``(obj, points, normals, mu, uncertainty) -> float``: the epsilon
  of the grasp with each contact's friction cone shrunk by its uncertainty (the cone of
  forces that stays inside the friction cone for every normal within ``uncertainty`` of
  the nominal one). A contact whose uncertainty reaches ``atan(mu)`` gives no guaranteed
  force and is dropped. Never above :func:`~grasp_apso.quality.measures.epsilon_quality`
  of the same grasp, and equal to it when every uncertainty is 0.
- :func:`robustness_score` bundles both for a ranking: ``(robust_epsilon, margin)``,
  ``margin = robust_epsilon / epsilon`` in [0, 1].

Frames and units: points (m) and normals (unit, outward) in the object frame of ``obj``
(a :class:`~grasp_apso.model.objects.GraspObject`); angles in rad.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from ..cache import cached
from .measures import hull_epsilon

__all__ = ["normal_uncertainty", "robust_epsilon", "robust_wrenches", "robustness_score", "DEFAULT_RADIUS",
           "BACK_FACE_COS"]

#: Neighbourhood of a contact (m): half the fingertip pad radius (8 mm) -- the pad's
#: contact patch under a few newtons is a few millimetres across.
DEFAULT_RADIUS: float = 0.004
#: Faces whose normal is more than 120 degrees from the closest face's normal are the far
#: side of a thin wall (a mug's inner wall), not part of the contact's neighbourhood.
BACK_FACE_COS: float = -0.5
#: m^2: two squared distances closer than this may be ordered otherwise by another
#: summation order (their rounding: about 1e-26 at a few millimetres): treated as a tie.
ROUNDING: float = 1e-15


def _points(value: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 1 and arr.shape == (3,):
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 3 or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected finite (k, 3), got shape {arr.shape}")
    return arr


def _face_boxes(obj) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The triangles of ``obj.mesh`` (F, 3, 3) and their axis-aligned boxes' corners (F, 3),
    (F, 3), m: kept per mesh hash (a third of a call's time on a 3000-face mesh)."""
    def build():
        tri = np.array(obj.mesh.triangles, dtype=np.float64)
        out = (tri, tri.min(axis=1), tri.max(axis=1))
        for a in out:
            a.flags.writeable = False  # shared by every caller
        return out
    key = getattr(obj, "mesh_hash", None)
    return build() if key is None else cached("face_boxes", key, build)


def normal_uncertainty(obj, points: ArrayLike, radius: float = DEFAULT_RADIUS) -> NDArray[np.float64]:
    """Spread of the face normals of ``obj.mesh`` within ``radius`` of each contact.

    For contact ``p`` the neighbourhood is every triangle whose closest point lies within
    ``radius`` of ``p`` (at distance ``d``) and whose normal is within 120 degrees of the
    normal of the triangle closest to ``p`` (so the far side of a thin wall is left out).
    Triangle ``j`` weighs ``w_j = min(area_j, pi (radius^2 - d_j^2))``, roughly its area
    inside the ball (exact for a plane cutting it). With ``m`` the normalised weighted
    mean normal, the uncertainty is the weighted RMS angle between the normals and ``m``::

        u = sqrt( sum_j w_j angle(n_j, m)^2 / sum_j w_j )

    Continuous in ``p`` (a far triangle enters with zero weight), insensitive to how a
    flat region is triangulated, robust to a single noisy scan triangle.

    Parameters
    ----------
    obj : GraspObject
        Uses ``obj.mesh`` (object frame, m).
    points : (k, 3) array_like of float, m
        Contact points in the object frame, on or near the surface.
    radius : float, m
        Neighbourhood radius, > 0.

    Returns
    -------
    (k,) ndarray of float, rad
        In [0, pi/2]; 0 on a flat face.

    Notes
    -----
    Vectorised over contacts and triangles: an axis-aligned box test of all triangles
    against all contacts, then exact point-triangle distances for the survivors only.
    """
    pts = _points(points, "points")
    if not (isinstance(radius, (int, float)) and math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius: expected a positive length in m, got {radius!r}")
    mesh = obj.mesh
    tri, lo, hi = _face_boxes(obj)                       # (F, 3, 3), (F, 3), (F, 3)
    normals = np.asarray(mesh.face_normals)              # (F, 3)
    areas = np.asarray(mesh.area_faces)                  # (F,)
    # box prefilter: (k, F) candidates, then exact distances for the survivors
    near_box = np.all((pts[:, None, :] >= lo[None] - radius) & (pts[:, None, :] <= hi[None] + radius), axis=2)
    ci, fi = np.nonzero(near_box)
    closest = trimesh.triangles.closest_point(tri[fi], pts[ci])
    d2 = np.einsum("ij,ij->i", closest - pts[ci], closest - pts[ci])
    n0 = normals[_closest_faces(mesh, pts, ci, fi, d2, radius)]   # (k, 3), for the thin-wall filter
    facing = np.einsum("ij,ij->i", normals[fi], n0[ci]) > BACK_FACE_COS
    w = np.where(facing, np.minimum(areas[fi], math.pi * np.maximum(radius ** 2 - d2, 0.0)), 0.0)
    k = pts.shape[0]
    mean = np.zeros((k, 3))
    np.add.at(mean, ci, w[:, None] * normals[fi])
    # a contact with no weighted neighbour (far from the surface): its closest face alone
    empty = np.bincount(ci, weights=w, minlength=k) <= 0.0
    mean[empty] = n0[empty]
    mean /= np.linalg.norm(mean, axis=1, keepdims=True)
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", normals[fi], mean[ci]), -1.0, 1.0))
    num = np.bincount(ci, weights=w * angle ** 2, minlength=k)
    den = np.bincount(ci, weights=w, minlength=k)
    return np.sqrt(np.where(den > 0.0, num / np.where(den > 0.0, den, 1.0), 0.0))


def _closest_faces(mesh, pts: NDArray, ci: NDArray, fi: NDArray, d2: NDArray, radius: float) -> NDArray[np.int64]:
    """The face of ``mesh`` closest to each contact pts (k, 3), as
    ``trimesh.proximity.closest_point`` finds it, from the candidate faces (ci, fi) and
    their squared distances d2 (the box prefilter within ``radius``).

    trimesh returns the nearest face of its candidates (which hold it) unless its two nearest
    lie within its ``tol.merge`` of each other (in squared distance) and both farther than
    that, when the normals decide. Where a contact's nearest candidate (a face outside the
    prefilter lies beyond ``radius``) is unique and trimesh's tie rule cannot apply, that
    face is trimesh's answer; for the other contacts (on or near an edge, or farther than
    ``radius`` from the surface) trimesh is asked, for them alone. Its query cost 0.8 of the
    1.5 ms of a grasp's uncertainty."""
    k = len(pts)
    best = np.full(k, np.inf)
    np.minimum.at(best, ci, d2)
    rows = np.flatnonzero(d2 == best[ci])
    first = np.zeros(len(ci), dtype=bool)  # one pair at each contact's minimum
    first[rows[np.unique(ci[rows], return_index=True)[1]]] = True
    second = np.full(k, radius * radius)  # the next face's, at most radius^2 (an exact tie: the minimum)
    np.minimum.at(second, ci[~first], d2[~first])
    face = np.zeros(k, dtype=np.int64)
    face[ci[first]] = fi[first]
    merge = trimesh.tol.merge
    # trimesh's answer is the nearest face unless its two nearest lie within ``merge`` of each
    # other and both farther than ``merge`` (then the normals decide); an exact tie, or one
    # within rounding, goes to trimesh too
    own = (best + merge <= second) | ((best <= merge) & (best + ROUNDING < second))
    ties = np.flatnonzero(~own)
    if len(ties):
        face[ties] = trimesh.proximity.closest_point(mesh, pts[ties])[2]
    return face


def _shrunk_cone_wrenches(points: NDArray, normals: NDArray, com: NDArray, mu: float, beta: NDArray,
                          edges: int, torque_scale: float) -> NDArray[np.float64]:
    """Primitive wrenches (sum_i edges_i, 6) of the friction cones shrunk to half-angles
    ``beta`` (k,), rad, each ``>= 0``.

    Edge ``e`` of contact ``i`` is ``cos(alpha) (a_i + tan(beta_i) t_ie)`` with
    ``alpha = atan(mu)``, the cone axis ``a_i = -n_i`` and the unit tangents ``t_ie`` of
    :func:`~grasp_apso.quality.measures.epsilon_quality` (same helper axis, same phases):
    for ``beta = alpha`` these are exactly its unit edges, and for ``beta < alpha`` they
    lie inside the convex hull of those edges, so the wrench hull can only shrink.
    """
    inward = -normals
    helper = np.where(np.abs(inward[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(inward, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(inward, t1)
    phi = 2.0 * math.pi * np.arange(edges) / edges
    tangential = np.cos(phi)[None, :, None] * t1[:, None, :] + np.sin(phi)[None, :, None] * t2[:, None, :]
    alpha = math.atan(mu)
    forces = math.cos(alpha) * (inward[:, None, :] + np.tan(beta)[:, None, None] * tangential)
    torques = np.cross((points - com)[:, None, :], forces) / torque_scale
    return np.concatenate([forces, torques], axis=-1).reshape(-1, 6)


def robust_epsilon(
    obj,
    points: ArrayLike,
    normals: ArrayLike,
    mu: float = 0.5,
    uncertainty: ArrayLike | None = None,
    edges: int = 8,
    torque_scale: float | None = None,
    radius: float = DEFAULT_RADIUS,
) -> float:
    """Ferrari-Canny L1 epsilon with each contact's friction cone shrunk by its normal
    uncertainty.

    The force at contact ``i`` is guaranteed to lie in the friction cone of every normal
    within ``u_i`` of the nominal ``n_i`` only inside the cone about ``-n_i`` of half-angle
    ``beta_i = atan(mu) - u_i``. Contacts with ``beta_i < 0`` are dropped (no force is safe
    there); the others enter the wrench hull as in
    :func:`~grasp_apso.quality.measures.epsilon_quality` with their shrunk cones.

    Parameters
    ----------
    obj : GraspObject
        The object (its mesh for the uncertainty, ``center_of_mass`` as the torque
        origin, ``characteristic_radius`` as the default torque scale, as the planner).
    points : (k, 3) array_like of float, m
        Contact points, object frame.
    normals : (k, 3) array_like of float
        Outward unit normals at the contacts (re-normalised here).
    mu : float
        Coulomb friction coefficient, > 0.
    uncertainty : (k,) array_like of float, rad, optional
        Per-contact normal uncertainty, >= 0; :func:`normal_uncertainty` with ``radius``
        when None.
    edges : int
        Edges of each linearised cone, >= 3.
    torque_scale : float, m, optional
        Torque normalisation; ``obj.characteristic_radius`` when None.

    Returns
    -------
    float
        The robust epsilon, in ``[0, epsilon_quality(points, normals, com, mu, edges,
        torque_scale)]``; 0.0 when the surviving contacts are not force closure.
    """
    wrenches = robust_wrenches(obj, points, normals, mu, uncertainty, edges, torque_scale, radius)
    # most fragile grasps stop at hull_epsilon's quick outside test, before qhull
    return 0.0 if wrenches is None else hull_epsilon(wrenches)


def robust_wrenches(
    obj,
    points: ArrayLike,
    normals: ArrayLike,
    mu: float = 0.5,
    uncertainty: ArrayLike | None = None,
    edges: int = 8,
    torque_scale: float | None = None,
    radius: float = DEFAULT_RADIUS,
) -> NDArray[np.float64] | None:
    """The primitive wrenches (n, 6) of the shrunk cones whose hull :func:`robust_epsilon`
    measures (arguments and errors as there); None when fewer than two contacts keep a
    cone (no force closure)."""
    pts = _points(points, "points")
    nrm = _points(normals, "normals")
    if nrm.shape != pts.shape:
        raise ValueError(f"normals: expected {pts.shape}, got {nrm.shape}")
    if not (math.isfinite(mu) and mu > 0.0):
        raise ValueError(f"mu: expected > 0, got {mu!r}")
    if int(edges) < 3:
        raise ValueError(f"edges: expected >= 3, got {edges!r}")
    unc = normal_uncertainty(obj, pts, radius) if uncertainty is None else np.asarray(uncertainty, float)
    if unc.shape != (pts.shape[0],) or not np.all(np.isfinite(unc)) or np.any(unc < 0.0):
        raise ValueError(f"uncertainty: expected ({pts.shape[0]},) non-negative values in rad")
    length = np.linalg.norm(nrm, axis=1)
    if np.any(length <= 0.0):
        raise ValueError("normals: zero-length normal")
    beta = math.atan(mu) - unc
    keep = beta >= 0.0
    if keep.sum() < 2:
        return None
    scale = float(obj.characteristic_radius if torque_scale is None else torque_scale)
    com = np.asarray(obj.center_of_mass, dtype=float)
    return _shrunk_cone_wrenches(pts[keep], nrm[keep] / length[keep, None], com, float(mu), beta[keep],
                                 int(edges), scale)


def robustness_score(obj, points: ArrayLike, normals: ArrayLike, mu: float = 0.5,
                     radius: float = DEFAULT_RADIUS, edges: int = 8) -> dict:
    """Everything a ranking needs about one grasp's contacts (object frame).

    Returns
    -------
    dict
        ``uncertainty`` (k,) rad (:func:`normal_uncertainty`), ``epsilon`` (the nominal
        epsilon, :func:`robust_epsilon` with zero uncertainty), ``robust_epsilon``, and
        ``margin = robust_epsilon / epsilon`` in [0, 1] (0 when ``epsilon`` is 0): the share
        of the grasp's wrench margin that survives its uncertain normals.
    """
    pts = _points(points, "points")
    unc = normal_uncertainty(obj, pts, radius)
    nominal = robust_epsilon(obj, pts, normals, mu, np.zeros(len(pts)), edges)
    robust = robust_epsilon(obj, pts, normals, mu, unc, edges)
    margin = min(1.0, robust / nominal) if nominal > 0.0 else 0.0
    return {"uncertainty": unc, "epsilon": nominal, "robust_epsilon": robust, "margin": margin}
