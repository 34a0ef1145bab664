"""Bringing a general hand's contacting pads onto the object's exact collision geometry
(:mod:`grasp_apso.search.exact_touch`).

A planned grasp of the Allegro-like URDF hand on the cube, one contacting finger then
opened until its pad link stands 3-8 mm off the cube (python-fcl on the links' exact
shapes, :func:`grasp_apso.geometry.any_hand_fcl.object_report`, measures; the closing is
what is tested): closed again, that finger's pad link rests on the cube (a fresh exact
report), no link of it presses in, no other finger moved, and the new contact point lies on
the cube's surface by trimesh's exact proximity. A finger already on the surface is left as
it is; one that cannot reach the object, or meets it with a link fixed to its pad link while
the pad link itself stays off, is no contact and does not move.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from grasp_apso.geometry import any_hand_fcl as fcl_api
from grasp_apso.geometry.sdf import cached_sdf_grid
from grasp_apso.search.exact_seat import SEAT_DEPTH
from grasp_apso.search.exact_touch import TOUCH_GAP, TOUCH_REST, touch_pads

PAD_TOLERANCE = 0.002  # m, the issue's


@pytest.fixture(scope="module")
def grasp(allegro_cube_grasp):
    hand, cube, cand = allegro_cube_grasp
    return hand, cube, cached_sdf_grid(cube.mesh, cube.mesh_hash, padding=0.025), cand


def _contact_mask(hand, cand) -> np.ndarray:
    names = {c.finger for c in cand.contacts}
    return np.array([f.name in names for f in hand.fingers])


def _opened(hand, hc, cand, cube, name: str):
    """The candidate with its contacting finger ``name`` opened until its pad link stands
    3-8 mm off the cube: (finger index, its joints, q, report)."""
    assert name in {c.finger for c in cand.contacts}
    finger = hand.finger(name)
    f = hand.fingers.index(finger)
    joints = [hand.actuated_joints.index(j) for j, s in zip(finger.joints, finger.closing) if s]
    senses = np.array([s for s in finger.closing if s], dtype=float)
    pad = hc.links.index(finger.pad_link)
    q = np.array(cand.joint_positions, dtype=float)
    for _ in range(300):  # bounded: 0.3 rad at most
        q[joints] -= 0.001 * senses
        q = np.clip(q, hand.lower, hand.upper)
        report = fcl_api.object_report(hc, q, cand.wrist_in_object, cube)
        if report.link_distance[pad] > 0.003:
            break
    assert 0.003 < report.link_distance[pad] < 0.008, report.link_distance[pad]
    return f, joints, q, report


def _reclosed(grasp, name: str):
    """The contacting finger ``name`` opened (:func:`_opened`), then ``touch_pads`` on the
    grasp: (hc, finger index, its joints, the opened q, touch_pads' (q, moved, lost, points))."""
    hand, cube, grid, cand = grasp
    hc = fcl_api.HandCollision(hand)
    f, joints, q, report = _opened(hand, hc, cand, cube, name)
    out = touch_pads(hc, hand, q, cand.wrist_in_object, cube, grid, report, _contact_mask(hand, cand))
    return hc, f, joints, q, out


def test_a_pad_standing_off_the_object_is_closed_onto_it(grasp):
    hand, cube, grid, cand = grasp
    hc, f, joints, q, (touched, moved, lost, points) = _reclosed(grasp, "thumb")
    assert moved[f] and not lost.any() and moved.sum() == 1
    again = fcl_api.object_report(hc, touched, cand.wrist_in_object, cube)  # exact, fresh
    finger = hand.fingers[f]
    rows = [i for i, link in enumerate(hc.links) if hc.shapes.finger[i] == f]
    # the fingertip rests on the cube (the pad link or a link fixed to it: the Allegro-like
    # tip is a small link on the distal), the pad link within the 2 mm
    assert -SEAT_DEPTH - 1e-4 <= float(np.min(again.link_distance[rows])) <= TOUCH_REST + 1e-4
    assert again.link_distance[hc.links.index(finger.pad_link)] <= PAD_TOLERANCE
    changed = np.flatnonzero(np.abs(touched - q) > 1e-12)
    assert changed.size and set(changed.tolist()) <= set(joints)
    # closed along the closing senses, not opened
    senses = np.array([s for s in finger.closing if s], dtype=float)
    assert np.all((touched[joints] - q[joints]) * senses >= -1e-12)
    # the new contact point is on the cube's surface (trimesh, exact)
    _, distance, _ = trimesh.proximity.closest_point(cube.mesh, points[f][None])
    assert distance[0] <= 0.001
    assert np.isnan(points[np.arange(len(hand.fingers)) != f]).all()


@pytest.fixture(scope="module")
def seed_3_grasp(grasp):
    """The same hand's cube grasp of seed 3 (:func:`plan_allegro_cube`)."""
    from conftest import plan_allegro_cube

    hand, _, grid, _ = grasp
    cube, cand = plan_allegro_cube(hand, 3)
    return hand, cube, grid, cand


def test_a_finger_whose_fixed_link_meets_the_object_before_its_pad_link_is_no_contact(seed_3_grasp):
    # The middle finger of the seed-3 grasp, opened 3 mm and closed back along its closing
    # path, meets the cube with its distal link (the pad link, its tip, is fixed to it)
    # 1.6 mm off while the pad link itself stays 3.1 mm off: beyond the judged 2 mm, so no
    # pad contact, and the finger stays open.
    hand, cube, grid, cand = seed_3_grasp
    hc, f, joints, q, (touched, moved, lost, points) = _reclosed(seed_3_grasp, "middle")
    assert lost[f] and not moved[f] and np.isnan(points[f]).all()
    np.testing.assert_array_equal(touched[joints], q[joints])
    again = fcl_api.object_report(hc, touched, cand.wrist_in_object, cube)
    assert again.link_distance[hc.links.index(hand.fingers[f].pad_link)] > PAD_TOLERANCE


def test_pads_already_on_the_object_are_left_as_they_are(grasp):
    hand, cube, grid, cand = grasp
    hc = fcl_api.HandCollision(hand)
    q = np.array(cand.joint_positions, dtype=float)
    report = fcl_api.object_report(hc, q, cand.wrist_in_object, cube)
    contact = _contact_mask(hand, cand)
    pads = [hc.links.index(hand.fingers[f].pad_link) for f in np.flatnonzero(contact)]
    assert np.all(report.link_distance[pads] <= TOUCH_GAP)  # the planner's own grasp
    touched, moved, lost, _ = touch_pads(hc, hand, q, cand.wrist_in_object, cube, grid, report, contact)
    np.testing.assert_array_equal(touched, q)
    assert not moved.any() and not lost.any()


def test_a_finger_that_cannot_reach_the_object_is_no_contact(grasp):
    hand, cube, grid, cand = grasp
    hc = fcl_api.HandCollision(hand)
    q = np.array(cand.joint_positions, dtype=float)
    far = np.array(cand.wrist_in_object, dtype=float)
    far[:3, 3] += 0.3 * far[:3, 3] / np.linalg.norm(far[:3, 3])  # 30 cm farther out
    report = fcl_api.object_report(hc, q, far, cube)
    contact = _contact_mask(hand, cand)
    touched, moved, lost, _ = touch_pads(hc, hand, q, far, cube, grid, report, contact)
    np.testing.assert_array_equal(touched, q)
    assert not moved.any()
    np.testing.assert_array_equal(lost, contact)
