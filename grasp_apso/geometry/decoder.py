"""Decoding particles into grasps: the paper's "forward direction" (section 2).

For every particle: place the wrist, set the pre-shape, close each finger along its
flexion until one of its links meets the surface (or its joint limits are reached),
compute the joint angles with the kinematic model, and detect fingertip contacts,
penetrations and finger-finger collisions. Everything is batched over particles and
fingers; the surface is the object's :class:`~grasp_apso.geometry.sdf.SignedDistanceGrid`.

Particle layout (D = 19, SI): the 18 values of Cg (see :mod:`grasp_apso.model.hand`) and the
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

from dataclasses import dataclass, field, fields, replace

import numpy as np

from . import kernels
from .collision import finger_collisions
from .link_points import (
    APPROACH_INDEX, CLEAR_OF_PALM, FINAL_COEFF, FINAL_POINTS, JOINT_INDEX, NON_TIP_LINKS, SWEEP_COEFF, SWEEP_POINTS,
    uncovered_depth,
)
from .scene_margins import (
    approach_object_gaps, finger_grasp_margins, finger_path_margins, palm_scene_margins, trace_approaches,
)
from ..model.hand import N_FINGERS, HandModel, wrist_rotation
from ..model.particle import LAYOUT
from .contact_settings import ContactSettings
from .normal_spread import NormalSpreadGrid, cached_normal_spread_grid
from .sdf import SignedDistanceGrid, cached_sdf_grid

#: Particle size and standoff index (named slices: :data:`grasp_apso.model.particle.LAYOUT`).
STANDOFF_INDEX = LAYOUT.standoff
N_DIMS = LAYOUT.dims

@dataclass(frozen=True)
class GraspModel:
    """Everything fixed during a plan: hand, object, its distance grid, settings.

    Build it with :func:`make_grasp_model`. ``obj`` is a
    :class:`~grasp_apso.model.objects.GraspObject` (mesh, centre of mass, hull vertices).
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
    #: (2, 3) m: the object's bounding box (least and greatest corner, object frame).
    object_box: np.ndarray = field(repr=False)
    #: (4,) m: the hand's radius at the base, PIP, DIP and tip of a finger (the largest
    #: of the capsules and the pad ending there): a finger's plane distance is exact there.
    joint_radii: np.ndarray = field(repr=False)
    #: (4,) m: the radii of a finger's proximal, middle and distal capsules and its pad.
    link_radii: np.ndarray = field(repr=False)
    #: (K,) m: radii of the link spheres the open hand is checked at along the approach
    #: (:data:`grasp_apso.geometry.link_points.APPROACH_INDEX`).
    approach_radii: np.ndarray = field(repr=False)
    #: Hand data as the compiled kernels read it (float64, C-contiguous): link lengths
    #: (5, 3) m, capsule radii of the proximal, middle and distal links (3,) m, palm box.
    link_lengths: np.ndarray = field(repr=False)
    capsule_radii: np.ndarray = field(repr=False)
    palm_center: np.ndarray = field(repr=False)
    palm_half_extents: np.ndarray = field(repr=False)
    #: The scene in the object frame (:meth:`grasp_apso.model.scene.Scene.packed`, read
    #: only), or None: no scene check at all (the decoding of a free-space plan).
    scene: dict | None = field(default=None, repr=False)
    #: Least hand-scene distance (m) and the pre-grasp retreat (m) of the scene check.
    scene_clearance: float = 0.0
    approach_distance: float = 0.0
    #: How far (m) this hand's capsules stick out between the approach points' spheres
    #: (the scene check subtracts it).
    approach_cover: float = 0.0
    #: Normal spread (rad) around the surface points (:mod:`grasp_apso.geometry.normal_spread`),
    #: read by the fitness per contact; None: every contact counts as well defined.
    spread: NormalSpreadGrid | None = field(default=None, repr=False)

    @property
    def dims(self) -> int:
        return N_DIMS


def with_scene(model: GraspModel, scene, clearance: float, approach_distance: float) -> GraspModel:
    """The model with a scene check: a particle whose palm, closed fingers (at the grasp)
    or open pre-shape (along the approach from the pre-grasp) comes within ``clearance``
    (m) of ``scene`` (a :class:`~grasp_apso.model.scene.Scene` in the object frame) is
    illegal. An empty scene or None returns ``model`` unchanged."""
    if scene is None or scene.is_empty:
        return model
    packed = {}
    for name, value in scene.packed().items():
        arr = np.ascontiguousarray(value, dtype=np.float64)
        arr.flags.writeable = False
        packed[name] = arr
    return replace(model, scene=packed, scene_clearance=float(clearance),
                   approach_distance=float(approach_distance))


