"""Seating a general hand's fingers on the object's exact collision geometry
(:mod:`grasp_apso.search.exact_seat`).

A planned grasp of the Allegro-like URDF hand on the cube, one contacting finger then
closed further until its exact geometry presses 1-3 mm into the cube (python-fcl on the
links' exact shapes, :func:`grasp_apso.geometry.any_hand_fcl.object_report`, decides; the
seating is what is tested): seated, that finger rests within SEAT_DEPTH, its pad still
touches, and no other finger moved.
"""

from __future__ import annotations

import numpy as np
import pytest

from grasp_apso.geometry import any_hand_fcl as fcl_api
from grasp_apso.search.exact_seat import SEAT_DEPTH, SEAT_TRAVEL, seat_fingers

PAD_TOLERANCE = 0.002


@pytest.fixture(scope="module")
def grasp(allegro_cube_grasp):
    return allegro_cube_grasp


def _pressed(hand, hc, cand, cube):
    """The candidate with its first contacting finger closed on until its links press
    1-3 mm into the cube: (finger, q, report)."""
    finger = hand.finger(cand.contacts[0].finger)
    joints = [hand.actuated_joints.index(j) for j, s in zip(finger.joints, finger.closing) if s]
    senses = np.array([s for s in finger.closing if s], dtype=float)
    rows = [hc.links.index(link) for link in hc.links if hc.shapes.finger[hc.links.index(link)]
            == hand.fingers.index(finger)]
    q = np.array(cand.joint_positions, dtype=float)
    for _ in range(200):  # bounded: 0.2 rad at most
        q[joints] += 0.001 * senses
        q = np.clip(q, hand.lower, hand.upper)
        report = fcl_api.object_report(hc, q, cand.wrist_in_object, cube)
        depth = -float(np.min(report.link_distance[rows]))
        if depth > 0.001:
            break
    assert 0.001 < depth < 0.003, depth
    return finger, rows, q, report


def test_a_finger_pressing_in_is_opened_onto_the_surface(grasp):
    hand, cube, cand = grasp
    hc = fcl_api.HandCollision(hand)
    finger, rows, q, report = _pressed(hand, hc, cand, cube)
    assert not report.legal
    q_open = np.array(cand.pre_grasp_positions, dtype=float)
    seated, seated_report = seat_fingers(fcl_api, hc, hand, q, q_open, cand.wrist_in_object, cube, report,
                                         PAD_TOLERANCE)
    again = fcl_api.object_report(hc, seated, cand.wrist_in_object, cube)  # not the returned report
    assert again.legal
    assert -float(np.min(again.link_distance[rows])) <= SEAT_DEPTH + 1e-9
    assert again.link_distance[hc.links.index(finger.pad_link)] <= PAD_TOLERANCE
    moved = np.flatnonzero(np.abs(seated - q) > 1e-12)
    own = {hand.actuated_joints.index(j) for j in finger.joints}
    assert moved.size and set(moved.tolist()) <= own
    # opened toward the pre-shape, never past SEAT_TRAVEL of the way
    assert np.all(np.abs(seated - q) <= SEAT_TRAVEL * np.abs(q_open - q) + 1e-12)
    np.testing.assert_array_equal(seated_report.link_distance, again.link_distance)


def test_a_legal_grasp_is_left_as_it_is(grasp):
    hand, cube, cand = grasp
    hc = fcl_api.HandCollision(hand)
    q = np.array(cand.joint_positions, dtype=float)
    report = fcl_api.object_report(hc, q, cand.wrist_in_object, cube)
    assert report.legal
    seated, same = seat_fingers(fcl_api, hc, hand, q, np.array(cand.pre_grasp_positions), cand.wrist_in_object,
                                cube, report, PAD_TOLERANCE)
    assert seated is q and same is report
