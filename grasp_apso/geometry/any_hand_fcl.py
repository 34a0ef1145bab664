"""python-fcl checks of ANY hand's exact collision geometry: against the object, the scene,
between fingers, and along the approach (DESIGN.md Part 3, issue 21).

:class:`HandCollision` holds a :class:`~grasp_apso.model.hands.model.HandModel` and its fcl
parts (:mod:`.any_hand_shapes`: every ``hand.collision[link]`` geometry as an fcl primitive
or a BVH, built once per hand, per-thread collision objects), placed by
``hand.link_transforms`` and the root pose.

- :func:`object_report`: per link the signed distance to the object (negative: the depth of
  its deepest point inside, see :mod:`.any_hand_shapes`), which links touch, the deepest
  penetration, and the link pairs of different fingers (or non-adjacent links of one
  finger) that overlap by more than ``allowed_overlap``, and of a finger and the palm by
  more than :data:`PALM_OVERLAP`.
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

Measured (``bench/bench_any_hand_fcl.py``; Shadow hand, 22 parts with its forearm mesh; best
of 5 on a shared 2-core machine): :func:`object_report` 1.7-3.2 ms with an 8 cm ball 1 cm
from the palm, 5.3 ms with links pressing 0.5 mm into it, 4.6 / 9.3 ms against the
non-convex mug (2,838 triangles) 1 cm off / in contact; :func:`scene_distance` 0.8 ms
against a table (the forward kinematics alone 0.5-0.8 ms); :func:`approach_report` over 8 cm
(17 poses) 14 / 18 ms with a table and the ball / the mug.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import fcl
import numpy as np

from ..errors import InputError
from ..model.hands.model import HandModel
from ..model.scene import Scene
from .any_hand_queries import object_distances, obstacle_distances, part_pair_distances, plane_distances
from .any_hand_shapes import DECIDE_WITHIN, EXACT_WITHIN, HandShapes, hand_shapes, object_shape
# The scene's fcl objects, the pose/number validation and the approach tolerances are the paper hand's (one source of truth).
from .hand_fcl import CONTACT_ZONE, OBJECT_TOLERANCE, _approach_steps, _nonnegative, _pose, _scene_geometry

__all__ = ["HandCollision", "AnyHandReport", "AnyApproachReport", "object_report", "scene_distance",
           "approach_report", "TOUCH_TOLERANCE", "ALLOWED_OVERLAP", "DEPTH_SLACK"]

#: A link within this distance (m) of the object touches it (and may press this deep).
TOUCH_TOLERANCE = 0.001
#: Links of different fingers may overlap this much (m) before they collide (soft skins).
ALLOWED_OVERLAP = 0.002
#: A finger link may press this deep (m) into a palm link (one it does not hinge on, apart
#: with the hand open): as deep as into another finger. It was 1 mm (TOUCH_TOLERANCE) while
#: the simulation let the hand's links collide with one another (dex-urdf's Schunk SVH's
#: thumb 1.7 mm into the palm blocked it there with 200-500 N); since the simulation leaves
#: the hand's self-contacts to this check (``grasp_apso.simulation.any_hand_model``), 1 mm
#: only refused the SVH's opposed thumbs: its thumb's first link swings 1-2.2 mm into the
#: palm's coarse collision box over the upper 40 % of its opposition range, and this check
#: refused 139 of the 148 grasps the search verified on the baseball (seed 1). Measured
#: (``bench/held_rate.py --seeds 3 --dexgraspbench --hand schunk``, 63 plans on a table, by
#: default): best grasps held 32 -> 40 in this check, 47 -> 54 with DexGraspBench's
#: parameters (docs/any-hand-measurements.md, "The stop of 2026-12-07, eighth").
PALM_OVERLAP = ALLOWED_OVERLAP
#: m: a link's depth is read at samples of its surface 2.5 mm apart (``any_hand_shapes``);
#: a face pressing into a curved surface reaches deeper between them, by up to about 0.1 mm
#: on a 10 mm radius (an independent check with random samples read 1.005 mm where ours
#: read less than the 1 mm tolerance: dex-urdf LEAP's thumb on the barrel). A link is legal
#: only this much inside the tolerance (``AnyHandReport.max_depth``), and the seating opens
#: a finger that is not.
DEPTH_SLACK = 0.0001
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
            hit = part_pair_distances(self.shapes, self.place(poses), poses, a, b, 0.0) < 0.0
            cached = (a[hit], b[hit])
            self.shapes._default_pairs = cached  # benign race: every thread computes the same
        return cached

    def checked_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(a, b) part indices checked for self-collision (candidates minus the default
        ones) and (len(a),) bool, the pairs with a palm part."""
        a, b = self.shapes.pair_candidates
        palm = self.shapes.palm_pair
        da, db = self._default_pairs()
        if len(da) == 0:
            return a, b, palm
        k = len(self.shapes.geoms)
        keep = ~np.isin(a * k + b, da * k + db)
        return a[keep], b[keep], palm[keep]


