"""python-fcl checks of ANY hand's exact collision geometry: against the object, the scene,
between fingers, and along the approach (DESIGN.md Part 3, issue 21).

:class:`HandCollision` holds a :class:`~grasp_apso.model.hands.model.HandModel` and its fcl
parts (:mod:`.any_hand_shapes`: every ``hand.collision[link]`` geometry as an fcl primitive
or a BVH, built once per hand, per-thread collision objects), placed by
``hand.link_transforms`` and the root pose.

- :func:`object_report`: per link the signed distance to the object (negative: the depth of
  its deepest point inside, see :mod:`.any_hand_shapes`), which links touch, the deepest
  penetration, and the link pairs of different fingers (or non-adjacent links of one
  finger) that overlap by more than ``allowed_overlap``.
- :func:`scene_distance`: the least distance of the whole hand to a
  :class:`~grasp_apso.model.scene.Scene`. Support planes in closed form (each part's support
  function along the plane normal: exact at any distance, for every part at once);
  obstacles as the fcl objects of :mod:`.hand_fcl` (its per-thread scene cache).
- :func:`approach_report`: the open hand from the pre-grasp to the grasp in steps of at most
  ``step``: planes exactly over the whole segment (a translation moves a part's plane
  distance linearly), obstacles and the object at every step with the conservative bounds
  of :func:`.hand_fcl.approach_report` (a part that a translation of t cannot bring closer
  than the least distance so far is not measured).

Frames: ``q`` (n,) over ``hand.actuated_joints``; a root pose (4, 4) is the root link's
frame in the frame of the object (:func:`object_report`) or the scene. Units: m, rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import fcl
import numpy as np

from ..errors import InputError
from ..model.hands.geometry import LinkGeometry
from ..model.hands.model import HandModel
from ..model.scene import Scene
from .any_hand_shapes import TOUCH_EPS, HandShapes, ObjectShape, hand_shapes, object_shape
# The scene's fcl objects, the pose/number validation and the approach tolerances are the paper hand's (one source of truth).
from .hand_fcl import CONTACT_ZONE, MAX_STEPS, OBJECT_TOLERANCE, _nonnegative, _pose, _scene_geometry

__all__ = ["HandCollision", "AnyHandReport", "AnyApproachReport", "object_report", "scene_distance",
           "approach_report", "TOUCH_TOLERANCE", "ALLOWED_OVERLAP"]

#: A link within this distance (m) of the object touches it (and may press this deep).
TOUCH_TOLERANCE = 0.001
#: Links of different fingers may overlap this much (m) before they collide (soft skins).
ALLOWED_OVERLAP = 0.002
_REQ = fcl.DistanceRequest()


def _fcl_distance(a: fcl.CollisionObject, b: fcl.CollisionObject) -> float:
    return float(fcl.distance(a, b, _REQ, fcl.DistanceResult()))


def _to_frame(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (N, 3) given in the frame ``pose`` (4, 4) maps from -> parent frame."""
    return points @ pose[:3, :3].T + pose[:3, 3]


