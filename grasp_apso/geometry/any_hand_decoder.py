"""Decoding particles of a general hand (:class:`grasp_apso.model.hands.HandModel`): the
paper's forward direction, GraspIt!'s auto-grasp, for arbitrary finger chains.

For every particle (layout :class:`.any_hand_tables.ParticleLayout`): place the root so the
palm normal aims at the object's centre of mass, with the object's support along that
normal ``clearance + standoff`` in front of the palm face; close each finger from its
pre-shape along its closing senses (one parameter ``s`` per finger, couplings applied)
until one of its link spheres meets the surface (:func:`.any_hand_kernels.close_fingers`).
A finger is in contact when its pad sphere (radius ``pad_radius``, its surface through the
pad point ``Finger.pad_center``: :func:`.any_hand_tables.pad_sphere_center`) is then within
the contact tolerance of the object's surface with its pad side (within :data:`PAD_CONE`
of the pad point), either side (the contact point: the
sphere's centre projected on the surface along the gradient; the normal: the outward
gradient); a finger without contact goes back to its pre-shape. Each pad point's distance
to the surface is reported (``pad_offset``); with ``pads_on`` a contact also needs it within
:data:`PAD_ON` (the final selection's strict reading, :mod:`grasp_apso.search.any_hand_pads`).
Illegal: a finger penetrating at its pre-shape (blocked), a link deeper than
``max_penetration``, a non-pad link touching (precision grasps), spheres of different
fingers overlapping, the palm (root and non-finger links) penetrating, and with a scene a
link within the clearance of it at the grasp or along the approach of the open hand.

Batched over particles and fingers: the loops are compiled (:mod:`.any_hand_kernels`); the
scene distances are vectorised numpy over sphere groups (:mod:`.any_hand_scene`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from . import any_hand_kernels as hk
from . import kernels
from .any_hand_approach import object_approach_margins
from .any_hand_scene import packed_scene, scene_margins
from .any_hand_tables import HandTables, hand_tables
from .contact_settings import ContactSettings
from .decoder import _support_points
from .normal_spread import NormalSpreadGrid, cached_normal_spread_grid
from .sdf import SignedDistanceGrid, cached_sdf_grid

__all__ = ["AnyHandModel", "AnyDecoded", "make_any_hand_model", "root_poses", "decode_any", "with_any_scene"]

#: Group clearances above this (m) are lower bounds (culled look-ups): far above every
#: tolerance the decoder decides with.
CUTOFF = 0.002
#: Bisection steps after the coarse sweep: about 0.2 mm of fingertip travel.
REFINE_STEPS = 6
#: The sphere covers stray up to about 2 mm outside the exact geometry (model.hands.spheres):
#: two fingers' covers overlap by up to twice that where the links do not, so this much
#: more overlap is allowed between fingers (python-fcl decides on the exact geometry).
COVER_OVERLAP = 0.003
#: A pad is in contact within the contact tolerance less this (m): the grid's trilinear
#: distance errs by up to about this much near edges and curved surfaces.
GRID_MARGIN = 0.0005
#: The pad is the part of the pad sphere within this angle of the pad point (rad): the
#: half facing the pad normal. A fingertip touching with its back or its very tip is no pad
#: contact. (Narrower cones put the pad point itself on the surface -- within
#: r (1 - cos PAD_CONE) -- but leave few postures in which a thumb can touch at all: on the
#: five test and dex-urdf hands a 45 degree cone left fewer than half as many force-closure
#: grasps.)
PAD_CONE = float(np.radians(90.0))
_COS_CONE = float(np.cos(PAD_CONE)) + 1e-9
#: A pad point this near the surface (m) is on it: the judged 2 mm less the grid's error
#: (GRID_MARGIN) and as much again for the trimesh reading of the exact surface.
PAD_ON = 0.0015


@dataclass(frozen=True)
class AnyHandModel:
    """Everything fixed during a plan with a general hand."""

    hand: object
    obj: object
    sdf: SignedDistanceGrid
    settings: ContactSettings
    tables: HandTables = field(repr=False)
    kin: tuple = field(repr=False)
    support_points: np.ndarray = field(repr=False)
    spread: NormalSpreadGrid | None = field(default=None, repr=False)
    #: The scene in the object frame, or None; clearance (m) and the approach distance (m).
    scene: object | None = field(default=None, repr=False)
    scene_clearance: float = 0.0
    approach_distance: float = 0.0
    scene_arrays: tuple = field(default=(), repr=False)

    @property
    def lower(self) -> np.ndarray:
        return self.tables.lower

    @property
    def upper(self) -> np.ndarray:
        return self.tables.upper

    @property
    def layout(self):
        return self.tables.layout


def make_any_hand_model(hand, obj, settings: ContactSettings | None = None) -> AnyHandModel:
    """The model of planning ``obj`` (GraspObject) with ``hand``: grids cached by mesh hash
    (the same as the paper hand's), the hand's tables cached by its source hash."""
    settings = settings or ContactSettings()
    grid = cached_sdf_grid(obj.mesh, obj.mesh_hash, padding=0.025)
    spread = cached_normal_spread_grid(obj.mesh, grid, obj.mesh_hash, padding=0.025)
    tables = hand_tables(hand)
    return AnyHandModel(hand=hand, obj=obj, sdf=grid, settings=settings, tables=tables, kin=hk.kin(tables),
                        support_points=_support_points(obj), spread=spread)


def with_any_scene(model: AnyHandModel, scene, clearance: float, approach_distance: float) -> AnyHandModel:
    """The model with a scene check (``scene`` in the object frame; None or empty: unchanged)."""
    if scene is None or scene.is_empty:
        return model
    return replace(model, scene=scene, scene_clearance=float(clearance), approach_distance=float(approach_distance),
                   scene_arrays=packed_scene(scene))


def root_poses(model: AnyHandModel, x: np.ndarray, wrist_position: np.ndarray | None = None) -> np.ndarray:
    """Root (palm link) poses in the object frame: x (P, D) -> (P, 4, 4).

    The grasp centre (on the palm face, between the pads) is put on the line along the
    palm normal through the centre of mass moved by the particle's shift (along palm x and
    y), ``clearance + standoff`` in front of the object's support along the normal; with
    ``wrist_position`` (3,) the root origin is there.
    """
    t, lay = model.tables, model.layout
    rot = t.root_rotations(x[:, lay.wrist])
    out = np.zeros((len(x), 4, 4))
    out[:, :3, :3] = rot
    out[:, 3, 3] = 1.0
    if wrist_position is not None:
        out[:, :3, 3] = np.asarray(wrist_position, dtype=float)
        return out
    normal = np.ascontiguousarray(rot @ t.basis[:, 2])
    support = np.empty(len(x))
    kernels.support_function(model.support_points, np.ascontiguousarray(-normal), support,
                             np.empty(len(x), dtype=np.int64))
    height = model.settings.clearance + x[:, lay.standoff] + support
    center = np.asarray(model.obj.center_of_mass, dtype=float)
    across = rot @ (x[:, lay.shift] @ t.basis[:, :2].T)[:, :, None]
    out[:, :3, 3] = center + across[:, :, 0] - height[:, None] * normal - rot @ t.grasp_center
    return out


@dataclass(frozen=True)
class AnyDecoded:
    """A batch of decoded particles (object frame, SI). F fingers, n actuated joints.

    Attributes
    ----------
    closed : (P, D) float
        The particles with the joints at the grasp posture.
    q_pre, q : (P, n) float
        Pre-shape and grasp posture.
    root : (P, 4, 4) float
        Root pose in the object frame.
    wrist : (P, 4, 4) float
        The palm frame (x fingers, z palm normal) in the object frame: the archive's and
        the shape factor's wrist.
    contact : (P, F) bool; contact_points, contact_normals : (P, F, 3)
    tip_gap : (P, F) float, m
        The pad's clearance where the closing stopped: the larger of the pad sphere's and
        the pad point's (guides toward contact).
    pad_points : (P, F, 3) float, m
        The pad spheres' centres at the grasp.
    penetration, blocked, link_contact, finger_collision : (P, F)
        (``finger_collision`` checked only for particles otherwise legal with two contacts)
    palm_clearance : (P,) float, m
    pad_offset : (P, F) float, m
        Each pad point's (``Finger.pad_center``) distance to the object's surface at the
        grasp: 0 when the pad itself touches, up to ``pad_radius`` when the pad sphere
        touches with its side.
    closing : (P, F) float
        The closing parameter ``s`` where each finger stopped (0 at the pre-shape, 1 at the
        closing limits; each closing joint moves ``q0 + s (limit - q0)``).
    scene_margin : (P,) float or None, m
        Least distance of the hand to the scene minus the clearance (grasp and approach);
        checked only for the particles otherwise legal with two contacts (0 for the others).
    """

    closed: np.ndarray
    q_pre: np.ndarray
    q: np.ndarray
    root: np.ndarray
    wrist: np.ndarray
    contact: np.ndarray
    contact_points: np.ndarray
    contact_normals: np.ndarray
    tip_gap: np.ndarray
    pad_points: np.ndarray
    penetration: np.ndarray
    blocked: np.ndarray
    link_contact: np.ndarray
    finger_collision: np.ndarray
    palm_clearance: np.ndarray
    pad_offset: np.ndarray
    closing: np.ndarray
    scene_margin: np.ndarray | None = None

    @property
    def n_contacts(self) -> np.ndarray:
        return self.contact.sum(axis=1)

    def finger_illegal(self, max_penetration: float) -> np.ndarray:
        """(P, F) bool: the fingers GRG's verification test regenerates."""
        return self.blocked | self.finger_collision | self.link_contact | (self.penetration > max_penetration)

    def legal(self, max_penetration: float) -> np.ndarray:
        ok = ~self.finger_illegal(max_penetration).any(axis=1) & (self.palm_clearance >= -max_penetration)
        if self.scene_margin is not None:
            ok &= self.scene_margin >= 0.0
        return ok

    @property
    def scene_violation(self) -> np.ndarray:
        if self.scene_margin is None:
            return np.zeros(len(self.closed))
        return np.maximum(0.0, -self.scene_margin)

    def take(self, index) -> "AnyDecoded":
        return AnyDecoded(**{f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[index]
                             for f in fields(self)})


