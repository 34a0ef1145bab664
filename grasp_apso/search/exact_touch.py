"""Bringing a general hand's contacting pads onto the object's exact collision geometry.

The search reads a finger as in contact when its pad sphere (radius ``Finger.pad_radius``
through the pad point, :func:`grasp_apso.geometry.any_hand_tables.pad_sphere_center`)
touches the object with its pad side. On a fingertip thinner or narrower than that sphere
(LEAP's flat fingertip plates carry 15 mm pad spheres on 7 mm of plate) the sphere can
touch where the link is not: measured on the dex-urdf LEAP hand, 29 of 78 contacts of the
returned grasps had the pad link's own collision mesh 2 to 11 mm off the object
(``bench/unseen_hands.py``, its ``pads`` check on the links themselves). Shrinking the pad
spheres to fit inside such links instead made contacts rare (LEAP's best grasps held 3 of
21 instead of 10 of 21, ``bench/held_rate.py --seeds 1 --hand leap``).

:func:`touch_pads` closes each contacting finger whose pad link stands off the object
(exact geometry, python-fcl) further along its closing path until the link rests on the
surface, the way a position-controlled finger keeps closing until it meets the object; its
contact is then where the link touches. The closing is found by bisection on the pad
body's surface samples read on the object's distance grid (a python-fcl query of a mesh
fingertip per step cost 1.4 s per LEAP plan), then corrected by a few secant steps on the
whole finger's exact distance where the samples stand off a mesh fingertip's nearest point
(:func:`_exact_rest`). A
finger that meets the object first with another link, whose pad link itself stays off the
object while a link fixed to it touches, or that meets nothing within its range, is
no contact: it stays where it is (the posture the search verified), only its contact is
dropped.
"""

from __future__ import annotations

import numpy as np

__all__ = ["touch_pads", "TOUCH_GAP", "TOUCH_REST", "TOUCH_STEPS", "TOUCH_REACH", "TOUCH_REFINE"]

#: m: a contacting finger whose pad link (exact geometry) is farther than this from the
#: object is closed onto it (the judged 2 mm, less room for the distance's own error).
#: Measured (``bench/held_rate.py --seeds 1 --hand shadow_urdf``, 21 objects on a table):
#: closing every pad link farther than 1 mm changed grasps that held (cup: 5 of 5
#: candidates held, then 0 of 4; all candidates 73/83 held before, 60/72 after); from
#: 1.8 mm, 67/77, the best grasps 17 of 21 either way.
TOUCH_GAP = 0.0018
#: m: a closed finger's pad body rests at most this far off the object (and, checked
#: exactly, no link of the finger deeper in it than a seated finger's
#: :data:`.exact_seat.SEAT_DEPTH`): found on the grid, then brought there on the exact
#: distance (:data:`TOUCH_REFINE` steps); a finger still farther than :data:`TOUCH_GAP`
#: after them is no contact.
TOUCH_REST = 0.0005
#: Bisection steps on the closing (the rest found to the first trial's travel / 2**steps).
TOUCH_STEPS = 5
#: Secant steps on the exact distance (python-fcl) after the grid's bisection, at most.
TOUCH_REFINE = 4
#: m: the first trial closes the pad point this much farther than the gap, by the pad
#: point's speed along the closing path at the grasp (then twice that, then the limit).
TOUCH_REACH = 0.003


def _closing_joints(hand, finger) -> tuple[list[int], np.ndarray]:
    """The finger's joints with a closing sense (indices into ``hand.actuated_joints``) and
    their closing limits."""
    joints, limits = [], []
    for joint, sense in zip(finger.joints, finger.closing):
        if sense:
            j = hand.actuated_joints.index(joint)
            joints.append(j)
            limits.append(hand.upper[j] if sense > 0 else hand.lower[j])
    return joints, np.asarray(limits, dtype=float)


def _exact_rest(distance, t: float, speed: float, deepest: float) -> tuple[float, float, int]:
    """The closing ``t`` at which the finger's exact distance rests within
    [-``deepest``, :data:`TOUCH_REST`], from the grid's estimate ``t``: secant steps on the exact
    distance (``distance(t) -> (d, part)``, python-fcl), at most :data:`TOUCH_REFINE`, the
    first along the pad point's ``speed`` (m per unit of t). The grid's surface samples can
    stand off a mesh fingertip's nearest point (measured, dex-urdf LEAP, Allegro and Shadow
    on the cube, sphere, barrel and mug, two seeds: 2 of 53 rests found on the grid were
    more than 0.5 mm off exactly, up to 1.08 mm; 3 secant steps brought both within).
    Returns (t, d, part) of the last trial."""
    target = 0.5 * TOUCH_REST
    d, part = distance(t)
    prev = None
    for _ in range(TOUCH_REFINE):
        if -deepest <= d <= TOUCH_REST:
            break
        slope = -speed
        if prev is not None and abs(t - prev[0]) > 1e-9 and (d - prev[1]) / (t - prev[0]) < 0.0:
            slope = (d - prev[1]) / (t - prev[0])
        if slope >= -1e-9:
            break
        t_next = float(np.clip(t - (d - target) / slope, 0.0, 1.0))
        if t_next == t:
            break
        prev = (t, d)
        t = t_next
        d, part = distance(t)
    return t, d, part


