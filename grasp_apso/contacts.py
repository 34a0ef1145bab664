"""Decoding particles into grasps: the paper's "forward direction" (section 2).

For every particle: place the wrist, set the pre-shape, close each finger along its
flexion until one of its links meets the surface (or its joint limits are reached),
compute the joint angles with the kinematic model, and detect fingertip contacts,
penetrations and finger-finger collisions. Everything is batched over particles and
fingers; the surface is the object's :class:`~grasp_apso.sdf.SignedDistanceGrid`.

Particle layout (D = 19, SI): the 18 values of Cg (see :mod:`grasp_apso.hand`) and the
standoff offset (m) added to the computed wrist standoff.

Closing motion: finger i moves from its pre-shape ``(theta_i1, theta_i2)`` linearly to
the upper limits of both flexions, ``theta(s) = pre + s * (upper - pre)``, ``s`` in
[0, 1], pivot fixed. The first ``s`` at which any link sphere of the finger touches the
surface is found by a coarse sweep and a regula falsi. The finger stops there: if its
fingertip pad is then within ``tolerance`` of the surface it is a fingertip contact;
if another link touched first, the finger is stopped with no fingertip contact. A
finger that meets nothing closes to its limits. Illegal fingers, the cases the GRG
verification test regenerates: *blocked* (already penetrating the object at its
pre-shape), a link deeper than ``max_penetration`` into the object, a proximal or middle
link touching the object (the paper plans precision grasps: only fingertips touch),
capsules overlapping another finger, the finger folded into itself, or a finger through
the palm.

Wrist position (computed apart, as the paper says): the palm's ``grasp_center`` is
aimed at the object's centre of mass along the palm normal, at a standoff that puts the
object's nearest point (its support along the palm normal) ``clearance + offset`` above
the palm face. A caller may instead fix the wrist position.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .collision import finger_collisions, palm_penetration
from .hand import N_FINGERS, HandModel, wrist_rotation
from .sdf import SignedDistanceGrid, cached_sdf_grid

#: Index of the standoff offset in a particle.
STANDOFF_INDEX = 18
N_DIMS = 19

# Points along the links checked while closing: (link, fraction). The last one is the
# fingertip pad centre. The finger base (link 0, fraction 0) does not move while closing
# and is checked at the final pose only.
# Spacing about 11 mm for 9 mm radii: a capsule may dip up to about 2 mm into the surface
# between two spheres while sweeping; the dense final check catches that.
_SWEEP_POINTS = np.array(
    [[0, 0.25], [0, 0.5], [0, 0.75], [0, 1.0], [1, 1 / 3], [1, 2 / 3], [1, 1.0],
     [2, 1 / 3], [2, 2 / 3], [2, 1.0]]
)
# Final check of the closed pose: base, joints, and spheres every ~4 mm (the capsule is
# covered to within 0.3 mm); the last point is the pad.
_FINAL_POINTS = np.array(
    [[0, 0.0]] + [[0, f] for f in np.linspace(1 / 12, 1.0, 12)]
    + [[1, f] for f in np.linspace(1 / 8, 1.0, 8)] + [[2, f] for f in np.linspace(1 / 7, 1.0, 7)]
)
_JOINT_INDEX = [0, 12, 20, 27]  # base, PIP, DIP, tip in _FINAL_POINTS
_NON_TIP_LINKS = slice(1, 18)     # proximal link and first 5/8 of the middle link (not the knuckle)
_CLEAR_OF_PALM = slice(7, 28)     # from the middle of the proximal link to the pad
# Coarse sweep steps evaluated at once; fingers that touched leave the sweep between chunks.
_SWEEP_CHUNK = 6


def _link_coefficients(points: np.ndarray) -> np.ndarray:
    """(3, K): a point (link k, fraction f) is sum_j C[j] * segment_j of the planar chain."""
    coeff = np.zeros((3, len(points)))
    for col, (link, frac) in enumerate(points):
        coeff[: int(link), col] = 1.0
        coeff[int(link), col] = frac
    return coeff


_SWEEP_COEFF = _link_coefficients(_SWEEP_POINTS)
_FINAL_COEFF = _link_coefficients(_FINAL_POINTS)


@dataclass(frozen=True)
class ContactSettings:
    """Tunables of decoding (SI units).

    Attributes
    ----------
    tolerance : float, m
        A fingertip pad within this distance of the surface is in contact; a finger
        deeper than this into the object at its pre-shape is blocked.
    max_penetration : float, m
        A link sphere deeper than this into the object after closing makes the particle
        illegal (closing stops at the surface, so only static parts, the knuckles, can).
    clearance : float, m
        Gap between the palm face and the object for the computed wrist position; the
        knuckle spheres protrude about 7 mm above the palm face.
    standoff_max : float, m
        Upper bound of the particle's standoff offset (its lower bound is 0).
    coarse_steps : int
        Samples of the closing sweep.
    refine_steps : int
        Regula falsi steps after the sweep (the finger stops on the free side of the
        first touch, within about 0.3 mm of it).
    finger_overlap : float, m
        Overlap allowed between capsules of different fingers (soft skin).
    link_contact_tolerance : float, m
        A proximal or middle link this close to the surface touches the object.
    allow_link_contacts : bool
        False (default, the paper's precision grasps: only fingertips touch): a finger
        whose proximal or middle link touches the object is illegal.
    palm_overlap : float, m
        Depth a finger may sink into the palm box (soft skin) before it collides.
    """

    tolerance: float = 0.002
    max_penetration: float = 0.0005
    clearance: float = 0.008
    standoff_max: float = 0.05
    coarse_steps: int = 12
    refine_steps: int = 3
    finger_overlap: float = 0.002
    link_contact_tolerance: float = 0.001
    allow_link_contacts: bool = False
    palm_overlap: float = 0.003

    def __post_init__(self) -> None:
        checks = {
            "tolerance": 0 < self.tolerance <= 0.02,
            "max_penetration": 0 <= self.max_penetration <= 0.02,
            "clearance": 0 <= self.clearance <= 0.05,
            "standoff_max": 0 < self.standoff_max <= 0.5,
            "coarse_steps": 2 <= self.coarse_steps <= 200,
            "refine_steps": 0 <= self.refine_steps <= 30,
            "finger_overlap": 0 <= self.finger_overlap <= 0.01,
            "link_contact_tolerance": 0 <= self.link_contact_tolerance <= 0.01,
            "palm_overlap": 0 <= self.palm_overlap <= 0.02,
        }
        for name, ok in checks.items():
            if not ok:
                raise ValueError(f"contact settings: {name} = {getattr(self, name)!r} is out of range")


@dataclass(frozen=True)
class GraspModel:
    """Everything fixed during a plan: hand, object, its distance grid, settings.

    Build it with :func:`make_grasp_model`. ``obj`` is a
    :class:`~grasp_apso.objects.GraspObject` (mesh, centre of mass, hull vertices).
    """

    hand: HandModel
    obj: object
    sdf: SignedDistanceGrid
    settings: ContactSettings
    lower: np.ndarray = field(repr=False)
    upper: np.ndarray = field(repr=False)
    point_radii: np.ndarray = field(repr=False)
    sweep_radii: np.ndarray = field(repr=False)
    support_points: np.ndarray = field(repr=False)

    @property
    def dims(self) -> int:
        return N_DIMS


def make_grasp_model(hand: HandModel, obj, settings: ContactSettings | None = None) -> GraspModel:
    """Prepare an object for planning: its signed-distance grid (cached by mesh hash).

    Parameters
    ----------
    hand : HandModel
    obj : GraspObject
    settings : ContactSettings, optional
    """
    settings = settings or ContactSettings()
    # Decisions are made within a link radius plus the tolerance of the surface; the
    # padding covers that with margin (farther points read an over-estimate).
    grid = cached_sdf_grid(obj.mesh, obj.mesh_hash, padding=0.025)
    lower = np.concatenate([hand.lower, [0.0]])
    upper = np.concatenate([hand.upper, [settings.standoff_max]])
    final_radii = np.array([hand.link_radii[int(k)] for k, _ in _FINAL_POINTS])
    sweep_radii = np.array([hand.link_radii[int(k)] for k, _ in _SWEEP_POINTS])
    final_radii[-1] = sweep_radii[-1] = hand.pad_radius
    for arr in (lower, upper, final_radii, sweep_radii):
        arr.flags.writeable = False
    return GraspModel(
        hand=hand, obj=obj, sdf=grid, settings=settings, lower=lower, upper=upper,
        point_radii=final_radii, sweep_radii=sweep_radii, support_points=_support_points(obj),
    )


def _support_points(obj, n_directions: int = 2000) -> np.ndarray:
    """Hull vertices (relative to the centre of mass) that are extreme along a fixed set
    of directions: the support function of a dense hull at a fraction of the cost
    (under-estimated by about R * 0.003 between the directions, far below the clearance)."""
    hull = np.asarray(obj.hull_vertices, dtype=float) - np.asarray(obj.center_of_mass, dtype=float)
    if len(hull) > 200:
        k = np.arange(n_directions) + 0.5
        polar = np.arccos(1.0 - 2.0 * k / n_directions)
        azimuth = np.pi * (1.0 + 5.0**0.5) * k
        dirs = np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], 1)
        hull = hull[np.unique(np.argmax(hull @ dirs.T, axis=0))]
    hull = np.ascontiguousarray(hull)
    hull.flags.writeable = False
    return hull


@dataclass(frozen=True)
class DecodedGrasps:
    """Batch of decoded particles (object frame, SI units).

    Attributes
    ----------
    closed : (P, 19) float
        The closed configurations (flexions at the stop of the closing motion).
    wrist : (P, 4, 4) float
        Palm frame in the object frame.
    joints : (P, 5, 4, 3) float, m
        Base, PIP, DIP and tip points of each finger, closed.
    tip_gap : (P, 5) float, m
        Clearance of each fingertip pad from the surface where its closing motion stopped
        (negative: inside); guides particles without contacts toward contact.
    contact : (P, 5) bool
        Fingertip contacts.
    contact_points, contact_normals : (P, 5, 3) float
        Surface point under each pad and the outward normal there (all fingers).
    penetration : (P, 5) float, m
        Deepest penetration of any link sphere of each finger (0 when none).
    blocked : (P, 5) bool
        Finger penetrating the object already at its pre-shape.
    finger_collision : (P, 5) bool
        Finger colliding with another finger, with the palm, or folded into itself.
    link_contact : (P, 5) bool
        Finger touching the object with its proximal or middle link (not a precision
        contact; illegal unless the settings allow link contacts).
    palm_penetration : (P,) float, m
        Deepest penetration of the palm face into the object (fixed wrist only).
    """

    closed: np.ndarray
    wrist: np.ndarray
    joints: np.ndarray
    tip_gap: np.ndarray
    contact: np.ndarray
    contact_points: np.ndarray
    contact_normals: np.ndarray
    penetration: np.ndarray
    blocked: np.ndarray
    finger_collision: np.ndarray
    palm_penetration: np.ndarray
    link_contact: np.ndarray

    @property
    def n_contacts(self) -> np.ndarray:
        """(P,) int: fingertip contacts per particle."""
        return self.contact.sum(axis=1)

    def finger_illegal(self, max_penetration: float) -> np.ndarray:
        """(P, 5) bool: fingers the verification test rejects."""
        return self.blocked | self.finger_collision | self.link_contact | (self.penetration > max_penetration)

    def legal(self, max_penetration: float) -> np.ndarray:
        """(P,) bool: no illegal finger and no palm penetration."""
        return ~self.finger_illegal(max_penetration).any(axis=1) & (self.palm_penetration <= max_penetration)


def wrist_transforms(
    model: GraspModel, x: np.ndarray, wrist_position: np.ndarray | None = None
) -> np.ndarray:
    """Palm frames in the object frame for particles.

    Parameters
    ----------
    x : (P, 19) float
    wrist_position : (3,) float, m, optional
        Fixed wrist (palm origin) position in the object frame; computed when None.

    Returns
    -------
    (P, 4, 4) float
    """
    rot = wrist_rotation(x[:, 15:18])
    tf = np.zeros((len(x), 4, 4))
    tf[:, :3, :3] = rot
    tf[:, 3, 3] = 1.0
    if wrist_position is not None:
        tf[:, :3, 3] = np.asarray(wrist_position, dtype=float)
        return tf
    normal = rot[:, :, 2]
    com = np.asarray(model.obj.center_of_mass)
    support = (model.support_points @ (-normal.T)).max(axis=0)  # extent toward the palm
    hand = model.hand
    palm_face = hand.palm_center[2] + hand.palm_half_extents[2]
    height = palm_face + model.settings.clearance + x[:, STANDOFF_INDEX] + support
    local = hand.grasp_center[None, :] + height[:, None] * np.array([0.0, 0.0, 1.0])
    tf[:, :3, 3] = com - np.einsum("pij,pj->pi", rot, local)
    return tf


class _FingerBasis:
    """Flexion planes of all fingers in the object frame (float32 on the hot path).

    Flattened over (particle, finger) rows, F = P * 5, and component-major, so a subset of
    fingers (those still closing) is one fancy index.
    """

    def __init__(self, model: GraspModel, origin: np.ndarray, ex: np.ndarray, ey: np.ndarray):
        n = origin.shape[0]
        # Positions of ~0.1 m to ~10 nm: float32 halves the memory traffic.
        self.origin = np.ascontiguousarray(origin.reshape(-1, 3).T, dtype=np.float32)  # (3, F)
        self.ex = np.ascontiguousarray(ex.reshape(-1, 3).T, dtype=np.float32)
        self.ey = np.ascontiguousarray(ey.reshape(-1, 3).T, dtype=np.float32)
        self.lengths = np.tile(model.hand.link_lengths.astype(np.float32), (n, 1))  # (F, 3)
        self.ratio = float(model.hand.coupling_ratio)

    def points(
        self, distal: np.ndarray, proximal: np.ndarray, coeff: np.ndarray, rows: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y, z of link points.

        distal, proximal : (F', ...) float, rad -- flexions of the fingers ``rows`` (all F when None)
        coeff : (3, M) float -- link points as combinations of the three segments
        -> x, y, z : each (F', ..., M) float32, m, object frame
        """
        extra = distal.ndim - 1
        phi = np.stack([proximal, proximal + self.ratio * distal,
                        proximal + (self.ratio + 1.0) * distal], axis=-1).astype(np.float32)
        lengths = self.lengths if rows is None else self.lengths[rows]
        lengths = lengths.reshape((len(lengths),) + (1,) * extra + (3,))
        coeff = coeff.astype(np.float32)
        u = (lengths * np.cos(phi)) @ coeff
        v = (lengths * np.sin(phi)) @ coeff
        shape = (len(lengths),) + (1,) * (extra + 1)
        origin, ex, ey = ((self.origin, self.ex, self.ey) if rows is None
                          else (self.origin[:, rows], self.ex[:, rows], self.ey[:, rows]))
        x, y, z = (origin[c].reshape(shape) + u * ex[c].reshape(shape) + v * ey[c].reshape(shape)
                   for c in range(3))
        return x, y, z


def _close_fingers(
    model: GraspModel, basis: _FingerBasis, distal0: np.ndarray, proximal0: np.ndarray,
    d_span: np.ndarray, p_span: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Closing parameter of every finger: where it first touches the surface.

    The flexions close linearly from the pre-shape (s = 0) to the joint limits (s = 1).
    A coarse sweep of s finds the first step whose link spheres touch the object, in
    chunks: a finger that touched leaves the sweep (most touch in its first half);
    regula falsi (Illinois) then refines the bracket of the fingers that touched after
    s = 0, the clearance being smooth along the sweep.

    distal0, proximal0, d_span, p_span : (F,) float, rad
    -> s : (F,) float in [0, 1] (0 for fingers touching at the pre-shape, 1 for fingers
       meeting nothing), blocked : (F,) bool (deeper than max_penetration at s = 0)
    """
    sdf, settings = model.sdf, model.settings

    def min_clearance(s: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Smallest link clearance (m) of fingers ``rows`` at closing parameters s (F', ...)."""
        extra = (1,) * (s.ndim - 1)
        d = distal0[rows].reshape(-1, *extra) + s * d_span[rows].reshape(-1, *extra)
        p = proximal0[rows].reshape(-1, *extra) + s * p_span[rows].reshape(-1, *extra)
        return (sdf.distance_xyz(*basis.points(d, p, _SWEEP_COEFF, rows)) - model.sweep_radii).min(axis=-1)

    n_rows = len(distal0)
    steps = np.linspace(0.0, 1.0, settings.coarse_steps)
    first = np.full(n_rows, -1)              # first step that touches; -1: none yet
    c_first = np.zeros(n_rows)               # clearance there
    c_prev = np.zeros(n_rows)                # clearance one step before (valid when first > 0)
    blocked = np.zeros(n_rows, dtype=bool)
    last_clear = np.zeros(n_rows)            # clearance at the last step swept, per finger
    rows = np.arange(n_rows)
    for start in range(0, len(steps), _SWEEP_CHUNK):
        if len(rows) == 0:
            break
        chunk = steps[start:start + _SWEEP_CHUNK]
        clear = min_clearance(np.broadcast_to(chunk, (len(rows), len(chunk))), rows)  # (F', K')
        if start == 0:
            blocked[rows] = clear[:, 0] < -settings.max_penetration
        hit = clear <= 0.0
        any_hit = hit.any(axis=1)
        k = np.argmax(hit, axis=1)
        touched = rows[any_hit]
        k_hit = k[any_hit]
        first[touched] = start + k_hit
        c_first[touched] = clear[any_hit, k_hit]
        # The step before the first touch: in this chunk, or the last of the previous one.
        before = np.where(k_hit > 0, clear[any_hit, np.maximum(k_hit - 1, 0)], last_clear[touched])
        c_prev[touched] = before
        last_clear[rows] = clear[:, -1]
        rows = rows[~any_hit]

    any_hit = first >= 0
    refine = first > 0
    k_lo = np.maximum(first - 1, 0)
    lo = np.where(refine, steps[k_lo], np.where(any_hit, 0.0, 1.0))
    hi = np.where(refine, steps[np.maximum(first, 0)], lo)
    rows = np.flatnonzero(refine)
    lo_r, hi_r, c_lo, c_hi = lo[rows], hi[rows], c_prev[rows], c_first[rows]
    side = np.zeros(len(rows))
    for _ in range(settings.refine_steps):
        if len(rows) == 0:
            break
        denom = c_lo - c_hi
        frac = np.clip(c_lo / np.where(np.abs(denom) > 1e-12, denom, 1.0), 0.05, 0.95)
        mid = lo_r + frac * (hi_r - lo_r)
        c_mid = min_clearance(mid, rows)
        free = c_mid > 0.0
        hit_mid = ~free
        # Illinois: halve the stale end's value when the same side moves twice.
        c_hi = np.where(free & (side > 0), 0.5 * c_hi, c_hi)
        c_lo = np.where(hit_mid & (side < 0), 0.5 * c_lo, c_lo)
        lo_r, c_lo = np.where(free, mid, lo_r), np.where(free, c_mid, c_lo)
        hi_r, c_hi = np.where(hit_mid, mid, hi_r), np.where(hit_mid, c_mid, c_hi)
        side = np.where(free, 1.0, -1.0)
    lo[rows] = lo_r
    return lo, blocked


def decode(model: GraspModel, x: np.ndarray, wrist_position: np.ndarray | None = None) -> DecodedGrasps:
    """Decode particles into closed grasps (vectorised over particles and fingers).

    Parameters
    ----------
    model : GraspModel
    x : (P, 19) float
        Particles (pre-shapes, wrist angles, standoff offset); clamped to the bounds.
    wrist_position : (3,) float, m, optional
        Fixed wrist position in the object frame (operator path).

    Returns
    -------
    DecodedGrasps
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != N_DIMS:
        raise ValueError(f"x: expected (P, {N_DIMS}), got {x.shape}")
    if not np.all(np.isfinite(x)):
        row, col = np.argwhere(~np.isfinite(x))[0]
        raise ValueError(f"x: particle {row} value {col} is not finite")
    x = np.clip(x, model.lower, model.upper)
    hand, sdf, settings = model.hand, model.sdf, model.settings
    n = len(x)
    tol = settings.tolerance

    wrist = wrist_transforms(model, x, wrist_position)
    rot, trans = wrist[:, :3, :3], wrist[:, :3, 3]
    theta = x[:, :15].reshape(n, N_FINGERS, 3)
    distal0, proximal0, pivot = theta[..., 0], theta[..., 1], theta[..., 2]
    o_palm, ex_palm, ey_palm = hand.flexion_planes(pivot)
    basis = _FingerBasis(
        model,
        np.einsum("pij,pfj->pfi", rot, o_palm) + trans[:, None, :],
        np.einsum("pij,pfj->pfi", rot, ex_palm),
        np.einsum("pij,pfj->pfi", rot, ey_palm),
    )
    d_span = hand.upper[0:15:3] - distal0
    p_span = hand.upper[1:15:3] - proximal0
    distal0_f, proximal0_f = distal0.reshape(-1), proximal0.reshape(-1)
    d_span_f, p_span_f = d_span.reshape(-1), p_span.reshape(-1)
    s_f, blocked_f = _close_fingers(model, basis, distal0_f, proximal0_f, d_span_f, p_span_f)
    s, blocked = s_f.reshape(n, N_FINGERS), blocked_f.reshape(n, N_FINGERS)

    def final_points(s_final: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """(F', 28, 3) float32 link points of fingers ``rows`` closed to s_final (F',)."""
        sel = slice(None) if rows is None else rows
        d = distal0_f[sel] + s_final * d_span_f[sel]
        p = proximal0_f[sel] + s_final * p_span_f[sel]
        return np.stack(basis.points(d, p, _FINAL_COEFF, rows), axis=-1)

    def clearance_of(points: np.ndarray) -> np.ndarray:
        return sdf.distance_xyz(points[..., 0], points[..., 1], points[..., 2]) - model.point_radii

    pts = final_points(s_f)                     # (F, 28, 3)
    clearance = clearance_of(pts)
    tip_gap = clearance[..., -1].reshape(n, N_FINGERS).copy()  # of the closed pose, before re-opening
    # The sphere that stopped the finger is within the search resolution of the
    # surface; a pad within the tolerance is a fingertip contact.
    contact = ((tip_gap <= tol) & ~blocked
               & (clearance.min(axis=-1).reshape(n, N_FINGERS) >= -settings.max_penetration))
    # Fingers without a fingertip contact take no part in the precision grasp: they stay
    # at their pre-shape (closed to their limits they would fold into the palm or
    # themselves; stopped by a middle link they would not be a precision contact).
    s = np.where(contact, s, 0.0)
    reopened = np.flatnonzero((~contact).reshape(-1) & (s_f != 0.0))
    if len(reopened):
        pts[reopened] = final_points(np.zeros(len(reopened)), reopened)
        clearance[reopened] = clearance_of(pts[reopened])
    pts = pts.reshape(n, N_FINGERS, -1, 3)
    clearance = clearance.astype(np.float64).reshape(n, N_FINGERS, -1)
    distal = distal0 + s * d_span
    proximal = proximal0 + s * p_span
    penetration = np.maximum(0.0, -clearance.min(axis=-1))
    tips = pts[..., -1, :]
    surface, normals = sdf.closest_surface_point(tips)

    link_contact = (clearance[..., _NON_TIP_LINKS].min(axis=-1) <= settings.link_contact_tolerance) & ~blocked
    if settings.allow_link_contacts:
        link_contact = np.zeros_like(link_contact)

    joints = pts[..., _JOINT_INDEX, :]
    collide = finger_collisions(joints, np.array([*hand.link_radii[:2], hand.pad_radius]), settings.finger_overlap)
    # Fingers through the palm (a free finger closed to its limits can fold back into it).
    rel = (pts[..., _CLEAR_OF_PALM, :] - trans[:, None, None, :]).reshape(n, -1, 3)
    in_palm = (rel @ rot).reshape(n, N_FINGERS, -1, 3)  # rows: R^T (p - t)
    depth = palm_penetration(in_palm, hand.palm_center, hand.palm_half_extents)
    collide |= depth.max(axis=-1) > settings.palm_overlap

    closed = x.copy()
    closed[:, 0:15:3] = distal
    closed[:, 1:15:3] = proximal
    if wrist_position is None:
        palm_pen = np.zeros(n)
    else:
        palm_pen = _palm_penetration(model, wrist)
    return DecodedGrasps(
        closed=closed, wrist=wrist, joints=joints, tip_gap=tip_gap, contact=contact,
        contact_points=surface, contact_normals=normals, penetration=penetration,
        blocked=blocked, finger_collision=collide, palm_penetration=palm_pen,
        link_contact=link_contact,
    )


def _palm_penetration(model: GraspModel, wrist: np.ndarray) -> np.ndarray:
    """Deepest penetration (m) of points on the palm face into the object: (P,)."""
    hand = model.hand
    cx, cy, cz = hand.palm_center
    hx, hy, hz = hand.palm_half_extents
    gx, gy = np.meshgrid(np.linspace(cx - hx, cx + hx, 7), np.linspace(cy - hy, cy + hy, 7), indexing="ij")
    face = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, cz + hz)], axis=1)
    pts = np.einsum("pij,kj->pki", wrist[:, :3, :3], face) + wrist[:, None, :3, 3]
    return np.maximum(0.0, -model.sdf.distance(pts).min(axis=1))
