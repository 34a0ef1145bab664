"""Grasp quality measures: polygon shape, antipodality, force balance, Ferrari-Canny epsilon.

Paper section 4.4 (eq. 8-12) and the "Fitness" section of the design. All lengths are in
metres; the polygon angles of eq. 8-10 are in degrees, as in the paper (they only enter the
dimensionless ratio Q).

Batch functions (``polygon_shape_q``, ``antipodal_score``, ``force_balance_residual``) take
the contacts of a whole swarm at once:

- ``points`` : (P, F, 3) float, m -- contact point of each finger slot (object frame);
- ``mask`` : (P, F) bool -- which slots are in contact; ``nc = mask.sum(1)``;
- ``normals`` : (P, F, 3) float -- unit *outward* surface normals at the contacts;
- ``com`` : (3,) float, m -- centre of mass, same frame as the points.

Values in masked-out slots are never read (they may hold NaN). The batch functions are
vectorised over particles (no per-particle Python loop): they run on every evaluation of the
swarm. ``epsilon_quality`` (one grasp) and ``epsilon_quality_batch`` (a loop over it) build a
6-D convex hull with qhull and are meant for the final candidates only.

Formulas
--------
Polygon shape (eq. 8-10), for ``nc >= 3``::

    theta_bar = 180 (nc - 2) / nc
    theta_max = (nc - 2) (180 - theta_bar) + 2 theta_bar
    Q = clip(sum_i |theta_i - theta_bar| / theta_max, 0, 1)

where ``theta_i`` (degrees, in [0, 360)) are the internal angles of the polygon obtained by
projecting the contacts on their least-squares plane and ordering them by angle around their
centroid. ``Q = 0`` is the regular polygon, ``Q = 1`` the degenerate (flat) one; the fitness
uses ``1 - Q``. Coincident contacts (in the plane) give ``Q = 1``.

Antipodality, for ``nc == 2`` (contacts p1, p2, outward normals n1, n2,
``u = (p2 - p1) / |p2 - p1|``)::

    A = ( (1 - n1.n2) / 2 + max(0, -n1.u) + max(0, n2.u) ) / 3

Each of the three terms is in [0, 1] and equals 1 for a perfect pinch: the normals are
opposed and each finger's pushing direction (-n) points along the line toward the other
contact. Normals on the wrong side of the line (for example both contacts on the same face)
score 0 in the corresponding term instead of being rewarded, as ``|n.u|`` would.

Force balance (eq. 11-12): finger i pushes along ``v_i = (com - p_i) / |com - p_i|``::

    R = |sum_i v_i| / nc       (0 balanced ... 1 all fingers pushing the same way)

Ferrari-Canny L1 epsilon: see :func:`epsilon_quality`.
"""

from __future__ import annotations

import math
from typing import Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import nnls
from scipy.spatial import ConvexHull

from . import kernels as quality_kernels

try:  # scipy >= 1.8 exposes QhullError here
    from scipy.spatial import QhullError
except ImportError:  # pragma: no cover - very old scipy
    from scipy.spatial.qhull import QhullError  # type: ignore[no-redef]

__all__ = [
    "polygon_shape_q",
    "antipodal_score",
    "force_balance_residual",
    "epsilon_quality",
    "epsilon_quality_batch",
    "closure_wrenches",
    "origin_may_be_inside",
    "hull_epsilon",
    "hull_only_epsilon",
    "FORCE_CLOSURE_EPS",
    "COINCIDENT_RTOL",
    "COINCIDENT_ATOL",
]

#: Epsilon values at or below this are treated as 0 (not force closure).
FORCE_CLOSURE_EPS: float = 1e-9
#: Contacts closer than this fraction of the polygon size (in the fitted plane) are coincident.
COINCIDENT_RTOL: float = 1e-9
#: Absolute size (m) below which a contact set is a single point (or a pair has no line).
COINCIDENT_ATOL: float = 1e-12


# --------------------------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------------------------
def _float_array(value: ArrayLike, name: str) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a float array ({exc})") from None
    return arr