def make_grasp_model(hand: HandModel, obj, settings: ContactSettings | None = None) -> GraspModel:
    """Prepare an object for planning: its signed-distance and normal-spread grids (cached
    by mesh hash).

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
    spread = cached_normal_spread_grid(obj.mesh, grid, obj.mesh_hash, padding=0.025)
    lower = np.concatenate([hand.lower, [0.0]])
    upper = np.concatenate([hand.upper, [settings.standoff_max]])
    final_radii = np.array([hand.link_radii[int(k)] for k, _ in FINAL_POINTS])
    sweep_radii = np.array([hand.link_radii[int(k)] for k, _ in SWEEP_POINTS])
    final_radii[-1] = sweep_radii[-1] = hand.pad_radius
    link_lengths, capsule_radii, palm_center, palm_half = (
        np.array(v, dtype=np.float64, order="C")
        for v in (hand.link_lengths, [*hand.link_radii[:2], hand.pad_radius], hand.palm_center,
                  hand.palm_half_extents)
    )
    object_box = np.array(obj.mesh.bounds, dtype=np.float64, order="C")
    r = hand.link_radii
    joint_radii = np.array([r[0], max(r[0], r[1]), max(r[1], r[2]), max(r[2], hand.pad_radius)], dtype=np.float64)
    link_radii = np.array([r[0], r[1], r[2], hand.pad_radius], dtype=np.float64)
    approach_radii = np.ascontiguousarray(final_radii[APPROACH_INDEX])
    for arr in (lower, upper, final_radii, sweep_radii, link_lengths, capsule_radii, palm_center, palm_half,
                object_box, joint_radii, link_radii, approach_radii):
        arr.flags.writeable = False
    return GraspModel(
        hand=hand, obj=obj, sdf=grid, settings=settings, lower=lower, upper=upper,
        point_radii=final_radii, sweep_radii=sweep_radii, support_points=_support_points(obj),
        link_lengths=link_lengths, capsule_radii=capsule_radii, palm_center=palm_center,
        palm_half_extents=palm_half, object_box=object_box, joint_radii=joint_radii, link_radii=link_radii,
        approach_radii=approach_radii,
        approach_cover=uncovered_depth(APPROACH_INDEX, hand.link_lengths, hand.link_radii, hand.pad_radius),
        spread=spread,
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
        extreme = np.empty(n_directions, dtype=np.int64)
        kernels.support_function(np.ascontiguousarray(hull), dirs, np.empty(n_directions), extreme)
        hull = hull[np.unique(extreme)]
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
    palm_depth : (P, 5) float, m
        Deepest point of each finger, from the middle of its proximal link to the pad,
        inside the palm box (0 when none); deeper than the settings' ``palm_overlap``
        counts as a finger collision.
    scene_margin : (P, 5) float or None, m
        Least distance of each finger to the scene (closed at the grasp, open along the
        approach) minus the clearance: negative = too close (illegal). None without a
        scene; read at most :data:`grasp_apso.geometry.scene_margins.SCENE_HORIZON`.
    palm_scene_margin : (P,) float or None, m
        The same for the palm box (grasp and approach).
    approach_traced : (P, 5) bool or None
        Fingers whose open approach past the object is in ``scene_margin``: only the
        particles otherwise legal with 2 or more contacts are traced (the others are
        rejected or regenerated whatever their approach).
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
    palm_depth: np.ndarray
    scene_margin: np.ndarray | None = None
    palm_scene_margin: np.ndarray | None = None
    approach_traced: np.ndarray | None = None

    @property
    def n_contacts(self) -> np.ndarray:
        """(P,) int: fingertip contacts per particle."""
        return self.contact.sum(axis=1)

    def finger_illegal(self, max_penetration: float) -> np.ndarray:
        """(P, 5) bool: fingers the verification test rejects."""
        bad = self.blocked | self.finger_collision | self.link_contact | (self.penetration > max_penetration)
        if self.scene_margin is not None:
            bad |= self.scene_margin < 0.0
        return bad

    def legal(self, max_penetration: float) -> np.ndarray:
        """(P,) bool: no illegal finger and no palm penetration."""
        ok = ~self.finger_illegal(max_penetration).any(axis=1) & (self.palm_penetration <= max_penetration)
        if self.palm_scene_margin is not None:
            ok &= self.palm_scene_margin >= 0.0
        return ok

    @property
    def scene_violation(self) -> np.ndarray:
        """(P,) float, m: how far the hand is inside the clearance of the scene (0 when
        clear or without a scene)."""
        if self.scene_margin is None:
            return np.zeros(len(self.closed))
        least = np.minimum(self.scene_margin.min(axis=1), self.palm_scene_margin)
        return np.maximum(0.0, -least)

    def take(self, index: np.ndarray) -> "DecodedGrasps":
        """The particles ``index`` (an index or boolean mask over P) of the batch."""
        return DecodedGrasps(**{f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[index]
                                for f in fields(self)})


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
    rot = wrist_rotation(x[:, LAYOUT.wrist])
    tf = np.zeros((len(x), 4, 4))
    tf[:, :3, :3] = rot
    tf[:, 3, 3] = 1.0
    if wrist_position is not None:
        tf[:, :3, 3] = np.asarray(wrist_position, dtype=float)
        return tf
    normal = rot[:, :, 2]
    com = np.asarray(model.obj.center_of_mass)
    support = np.empty(len(x))  # the object's extent toward the palm
    kernels.support_function(model.support_points, np.ascontiguousarray(-normal), support,
                             np.empty(len(x), dtype=np.int64))
    hand = model.hand
    palm_face = hand.palm_center[2] + hand.palm_half_extents[2]
    height = palm_face + model.settings.clearance + x[:, STANDOFF_INDEX] + support
    local = hand.grasp_center[None, :] + height[:, None] * np.array([0.0, 0.0, 1.0])
    tf[:, :3, 3] = com - np.einsum("pij,pj->pi", rot, local)
    return tf


def decode(
    model: GraspModel,
    x: np.ndarray,
    wrist_position: np.ndarray | None = None,
    reuse: DecodedGrasps | None = None,
    changed: np.ndarray | None = None,
) -> DecodedGrasps:
    """Decode particles into closed grasps (vectorised over particles and fingers).

    The wrist and the flexion planes are placed with numpy; closing the fingers and
    checking their closed pose run in compiled loops (:func:`grasp_apso.geometry.kernels.close_fingers`).

    Parameters
    ----------
    model : GraspModel
    x : (P, 19) float
        Particles (pre-shapes, wrist angles, standoff offset); clamped to the bounds.
    wrist_position : (3,) float, m, optional
        Fixed wrist position in the object frame (operator path).
    reuse, changed : DecodedGrasps of P particles and (P, 5) bool, optional
        Re-decode only the ``changed`` fingers (GRG's verification test regenerates single
        fingers): ``reuse`` is the decoding of the same particles in which only those
        fingers had other values (and the same ``wrist_position``); every finger of
        ``reuse`` is kept except these, and the collisions between fingers are checked
        again. The result equals a full decode (tested).

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
    rows = _rows_to_decode(x, reuse, changed)

    wrist = wrist_transforms(model, x, wrist_position) if reuse is None else reuse.wrist
    rot, trans = np.ascontiguousarray(wrist[:, :3, :3]), np.ascontiguousarray(wrist[:, :3, 3])
    theta = LAYOUT.finger_values(x)
    distal0, proximal0, pivot = theta[..., 0], theta[..., 1], theta[..., 2]
    # Flexion planes in the palm frame, one row per finger: (F, 3: base, ex, ey, 3).
    planes = np.ascontiguousarray(np.stack(hand.flexion_planes(pivot), axis=-2).reshape(-1, 3, 3))
    d_span = hand.upper[LAYOUT.distal] - distal0
    p_span = hand.upper[LAYOUT.proximal] - proximal0

    r = len(rows)
    path_margin = closing = None
    if model.scene is not None:
        # The open hand's way in first: a finger whose pre-shape comes within the
        # clearance of the scene on the approach is illegal however it closes, so it is
        # not closed (GRG regenerates it, the swarm's particle is illegal anyway).
        path_margin = finger_path_margins(model, rows, rot, trans, planes, distal0, proximal0)
        closing = path_margin >= 0.0
    s_r, blocked_r, contact_r, pts, clearance, tip_gap_r = _close_rows(
        model, rows, rot, trans, planes, distal0, proximal0, d_span, p_span, closing)
    palm_depth_r = np.empty(r)
    kernels.palm_depths(pts, CLEAR_OF_PALM.start, CLEAR_OF_PALM.stop, rows, rot, trans, model.palm_center,
                        model.palm_half_extents, palm_depth_r)
    surface_r, normals_r = sdf.closest_surface_point(pts[:, -1, :])
    link_contact_r = (clearance[:, NON_TIP_LINKS].min(axis=-1) <= settings.link_contact_tolerance) & ~blocked_r
    if settings.allow_link_contacts:
        link_contact_r[:] = False
    # Fingers without a fingertip contact take no part in the precision grasp: they are
    # back at their pre-shape (closed to their limits they would fold into the palm or
    # themselves; stopped by a middle link they would not be a precision contact).
    flex_r = np.stack([distal0.reshape(-1)[rows] + s_r * d_span.reshape(-1)[rows],
                       proximal0.reshape(-1)[rows] + s_r * p_span.reshape(-1)[rows]], axis=-1)
    per_row = {
        "tip_gap": tip_gap_r, "contact": contact_r, "blocked": blocked_r,
        "penetration": np.maximum(0.0, -clearance.min(axis=-1)), "link_contact": link_contact_r,
        "contact_points": surface_r, "contact_normals": normals_r, "palm_depth": palm_depth_r,
        "joints": pts[:, JOINT_INDEX, :],
    }
    if model.scene is not None:
        margin = path_margin
        closed_rows = np.flatnonzero(closing)
        if closed_rows.size:
            margin[closed_rows] = np.minimum(margin[closed_rows], finger_grasp_margins(
                model, rows[closed_rows], rot, pts[closed_rows]))
        per_row["scene_margin"] = margin
        per_row["approach_traced"] = np.zeros(r, dtype=bool)
    if reuse is None:
        out = {name: value.reshape((n, N_FINGERS) + value.shape[1:]) for name, value in per_row.items()}
        flexions = flex_r.reshape(n, N_FINGERS, 2)
    else:
        out = {}
        for name, value in per_row.items():
            full = getattr(reuse, name).copy()
            full.reshape((n * N_FINGERS,) + value.shape[1:])[rows] = value
            out[name] = full
        flexions = LAYOUT.finger_values(reuse.closed)[..., :2].copy()
        flexions.reshape(-1, 2)[rows] = flex_r

    joints = np.ascontiguousarray(out["joints"])
    collide = finger_collisions(joints, model.capsule_radii, settings.finger_overlap)
    # Fingers through the palm (a finger flexed across the palm can pass through it).
    collide |= out["palm_depth"] > settings.palm_overlap

    closed = x.copy()
    closed[:, LAYOUT.distal] = flexions[..., 0]
    closed[:, LAYOUT.proximal] = flexions[..., 1]
    if reuse is not None:
        palm_pen = reuse.palm_penetration
    elif wrist_position is None:
        palm_pen = np.zeros(n)
    else:
        palm_pen = _palm_penetration(model, wrist)
    if model.scene is not None:
        out["palm_scene_margin"] = palm_scene_margins(model, wrist) if reuse is None else reuse.palm_scene_margin
    decoded = DecodedGrasps(closed=closed, wrist=wrist, finger_collision=collide, palm_penetration=palm_pen, **out)
    if model.scene is not None:
        trace_approaches(model, decoded, rot, trans, planes, distal0, proximal0)
    return decoded