def _check(hc) -> HandCollision:
    if isinstance(hc, HandModel):
        return HandCollision(hc)
    if not isinstance(hc, HandCollision):
        raise InputError(f"hc: expected a HandCollision (or a HandModel), got {type(hc).__name__}", "hc")
    return hc


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
        deepest point inside (penetration). Exact below ``exact_within``; at or beyond it,
        a lower bound (GJK against the object's convex hull: a primitive link against a
        convex object within ~0.4 mm; a mesh link, its own convex hull against the
        object's; for a non-convex one possibly much less than the true gap).
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
    exact_within : float, m
    """

    links: tuple[str, ...]
    link_distance: np.ndarray
    touching: np.ndarray
    deepest_penetration: float
    deepest_link: str
    link_pairs_colliding: tuple[tuple[str, str], ...]
    finger_pairs_colliding: tuple[tuple[str, str], ...]
    tolerance: float
    exact_within: float = EXACT_WITHIN

    @property
    def max_depth(self) -> float:
        """The deepest a link may read (m): ``tolerance`` less :data:`DEPTH_SLACK`."""
        return max(0.0, self.tolerance - DEPTH_SLACK)

    @property
    def legal(self) -> bool:
        """No link deeper than :attr:`max_depth` in the object and no links colliding."""
        return self.deepest_penetration <= self.max_depth and not self.link_pairs_colliding

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
    ``allowed_overlap`` (m; a pair with a palm link: at most :data:`PALM_OVERLAP`) at part
    ``poses`` (K, 4, 4) (from :meth:`HandCollision.part_poses`)."""
    a, b, palm = hc.checked_pairs()
    if len(a) == 0:
        return ()
    allowed = np.where(palm, min(allowed_overlap, PALM_OVERLAP), allowed_overlap)
    parts = np.union1d(a, b)
    # each pair measured exactly only where it can come below its own allowance
    d = part_pair_distances(hc.shapes, hc.place(poses, parts), poses, a, b, -allowed)
    pairs: list[tuple[str, str]] = []
    for i in np.flatnonzero(d < -allowed):
        key = (hc.links[hc.shapes.part_link[a[i]]], hc.links[hc.shapes.part_link[b[i]]])
        if key not in pairs:
            pairs.append(key)
    return tuple(pairs)


def object_report(hc: HandCollision | HandModel, q: np.ndarray, root_in_object: np.ndarray, obj,
                  tolerance: float = TOUCH_TOLERANCE, allowed_overlap: float = ALLOWED_OVERLAP,
                  exact_within: float = EXACT_WITHIN) -> AnyHandReport:
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
    exact_within : float, m, >= ``tolerance``
        Links nearer the object's convex hull than this are measured exactly (``inf``:
        every link, at the cost of a BVH query each).

    Raises
    ------
    InputError
        A bad argument, named.
    """
    hc = _check(hc)
    root = _pose(root_in_object, "root_in_object")
    tol = _nonnegative(tolerance, "tolerance")
    overlap = _nonnegative(allowed_overlap, "allowed_overlap")
    exact = float(exact_within) if exact_within == math.inf else _nonnegative(exact_within, "exact_within")
    if exact < tol:
        raise InputError(f"exact_within: {exact} m is below tolerance {tol} m", "exact_within")
    shape = object_shape(obj)
    poses = hc.part_poses(q, root)
    objs = hc.place(poses)
    dist = _link_min(hc, object_distances(hc.shapes, objs, poses, np.arange(len(objs)), shape, None, exact))
    worst = int(np.argmin(dist))
    pairs = self_collisions(hc, poses, overlap)
    names = [f.name for f in hc.hand.fingers]
    finger_pairs: list[tuple[str, str]] = []
    for la, lb in pairs:
        fa, fb = hc.shapes.finger[hc.links.index(la)], hc.shapes.finger[hc.links.index(lb)]
        if min(fa, fb) < 0:  # a finger in the palm: a link pair, no finger pair
            continue
        key = (names[min(fa, fb)], names[max(fa, fb)])
        if fa != fb and key not in finger_pairs:
            finger_pairs.append(key)
    dist.flags.writeable = False
    touching = dist <= tol
    touching.flags.writeable = False
    return AnyHandReport(links=hc.links, link_distance=dist, touching=touching,
                         deepest_penetration=float(max(0.0, -dist[worst])), deepest_link=hc.links[worst],
                         link_pairs_colliding=pairs, finger_pairs_colliding=tuple(finger_pairs), tolerance=tol,
                         exact_within=exact)


# ------------------------------------------------------------------ scene
def _scene(scene) -> Scene:
    if not isinstance(scene, Scene):
        raise InputError(f"scene: expected a Scene, got {type(scene).__name__}", "scene")
    return scene


def scene_distance(hc: HandCollision | HandModel, q: np.ndarray, root_pose: np.ndarray, scene: Scene) -> float:
    """Least distance (m) of the whole hand at ``q`` to the scene's support planes and
    obstacles (negative: the depth of the deepest part; ``inf`` for an empty scene).

    q : (n,) float; root_pose : (4, 4), the root link in the scene's frame."""
    hc = _check(hc)
    root = _pose(root_pose, "root_pose")
    scene = _scene(scene)
    poses = hc.part_poses(q, root)
    if scene.is_empty:
        return math.inf
    best = float(plane_distances(hc.shapes, poses, scene.planes).min()) if len(scene.planes) else math.inf
    if scene.obstacles:
        objs = hc.place(poses)
        obstacles = obstacle_distances(hc.shapes, objs, poses, np.arange(len(poses)), scene,
                                       _scene_geometry(scene).obstacles, best)
        best = min(best, float(obstacles.min()))
    return best