def _pad_facing(model: AnyHandModel, points: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """(P, F) cosine between each pad's normal (its sphere's centre to its pad point) and
    the inward surface normal where the pad sphere is nearest the object: 1 when the pad
    point itself faces the surface, 0 when the fingertip touches with its side (the
    compiled :func:`.any_hand_kernels.pad_facings`, which the closing computes too)."""
    points, centers = np.broadcast_arrays(np.asarray(points, np.float64), np.asarray(centers, np.float64))
    out = np.empty(points.shape[:-1])
    hk.pad_facings(model.sdf._values64, model.sdf._origin64, float(model.sdf.spacing),
                   np.ascontiguousarray(points.reshape(-1, 3)), np.ascontiguousarray(centers.reshape(-1, 3)),
                   out.reshape(-1))
    return out


def decode_any(model: AnyHandModel, x: np.ndarray, wrist_position: np.ndarray | None = None,
               pads_on: bool = False, scene_check: bool = True, palm: np.ndarray | None = None) -> AnyDecoded:
    """Decode particles x (P, D) (clamped to the bounds) into grasps; see the module docstring.
    ``pads_on``: a contact also needs its pad point within :data:`PAD_ON` of the surface (the
    final selection's strict reading; the search's contacts are the pad spheres').
    ``scene_check`` False: no scene margins (``scene_margin`` None), for trial decodings
    that read only the fingers' contacts and legality. ``palm`` (P,) m: the particles' palm
    clearance when known (it depends on the wrist and the standoff alone: variants of
    decoded particles that change only joints), else computed. Each particle's decoding is
    its own (the same in any batch)."""
    lay, t, s = model.layout, model.tables, model.settings
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != lay.dims:
        raise ValueError(f"x: expected (P, {lay.dims}), got {x.shape}")
    if not np.all(np.isfinite(x)):
        row, col = np.argwhere(~np.isfinite(x))[0]
        raise ValueError(f"x: particle {row} value {col} is not finite")
    x = np.clip(x, t.lower, t.upper)
    n_p, n_f, lmax = len(x), t.n_fingers, t.finger_link.shape[1]
    root = root_poses(model, x, wrist_position)
    rot, trans = np.ascontiguousarray(root[:, :3, :3]), np.ascontiguousarray(root[:, :3, 3])
    q0 = np.ascontiguousarray(x[:, lay.joints])
    grid = (model.sdf._values64, model.sdf._origin64, float(model.sdf.spacing))
    q = np.empty_like(q0)
    s_out, start = np.empty((n_p, n_f)), np.empty((n_p, n_f))
    stopped = np.empty((n_p, n_f), dtype=bool)
    link_clear = np.full((n_p, n_f, lmax), np.inf)
    pad_pos, pad_gap = np.empty((n_p, n_f, 3)), np.empty((n_p, n_f))
    pads, facing, pad_offset = np.empty((n_p, n_f, 3)), np.empty((n_p, n_f)), np.empty((n_p, n_f))
    open_clear, open_pad, open_gap = np.full((n_p, n_f, lmax), np.inf), np.empty((n_p, n_f, 3)), np.empty((n_p, n_f))
    hk.close_fingers(*grid, rot, trans, q0, model.kin, int(s.coarse_steps), max(REFINE_STEPS, s.refine_steps),
                     CUTOFF, t.pad_point, q, s_out, start, stopped, link_clear, pad_pos, pad_gap, pads, facing,
                     pad_offset, open_clear, open_pad, open_gap)
    blocked = start < -s.tolerance
    # The pad sphere may touch the object with the fingertip's side or tip, away from the
    # pad: a contact is made with the pad, so the pad sphere must touch within PAD_CONE of
    # the pad point's direction (``facing``); the rest of the way guides the swarm toward it.
    off = np.maximum(0.0, _COS_CONE - facing) * t.pad_radius[None, :]
    pad_offset = np.abs(pad_offset)
    tip_gap = pad_gap + off
    contact = stopped & ~blocked & (np.abs(pad_gap) <= s.tolerance - GRID_MARGIN) & (facing >= _COS_CONE)
    if pads_on:
        contact &= pad_offset <= PAD_ON
    # Fingers without a pad contact take no part in the precision grasp: back to the pre-shape.
    reset = ~contact
    if reset.any():
        owned = np.zeros((n_f, q.shape[1]), dtype=bool)  # (F, n): the joints each finger closes
        for f in range(n_f):
            owned[f, t.j_index[f, :t.j_count[f]]] = True
        back = (reset[:, :, None] & owned[None]).any(axis=1)
        q[back] = q0[back]
        # their links and pads as the closing found them at the pre-shape
        link_clear[reset], pad_pos[reset], pad_gap[reset] = open_clear[reset], open_pad[reset], open_gap[reset]
        s_out[reset] = 0.0
    penetration = np.maximum(0.0, -link_clear.min(axis=2))
    non_pad = link_clear.copy()
    non_pad[:, t.pad_body.astype(bool)] = np.inf  # the pad link and links fixed to it: one body
    link_contact = (non_pad.min(axis=2) <= s.link_contact_tolerance) & ~blocked
    if s.allow_link_contacts:
        link_contact[:] = False
    if palm is None:
        palm = np.empty(n_p)
        hk.palm_clearance(*grid, rot, trans, t.palm_groups, t.palm_pose, t.palm_bound, model.kin, CUTOFF, palm)
    else:
        palm = np.array(palm, dtype=float)
        if palm.shape != (n_p,):
            raise ValueError(f"palm: expected ({n_p},), got {palm.shape}")
    # Overlaps between fingers only where they can decide (two contacts, nothing else
    # illegal): the others are inactive whatever their fingers do.
    collide = np.zeros((n_p, n_f), dtype=bool)
    check = (contact.sum(axis=1) >= 2) & (palm >= -s.max_penetration) & ~(
        blocked | link_contact | (penetration > s.max_penetration)).any(axis=1)
    # The grasp's link poses only where they are read: the overlaps and the scene margins
    # (whose particles are among these).
    poses = np.empty((int(check.sum()), n_f, lmax, 4, 4))
    if len(poses):
        hk.link_poses(np.ascontiguousarray(q[check]), model.kin, poses)
        out = np.empty((len(poses), n_f), dtype=bool)
        hk.finger_overlaps(poses, t.pairs, model.kin, float(s.finger_overlap) + COVER_OVERLAP, out)
        collide[check] = out
    points, normals = model.sdf.closest_surface_point(pad_pos)
    closed = x.copy()
    closed[:, lay.joints] = q
    wrist = root.copy()
    wrist[:, :3, :3] = rot @ t.basis
    margin = None
    if model.scene is not None and scene_check:
        # Only the particles otherwise legal with two contacts (the others are inactive or
        # regenerated whatever the scene): the rest read 0 (not checked).
        margin = np.zeros(n_p)
        ok = ((contact.sum(axis=1) >= 2) & (palm >= -s.max_penetration) & ~(
            blocked | collide | link_contact | (penetration > s.max_penetration)).any(axis=1))
        if ok.any():
            open_poses = np.empty((int(ok.sum()),) + poses.shape[1:])
            hk.link_poses(np.ascontiguousarray(q0[ok]), model.kin, open_poses)
            margin[ok] = np.minimum(
                scene_margins(model, root[ok], np.ascontiguousarray(poses[ok[check]]), open_poses),
                object_approach_margins(model, rot[ok], trans[ok], q0[ok], model.approach_distance))
    return AnyDecoded(closed=closed, q_pre=q0, q=q, root=root, wrist=wrist, contact=contact,
                      contact_points=points, contact_normals=normals, tip_gap=tip_gap, pad_points=pad_pos,
                      penetration=penetration, blocked=blocked, link_contact=link_contact, finger_collision=collide,
                      palm_clearance=palm, pad_offset=pad_offset, closing=s_out, scene_margin=margin)
