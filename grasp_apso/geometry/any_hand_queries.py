"""Per-pose distance queries of any hand's parts (:mod:`.any_hand_shapes`) against an
object, support planes, obstacles and each other: the machinery of :mod:`.any_hand_fcl`.

Every function takes the parts' geometry-frame poses ``poses`` (K, 4, 4) in one query
frame. Separated shapes: fcl's exact distance (or closed forms: sphere and capsule pairs by
their segments, a sphere against a mesh by the mesh's exact signed distance at its centre,
any part against a plane by its support function). Overlapping shapes: minus the depth of
the deepest sample of one solid inside the other (see :mod:`.any_hand_shapes`); never fcl's
signed distance, whose EPA hangs on overlapping capsules and which a BVH does not support.
"""

from __future__ import annotations

import math

import fcl
import numpy as np

from ..cache import PerThreadCache
from ..model.hands.geometry import LinkGeometry
from ..model.scene import BOX, SPHERE, Obstacle
from .any_hand_shapes import EXACT_WITHIN, TOUCH_EPS, HandShapes, ObjectShape, local_samples
from .collision import segment_distances

__all__ = ["fcl_distance", "to_frame", "from_frame", "solid_pair", "part_pair_distances", "object_distances",
           "plane_distances", "obstacle_distances"]

_REQ = fcl.DistanceRequest()


def fcl_distance(a: fcl.CollisionObject, b: fcl.CollisionObject) -> float:
    """fcl's plain distance (m); <= :data:`TOUCH_EPS` when the two touch or overlap."""
    return float(fcl.distance(a, b, _REQ, fcl.DistanceResult()))