def _check_batch(
    points: ArrayLike, mask: ArrayLike
) -> Tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Validate batch contacts; return float64 points (P, F, 3) and bool mask (P, F)."""
    pts = _float_array(points, "points")
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise ValueError(f"points: expected (P, F, 3), got {pts.shape}")
    msk = np.asarray(mask)
    if msk.dtype != np.bool_:
        raise ValueError(f"mask: expected a boolean array, got dtype {msk.dtype}")
    if msk.shape != pts.shape[:2]:
        raise ValueError(f"mask: expected {pts.shape[:2]} to match points, got {msk.shape}")
    return pts, msk


def _check_normals(normals: ArrayLike, shape: Tuple[int, ...]) -> NDArray[np.float64]:
    nrm = _float_array(normals, "normals")
    if nrm.shape != shape:
        raise ValueError(f"normals: expected {shape} to match points, got {nrm.shape}")
    return nrm


def _check_com(com: ArrayLike) -> NDArray[np.float64]:
    c = _float_array(com, "com")
    if c.shape != (3,):
        raise ValueError(f"com: expected (3,), got {c.shape}")
    if not np.isfinite(c).all():
        raise ValueError("com: must be finite")
    return c


def _check_friction(mu: float, edges: int, torque_scale: Optional[float]) -> int:
    try:
        mu_f = float(mu)
    except (TypeError, ValueError):
        raise ValueError(f"mu: expected a positive number, got {mu!r}") from None
    if not (math.isfinite(mu_f) and mu_f > 0.0):
        raise ValueError(f"mu: friction coefficient must be finite and > 0, got {mu!r}")
    if isinstance(edges, (bool, np.bool_)) or not isinstance(edges, (int, np.integer)):
        raise ValueError(f"edges: expected an integer >= 3, got {edges!r}")
    if edges < 3:
        raise ValueError(f"edges: friction cone needs >= 3 edges, got {edges}")
    if torque_scale is not None:
        try:
            ts = float(torque_scale)
        except (TypeError, ValueError):
            raise ValueError(
                f"torque_scale: expected a positive number, got {torque_scale!r}"
            ) from None
        if not (math.isfinite(ts) and ts > 0.0):
            raise ValueError(f"torque_scale: must be finite and > 0 (m), got {torque_scale!r}")
    return int(edges)


def _masked(arr: NDArray[np.float64], msk: NDArray[np.bool_], name: str) -> NDArray[np.float64]:
    """Zero the masked-out slots of a (P, F, 3) array and check the kept ones are finite."""
    out = np.where(msk[..., None], arr, 0.0)
    if not np.isfinite(out).all():
        raise ValueError(f"{name}: values of in-contact fingers must be finite")
    return out


# --------------------------------------------------------------------------------------------
# polygon shape, eq. 8-10
# --------------------------------------------------------------------------------------------
def polygon_shape_q(points: ArrayLike, mask: ArrayLike) -> NDArray[np.float64]:
    """Contact-polygon regularity Q of eq. 8-10 for a batch of grasps.

    For each particle the ``nc`` contact points are centred, projected onto their best-fit
    plane (the two principal directions of their scatter matrix, i.e. the SVD of the centred
    points) and ordered by angle around the centroid. Because the centroid is the mean of the
    points, no angular gap exceeds 180 degrees, so this ordering is a counter-clockwise,
    star-shaped polygon; its internal angle at vertex i is the counter-clockwise angle from
    edge (p_i -> p_i+1) to edge (p_i -> p_i-1), in [0, 360) degrees (reflex angles > 180 occur
    for non-convex orderings). Then, with ``theta_bar = 180 (nc - 2) / nc`` and
    ``theta_max = (nc - 2)(180 - theta_bar) + 2 theta_bar`` (both degrees)::

        Q = clip(sum_i |theta_i - theta_bar| / theta_max, 0, 1)

    ``theta_max`` is the deviation of the fully flat polygon (nc - 2 angles of 180 and two of
    0), so Q is 0 for the regular polygon and 1 for a degenerate one.

    Parameters
    ----------
    points : (P, F, 3) array_like of float, m
        Contact points per particle and finger slot. Masked-out slots are ignored (may be NaN).
    mask : (P, F) array_like of bool
        True where the finger is in contact.

    Returns
    -------
    q : (P,) ndarray of float, dimensionless
        Q in [0, 1] for particles with ``nc >= 3``; NaN when ``nc < 3`` (use
        :func:`antipodal_score` for ``nc == 2``). Particles whose contacts coincide in the
        fitted plane (closer than ``COINCIDENT_RTOL`` times the polygon radius) get 1.

    Raises
    ------
    ValueError
        If ``points`` is not (P, F, 3), ``mask`` not a matching bool array, or an in-contact
        point is not finite.
    """
    pts, msk = _check_batch(points, mask)
    sel = msk.sum(axis=1) >= 3
    _masked(pts[sel], msk[sel], "points")  # the polygons' points must be finite
    q = np.empty(msk.shape[0])
    quality_kernels.polygon_batch(np.ascontiguousarray(pts), np.ascontiguousarray(msk), COINCIDENT_RTOL,
                                  COINCIDENT_ATOL, q)
    return q


# --------------------------------------------------------------------------------------------
# antipodality (nc == 2)
# --------------------------------------------------------------------------------------------
def antipodal_score(points: ArrayLike, normals: ArrayLike, mask: ArrayLike) -> NDArray[np.float64]:
    """Antipodality of two-contact grasps, in [0, 1] (1 best).

    With the two contacts p1, p2 (in slot order), their outward unit normals n1, n2 and
    ``u = (p2 - p1) / |p2 - p1|``::

        A = ( (1 - n1.n2) / 2 + max(0, -n1.u) + max(0, n2.u) ) / 3

    The first term is 1 when the normals are exactly opposed; the other two are 1 when each
    finger's pushing direction ``-n`` points along the line toward the other contact (and 0
    when the normal lies on the wrong side of the line). So A = 1 exactly for the ideal
    pinch, and decreases to 0 (for example two contacts with equal normals perpendicular to
    the line joining them). The value does not depend on which contact is called 1.
    Normals are re-normalised; coincident contacts (no line) give 0.

    Parameters
    ----------
    points : (P, F, 3) array_like of float, m
        Contact points; masked-out slots are ignored (may be NaN).
    normals : (P, F, 3) array_like of float
        Outward unit surface normals at the contacts (re-normalised here).
    mask : (P, F) array_like of bool
        True where the finger is in contact.

    Returns
    -------
    score : (P,) ndarray of float, dimensionless
        A in [0, 1] where ``nc == 2``, NaN elsewhere.

    Raises
    ------
    ValueError
        On badly shaped inputs, non-finite or zero-length in-contact values.
    """
    pts, msk = _check_batch(points, mask)
    nrm = _check_normals(normals, pts.shape)
    sel = msk.sum(axis=1) == 2
    _masked(pts[sel], msk[sel], "points")
    n = _masked(nrm[sel], msk[sel], "normals")
    if np.any(np.linalg.norm(n, axis=-1)[msk[sel]] <= 0.0):
        raise ValueError("normals: zero-length normal at an in-contact finger")
    out = np.empty(msk.shape[0])
    quality_kernels.antipodal_batch(np.ascontiguousarray(pts), np.ascontiguousarray(nrm), np.ascontiguousarray(msk),
                                    COINCIDENT_ATOL, out)
    return out


# --------------------------------------------------------------------------------------------
# force balance, eq. 11-12
# --------------------------------------------------------------------------------------------
def force_balance_residual(
    points: ArrayLike, mask: ArrayLike, com: ArrayLike
) -> NDArray[np.float64]:
    """Normalised residual of the unit finger forces directed at the centre of mass.

    Eq. 11-12: each in-contact finger pushes with a unit force along
    ``v_i = (com - p_i) / |com - p_i|``; a balanced grasp has ``sum_i v_i = 0``::

        R = |sum_i v_i| / nc

    A contact lying exactly on the centre of mass has no direction and contributes a zero
    force (it still counts in ``nc``).

    Parameters
    ----------
    points : (P, F, 3) array_like of float, m
        Contact points; masked-out slots are ignored (may be NaN).
    mask : (P, F) array_like of bool
        True where the finger is in contact.
    com : (3,) array_like of float, m
        Centre of mass, same frame as ``points``.

    Returns
    -------
    residual : (P,) ndarray of float, dimensionless
        R in [0, 1]: 0 balanced, 1 when all fingers push the same way (or ``nc == 0``).

    Raises
    ------
    ValueError
        On badly shaped inputs or non-finite in-contact points / com.
    """
    pts, msk = _check_batch(points, mask)
    c = _check_com(com)
    _masked(pts, msk, "points")
    out = np.empty(msk.shape[0])
    quality_kernels.balance_batch(np.ascontiguousarray(pts), np.ascontiguousarray(msk), c, out)
    return out


# --------------------------------------------------------------------------------------------
# Ferrari-Canny epsilon
# --------------------------------------------------------------------------------------------
def _cone_wrenches(
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    com: NDArray[np.float64],
    mu: float,
    edges: int,
    torque_scale: float,
) -> NDArray[np.float64]:
    """(nc * edges, 6) unit-force primitive wrenches of the linearised friction cones."""
    inward = -normals  # force direction into the object
    helper = np.where(np.abs(inward[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(inward, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(inward, t1)
    half = math.atan(mu)
    phi = 2.0 * math.pi * np.arange(edges) / edges
    tangential = (
        np.cos(phi)[None, :, None] * t1[:, None, :] + np.sin(phi)[None, :, None] * t2[:, None, :]
    )
    # (nc, edges, 3), unit vectors on the cone surface
    forces = math.cos(half) * inward[:, None, :] + math.sin(half) * tangential
    arms = (points - com)[:, None, :]
    torques = np.cross(arms, forces) / torque_scale
    return np.concatenate([forces, torques], axis=-1).reshape(-1, 6)


#: Least distance-like residual (dimensionless) of :func:`origin_may_be_inside` that
#: proves the origin outside the wrench hull; a round-off residual is about 1e-15.
OUTSIDE_RESIDUAL = 1e-9


def origin_may_be_inside(wrenches: NDArray[np.float64]) -> bool:
    """False when the origin is certainly outside the convex hull of ``wrenches`` (n, 6).

    The cheap test before qhull (about 25 us against several ms for 40 wrenches in 6-D):
    non-negative least squares of ``sum_i l_i w_i = 0`` with ``sum_i l_i = 1`` appended
    as a row. A convex combination reaching the origin gives residual 0; an origin at
    distance ``delta`` from the hull leaves a residual of at least ``delta / sqrt(1 +
    delta^2)``. Most runner-up grasps the planner screens are not force closure and stop
    here; the qhull verdict is unchanged (epsilon needs the hull anyway).
    """
    a = np.vstack([wrenches.T, np.ones(len(wrenches))])
    b = np.zeros(7)
    b[6] = 1.0
    try:
        _, residual = nnls(a, b)
    except (RuntimeError, ValueError):  # no convergence: let qhull decide
        return True
    return bool(residual <= OUTSIDE_RESIDUAL)


def epsilon_quality(
    points: ArrayLike,
    normals: ArrayLike,
    com: ArrayLike,
    mu: float = 0.5,
    edges: int = 8,
    torque_scale: Optional[float] = None,
) -> Tuple[float, bool]:
    """Ferrari-Canny L1 epsilon quality and force closure of one grasp.

    Point contacts with Coulomb friction. At contact i the friction cone points into the
    object (axis ``-n_i``) with half-angle ``atan(mu)``, linearised by ``edges`` unit force
    vectors on its surface (an inscribed pyramid, so slightly conservative). Each edge force
    ``f`` gives the primitive wrench ``[f, (p_i - com) x f / torque_scale]``. The L1 grasp
    wrench space is the convex hull of all ``nc * edges`` primitive wrenches (6-D, qhull via
    :class:`scipy.spatial.ConvexHull`); epsilon is the radius of the largest origin-centred
    ball inside it, i.e. the smallest distance from the origin to a facet hyperplane, when the
    origin is strictly inside (all facet offsets negative). Otherwise epsilon is 0.

    ``torque_scale`` (m) makes torques commensurate with forces. Default: the largest
    distance of the contacts from ``com``, ``max_i |p_i - com|`` (then every torque
    component is at most 1, like the forces); the planner passes the object's characteristic
    radius instead, so grasps on one object share a scale.

    Epsilon is exactly invariant under translations of the whole grasp, contact order and
    uniform scaling (when ``torque_scale`` scales too). The pyramid's phase about each cone
    axis a = -n is set by a fixed helper axis (first tangent ``a x e_x``, or ``a x e_y`` when
    ``|a_x| >= 0.9``), so under rotations epsilon is invariant only up to the linearisation:
    measured within 3 % with 8 edges, 1 % with 16.

    Parameters
    ----------
    points : (nc, 3) array_like of float, m
        Contact points.
    normals : (nc, 3) array_like of float
        Outward unit surface normals at the contacts (re-normalised here).
    com : (3,) array_like of float, m
        Centre of mass (torque reference point).
    mu : float, default 0.5
        Coulomb friction coefficient, > 0.
    edges : int, default 8
        Edges of the linearised friction cone, >= 3.
    torque_scale : float or None, m
        Torque normalisation length, > 0; None for the default above.

    Returns
    -------
    epsilon : float
        Epsilon quality (dimensionless: unit total normal force), 0.0 when not force closure.
    force_closure : bool
        ``epsilon > FORCE_CLOSURE_EPS`` (1e-9).

    Raises
    ------
    ValueError
        On bad shapes, non-finite values, zero normals, ``mu <= 0``, ``edges < 3`` or
        ``torque_scale <= 0``. Rank-deficient contact sets (no contact, one or two contacts,
        all normals through one line, ...) are not errors: they return ``(0.0, False)``.
    """
    wrenches = closure_wrenches(points, normals, com, mu, edges, torque_scale)
    eps = 0.0 if wrenches is None else hull_epsilon(wrenches)
    return eps, eps > 0.0


def closure_wrenches(
    points: ArrayLike,
    normals: ArrayLike,
    com: ArrayLike,
    mu: float = 0.5,
    edges: int = 8,
    torque_scale: Optional[float] = None,
) -> Optional[NDArray[np.float64]]:
    """The primitive wrenches (nc * edges, 6) whose hull :func:`epsilon_quality` measures
    (arguments and errors as there); None when the grasp cannot be force closure whatever
    the hull (fewer than three contacts, or every contact at the centre of mass)."""
    edges_i = _check_friction(mu, edges, torque_scale)
    pts = _float_array(points, "points")
    nrm = _float_array(normals, "normals")
    c = _check_com(com)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points: expected (nc, 3), got {pts.shape}")
    if nrm.shape != pts.shape:
        raise ValueError(f"normals: expected {pts.shape} to match points, got {nrm.shape}")
    if not np.isfinite(pts).all():
        raise ValueError("points: must be finite")
    if not np.isfinite(nrm).all():
        raise ValueError("normals: must be finite")
    n_len = np.linalg.norm(nrm, axis=1)
    if np.any(n_len <= 0.0):
        raise ValueError("normals: zero-length normal")
    if pts.shape[0] < 3:
        # One or two point contacts never enclose the origin in 6-D: no force at them has
        # a moment about the line through them, so every wrench lies in a hyperplane.
        return None
    nrm = nrm / n_len[:, None]

    if torque_scale is None:
        scale = float(np.linalg.norm(pts - c, axis=1).max())
    else:
        scale = float(torque_scale)
    if not scale > 0.0:  # every contact at the com: no torque at all
        return None
    return _cone_wrenches(pts, nrm, c, float(mu), edges_i, scale)


def hull_epsilon(wrenches: NDArray[np.float64]) -> float:
    """Radius of the largest origin-centred ball inside the convex hull of ``wrenches``
    (n, 6): the smallest distance from the origin to a facet hyperplane when the origin is
    strictly inside, else 0.0 (also at or below :data:`FORCE_CLOSURE_EPS`). The quick test
    (:func:`origin_may_be_inside`) first; qhull only when the origin may be inside."""
    if not origin_may_be_inside(wrenches):
        return 0.0  # the hull would find the origin outside too
    return hull_only_epsilon(wrenches)


#: Qhull's options for the wrench hull, tried first: no facet merging. Qhull's default in
#: 6-D (``Qt Qx``: merged facets) builds the ~1,000 facets of 32 cone edges in about 4.5 ms,
#: without merging in about 1.4 ms; every facet is still a supporting hyperplane of the
#: hull, so the least facet distance is the same (measured on 418 wrench sets of the paper
#: hand, the Shadow and the Inspire hands on 8 objects: at most 4e-16 apart). Where it
#: cannot (a precision error of nearly coplanar wrenches, 13 of the 418) the default decides.
FAST_HULL_OPTIONS = "Q0"


def hull_only_epsilon(wrenches: NDArray[np.float64]) -> float:
    """:func:`hull_epsilon` without its quick test (for a caller that made it)."""
    try:
        hull = ConvexHull(wrenches, qhull_options=FAST_HULL_OPTIONS)
    except (QhullError, ValueError):
        try:
            hull = ConvexHull(wrenches)
        except (QhullError, ValueError):
            return 0.0  # lower-dimensional wrench set: cannot contain a 6-D ball
    offsets = hull.equations[:, -1]  # unit facet normals; inside means n.x + offset <= 0
    if not np.all(offsets < 0.0):
        return 0.0
    eps = float(-offsets.max())
    return eps if eps > FORCE_CLOSURE_EPS else 0.0


def epsilon_quality_batch(
    points: ArrayLike,
    normals: ArrayLike,
    mask: ArrayLike,
    com: ArrayLike,
    mu: float = 0.5,
    edges: int = 8,
    torque_scale: Optional[float] = None,
) -> Tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`epsilon_quality` for each particle of a batch (a Python loop: final candidates).

    Parameters
    ----------
    points : (P, F, 3) array_like of float, m
        Contact points; masked-out slots are ignored (may be NaN).
    normals : (P, F, 3) array_like of float
        Outward unit surface normals.
    mask : (P, F) array_like of bool
        True where the finger is in contact.
    com : (3,) array_like of float, m
        Centre of mass.
    mu, edges, torque_scale
        As in :func:`epsilon_quality` (the default torque scale is per particle).

    Returns
    -------
    epsilon : (P,) ndarray of float
        Epsilon quality, 0 where not force closure.
    force_closure : (P,) ndarray of bool

    Raises
    ------
    ValueError
        As :func:`epsilon_quality`, and on mismatched batch shapes.
    """
    _check_friction(mu, edges, torque_scale)
    pts, msk = _check_batch(points, mask)
    nrm = _check_normals(normals, pts.shape)
    c = _check_com(com)
    eps = np.zeros(msk.shape[0])
    fc = np.zeros(msk.shape[0], dtype=bool)
    for i in range(msk.shape[0]):
        eps[i], fc[i] = epsilon_quality(
            pts[i][msk[i]], nrm[i][msk[i]], c, mu=mu, edges=edges, torque_scale=torque_scale
        )
    return eps, fc