def _from_frame(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (N, 3) in the parent frame -> the frame ``pose`` (4, 4)."""
    return (points - pose[:3, 3]) @ pose[:3, :3]


class HandCollision:
    """The exact collision geometry of one hand, ready for python-fcl queries.

    Cheap to construct: the fcl parts come from a cache keyed by the hand's content
    (``source_hash`` and its geometry); safe to use from several threads (each thread moves
    its own fcl objects).

    Attributes
    ----------
    hand : HandModel
    links : tuple of str
        The links with collision geometry: the rows of :attr:`AnyHandReport.link_distance`.
    """

    def __init__(self, hand: HandModel):
        self.shapes: HandShapes = hand_shapes(hand)
        self.hand = hand
        self.links = self.shapes.links

    def part_poses(self, q: np.ndarray, root_pose: np.ndarray, field: str = "q") -> np.ndarray:
        """Pose of every part's geometry frame: ``root_pose @ link @ origin``, (K, 4, 4).

        q : (n,) float, rad or m; root_pose : (4, 4), the root link in the query frame.
        """
        q = np.asarray(q, dtype=float)
        if q.shape != (self.hand.n_joints,) or not np.all(np.isfinite(q)):
            raise InputError(f"{field}: expected {self.hand.n_joints} finite joint values "
                             f"(hand.actuated_joints), got shape {q.shape}", field)
        links = self.hand.link_transforms_batch(q[None])[0][self.shapes.link_rows]
        return root_pose @ links[self.shapes.part_link] @ self.shapes.origins

    def place(self, poses: np.ndarray, parts=None) -> list:
        """This thread's fcl objects with the parts ``parts`` (default all) at ``poses``."""
        objs = self.shapes.objects()
        for k in range(len(objs)) if parts is None else parts:
            objs[k].setTransform(fcl.Transform(poses[k, :3, :3], poses[k, :3, 3]))
        return objs

    @property
    def excluded_pairs(self) -> tuple[tuple[str, str], ...]:
        """Link pairs not checked between fingers: they overlap already in the hand's open
        configuration (by design, as MoveIt's "default" collisions)."""
        return tuple((self.links[self.shapes.part_link[a]], self.links[self.shapes.part_link[b]])
                     for a, b in zip(*self._default_pairs()))

    def _default_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        cached = getattr(self.shapes, "_default_pairs", None)
        if cached is None:
            poses = self.part_poses(self.hand.open_configuration(), np.eye(4))
            a, b = self.shapes.pair_candidates
            hit = np.array([_part_pair_distance(self, poses, int(i), int(j)) < 0.0 for i, j in zip(a, b)], dtype=bool)
            cached = (a[hit], b[hit])
            self.shapes._default_pairs = cached  # benign race: every thread computes the same
        return cached

    def checked_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """(a, b) part indices checked for self-collision (candidates minus the default ones)."""
        a, b = self.shapes.pair_candidates
        da, db = self._default_pairs()
        if len(da) == 0:
            return a, b
        k = len(self.shapes.geoms)
        keep = ~np.isin(a * k + b, da * k + db)
        return a[keep], b[keep]


def _check(hc) -> HandCollision:
    if isinstance(hc, HandModel):
        return HandCollision(hc)
    if not isinstance(hc, HandCollision):
        raise InputError(f"hc: expected a HandCollision (or a HandModel), got {type(hc).__name__}", "hc")
    return hc


# ------------------------------------------------------------------ depths from samples
def _samples_world(hc: HandCollision, poses: np.ndarray, k: int) -> tuple[np.ndarray, float]:
    points, inflate = hc.shapes.samples[k]
    return _to_frame(poses[k], points), inflate


def _part_sdf(hc: HandCollision, poses: np.ndarray, k: int, points: np.ndarray) -> np.ndarray:
    """Exact signed distance (m) of points (N, 3), query frame, to part ``k``'s solid."""
    geom = hc.shapes.geoms[k]
    return geom.signed_distance(_to_frame(geom.origin, _from_frame(poses[k], points)))


def _near_points(hc: HandCollision, poses: np.ndarray, k: int, points: np.ndarray) -> np.ndarray:
    """The points (N, 3) within part ``k``'s bounding sphere."""
    centre = _to_frame(poses[k], hc.shapes.bound_centre[k][None])[0]
    return points[np.einsum("ij,ij->i", points - centre, points - centre) <= hc.shapes.bound_radius[k] ** 2]


def _solid_pair(geom_a: LinkGeometry, pose_a: np.ndarray, samples_a, geom_b: LinkGeometry, pose_b: np.ndarray,
                samples_b) -> float:
    """Minus the overlap depth (m, <= 0) of two solids that touch: the deepest sample of
    each inside the other (exact signed distances); poses are geometry frames (4, 4)."""
    out = 0.0
    for g_in, p_in, (points, inflate), p_out in ((geom_b, pose_b, samples_a, pose_a),
                                                 (geom_a, pose_a, samples_b, pose_b)):
        world = _to_frame(p_out, points)
        sdf = g_in.signed_distance(_to_frame(g_in.origin, _from_frame(p_in, world)))
        out = min(out, float((sdf - inflate).min()))
    return out


def _part_pair_distance(hc: HandCollision, poses: np.ndarray, a: int, b: int) -> float:
    """Signed distance (m) between parts ``a`` and ``b`` at ``poses`` (negative: depth).
    Never fcl's signed distance: its EPA hangs on overlapping capsules (python-fcl 0.7)."""
    objs = hc.place(poses, (a, b))
    d = _fcl_distance(objs[a], objs[b])
    if d > TOUCH_EPS:
        return d
    s = hc.shapes
    return _solid_pair(s.geoms[a], poses[a], s.samples[a], s.geoms[b], poses[b], s.samples[b])


def _object_signed(hc: HandCollision, poses: np.ndarray, k: int, shape: ObjectShape, to_object: np.ndarray,
                   d: float) -> float:
    """Signed distance of part ``k`` to the object, given fcl's plain distance ``d``.

    ``to_object`` (4, 4): query frame -> object frame. A part that fcl finds apart may lie
    wholly inside the (hollow, to fcl) mesh, or hold the object wholly: one point decides."""
    points, inflate = _samples_world(hc, poses, k)
    local = _from_frame(to_object, points) if to_object is not None else points
    if d > TOUCH_EPS:
        if shape.distance(local[:1])[0] - inflate >= 0.0:
            vertex = _to_frame(to_object, shape.vertices[:1]) if to_object is not None else shape.vertices[:1]
            if _part_sdf(hc, poses, k, vertex)[0] >= 0.0:
                return d
    inside = float((shape.distance(local) - inflate).min())
    verts = shape.vertices if to_object is None else _to_frame(to_object, shape.vertices)
    near = _near_points(hc, poses, k, verts)
    holds = float(_part_sdf(hc, poses, k, near).min()) if len(near) else math.inf
    return min(inside, holds, 0.0)


# ------------------------------------------------------------------ object report
@dataclass(frozen=True)
class AnyHandReport:
    """Result of :func:`object_report`.

    Attributes
    ----------
    links : tuple of str
        The hand's links with collision geometry (rows of the arrays).
    link_distance : (Lg,) float, m
        Signed distance of each link to the object: the gap, or minus the depth of its
        deepest point inside (penetration).
    touching : (Lg,) bool
        ``link_distance <= tolerance``.
    deepest_penetration : float, m, >= 0
        ``max(0, -min(link_distance))``.
    deepest_link : str
        The link of least ``link_distance``.
    link_pairs_colliding : tuple of (str, str)
        Link pairs (of different fingers, or non-adjacent links of one finger) that overlap
        by more than ``allowed_overlap``.
    finger_pairs_colliding : tuple of (str, str)
        The finger names of the pairs of different fingers among them.
    tolerance : float, m
    """

    links: tuple[str, ...]
    link_distance: np.ndarray
    touching: np.ndarray
    deepest_penetration: float
    deepest_link: str
    link_pairs_colliding: tuple[tuple[str, str], ...]
    finger_pairs_colliding: tuple[tuple[str, str], ...]
    tolerance: float

    @property
    def legal(self) -> bool:
        """No link deeper than ``tolerance`` in the object and no links colliding."""
        return self.deepest_penetration <= self.tolerance and not self.link_pairs_colliding

    def distance_of(self, link: str) -> float:
        """``link_distance`` of one link (KeyError naming it when it has no geometry)."""
        if link not in self.links:
            raise KeyError(f"link {link!r} has no collision geometry")
        return float(self.link_distance[self.links.index(link)])


def _link_min(hc: HandCollision, part_values: np.ndarray) -> np.ndarray:
    out = np.full(len(hc.links), math.inf)
    np.minimum.at(out, hc.shapes.part_link, part_values)
    return out


def self_collisions(hc: HandCollision, poses: np.ndarray, allowed_overlap: float = ALLOWED_OVERLAP
                    ) -> tuple[tuple[str, str], ...]:
    """Link pairs (names) of :meth:`HandCollision.checked_pairs` overlapping by more than
    ``allowed_overlap`` (m) at part ``poses`` (K, 4, 4); bounding spheres first, in one batch."""
    a, b = hc.checked_pairs()
    if len(a) == 0:
        return ()
    s = hc.shapes
    centre = np.einsum("kij,kj->ki", poses[:, :3, :3], s.bound_centre) + poses[:, :3, 3]
    gap = np.linalg.norm(centre[a] - centre[b], axis=1) - s.bound_radius[a] - s.bound_radius[b]
    pairs = []
    for i in np.flatnonzero(gap < -allowed_overlap):
        la, lb = hc.links[s.part_link[a[i]]], hc.links[s.part_link[b[i]]]
        if (la, lb) in pairs:
            continue
        if _part_pair_distance(hc, poses, int(a[i]), int(b[i])) < -allowed_overlap:
            pairs.append((la, lb))
    return tuple(pairs)


def object_report(hc: HandCollision | HandModel, q: np.ndarray, root_in_object: np.ndarray, obj,
                  tolerance: float = TOUCH_TOLERANCE, allowed_overlap: float = ALLOWED_OVERLAP) -> AnyHandReport:
    """The hand at ``q`` against the object and itself (python-fcl, exact geometry).

    Parameters
    ----------
    hc : HandCollision (or a HandModel, wrapped)
    q : (n,) float, rad or m
        Over ``hand.actuated_joints``.
    root_in_object : (4, 4) float
        The root link's pose in the object frame.
    obj : GraspObject, trimesh.Trimesh or ObjectShape
        The object (its mesh, object frame); see :func:`.any_hand_shapes.object_shape`.
    tolerance : float, m, >= 0
        A link within it touches; a deeper penetration is illegal.
    allowed_overlap : float, m, >= 0

    Raises
    ------
    InputError
        A bad argument, named.
    """
    hc = _check(hc)
    root = _pose(root_in_object, "root_in_object")
    tol = _nonnegative(tolerance, "tolerance")
    overlap = _nonnegative(allowed_overlap, "allowed_overlap")
    shape = object_shape(obj)
    poses = hc.part_poses(q, root)
    objs = hc.place(poses)
    target = shape.collision_object()
    target.setTransform(fcl.Transform())
    part_d = np.empty(len(objs))
    for k, o in enumerate(objs):
        part_d[k] = _object_signed(hc, poses, k, shape, None, _fcl_distance(o, target))
    dist = _link_min(hc, part_d)
    worst = int(np.argmin(dist))
    pairs = self_collisions(hc, poses, overlap)
    fingers = hc.shapes.finger
    names = [f.name for f in hc.hand.fingers]
    finger_pairs = []
    for la, lb in pairs:
        fa, fb = fingers[hc.links.index(la)], fingers[hc.links.index(lb)]
        key = tuple(sorted((names[fa], names[fb]), key=names.index))
        if fa != fb and key not in finger_pairs:
            finger_pairs.append(key)
    dist.flags.writeable = False
    touching = dist <= tol
    touching.flags.writeable = False
    return AnyHandReport(links=hc.links, link_distance=dist, touching=touching,
                         deepest_penetration=float(max(0.0, -dist[worst])), deepest_link=hc.links[worst],
                         link_pairs_colliding=pairs, finger_pairs_colliding=tuple(finger_pairs), tolerance=tol)
