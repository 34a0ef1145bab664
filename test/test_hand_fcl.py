"""python-fcl checks of the whole hand against the scene (grasp_apso.geometry.hand_fcl).

Expected values are analytic (plane distances of box corners, capsule end points and
pad centres), never the module's own code.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from grasp_apso.errors import InputError
from grasp_apso.geometry.collision import mesh_bvh
from grasp_apso.geometry.hand_fcl import (
    CONTACT_ZONE, OBJECT_TOLERANCE, approach_report, hand_scene_distance,
)
from grasp_apso.model.hand import load_hand, wrist_rotation
from grasp_apso.model.scene import BOX, Scene

HAND = load_hand()
OPEN = np.zeros(15)  # straight fingers, no abduction


def _pose(rot: np.ndarray, position) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = position
    return out


def _analytic_plane_gap(values: np.ndarray, wrist: np.ndarray, plane: np.ndarray) -> tuple[float, float]:
    """(least distance of every hand part to the plane, that of the palm box alone), m."""
    n, d = plane[:3] / np.linalg.norm(plane[:3]), plane[3] / np.linalg.norm(plane[:3])
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    corners = HAND.palm_center + signs * HAND.palm_half_extents  # (8, 3) palm frame
    corners = corners @ wrist[:3, :3].T + wrist[:3, 3]
    palm = float((corners @ n + d).min())
    pts = HAND.finger_frames(values[None])[0][..., :3, 3] @ wrist[:3, :3].T + wrist[:3, 3]  # (5, 4, 3)
    h = pts @ n + d
    links = min(float(min(h[f, k], h[f, k + 1]) - HAND.link_radii[k]) for f in range(5) for k in range(3))
    pads = float((h[:, 3] - HAND.pad_radius).min())
    return min(palm, links, pads), palm


def test_hand_above_a_table_is_the_palm_corner_gap():
    # Palm facing up, 0.3 m above the table: the palm's lower face is the lowest part.
    wrist = _pose(np.eye(3), [0.2, -0.1, 0.3])
    table = Scene.from_primitives(planes=[(0, 0, 1, 0)])
    expected, palm = _analytic_plane_gap(OPEN, wrist, table.planes[0])
    assert palm == pytest.approx(0.3 - 0.022, abs=1e-12)  # centre z -0.010, half z 0.012
    assert expected == palm
    assert hand_scene_distance(HAND, OPEN, wrist, table) == pytest.approx(palm, abs=1e-6)


def test_tilted_hands_and_planes_match_the_analytic_gap():
    rng = np.random.default_rng(11)
    for _ in range(6):
        rot = wrist_rotation(rng.uniform(-math.pi, math.pi, 3))
        values = rng.uniform(HAND.lower[:15], HAND.upper[:15])
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        plane = np.array([*normal, -0.05])
        wrist = _pose(rot, normal * (0.05 + rng.uniform(0.2, 0.4)))
        # 3 m along the plane: the box standing in for the plane must follow the hand
        lateral = np.cross(normal, [1.0, 0.0, 0.0])
        wrist[:3, 3] += 3.0 * lateral / np.linalg.norm(lateral)
        scene = Scene.from_primitives(planes=[plane])
        expected, _ = _analytic_plane_gap(values, wrist, plane)
        assert expected > 0.05
        assert hand_scene_distance(HAND, values, wrist, scene) == pytest.approx(expected, abs=1e-6)


def test_a_finger_below_the_table_is_a_negative_distance():
    # Palm facing down 30 mm above the table, fingers curled: the tips go below it.
    rot = wrist_rotation(np.array([math.pi, 0.0, 0.0]))
    values = np.tile([0.6, 1.2, 0.0], 5)
    wrist = _pose(rot, [0.0, 0.0, 0.03])
    table = Scene.from_primitives(planes=[(0, 0, 1, 0)])
    expected, _ = _analytic_plane_gap(values, wrist, table.planes[0])
    assert expected < -0.005
    assert hand_scene_distance(HAND, values, wrist, table) == pytest.approx(expected, abs=1e-5)


def test_hand_pushed_into_a_box_is_negative_and_not_clear():
    # Palm facing down, the wrist 1 mm above the box top: the straight finger capsules
    # (palm z = 0, radius link_radii[0] = 9 mm) reach 8 mm into the box; the palm's front
    # face (palm z +0.002) 1 mm.
    box = Scene.from_primitives(obstacles=[(BOX, (0.4, 0.4, 0.1))], obstacle_poses=[_pose(np.eye(3), [0.05, 0, -0.05])])
    rot = wrist_rotation(np.array([math.pi, 0.0, 0.0]))
    wrist = _pose(rot, [0.0, 0.0, 0.001])
    depth = HAND.link_radii[0] - 0.001
    assert hand_scene_distance(HAND, OPEN, wrist, box) == pytest.approx(-depth, abs=1e-5)
    report = approach_report(HAND, OPEN, wrist, 0.08, box, None, None, clearance=0.005)
    assert not report.clear
    assert report.min_scene_distance == pytest.approx(-depth, abs=1e-5)
    # 20 mm higher the hand is clear of the box by 20 - 8 = 12 mm, and so is the approach.
    wrist[2, 3] += 0.02
    assert hand_scene_distance(HAND, OPEN, wrist, box) == pytest.approx(0.02 - depth, abs=1e-6)
    assert approach_report(HAND, OPEN, wrist, 0.08, box, None, None, clearance=0.005).clear


def test_approach_through_an_obstacle_is_not_clear():
    # Palm facing down, approaching the table from above; a thin plate hangs between the
    # pre-grasp and the grasp. Both end poses are clear of it, the path is not.
    rot = wrist_rotation(np.array([math.pi, 0.0, 0.0]))  # palm normal (+z) points down
    grasp = _pose(rot, [0.0, 0.0, 0.10])
    plate = _pose(np.eye(3), [0.05, 0.0, 0.15])
    scene = Scene.from_primitives(planes=[(0, 0, 1, 0)], obstacles=[(BOX, (0.3, 0.3, 0.004))], obstacle_poses=[plate])
    assert hand_scene_distance(HAND, OPEN, grasp, scene) > 0.02
    pre = grasp.copy()
    pre[:3, 3] -= 0.1 * grasp[:3, 2]  # 0.20 m high
    assert hand_scene_distance(HAND, OPEN, pre, scene) > 0.02
    report = approach_report(HAND, OPEN, grasp, 0.1, scene, None, None, clearance=0.005)
    assert not report.clear
    assert report.min_scene_distance < 0.0
    assert report.steps == 21


def test_approach_in_free_space_is_clear_with_the_expected_steps():
    rot = wrist_rotation(np.array([math.pi, 0.0, 0.0]))
    grasp = _pose(rot, [0.0, 0.0, 0.05])
    table = Scene.from_primitives(planes=[(0, 0, 1, 0)])
    report = approach_report(HAND, OPEN, grasp, 0.08, table, None, None, clearance=0.005)
    assert report.clear and report.steps == 17  # 16 steps of 5 mm, both ends included
    # The hand only rises along the approach: the least distance is the grasp pose's.
    expected, _ = _analytic_plane_gap(OPEN, grasp, table.planes[0])
    assert report.min_scene_distance == pytest.approx(expected, abs=1e-6)
    assert report.min_object_distance == math.inf
    # 7 mm steps: ceil(80 / 7) = 12 steps, 13 poses; an empty scene is always clear.
    free = approach_report(HAND, OPEN, grasp, 0.08, Scene(), None, None, clearance=0.005, step=0.007)
    assert free.clear and free.steps == 13 and free.min_scene_distance == math.inf
    # The same approach with a clearance larger than the gap is not clear.
    assert not approach_report(HAND, OPEN, grasp, 0.08, table, None, None, clearance=expected + 0.001).clear


def _analytic_ball_gap(values: np.ndarray, wrist: np.ndarray, centre: np.ndarray, radius: float) -> float:
    """Least distance (m) between the hand's parts and a ball."""
    local = (centre - wrist[:3, 3]) @ wrist[:3, :3]  # ball centre in the palm frame
    q = np.abs(local - HAND.palm_center) - HAND.palm_half_extents
    palm = float(np.linalg.norm(np.maximum(q, 0.0)) + min(q.max(), 0.0))
    pts = HAND.finger_frames(values[None])[0][..., :3, 3]
    gaps = [palm]
    for f in range(5):
        for k in range(3):
            a, b = pts[f, k], pts[f, k + 1]
            t = np.clip((local - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
            gaps.append(float(np.linalg.norm(a + t * (b - a) - local)) - HAND.link_radii[k])
        gaps.append(float(np.linalg.norm(pts[f, 3] - local)) - HAND.pad_radius)
    return min(gaps) - radius


def _height_for_gap(rot: np.ndarray, xy: np.ndarray, gap: float, centre: np.ndarray, radius: float) -> np.ndarray:
    """Wrist pose (palm down, at ``xy``) whose analytic gap to the ball is ``gap`` (bisection)."""
    lo, hi = centre[2], centre[2] + 0.3  # the gap grows with the height above the centre
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _analytic_ball_gap(OPEN, _pose(rot, [*xy, mid]), centre, radius) > gap:
            hi = mid
        else:
            lo = mid
    return _pose(rot, [*xy, hi])


def test_approach_and_the_object():
    # A 60 mm ball (fine icosphere: facets within 0.03 mm of the sphere) below a palm
    # facing down, the palm's grasp centre above the ball's centre.
    radius = 0.03
    bvh = mesh_bvh(trimesh.creation.icosphere(subdivisions=4, radius=radius))
    rot = wrist_rotation(np.array([math.pi, 0.0, 0.0]))
    xy = (-np.asarray(HAND.grasp_center) @ rot.T)[:2]
    centre = np.zeros(3)

    grasp = _height_for_gap(rot, xy, 0.003, centre, radius)
    clear = approach_report(HAND, OPEN, grasp, 0.08, Scene(), bvh, np.eye(4), clearance=0.005)
    assert clear.clear and clear.min_object_distance == pytest.approx(0.003, abs=1e-4)
    assert clear.steps == 17
    # pressing 0.4 mm into the object at the grasp (in the contact zone) is accepted
    touch = _height_for_gap(rot, xy, -0.4 * OBJECT_TOLERANCE, centre, radius)
    report = approach_report(HAND, OPEN, touch, 0.08, Scene(), bvh, np.eye(4), 0.005)
    assert report.clear and report.min_object_distance == 0.0
    # 5 mm into it is not
    deep = _height_for_gap(rot, xy, -0.005, centre, radius)
    assert not approach_report(HAND, OPEN, deep, 0.08, Scene(), bvh, np.eye(4), 0.005).clear
    # The object pose is applied: the same ball 10 cm to the side is far away.
    aside = np.eye(4)
    aside[0, 3] = 0.3
    far = approach_report(HAND, OPEN, deep, 0.08, Scene(), bvh, aside, 0.005)
    assert far.clear and far.min_object_distance > 0.1


def test_touching_the_object_before_the_contact_zone_is_refused():
    # A thin plate (the "object") that the open hand passes through 40 mm before the
    # grasp: the grasp pose itself is clear of it.
    plate = mesh_bvh(trimesh.creation.box((0.3, 0.3, 0.002)))
    rot = wrist_rotation(np.array([math.pi, 0.0, 0.0]))
    grasp = _pose(rot, [0.0, 0.0, 0.10])
    plate_pose = np.eye(4)
    plate_pose[:3, 3] = [0.05, 0.0, 0.14]
    assert CONTACT_ZONE < 0.03
    report = approach_report(HAND, OPEN, grasp, 0.08, Scene(), plate, plate_pose, 0.005)
    assert not report.clear and report.min_object_distance == 0.0
    # ... and with a shorter approach that starts below the plate it is clear.
    short = approach_report(HAND, OPEN, grasp, 0.01, Scene(), plate, plate_pose, 0.005)
    # pre-grasp: the palm's back face (palm z -0.022) at 0.11 + 0.022, the plate's
    # lower face at 0.139
    assert short.clear and short.min_object_distance == pytest.approx(0.139 - 0.132, abs=1e-6)


def test_bad_input_names_the_field():
    table = Scene.from_primitives(planes=[(0, 0, 1, 0)])
    with pytest.raises(InputError, match="^finger_values"):
        hand_scene_distance(HAND, np.zeros(7), np.eye(4), table)
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(InputError, match="^wrist_pose"):
        hand_scene_distance(HAND, OPEN, bad, table)
    with pytest.raises(InputError, match="^approach_distance"):
        approach_report(HAND, OPEN, np.eye(4), -0.1, table, None, None, 0.005)
    with pytest.raises(InputError, match="^clearance"):
        approach_report(HAND, OPEN, np.eye(4), 0.1, table, None, None, math.nan)
    with pytest.raises(InputError, match="^step"):
        approach_report(HAND, OPEN, np.eye(4), 0.1, table, None, None, 0.005, step=0.0)
    assert hand_scene_distance(HAND, OPEN, np.eye(4), Scene()) == math.inf


def test_skipped_poses_do_not_change_the_report():
    """approach_report skips poses that a distance bound proves harmless: its minimum and
    verdict equal those of measuring every pose with hand_scene_distance."""
    rng = np.random.default_rng(5)
    scene = Scene.from_primitives(
        planes=[(0, 0, 1, 0)], obstacles=[(BOX, (0.08, 0.3, 0.2))],
        obstacle_poses=[_pose(np.eye(3), [0.25, 0.0, 0.1])])
    verdicts = set()
    for _ in range(8):
        rot = wrist_rotation(np.array([math.pi, 0.0, 0.0]) + rng.uniform(-0.6, 0.6, 3))
        grasp = _pose(rot, [rng.uniform(-0.2, 0.0), rng.uniform(-0.1, 0.1), rng.uniform(0.05, 0.25)])
        values = rng.uniform(HAND.lower[:15], HAND.upper[:15]) * 0.5
        report = approach_report(HAND, values, grasp, 0.08, scene, None, None, clearance=0.005)
        every = []
        for i in range(17):
            pose = grasp.copy()
            pose[:3, 3] -= 0.08 * (1 - i / 16) * grasp[:3, 2]
            every.append(hand_scene_distance(HAND, values, pose, scene))
        assert report.min_scene_distance == pytest.approx(min(every), abs=1e-9)
        assert report.clear == (min(every) >= 0.005)
        verdicts.add(report.clear)
    assert verdicts == {True, False}  # both outcomes exercised


def test_the_object_box_screen_leaves_the_report_unchanged():
    """With the object's bounding box given, parts it shows far from the object are not
    measured against the mesh; the verdict and both minima stay exactly the same."""
    from grasp_apso.model.builtin import builtin

    fish = builtin("fish").mesh
    bvh = mesh_bvh(fish)
    rng = np.random.default_rng(4)
    object_pose = _pose(wrist_rotation(np.array([0.2, -0.1, 0.4])), [0.01, -0.02, 0.03])
    scene = Scene.from_primitives(planes=[(0.0, 0.0, 1.0, 0.06)])
    verdicts = set()
    for _ in range(40):
        rot = wrist_rotation(rng.uniform(-math.pi, math.pi, 3))
        centre = object_pose[:3, :3] @ fish.sample(1, seed=int(rng.integers(1 << 30)))[0] + object_pose[:3, 3]
        grasp = _pose(rot, centre - rot[:, 2] * rng.uniform(0.02, 0.06) - rot @ HAND.grasp_center)
        values = rng.uniform(0.0, 0.4, 15)
        plain = approach_report(HAND, values, grasp, 0.08, scene, bvh, object_pose, 0.005)
        screened = approach_report(HAND, values, grasp, 0.08, scene, bvh, object_pose, 0.005,
                                   obj_bounds=fish.bounds)
        assert screened == plain
        verdicts.add(plain.clear)
    assert verdicts == {True, False}