def _close_rows(model, rows, rot, trans, planes, distal0, proximal0, d_span, p_span, closing) -> tuple:
    """Close the finger rows (:func:`grasp_apso.geometry.kernels.close_fingers`); rows
    with ``closing`` (R,) bool False stay open (:func:`~grasp_apso.geometry.kernels.open_fingers`).
    Returns per row: s (R,), blocked (R,), contact (R,), points (R, K, 3), clearance (R, K), tip gap (R,)."""
    hand, sdf, settings = model.hand, model.sdf, model.settings
    r = len(rows)
    out = (np.empty(r), np.empty(r, dtype=bool), np.empty(r, dtype=bool), np.empty((r, len(FINAL_POINTS), 3)),
           np.empty((r, len(FINAL_POINTS))), np.empty(r))
    grid = (sdf._values64, sdf._origin64, float(sdf.spacing), rot, trans, planes, model.link_lengths,
            float(hand.coupling_ratio), np.ascontiguousarray(distal0).reshape(-1),
            np.ascontiguousarray(proximal0).reshape(-1))
    close = np.arange(r) if closing is None else np.flatnonzero(closing)
    if close.size:  # without a scene every row, in order: no gather of the rows
        kernels.close_fingers(
            *grid, np.ascontiguousarray(d_span).reshape(-1), np.ascontiguousarray(p_span).reshape(-1),
            SWEEP_COEFF, model.sweep_radii, FINAL_COEFF, model.point_radii, settings.coarse_steps,
            settings.refine_steps, settings.max_penetration, settings.tolerance,
            rows if closing is None else rows[close], close, *out)
    if close.size < r:
        stay = np.flatnonzero(~closing)
        kernels.open_fingers(*grid, FINAL_COEFF, rows[stay], stay, *out)
    return out