def touch_pads(hc, hand, q: np.ndarray, root: np.ndarray, obj, grid, report, contact: np.ndarray):
    """Close the contacting fingers whose pad links stand off the object onto it.

    Parameters
    ----------
    hc : HandCollision (:mod:`grasp_apso.geometry.any_hand_fcl`)
    hand : HandModel
    q : (n,) float, rad or m
        The grasp posture.
    root : (4, 4) float
        The root link in the object frame.
    obj : GraspObject
    grid : SignedDistanceGrid
        The object's grid (``distance(points)``): where a moved pad link is nearest it.
    report : AnyHandReport
        ``object_report`` of ``q`` (its ``link_distance`` per link).
    contact : (F,) bool
        The fingers in contact.

    Returns
    -------
    (q, moved, lost, points)
        The posture with those fingers closed onto the object (a lost finger where it
        was), ``moved`` (F,) bool the fingers closed onto it, ``lost`` (F,) bool the
        fingers that are no contact after all, ``points`` (F, 3) object frame the point of
        each moved finger's pad link nearest the object (NaN for the others).
    """
    from ..geometry.any_hand_shapes import object_shape
    from .exact_seat import SEAT_DEPTH, finger_distance, pad_body_rows, pad_nearest

    n_f = len(hand.fingers)
    moved, lost = np.zeros(n_f, dtype=bool), np.zeros(n_f, dtype=bool)
    points = np.full((n_f, 3), np.nan)
    out = np.array(q, dtype=float)
    links = list(hc.links)
    shape = None
    for f in np.flatnonzero(contact):
        finger = hand.fingers[int(f)]
        if finger.pad_link not in links:
            continue
        pad_row = links.index(finger.pad_link)
        # the pad link and the links rigidly fixed to it: one body
        body_rows = pad_body_rows(hand, hc, int(f))
        gap = float(report.link_distance[pad_row])
        if gap <= TOUCH_GAP:
            continue
        shape = shape or object_shape(obj)
        joints, limits = _closing_joints(hand, finger)
        parts = np.flatnonzero(hc.shapes.finger[hc.shapes.part_link] == f)
        pad_parts = np.flatnonzero(np.isin(hc.shapes.part_link, body_rows))
        link_parts = np.flatnonzero(hc.shapes.part_link == pad_row)
        base = out.copy()

        def at(t: float) -> np.ndarray:
            x = base.copy()
            x[joints] += t * (limits - base[joints])
            return x

        # the first trial: the travel that moves the pad point the gap and TOUCH_REACH more
        pad = np.append(np.asarray(finger.pad_center, float), 1.0)
        step = 0.05
        speed = float(np.linalg.norm((hand.link_transforms(at(step))[finger.pad_link] @ pad)[:3]
                                     - (hand.link_transforms(base)[finger.pad_link] @ pad)[:3])) / step
        hi = 1.0 if speed <= 1e-9 else min(1.0, (gap + TOUCH_REACH) / speed)
        # the pad body's surface on the object's grid while searching, the whole finger
        # exactly (python-fcl) at the rest
        found = False
        for _ in range(3):
            if pad_nearest(hc, at(hi), root, grid, pad_parts)[0] <= TOUCH_REST:
                found = True
                break
            if hi >= 1.0:
                break
            hi = min(1.0, 2.0 * hi)
        if found:
            lo = 0.0
            for _ in range(TOUCH_STEPS):
                mid = 0.5 * (lo + hi)
                if pad_nearest(hc, at(mid), root, grid, pad_parts)[0] <= TOUCH_REST:
                    hi = mid
                else:
                    lo = mid
            hi, d, part = _exact_rest(lambda t: finger_distance(hc, at(t), root, shape, parts), hi, speed, SEAT_DEPTH)
            # resting on the pad, no deeper than a seated finger; another link nearer is no pad contact
            found = -SEAT_DEPTH <= d <= TOUCH_GAP and part in pad_parts
            if found and hc.shapes.part_link[part] != pad_row:
                # a link fixed to the pad link touches: the pad link itself must rest within the gap too
                found = finger_distance(hc, at(hi), root, shape, link_parts)[0] <= TOUCH_GAP
        if found:
            out = at(hi)
            moved[f] = True
            points[f] = pad_nearest(hc, out, root, grid, pad_parts)[1]
        else:
            lost[f] = True
    return out, moved, lost, points