# ------------------------------------------------------------------ approach
@dataclass(frozen=True)
class AnyApproachReport:
    """Result of :func:`approach_report`.

    Attributes
    ----------
    clear : bool
        ``min_scene_distance >= clearance`` and not ``hits_object``.
    min_scene_distance : float, m
        Least whole-hand distance to the scene over the approach (planes: over the whole
        segment; obstacles: at the steps), negative: a penetration; ``inf``: empty scene.
    min_object_distance : float, m
        Least signed distance of the hand to the object over the steps (``inf``: no object).
    hits_object : bool
        The open hand touches the object farther than :data:`.hand_fcl.CONTACT_ZONE` before
        the grasp, or presses into it deeper than :data:`.hand_fcl.OBJECT_TOLERANCE` within it.
    hit_link : str
        The deepest link at the farthest such step ("" when none).
    hit_at : float, m
        How far before the grasp that step is (nan when none).
    steps : int
        Hand poses checked, the pre-grasp and the grasp included: ``ceil(distance / step) + 1``.
    """

    clear: bool
    min_scene_distance: float
    min_object_distance: float
    hits_object: bool
    hit_link: str
    hit_at: float
    steps: int


def _unit(vector, field: str) -> np.ndarray:
    v = np.asarray(vector, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) < 1e-9:
        raise InputError(f"{field}: expected a finite non-zero (3,) vector, got {v.tolist()}", field)
    return v / np.linalg.norm(v)


