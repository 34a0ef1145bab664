"""Seating a general hand's fingers on the object's exact collision geometry.

The search closes fingers against sphere covers of the links (:mod:`grasp_apso.model.hands.spheres`);
a link's exact mesh may stick out of its cover by a millimetre or two where the cover
is thin (measured: LEAP's thumb fingertip, 1.0 to 1.4 mm into a cube in every one of 40
otherwise valid grasps, so no cube plan with that hand passed the python-fcl check).
:func:`seat_fingers` opens each finger whose exact geometry presses deeper than the
python-fcl check allows (``AnyHandReport.max_depth``: the tolerance less the samples'
slack) back along its own closing path, by bisection, until it rests within
:data:`SEAT_DEPTH`, the way a position-controlled finger stops on the surface: the
verification then decides on the seated posture.
"""

from __future__ import annotations

import numpy as np

__all__ = ["seat_fingers", "finger_distance", "pad_body_distances", "pad_body_rows", "pad_nearest", "SEAT_DEPTH",
           "SEAT_TRAVEL", "SEAT_STEPS"]

#: m: a seated finger's exact geometry is at most this deep in the object (the python-fcl
#: check allows 1 mm; half of it leaves room for the mesh distance's own error).
SEAT_DEPTH = 0.0005
#: The furthest a finger is opened: this fraction of its way back to the pre-shape.
SEAT_TRAVEL = 0.25
#: Bisection steps per finger (the opening found to SEAT_TRAVEL / 2**SEAT_STEPS).
SEAT_STEPS = 5
#: m: a seated pad (sphere or point) stays this much inside the contact tolerance of the surface
#: (an exact-distance check of it may differ by a few tenths of a millimetre).
PAD_MARGIN = 0.00025


def finger_distance(hc, q: np.ndarray, root: np.ndarray, shape, parts: np.ndarray,
                    exact_within: float | None = None) -> tuple[float, int]:
    """The least signed distance (m) to the object of the collision parts ``parts`` (one
    finger's) at posture q, and the part that has it: python-fcl and the exact mesh
    distance on those parts only (a whole-hand report per bisection step cost 60 ms with
    LEAP's meshes). ``exact_within``: as :func:`grasp_apso.geometry.any_hand_queries.object_distances`
    (None: its :data:`~grasp_apso.geometry.any_hand_shapes.EXACT_WITHIN`)."""
    from ..geometry.any_hand_queries import object_distances
    from ..geometry.any_hand_shapes import EXACT_WITHIN

    poses = hc.part_poses(q, root)
    d = object_distances(hc.shapes, hc.place(poses, parts), poses, parts, shape, None,
                         EXACT_WITHIN if exact_within is None else exact_within)
    k = int(np.argmin(d))
    return float(d[k]), int(parts[k])


def pad_body_rows(hand, hc, f: int) -> list[int]:
    """Rows of ``hc.links`` of finger ``f``'s pad body: its pad link and the links rigidly
    fixed to it (one body: the Allegro-like tip is a small link on the distal)."""
    from ..geometry.any_hand_tables import pad_body_links

    links = list(hc.links)
    return [links.index(name) for name in pad_body_links(hand, f) if name in links]