def normal_wrench_residual(
    points: np.ndarray, normals: np.ndarray, mask: np.ndarray, com: np.ndarray, torque_scale: float,
    min_share: float = 0.0,
) -> np.ndarray:
    """Distance from the origin to the convex hull of the contacts' normal wrenches.

    Each contact pushes along its inward normal (the axis of its friction cone); its unit
    wrench is ``w_i = [-n_i, (p_i - com) x (-n_i) / torque_scale]``. The result is 0 when
    some non-negative squeeze along the normals balances both force and torque; with
    friction and three or more non-collinear contacts such a grasp is force closure
    (the squeeze lies strictly inside every cone). It grows as the best squeeze leaves
    a net wrench. Exact: the min-norm point of at most F points is found by enumerating
    the faces spanned by subsets of contacts (26 of two or more for F = 5; compiled,
    :func:`grasp_apso.quality.kernels.wrench_batch`).

    Parameters
    ----------
    points, normals : (P, F, 3) float (m; outward unit normals)
    mask : (P, F) bool
    com : (3,) float, m
    torque_scale : float, m (characteristic radius of the object)
    min_share : float in [0, 1)
        Every contact must carry at least ``min_share / nc`` of the squeeze. With 0 a
        balanced subset suffices (contacts may carry nothing); force closure needs every
        contact loaded (an internal force strictly inside every cone), so the planner
        uses 0.25: a squeeze of two opposed fingers with three more pushing one way is
        then not balanced. Implemented by shifting the points: with weights
        ``a_i = delta + (1 - nc delta) b_i``, ``sum a_i w_i`` is a convex combination of
        ``(1 - nc delta) w_i + delta sum_j w_j``.

    Returns
    -------
    (P,) float >= 0 (inf for particles with no contact)
    """
    points, mask = _check_batch(points, mask)
    normals = _check_normals(normals, points.shape)
    com = _check_com(com)
    if not torque_scale > 0:
        raise ValueError(f"torque_scale: expected > 0, got {torque_scale!r}")
    if not 0.0 <= min_share < 1.0:
        raise ValueError(f"min_share: expected [0, 1), got {min_share!r}")
    _masked(points, mask, "points")
    _masked(normals, mask, "normals")
    best = np.empty(mask.shape[0])
    quality_kernels.wrench_batch(np.ascontiguousarray(points), np.ascontiguousarray(normals),
                                 np.ascontiguousarray(mask), com, float(torque_scale), float(min_share), best)
    return best