def warm_scene_kernels(model: GraspModel) -> None:
    """Load the scene kernels a decode may call (``model`` with a scene): some run only
    for the finger rows that need them, so a decode alone may not load them all."""
    x = 0.5 * (model.lower + model.upper)[None, :]
    decode(model, x)
    wrist = wrist_transforms(model, x)
    rot, trans = np.ascontiguousarray(wrist[:, :3, :3]), np.ascontiguousarray(wrist[:, :3, 3])
    theta = LAYOUT.finger_values(x)
    planes = np.ascontiguousarray(np.stack(model.hand.flexion_planes(theta[..., 2]), axis=-2).reshape(-1, 3, 3))
    rows = np.arange(N_FINGERS, dtype=np.int64)
    approach_object_gaps(model, rows, rot, trans, planes, theta[..., 0], theta[..., 1])
    d_span = model.hand.upper[LAYOUT.distal] - theta[..., 0]
    p_span = model.hand.upper[LAYOUT.proximal] - theta[..., 1]
    pts = _close_rows(model, rows, rot, trans, planes, theta[..., 0], theta[..., 1], d_span, p_span,
                      np.arange(N_FINGERS) % 2 == 0)[3]  # closes some rows, leaves the others open
    finger_grasp_margins(model, rows, rot, pts)