def pad_body_distances(hand, q: np.ndarray, root: np.ndarray, fingers: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The exact signed distances (k,) m, > 0 outside, from ``points`` (k, 3), object
    frame, to the pad bodies of ``fingers`` (k,) int (each its pad link and the links
    fixed to it: their collision geometry,
    :meth:`grasp_apso.model.hands.LinkGeometry.signed_distance`) at posture q (n,) with
    the root link at ``root`` (4, 4) in the object frame; inf for a pad body without
    collision geometry."""
    from ..geometry.any_hand_tables import pad_body_links
    from ..model.hands.spheres import union_signed_distance

    poses = hand.link_transforms(np.asarray(q, float))  # one forward kinematics for all
    out = np.full(len(fingers), np.inf)
    for i, (f, point) in enumerate(zip(fingers, np.asarray(points, float).reshape(-1, 3))):
        for link in pad_body_links(hand, int(f)):
            geoms = hand.collision.get(link)
            if geoms:
                pose = np.asarray(root, float) @ poses[link]
                local = np.linalg.solve(pose, np.append(point, 1.0))[:3]
                out[i] = min(out[i], float(union_signed_distance(geoms, local[None])[0]))
    return out


def pad_nearest(hc, q: np.ndarray, root: np.ndarray, grid, parts: np.ndarray) -> tuple[float, np.ndarray]:
    """The least distance (m) of the pad body's collision surface to the object and the
    point (3,) object frame that has it: the parts' surface samples
    (:func:`grasp_apso.geometry.any_hand_shapes.local_samples`) read on the object's
    signed-distance ``grid`` (a few hundred microseconds where a python-fcl query of a
    mesh fingertip takes milliseconds; the rest is then checked exactly), or on its exact
    distance (an :class:`~grasp_apso.geometry.any_hand_shapes.ObjectShape`: ``.distance``
    too)."""
    from ..geometry.any_hand_queries import to_frame

    poses = hc.part_poses(q, root)
    best, point = np.inf, None
    for k in parts:
        samples, inflate = hc.shapes.samples[k]
        pts = to_frame(poses[k], samples)
        d = grid.distance(pts) - inflate
        i = int(np.argmin(d))
        if d[i] < best:
            best, point = float(d[i]), pts[i]
    return best, point


def _finger_depth(hc, q: np.ndarray, root: np.ndarray, shape, parts: np.ndarray) -> float:
    """The deepest penetration (m, >= 0) in the object of one finger's parts at posture q."""
    from ..geometry.any_hand_shapes import DECIDE_WITHIN

    # only a depth is wanted: parts apart from the object's hull keep that lower bound
    return max(0.0, -finger_distance(hc, q, root, shape, parts, DECIDE_WITHIN)[0])


def seat_fingers(fcl_api, hc, hand, q: np.ndarray, q_open: np.ndarray, root: np.ndarray, obj, report,
                 pad_tolerance: float):
    """Open the fingers that press into the object (exact geometry) until they rest on it.

    Parameters
    ----------
    fcl_api : module
        :mod:`grasp_apso.geometry.any_hand_fcl`.
    hc : HandCollision
    hand : HandModel
    q, q_open : (n,) float, rad or m
        The grasp posture and the search's pre-shape (the closing path runs from q_open to q).
    root : (4, 4) float
        The root link in the object frame.
    obj : GraspObject
    report : AnyHandReport
        ``fcl_api.object_report`` of ``q``.
    pad_tolerance : float, m
        A seated finger whose pad touched (its sphere or its point within this of the
        surface) must still touch, one of them within this less :data:`PAD_MARGIN`.

    Returns
    -------
    (q, report, rest)
        The seated posture and its report, or the given ones unchanged when no finger
        presses in, the palm does (a finger cannot fix it), or a finger would have to
        open further than :data:`SEAT_TRAVEL` or lose its pad contact (the link then
        touched the object away from its pad). ``rest`` (F,) bool: the seated fingers whose
        pad sphere and pad point left the surface while their pad link rests on it (within
        ``pad_tolerance`` less :data:`PAD_MARGIN`), their pad body (the pad link and the
        links fixed to it) nearer than the finger's other links: the contact is where that
        body touches (a curved fingertip meeting a small object
        below its pad point: the dex-urdf Barrett's distal link on the sphere).
    """
    fingers = hc.shapes.finger
    rest = np.zeros(len(hand.fingers), dtype=bool)
    deep = np.flatnonzero(report.link_distance < -report.max_depth)
    if not len(deep) or np.any(fingers[deep] < 0) or report.link_pairs_colliding:
        return q, report, rest
    from ..geometry.any_hand_shapes import object_shape

    shape = object_shape(obj)
    seated = np.array(q, dtype=float)
    moved = np.unique(fingers[deep])
    for f in moved:
        finger = hand.fingers[int(f)]
        parts = np.flatnonzero(fingers[hc.shapes.part_link] == f)
        joints = [hand.actuated_joints.index(j) for j, sense in zip(finger.joints, finger.closing) if sense]
        base = seated.copy()

        def at(t: float) -> np.ndarray:
            out = base.copy()
            out[joints] += t * (np.asarray(q_open, float)[joints] - base[joints])
            return out

        lo, hi = 0.0, SEAT_TRAVEL
        if _finger_depth(hc, at(hi), root, shape, parts) > SEAT_DEPTH:
            return q, report, rest  # the penetration is not the closing's: opening does not clear it
        for _ in range(SEAT_STEPS):
            mid = 0.5 * (lo + hi)
            if _finger_depth(hc, at(mid), root, shape, parts) > SEAT_DEPTH:
                lo = mid
            else:
                hi = mid
        seated = at(hi)
    # the pads first: a few point queries, where the whole hand's report takes tens of ms
    before, after = _pad_gaps(hand, q, root, obj, moved), _pad_gaps(hand, seated, root, obj, moved)
    left = (before <= pad_tolerance).any(axis=1) & (after > pad_tolerance - PAD_MARGIN).all(axis=1)
    seated_report = fcl_api.object_report(hc, seated, root, obj)
    if not seated_report.legal:
        return q, report, rest
    for f in moved[left]:
        # a pad that touched and no longer does: still a pad contact when the pad link
        # itself rests on the object and no link of the finger off its pad body is nearer
        finger = hand.fingers[int(f)]
        pad = seated_report.link_distance[list(hc.links).index(finger.pad_link)] \
            if finger.pad_link in hc.links else np.inf
        body = seated_report.link_distance[pad_body_rows(hand, hc, int(f))]
        own = seated_report.link_distance[fingers == f]
        if not (pad <= pad_tolerance - PAD_MARGIN and body.min() <= own.min()):
            return q, report, np.zeros_like(rest)  # the contact was not the pad's
        rest[int(f)] = True
    return seated, seated_report, rest


def _pad_gaps(hand, q: np.ndarray, root: np.ndarray, obj, fingers: np.ndarray) -> np.ndarray:
    """(len(fingers), 2) m: for each finger, the gap between its pad sphere (centre in the
    hand's tables, :func:`.any_hand_tables.pad_sphere_center`) and the object's surface, and
    the signed distance of its pad point (``Finger.pad_center``, on the pad link's exact
    surface) to it (negative inside; the object's exact mesh distance), at posture q (n,)
    and the root pose ``root`` (object frame).

    A pad touches when either does: where a link's exact mesh stands out of its spheres at
    the pad, a seated finger may touch with its exact pad point while its sphere stays off.
    The pad point alone is not enough before seating: it let fingers whose pads did not
    touch leave the surface (the independent unseen-hands check found LEAP thumbs and a
    Barrett finger 2-4 mm off)."""
    from ..geometry.any_hand_shapes import object_shape
    from ..geometry.any_hand_tables import hand_tables

    sphere_local = hand_tables(hand).pad_center  # (F, 3), cached per hand
    poses = hand.link_transforms(q)
    out = np.empty((len(fingers), 2))
    points = []
    for f in fingers:
        finger = hand.fingers[int(f)]
        pose = root @ poses[finger.pad_link]
        points.append((pose @ np.append(sphere_local[int(f)], 1.0))[:3])
        points.append((pose @ np.append(finger.pad_center, 1.0))[:3])
    distance = object_shape(obj).distance(np.array(points)).reshape(-1, 2)
    out[:, 0] = distance[:, 0] - np.array([hand.fingers[int(f)].pad_radius for f in fingers])
    out[:, 1] = distance[:, 1]
    return out
