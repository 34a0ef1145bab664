"""python-fcl checks of the WHOLE hand against the scene, at one pose and along an approach.

The hand's collision geometry (the same shapes as the decoder and the URDF): the palm box
(``hand.palm_center`` / ``hand.palm_half_extents`` in the palm frame), one capsule per
link between consecutive finger frames of :meth:`HandModel.finger_frames` (base -> PIP ->
DIP -> tip, radius ``hand.link_radii[k]``) and a pad sphere (``hand.pad_radius``) on each
fingertip: 21 parts. The scene (:class:`~grasp_apso.model.scene.Scene`, shape_msgs
conventions): obstacles as ``fcl.Box`` / ``fcl.Sphere`` / ``fcl.Cylinder`` at their poses;
a support plane as a thick box under the plane (python-fcl 0.7's ``distance`` against an
``fcl.Halfspace`` crashes the interpreter; a box of :data:`PLANE_BOX_HALF_WIDTH` half width
and :data:`PLANE_BOX_THICKNESS` thickness, its top face on the plane, re-centred under the
wrist at every query, is exact for any hand within a metre of the wrist).

Distances: fcl's plain distance (exact for these primitive pairs); a pair in collision
(fcl answers -1) is measured again with signed distance (GJK/EPA), so a penetration is a
negative number (its depth, m, to about 1e-6).

Collision objects are built once per hand and scene and per thread (their transforms are
updated per query; the objects are mutable, so threads do not share them). Measured
(one core, idle machine): :func:`hand_scene_distance` about 1.1 ms per hand pose against a
table (forward kinematics included), 1.4 ms with three more obstacles; along an approach
about 0.6 ms per pose (the posture is fixed), and with an object mesh (the 2,900-triangle
fish) about 1.5 ms per pose, thanks to the distance bound that skips poses.
"""

from __future__ import annotations

import math
import threading
import weakref
from dataclasses import dataclass

import fcl
import numpy as np

from ..cache import PerThreadCache
from ..errors import InputError
from ..model.hand import N_FINGERS, HandModel
from ..model.scene import BOX, CYLINDER, SPHERE, Scene
from .collision import capsule_frames

__all__ = [
    "ApproachReport", "hand_scene_distance", "approach_report",
    "PLANE_BOX_HALF_WIDTH", "PLANE_BOX_THICKNESS", "OBJECT_TOLERANCE", "CONTACT_ZONE", "MAX_STEPS",
]

#: Half width (m) of the box standing in for a support plane (re-centred under the wrist).
PLANE_BOX_HALF_WIDTH = 1.0
#: Thickness (m) of that box, below the plane.
PLANE_BOX_THICKNESS = 1.0
#: The open hand may press into the object by this much (m) near the grasp (the decoder's
#: contact tolerance: a pre-shaped fingertip may already rest on the surface).
OBJECT_TOLERANCE = 0.001
#: ... but only within this last stretch of the approach (m before the grasp pose).
CONTACT_ZONE = 0.010
#: Most hand poses one approach check visits (bounds the loop).
MAX_STEPS = 10_000


@dataclass(frozen=True)
class ApproachReport:
    """Result of :func:`approach_report`.

    Attributes
    ----------
    clear : bool
        Every pose keeps ``clearance`` from the scene and the open hand does not penetrate
        the object (see :func:`approach_report` for the tolerance near the grasp).
    min_scene_distance : float, m
        Least whole-hand distance to the scene over all poses (negative: penetration
        depth; ``inf`` for an empty scene).
    min_object_distance : float, m
        Least whole-hand distance to the object over all poses (0 when touching or
        penetrating; ``inf`` without an object).
    steps : int
        Hand poses checked, the pre-grasp and the grasp included: ``ceil(d / step) + 1``.
    """

    clear: bool
    min_scene_distance: float
    min_object_distance: float
    steps: int