def approach_report(hc: HandCollision | HandModel, q_pre: np.ndarray, root_pose: np.ndarray, approach: np.ndarray,
                    distance: float, scene: Scene, obj=None, obj_pose: np.ndarray | None = None,
                    step: float = 0.005, clearance: float = 0.0, decide_only: bool = False) -> AnyApproachReport:
    """The open hand (``q_pre``) moved in a straight line from the pre-grasp (``root_pose``
    retreated ``distance`` along minus ``approach``) to ``root_pose``, checked at
    ``ceil(distance / step) + 1`` equal steps (each at most ``step``).

    Parameters
    ----------
    hc : HandCollision (or a HandModel)
    q_pre : (n,) float
        The open pre-shape, over ``hand.actuated_joints``.
    root_pose : (4, 4) float
        The root link at the grasp, scene frame.
    approach : (3,) float
        The direction of motion (scene frame; normalised here).
    distance : float, m, >= 0
    scene : Scene
    obj : GraspObject, trimesh.Trimesh, ObjectShape or None (no object check)
    obj_pose : (4, 4) float or None
        The object frame in the scene frame (None: the identity).
    step : float, m, > 0
    clearance : float, m, >= 0
    decide_only : bool
        Measure only what decides ``clear``: the object's distances of parts that cannot
        touch it are left at lower bounds (their convex hulls' gap), and the check stops
        at the first step where the hand hits the object (``min_object_distance`` is then
        a lower bound over the steps visited, ``hit_at`` that step). ``clear`` is the same
        either way; the selection of the pre-grasp uses it (a refused posture's mesh
        queries are most of a plan's approach checks).

    Raises
    ------
    InputError
        A bad argument, named; more than :data:`.hand_fcl.MAX_STEPS` poses.
    """
    hc = _check(hc)
    root = _pose(root_pose, "root_pose")
    a = _unit(approach, "approach")
    dist = _nonnegative(distance, "distance")
    step = _nonnegative(step, "step")
    clear_min = _nonnegative(clearance, "clearance")
    n = _approach_steps(dist, step, "distance")
    scene = _scene(scene)
    shape = None if obj is None else object_shape(obj)
    opose = np.eye(4) if obj_pose is None else _pose(obj_pose, "obj_pose")
    start = hc.part_poses(q_pre, root, "q_pre")
    count = len(start)
    min_scene = min_obj = math.inf
    if len(scene.planes):  # a translation by s moves each plane distance by -s (n . a): exact
        planes = plane_distances(hc.shapes, start, scene.planes)
        min_scene = float(min(planes.min(), (planes - dist * (scene.planes[:, :3] @ a)).min()))
    fcl_obstacles = _scene_geometry(scene).obstacles if scene.obstacles else None
    last_obs, at_obs = np.full(count, -math.inf), np.zeros(count)
    last_obj, at_obj = np.full(count, -math.inf), np.zeros(count)
    hit_at, hit_link = -math.inf, ""
    none = np.empty(0, dtype=np.int64)
    for i in range(n + 1):  # from the grasp back: the nearest poses set the minima first
        s = dist * i / n if n else 0.0
        # A translation by t changes a distance by at most t: a part whose lower bound
        # cannot lower a minimum (nor touch the object) is not measured at this step.
        obs_parts = none if fcl_obstacles is None else np.flatnonzero(last_obs - np.abs(s - at_obs) < min_scene)
        obj_parts = none
        if shape is not None:
            bound = last_obj - np.abs(s - at_obj)
            obj_parts = np.flatnonzero((bound <= 0.0) | ((bound < min_obj) & (not decide_only)))
        if not (len(obs_parts) or len(obj_parts)):
            continue
        poses = start.copy()
        poses[:, :3, 3] -= s * a
        objs = hc.place(poses, np.union1d(obs_parts, obj_parts))
        if len(obs_parts):
            d = obstacle_distances(hc.shapes, objs, poses, obs_parts, scene, fcl_obstacles, min_scene)
            last_obs[obs_parts], at_obs[obs_parts] = d, s
            min_scene = min(min_scene, float(d.min()))
        if len(obj_parts):
            d = object_distances(hc.shapes, objs, poses, obj_parts, shape, opose,
                                 DECIDE_WITHIN if decide_only else EXACT_WITHIN)
            last_obj[obj_parts], at_obj[obj_parts] = d, s
            min_obj = min(min_obj, float(d.min()))
            bad = d < -OBJECT_TOLERANCE if s <= CONTACT_ZONE + 1e-12 else d <= 0.0
            if bad.any() and s > hit_at:
                hit_at = s
                hit_link = hc.links[hc.shapes.part_link[obj_parts[np.argmin(np.where(bad, d, np.inf))]]]
                if decide_only:
                    break
    hits = hit_at > -math.inf
    return AnyApproachReport(clear=bool(min_scene >= clear_min and not hits), min_scene_distance=float(min_scene),
                             min_object_distance=float(min_obj), hits_object=bool(hits), hit_link=hit_link,
                             hit_at=float(hit_at) if hits else math.nan, steps=n + 1)