def to_frame(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (N, 3) given in the frame ``pose`` (4, 4) maps from -> its parent frame."""
    return points @ pose[:3, :3].T + pose[:3, 3]


def from_frame(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (N, 3) in the parent frame -> the frame ``pose`` (4, 4)."""
    return (points - pose[:3, 3]) @ pose[:3, :3]


def _sdf(geom: LinkGeometry, pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Exact signed distance (m) of points (N, 3), query frame, to a geometry posed at
    ``pose`` (its geometry frame)."""
    return geom.signed_distance(to_frame(geom.origin, from_frame(pose, points)))


def _within(points: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """The points (N, 3) inside the ball (centre (3,), radius m): only they can be inside
    a solid that the ball holds."""
    return points[np.einsum("ij,ij->i", points - centre, points - centre) <= radius * radius]


def solid_pair(geom_a: LinkGeometry, pose_a: np.ndarray, samples_a, geom_b: LinkGeometry, pose_b: np.ndarray,
               samples_b, ball_a: tuple[np.ndarray, float], ball_b: tuple[np.ndarray, float]) -> float:
    """Minus the overlap depth (m, <= 0) of two solids that touch: the deepest sample of
    each inside the other; ``samples_*`` (points (S, 3) geometry frame, inflation m),
    ``ball_*`` (centre (3,) query frame, radius m) a ball holding each solid."""
    out = 0.0
    for g_in, p_in, (points, inflate), p_out, (centre, radius) in (
            (geom_b, pose_b, samples_a, pose_a, ball_b), (geom_a, pose_a, samples_b, pose_b, ball_a)):
        near = _within(to_frame(p_out, points), centre, radius + inflate)
        if len(near):
            out = min(out, float((_sdf(g_in, p_in, near) - inflate).min()))
    return out


def _ball(shapes: HandShapes, poses: np.ndarray, k: int) -> tuple[np.ndarray, float]:
    return poses[k, :3, :3] @ shapes.bound_centre[k] + poses[k, :3, 3], float(shapes.bound_radius[k])


def _segments(shapes: HandShapes, poses: np.ndarray, parts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """End points (M, 3), (M, 3) of the axes of rounded parts (a sphere: both its centre)."""
    axis = poses[parts, :3, 2] * shapes.sup_axial[parts, None]
    return poses[parts, :3, 3] - axis, poses[parts, :3, 3] + axis


def part_pair_distances(shapes: HandShapes, objs: list, poses: np.ndarray, a: np.ndarray, b: np.ndarray,
                        below) -> np.ndarray:
    """Signed distances (m) of the part pairs (a[i], b[i]); pairs that cannot come below
    ``below`` (m, one for all pairs or (len(a),) one per pair) are left at a lower bound
    (their bounding spheres' gap, or for a pair with a mesh part, the gap between the parts'
    convex hulls), not measured.

    Rounded pairs in closed form (segment distance minus the radii, in one batch); the
    others fcl (``objs`` this thread's part objects, placed at ``poses``), then samples."""
    out = np.empty(len(a))
    below = np.broadcast_to(np.asarray(below, dtype=float), (len(a),))
    both = shapes.rounded[a] & shapes.rounded[b]
    if both.any():
        p0, p1 = _segments(shapes, poses, a[both])
        q0, q1 = _segments(shapes, poses, b[both])
        out[both] = segment_distances(p0, p1, q0, q1) - shapes.sup_radius[a[both]] - shapes.sup_radius[b[both]]
    rest = np.flatnonzero(~both)
    if len(rest):
        centre = np.einsum("kij,kj->ki", poses[:, :3, :3], shapes.bound_centre) + poses[:, :3, 3]
        ra, rb = a[rest], b[rest]
        out[rest] = np.linalg.norm(centre[ra] - centre[rb], axis=1) - shapes.bound_radius[ra] - shapes.bound_radius[rb]
        hulls = None
        for idx in rest[out[rest] < below[rest]]:
            i, j = int(a[idx]), int(b[idx])
            if not (shapes.primitive[i] and shapes.primitive[j]):
                # The parts' hulls first: apart, they bound the pair's distance from below
                # (a mesh pair's BVHs take milliseconds, their hulls microseconds).
                if hulls is None:
                    hulls = shapes.hull_objects()
                    placed: set[int] = set()
                for k in (i, j):
                    if k not in placed:
                        hulls[k].setTransform(fcl.Transform(poses[k, :3, :3], poses[k, :3, 3]))
                        placed.add(k)
                d = fcl_distance(hulls[i], hulls[j])
                if d > max(float(below[idx]), TOUCH_EPS):
                    out[idx] = d
                    continue
            d = fcl_distance(objs[i], objs[j])
            if d <= TOUCH_EPS:
                d = solid_pair(shapes.geoms[i], poses[i], shapes.samples[i], shapes.geoms[j], poses[j],
                               shapes.samples[j], _ball(shapes, poses, i), _ball(shapes, poses, j))
            out[idx] = d
    return out


def object_distances(shapes: HandShapes, objs: list, poses: np.ndarray, parts: np.ndarray, shape: ObjectShape,
                     object_pose: np.ndarray | None, exact_within: float = EXACT_WITHIN) -> np.ndarray:
    """Signed distance (m) of each part of ``parts`` (placed in ``objs``) to the object.

    ``object_pose`` (4, 4): the object frame in the query frame (None: the same frame).
    First GJK against the object's convex hull (a solid ``fcl.Convex``: quick, a lower
    bound for a non-convex object, within ~0.4 mm for a convex one), a mesh part's own
    convex hull first (a mesh part whose hull stays ``exact_within`` away keeps that
    lower bound; one whose hull is nearer but apart, or touches a non-convex object's
    hull, goes to the exact query directly);
    parts it finds within ``exact_within`` (m) are measured exactly: on the
    BVH, a sphere by the mesh's exact signed distance at its centre. Beyond it the value
    is a lower bound (a primitive against a convex object: within ~0.4 mm). fcl finds a part wholly inside a
    non-convex mesh (a hollow surface to fcl) apart: one sample per part decides, in one
    batch; a mesh part holding the object wholly: one object vertex decides. Touching
    parts then get their depth from their samples."""
    parts = np.asarray(parts, dtype=np.int64)
    out = np.empty(len(parts))
    if len(parts) == 0:
        return out
    target, hull = shape.collision_objects()
    pose = np.eye(4) if object_pose is None else object_pose
    for o in (target, hull):
        o.setTransform(fcl.Transform(pose[:3, :3], pose[:3, 3]))
    inflate = np.array([shapes.samples[k][1] for k in parts])
    far = np.zeros(len(parts), dtype=bool)
    hulls = shapes.hull_objects() if not shapes.primitive[parts].all() else None
    for i, k in enumerate(parts):
        if hulls is not None and not shapes.primitive[k]:
            # The part's hull against the object's: a lower bound in microseconds; a mesh
            # part's BVH against the hull only where the hulls touch. Where they are apart
            # (neither is inside the other) the part is measured exactly below, on the
            # BVHs: its BVH against the hull (a solid fcl.Convex) took 1-5 ms, 3-4 times
            # the exact query, and told nothing more.
            hulls[k].setTransform(fcl.Transform(poses[k, :3, :3], poses[k, :3, 3]))
            out[i] = fcl_distance(hulls[k], hull)
            far[i] = out[i] >= exact_within
            if out[i] > TOUCH_EPS or not shape.convex:
                # Hulls that touch, the object not convex: the exact query decides (its
                # BVH against the object's hull, about as slow, could only spare it).
                continue
        out[i] = fcl_distance(objs[k], hull)
    deep = out <= TOUCH_EPS
    refine = np.flatnonzero((out < exact_within) & (~deep if shape.convex else True))
    inside = np.zeros(len(parts), dtype=bool)
    if len(refine) and not shape.convex:  # one sample per part: inside the (hollow) mesh?
        first = np.array([to_frame(poses[parts[i]], shapes.samples[parts[i]][0][:1])[0] for i in refine])
        first_sdf = shape.distance(from_frame(pose, first)) - inflate[refine]
        inside[refine] = first_sdf < 0.0
    for n, i in enumerate(refine):
        k = parts[i]
        if not shape.convex and shapes.geoms[k].kind == "sphere":
            out[i], deep[i], inside[i] = first_sdf[n], False, False  # exact
        else:
            out[i] = fcl_distance(objs[k], target)
            deep[i] = out[i] <= TOUCH_EPS
    deep |= inside
    vertex = to_frame(pose, shape.vertices[:1])[0]
    centre = np.einsum("kij,kj->ki", poses[parts, :3, :3], shapes.bound_centre[parts]) + poses[parts, :3, 3]
    holds = (np.linalg.norm(centre - vertex, axis=1) <= shapes.bound_radius[parts]) & ~shapes.primitive[parts]
    for i in np.flatnonzero(holds & ~deep & ~far):  # a (hollow) mesh part around the object?
        k = parts[i]
        deep[i] = _sdf(shapes.geoms[k], poses[k], vertex[None])[0] < 0.0
    ball = (to_frame(pose, shape.centre[None])[0], shape.radius)
    for i in np.flatnonzero(deep):
        k = parts[i]
        near = from_frame(pose, _within(to_frame(poses[k], shapes.samples[k][0]), ball[0], ball[1] + inflate[i]))
        # only samples that may come within their inflation of the inside can deepen it
        # (the hull's planes bound the rest from below: most of a touching link's samples)
        near = near[shape.may_reach(near, inflate[i])]
        depth = float(shape.distance(near).min()) - inflate[i] if len(near) else 0.0
        # the object's edge points near the part, picked in the object frame (only those
        # few are moved: the mug has 12,282)
        near = _within(shape.edge_points, from_frame(pose, centre[i][None])[0], shapes.bound_radius[k])
        if len(near):
            depth = min(depth, float(_sdf(shapes.geoms[k], poses[k], to_frame(pose, near)).min()))
        out[i] = min(depth, 0.0)
    return out


def plane_distances(shapes: HandShapes, poses: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """(K, P) signed distance (m) of every part to every support plane's solid side
    (planes (P, 4) normalised, solid where a x + b y + c z + d < 0): the support function
    of each part along the normal, exact, at any distance (negative: its depth)."""
    n = planes[:, :3]
    u = np.einsum("kji,pj->kpi", poses[:, :3, :3], n)  # the normals in each geometry frame
    h = np.einsum("kpi,ki->kp", np.abs(u), shapes.sup_half)
    uz = np.abs(u[..., 2])
    h += shapes.sup_radius[:, None] + shapes.sup_axial[:, None] * uz
    h += shapes.sup_disc[:, None] * np.sqrt(np.maximum(0.0, 1.0 - uz * uz))
    for k, hull in shapes.hull_vertices.items():
        h[k] = -(hull @ u[k].T).min(axis=0)  # min over the hull of u . v, as a support value
    return poses[:, :3, 3] @ n.T + planes[:, 3] - h


class _ObstacleShapes:
    """One scene's obstacles as LinkGeometry (exact signed distance, samples) with their
    bounding spheres; per thread (keyed by the scene), built on first use."""

    def __init__(self, obstacles: tuple[Obstacle, ...]):
        self.geoms, self.poses, self.radius = [], [], []
        for o in obstacles:
            dims = np.asarray(o.dimensions, dtype=float)
            if o.kind == BOX:
                geom = LinkGeometry("box", tuple(dims / 2.0))
                radius = float(np.linalg.norm(dims / 2.0))
            elif o.kind == SPHERE:
                geom, radius = LinkGeometry("sphere", (dims[0],)), float(dims[0])
            else:  # CYLINDER: [height, radius]
                geom, radius = LinkGeometry("cylinder", (dims[1], dims[0] / 2.0)), math.hypot(dims[1], dims[0] / 2.0)
            self.geoms.append(geom)
            self.poses.append(np.asarray(o.pose, dtype=float))
            self.radius.append(radius)
        self.centres = np.array([p[:3, 3] for p in self.poses]).reshape(-1, 3)
        self.radius = np.array(self.radius)
        self._samples: dict[int, tuple[np.ndarray, float]] = {}

    def samples(self, j: int) -> tuple[np.ndarray, float]:
        if j not in self._samples:
            self._samples[j] = local_samples(self.geoms[j])
        return self._samples[j]


_OBSTACLES: "PerThreadCache[_ObstacleShapes]" = PerThreadCache(max_entries=8)


def obstacle_distances(shapes: HandShapes, objs: list, poses: np.ndarray, parts: np.ndarray, scene,
                       fcl_obstacles: list, below: float) -> np.ndarray:
    """(len(parts),) least signed distance (m) of each part to the scene's obstacles
    (``fcl_obstacles``: their fcl objects, :mod:`.hand_fcl`'s); a part whose bounding
    sphere stays ``below`` or farther from every obstacle's keeps that lower bound."""
    parts = np.asarray(parts, dtype=np.int64)
    out = np.full(len(parts), math.inf)
    if not scene.obstacles or len(parts) == 0:
        return out
    obs = _OBSTACLES.get(scene, lambda s: _ObstacleShapes(s.obstacles))
    centre = np.einsum("kij,kj->ki", poses[parts, :3, :3], shapes.bound_centre[parts]) + poses[parts, :3, 3]
    bound = (np.linalg.norm(centre[:, None] - obs.centres[None], axis=2) - shapes.bound_radius[parts, None]
             - obs.radius[None])  # (M, O)
    for i, k in enumerate(parts):
        for j in np.argsort(bound[i]):
            if bound[i, j] >= min(out[i], below):
                out[i] = min(out[i], bound[i, j])
                break
            d = fcl_distance(objs[k], fcl_obstacles[j])
            if d > TOUCH_EPS and not shapes.primitive[k]:  # an obstacle inside a (hollow) mesh part?
                if _sdf(shapes.geoms[k], poses[k], obs.centres[j][None])[0] < 0.0:
                    d = 0.0
            if d <= TOUCH_EPS:
                d = solid_pair(shapes.geoms[k], poses[k], shapes.samples[k], obs.geoms[j], obs.poses[j],
                               obs.samples(j), _ball(shapes, poses, k), (obs.centres[j], obs.radius[j]))
            out[i] = min(out[i], d)
    return out