# ------------------------------------------------------------------ validation
def _finger_values(values: np.ndarray, field: str) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    if v.ndim != 1 or v.shape[0] not in (15, 18, 19):
        raise InputError(f"{field}: expected shape (15,), (18,) or (19,), got {v.shape}", field)
    if not np.all(np.isfinite(v[:15])):
        raise InputError(f"{field}: finger values must be finite", field)
    return v[:15]


def _pose(pose: np.ndarray, field: str) -> np.ndarray:
    m = np.asarray(pose, dtype=float)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InputError(f"{field}: expected a finite (4, 4) transform, got shape {m.shape}", field)
    rot = m[:3, :3]
    if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
        raise InputError(f"{field}: the rotation part is not a rotation", field)
    return m


def _nonnegative(value: float, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{field}: expected a number, got {value!r}", field)
    v = float(value)
    if not math.isfinite(v) or v < 0:
        raise InputError(f"{field}: must be finite and >= 0, got {v!r}", field)
    return v


def _approach_steps(distance: float, step: float, distance_field: str) -> int:
    """Steps n (n + 1 poses) of ``step`` m over an approach of ``distance`` m (both
    checked >= 0 already); InputError naming ``step`` when it is 0 or the poses exceed
    :data:`MAX_STEPS`."""
    if step <= 0:
        raise InputError("step: must be > 0", "step")
    n = int(math.ceil(distance / step - 1e-12)) if distance > 0 else 0
    if n + 1 > MAX_STEPS:
        raise InputError(f"step: {n + 1} poses for {distance_field} {distance} m, at most {MAX_STEPS}", "step")
    return n


# ------------------------------------------------------------------ geometry
def _local_parts(hand: HandModel, values15: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """(rotation (3, 3), centre (3,) m) of each part in the palm frame: the palm box, the
    15 link capsules (finger-major, proximal first), the 5 pads; ``values15`` (15,) rad."""
    frames = hand.finger_frames(values15[None, :])[0]  # (5, 4, 4, 4)
    pts = frames[..., :3, 3]
    rot, centre, _ = capsule_frames(pts[:, :3], pts[:, 1:])  # (5, 3, 3, 3), (5, 3, 3)
    out = [(np.eye(3), np.asarray(hand.palm_center, dtype=float))]
    out.extend((rot[f, k], centre[f, k]) for f in range(N_FINGERS) for k in range(3))
    out.extend((np.eye(3), pts[f, 3]) for f in range(N_FINGERS))
    return out


class _HandGeometry:
    """Cached fcl objects of one hand: full size and shrunk by :data:`OBJECT_TOLERANCE`."""

    def __init__(self, hand: HandModel):
        half = np.asarray(hand.palm_half_extents, dtype=float)
        lengths = np.asarray(hand.link_lengths, dtype=float)
        radii = np.asarray(hand.link_radii, dtype=float)

        def shapes(shrink: float) -> list:
            out = [fcl.Box(*(2.0 * np.maximum(half - shrink, 1e-6)))]
            out += [fcl.Capsule(max(float(radii[k]) - shrink, 1e-6), float(lengths[f, k]))
                    for f in range(N_FINGERS) for k in range(3)]
            out += [fcl.Sphere(max(hand.pad_radius - shrink, 1e-6)) for _ in range(N_FINGERS)]
            return out

        self.full = [fcl.CollisionObject(g, fcl.Transform()) for g in shapes(0.0)]
        self.shrunk = [fcl.CollisionObject(g, fcl.Transform()) for g in shapes(OBJECT_TOLERANCE)]

    def place(self, local: list[tuple[np.ndarray, np.ndarray]], wrist: np.ndarray, shrunk: bool = False,
              parts=None) -> list:
        """The parts' fcl objects (all of them) with the parts ``parts`` (indices, default
        all) moved to ``local`` under ``wrist``."""
        objs = self.shrunk if shrunk else self.full
        rw, tw = wrist[:3, :3], wrist[:3, 3]
        for k in range(len(local)) if parts is None else parts:
            r, c = local[k]
            objs[k].setTransform(fcl.Transform(rw @ r, rw @ c + tw))
        return objs


class _SceneGeometry:
    """Cached fcl objects of one scene: plane boxes (re-centred per query) and obstacles."""

    def __init__(self, scene: Scene):
        self.planes = np.array(scene.planes, dtype=float).reshape(-1, 4)
        self.plane_rot = [_frame_with_z(p[:3]) for p in self.planes]
        size = (2 * PLANE_BOX_HALF_WIDTH, 2 * PLANE_BOX_HALF_WIDTH, PLANE_BOX_THICKNESS)
        self.plane_objs = [fcl.CollisionObject(fcl.Box(*size), fcl.Transform()) for _ in self.planes]
        self.obstacles = []
        for o in scene.obstacles:
            if o.kind == BOX:
                geom = fcl.Box(*o.dimensions)
            elif o.kind == SPHERE:
                geom = fcl.Sphere(o.dimensions[0])
            elif o.kind == CYLINDER:
                geom = fcl.Cylinder(o.dimensions[1], o.dimensions[0])  # radius, height (along z)
            else:  # Scene validates kinds; kept for safety
                raise InputError(f"scene: unknown obstacle kind {o.kind}", "scene")
            pose = np.asarray(o.pose, dtype=float)
            self.obstacles.append(fcl.CollisionObject(geom, fcl.Transform(pose[:3, :3], pose[:3, 3])))

    def objects(self, anchor: np.ndarray) -> list:
        """All scene objects, each plane box centred under ``anchor`` (3,) m."""
        for p, rot, obj in zip(self.planes, self.plane_rot, self.plane_objs):
            n, d = p[:3], p[3]
            foot = anchor - (n @ anchor + d) * n  # projection onto the plane
            obj.setTransform(fcl.Transform(rot, foot - 0.5 * PLANE_BOX_THICKNESS * n))
        return self.plane_objs + self.obstacles


def _frame_with_z(n: np.ndarray) -> np.ndarray:
    z = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


_LOCAL = threading.local()


_HANDS: "PerThreadCache[_HandGeometry]" = PerThreadCache(max_entries=8)


def _hand_geometry(hand: HandModel) -> _HandGeometry:
    return _HANDS.get(hand, _HandGeometry)


def _scene_geometry(scene: Scene) -> _SceneGeometry:
    cache = getattr(_LOCAL, "scenes", None)
    if cache is None:
        cache = _LOCAL.scenes = weakref.WeakKeyDictionary()
    geo = cache.get(scene)
    if geo is None:
        geo = cache[scene] = _SceneGeometry(scene)
    return geo


def _pair_distance(a: fcl.CollisionObject, b: fcl.CollisionObject) -> float:
    """Distance (m) between two primitives, negative penetration depth when they overlap."""
    d = fcl.distance(a, b, fcl.DistanceRequest(), fcl.DistanceResult())
    if d >= 0.0:
        return float(d)
    signed = fcl.distance(a, b, fcl.DistanceRequest(enable_signed_distance=True), fcl.DistanceResult())
    return float(min(signed, 0.0))


def _min_distance(parts: list, others: list) -> float:
    best = math.inf
    for a in parts:
        for b in others:
            best = min(best, _pair_distance(a, b))
    return best


def _object_contact(parts: list, obj: fcl.CollisionObject) -> tuple[float, bool]:
    """(least distance of the parts to the object m, 0 when touching; whether any touches)."""
    best = math.inf
    for a in parts:
        d = fcl.distance(a, obj, fcl.DistanceRequest(), fcl.DistanceResult())
        if d <= 0.0:  # fcl answers -1 for a pair in collision
            return 0.0, True
        best = min(best, float(d))
    return best, False


# ------------------------------------------------------------------ public API
def hand_scene_distance(hand: HandModel, finger_values: np.ndarray, wrist_pose: np.ndarray,
                        scene: Scene) -> float:
    """Least distance (m) between the whole hand and the scene (python-fcl).

    Parameters
    ----------
    hand : HandModel
    finger_values : (15,), (18,) or (19,) float, rad
        Only the 15 finger values are used.
    wrist_pose : (4, 4) float
        Palm frame in the scene's frame.
    scene : Scene

    Returns
    -------
    float, m
        Positive: the gap; negative: the deepest penetration of a hand part into a
        support plane's solid side or an obstacle; ``inf`` for an empty scene.

    Raises
    ------
    InputError
        Bad ``finger_values`` or ``wrist_pose`` (the message names the field).
    """
    values = _finger_values(finger_values, "finger_values")
    wrist = _pose(wrist_pose, "wrist_pose")
    if not isinstance(scene, Scene):
        raise InputError(f"scene: expected a Scene, got {type(scene).__name__}", "scene")
    if scene.is_empty:
        return math.inf
    parts = _hand_geometry(hand).place(_local_parts(hand, values), wrist)
    return _min_distance(parts, _scene_geometry(scene).objects(wrist[:3, 3]))


def approach_report(
    hand: HandModel,
    open_values: np.ndarray,
    grasp_pose: np.ndarray,
    approach_distance: float,
    scene: Scene,
    obj_bvh: fcl.BVHModel | None,
    object_pose: np.ndarray | None,
    clearance: float,
    step: float = 0.005,
    obj_bounds: np.ndarray | None = None,
) -> ApproachReport:
    """Check the straight approach of the open hand from the pre-grasp to the grasp.

    The wrist moves from the pre-grasp (``grasp_pose`` retreated ``approach_distance``
    along minus its +z) to ``grasp_pose`` in ``n = ceil(approach_distance / step)`` equal
    steps (each at most ``step``); the n + 1 poses are checked with the fingers at
    ``open_values``.

    Clear when, at every pose:

    - the whole hand keeps at least ``clearance`` from every support plane and obstacle
      (strict: no tolerance anywhere), and
    - the open hand does not touch the object, except within the last
      :data:`CONTACT_ZONE` (10 mm) before the grasp, where it may press into it by at most
      :data:`OBJECT_TOLERANCE` (1 mm: each part shrunk by that much must not collide).
      The decoder's pre-shape may rest a fingertip on the surface within its contact
      tolerance; deeper penetration is a blocked finger and is refused.

    Parameters
    ----------
    hand : HandModel
    open_values : (15,), (18,) or (19,) float, rad
        The open pre-shape (finger values only are used).
    grasp_pose : (4, 4) float
        Palm frame at the grasp, scene frame.
    approach_distance : float, m, >= 0
    scene : Scene
    obj_bvh : fcl.BVHModel or None
        The object mesh (:func:`~grasp_apso.geometry.collision.mesh_bvh`); None skips the
        object check.
    object_pose : (4, 4) float or None
        Object frame -> scene frame for ``obj_bvh``; None: the BVH is in the scene frame.
    clearance : float, m, >= 0
    step : float, m, > 0
    obj_bounds : (2, 3) float, m, optional
        The object's axis-aligned bounding box in its frame (least and greatest corner).
        A hand part's distance to that box (a primitive query, some 30 times cheaper than
        one against the mesh) bounds its distance to the object from below: a part that
        this bound shows can neither touch the object nor lower the least distance is
        not measured against the mesh (the report is unchanged).

    Raises
    ------
    InputError
        A bad argument, named; more than :data:`MAX_STEPS` poses.
    """
    values = _finger_values(open_values, "open_values")
    grasp = _pose(grasp_pose, "grasp_pose")
    dist = _nonnegative(approach_distance, "approach_distance")
    clear_min = _nonnegative(clearance, "clearance")
    step = _nonnegative(step, "step")
    if step <= 0:
        raise InputError("step: must be > 0", "step")
    if not isinstance(scene, Scene):
        raise InputError(f"scene: expected a Scene, got {type(scene).__name__}", "scene")
    n = _approach_steps(dist, step, "approach_distance")
    obj = box = None
    if obj_bvh is not None:
        pose = np.eye(4) if object_pose is None else _pose(object_pose, "object_pose")
        obj = fcl.CollisionObject(obj_bvh, fcl.Transform(pose[:3, :3], pose[:3, 3]))
        if obj_bounds is not None:
            lo_hi = np.asarray(obj_bounds, dtype=float)
            if lo_hi.shape != (2, 3) or not np.all(np.isfinite(lo_hi)) or np.any(lo_hi[1] < lo_hi[0]):
                raise InputError("obj_bounds: expected finite (2, 3) least and greatest corners", "obj_bounds")
            centre = pose[:3, :3] @ (0.5 * (lo_hi[0] + lo_hi[1])) + pose[:3, 3]
            box = fcl.CollisionObject(fcl.Box(*np.maximum(lo_hi[1] - lo_hi[0], 1e-9)),
                                      fcl.Transform(pose[:3, :3], centre))

    geo = _hand_geometry(hand)
    local = _local_parts(hand, values)
    scene_geo = None if scene.is_empty else _scene_geometry(scene)
    approach = grasp[:3, 2]
    min_scene, min_obj, clear = math.inf, math.inf, True
    # From the grasp back to the pre-grasp. A translation by t changes a part's distance
    # by at most t, so a part whose lower bound (its last measured distance minus the
    # travel since) can neither lower a minimum nor break the clearance nor touch the
    # object is not measured at that pose: the minima stay exact over the n + 1 poses,
    # and the parts far from the scene and the object are measured a few times only.
    n_parts = len(local)
    last_scene = np.full(n_parts, -math.inf)  # per part: distance at its last measurement
    last_obj = np.full(n_parts, -math.inf)
    at_scene = np.zeros(n_parts)  # ... and the ``remaining`` there
    at_obj = np.zeros(n_parts)
    for i in range(n, -1, -1):
        remaining = dist * (1.0 - i / n) if n else 0.0
        scene_parts = obj_parts = np.empty(0, dtype=np.int64)
        if scene_geo is not None:
            scene_parts = np.flatnonzero(last_scene - np.abs(remaining - at_scene) < min_scene)
        if obj is not None:
            bound = last_obj - np.abs(remaining - at_obj)
            obj_parts = np.flatnonzero(~((bound > 0.0) & (bound >= min_obj)))
        if not (len(scene_parts) or len(obj_parts)):
            continue
        wrist = grasp.copy()
        wrist[:3, 3] -= remaining * approach
        parts = geo.place(local, wrist, parts=np.union1d(scene_parts, obj_parts))
        if len(scene_parts):
            others = scene_geo.objects(wrist[:3, 3])
            for k in scene_parts:
                d = _min_distance((parts[k],), others)
                last_scene[k], at_scene[k] = d, remaining
                min_scene = min(min_scene, d)
                clear &= d >= clear_min
        below = np.zeros(len(obj_parts))  # lower bounds of the parts' object distances
        if box is not None and len(obj_parts):
            below = np.array([max(0.0, fcl.distance(parts[k], box, fcl.DistanceRequest(), fcl.DistanceResult()))
                              for k in obj_parts])
        for j in np.argsort(below, kind="stable"):  # the nearest first: they set min_obj
            k = obj_parts[j]
            if below[j] > 0.0 and below[j] >= min_obj:  # cannot touch nor lower the minimum
                last_obj[k], at_obj[k] = below[j], remaining
                continue
            d, touching = _object_contact((parts[k],), obj)
            last_obj[k], at_obj[k] = d, remaining
            min_obj = min(min_obj, d)
            if touching:
                if remaining > CONTACT_ZONE + 1e-12:
                    clear = False
                else:
                    shrunk = geo.place(local, wrist, shrunk=True, parts=(k,))
                    clear &= not _object_contact((shrunk[k],), obj)[1]
    return ApproachReport(clear=bool(clear), min_scene_distance=float(min_scene),
                          min_object_distance=float(min_obj), steps=n + 1)