def _rows_to_decode(x: np.ndarray, reuse: DecodedGrasps | None, changed: np.ndarray | None) -> np.ndarray:
    """Finger rows (particle * 5 + finger) that :func:`decode` closes: (R,) int64."""
    n = len(x)
    if reuse is None and changed is None:
        return np.arange(n * N_FINGERS, dtype=np.int64)
    if reuse is None or changed is None:
        raise ValueError("reuse, changed: give both or neither")
    changed = np.asarray(changed)
    if changed.shape != (n, N_FINGERS) or changed.dtype != bool:
        raise ValueError(f"changed: expected a ({n}, {N_FINGERS}) bool array, got {changed.dtype} {changed.shape}")
    if reuse.closed.shape != x.shape:
        raise ValueError(f"reuse: decodes {reuse.closed.shape[0]} particles, x has {n}")
    # A kept finger's flexions are closed in ``reuse`` (not comparable); its pivot is not.
    if not np.array_equal(reuse.closed[:, 15:], x[:, 15:]):
        raise ValueError("reuse: the wrist angles or the standoff differ from x")
    if not np.all((reuse.closed[:, LAYOUT.pivot] == x[:, LAYOUT.pivot]) | changed):
        raise ValueError("reuse: the pivot of a finger not in changed differs from x")
    return np.flatnonzero(changed.reshape(-1)).astype(np.int64)


def _palm_penetration(model: GraspModel, wrist: np.ndarray) -> np.ndarray:
    """Deepest penetration (m) of points on the palm face into the object: (P,)."""
    hand = model.hand
    cx, cy, cz = hand.palm_center
    hx, hy, hz = hand.palm_half_extents
    gx, gy = np.meshgrid(np.linspace(cx - hx, cx + hx, 7), np.linspace(cy - hy, cy + hy, 7), indexing="ij")
    face = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, cz + hz)], axis=1)
    pts = np.einsum("pij,kj->pki", wrist[:, :3, :3], face) + wrist[:, None, :3, 3]
    return np.maximum(0.0, -model.sdf.distance(pts).min(axis=1))
