"""The URDF generated from the hand description (issue 13, part 1).

Checked with yourdfpy (an independent URDF parser and FK): the kinematics equal the
planner's DH chain, the actuated joints are the 18 JointState names, the committed file is
up to date, and a planned grasp drawn from the URDF puts the pads on the reported contacts.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from grasp_apso.model.hand import FINGER_NAMES, JOINT_NAMES, load_hand, wrist_rotation
from grasp_apso.model.urdf import hand_to_urdf, rotation_to_rpy, write_urdf

import yourdfpy  # noqa: E402  (a pinned test dependency: a missing install must fail, not skip)

ROOT = Path(__file__).resolve().parents[1]
COMMITTED = ROOT / "urdf" / "apso_paper_hand.urdf"


@pytest.fixture(scope="module")
def hand():
    return load_hand()


@pytest.fixture(scope="module")
def robot(hand):
    return yourdfpy.URDF.load(io.StringIO(hand_to_urdf(hand)), build_scene_graph=True,
                              load_meshes=False, build_collision_scene_graph=False)


def _set(robot, q: np.ndarray) -> None:
    robot.update_cfg({name: float(q[i]) for i, name in enumerate(JOINT_NAMES)})


def test_fk_equals_planner_dh(hand, robot):
    rng = np.random.default_rng(20261202)
    qs = rng.uniform(hand.lower, hand.upper, size=(50, 18))
    frames = hand.finger_frames(qs)  # (50, 5, 4, 4, 4)
    tips = hand.fingertip_positions(qs)
    for p, q in enumerate(qs):
        _set(robot, q)
        for f, finger in enumerate(FINGER_NAMES):
            knuckle = robot.get_transform(f"{finger}_knuckle", "palm")
            pip = robot.get_transform(f"{finger}_proximal_link", "palm") @ robot.joint_map[f"{finger}_middle"].origin
            dip = robot.get_transform(f"{finger}_middle_link", "palm") @ robot.joint_map[f"{finger}_distal"].origin
            tip = robot.get_transform(f"{finger}_tip", "palm")
            for got, want in zip((knuckle, pip, dip, tip), frames[p, f]):
                np.testing.assert_allclose(got, want, atol=1e-6)
            np.testing.assert_allclose(tip[:3, 3], tips[p, f], atol=1e-6)
        # The wrist joints: palm orientation in the wrist frame is Rz Ry Rx.
        palm = robot.get_transform("palm", "wrist")
        np.testing.assert_allclose(palm[:3, :3], wrist_rotation(q[15:18]), atol=1e-9)
        np.testing.assert_allclose(palm[:3, 3], 0.0, atol=1e-12)


def test_mimic_joint_follows_the_coupling(hand, robot):
    q = np.zeros(18)
    q[3 * 2] = 0.4  # middle finger distal
    _set(robot, q)
    mimic = robot.joint_map["middle_middle"].mimic
    assert mimic.joint == "middle_distal" and mimic.multiplier == pytest.approx(hand.coupling_ratio)
    rel = np.linalg.inv(robot.get_transform("middle_proximal_link", "palm")) @ robot.get_transform("middle_middle_link", "palm")
    angle = np.arctan2(rel[1, 0], rel[0, 0])
    assert angle == pytest.approx(hand.coupling_ratio * 0.4, abs=1e-9)


def test_actuated_joints_are_the_joint_state_names(robot):
    assert sorted(robot.actuated_joint_names) == sorted(JOINT_NAMES)
    assert len(robot.actuated_joint_names) == 18
    names = {j.name for j in robot.robot.joints}
    for finger in FINGER_NAMES:
        assert robot.joint_map[f"{finger}_middle"].mimic is not None
        assert f"{finger}_tip" in robot.link_map
    assert robot.base_link == "wrist"
    assert {"wrist_z", "wrist_y", "wrist_x"} <= names
    # wrist_z from wrist, then wrist_y, then wrist_x ending in palm
    assert robot.joint_map["wrist_z"].parent == "wrist"
    assert robot.joint_map["wrist_y"].parent == robot.joint_map["wrist_z"].child
    assert robot.joint_map["wrist_x"].parent == robot.joint_map["wrist_y"].child
    assert robot.joint_map["wrist_x"].child == "palm"


def test_limits_and_collision_geometry(hand, robot):
    for i, name in enumerate(JOINT_NAMES):
        limit = robot.joint_map[name].limit
        assert limit.lower == pytest.approx(hand.lower[i], abs=1e-9)
        assert limit.upper == pytest.approx(hand.upper[i], abs=1e-9)
    palm = robot.link_map["palm"].collisions
    assert len(palm) == 1
    np.testing.assert_allclose(palm[0].geometry.box.size, 2 * np.asarray(hand.palm_half_extents), atol=1e-12)
    np.testing.assert_allclose(palm[0].origin[:3, 3], hand.palm_center, atol=1e-12)
    for f, finger in enumerate(FINGER_NAMES):
        pad = robot.link_map[f"{finger}_tip"].collisions
        assert len(pad) == 1 and pad[0].geometry.sphere.radius == pytest.approx(hand.pad_radius)
        for k, link in enumerate(("proximal_link", "middle_link", "distal_link")):
            shapes = robot.link_map[f"{finger}_{link}"].collisions
            cylinder = [c for c in shapes if c.geometry.cylinder is not None]
            spheres = [c for c in shapes if c.geometry.sphere is not None]
            assert len(cylinder) == 1 and len(spheres) == 2
            assert cylinder[0].geometry.cylinder.radius == pytest.approx(hand.link_radii[k])
            assert cylinder[0].geometry.cylinder.length == pytest.approx(hand.link_lengths[f, k])
            ends = sorted(float(s.origin[0, 3]) for s in spheres)
            assert ends == pytest.approx([0.0, hand.link_lengths[f, k]], abs=1e-12)
            # The cylinder lies along the link's x axis, centred on it.
            axis = cylinder[0].origin[:3, :3] @ np.array([0.0, 0.0, 1.0])
            assert abs(axis[0]) == pytest.approx(1.0, abs=1e-9)
            assert cylinder[0].origin[0, 3] == pytest.approx(hand.link_lengths[f, k] / 2)
        assert len(robot.link_map[f"{finger}_tip"].visuals) == 1


def test_committed_urdf_is_up_to_date(hand):
    assert COMMITTED.exists(), "urdf/apso_paper_hand.urdf missing: run grasp_apso_urdf --out urdf"
    assert COMMITTED.read_text(encoding="utf-8") == hand_to_urdf(hand), (
        "urdf/apso_paper_hand.urdf is stale: regenerate with `grasp_apso_urdf --out urdf`")


def test_generation_is_deterministic(hand):
    assert hand_to_urdf(hand) == hand_to_urdf(load_hand())


def test_pads_touch_the_planned_contacts(hand, robot):
    from grasp_apso.search.planner import PlanOptions, plan
    try:
        from grasp_apso.model.objects import builtin
    except ImportError:
        from grasp_apso.model.builtin import builtin

    result = plan(builtin("sphere"), options=PlanOptions(particles=30, iterations=20),
                  rng=np.random.default_rng(3))
    assert len(result.contacts) >= 2
    roll, pitch, yaw = rotation_to_rpy(result.wrist_pose[:3, :3])
    # With the identity object pose the wrist angles are the configuration's.
    np.testing.assert_allclose(wrist_rotation(np.array([roll, pitch, yaw])), wrist_rotation(result.joint_positions[15:18]),
                               atol=1e-9)
    q = np.concatenate([result.joint_positions[:15], [roll, pitch, yaw]])
    _set(robot, q)
    wrist = np.eye(4)
    wrist[:3, 3] = result.wrist_pose[:3, 3]
    np.testing.assert_allclose(wrist @ robot.get_transform("palm", "wrist"), result.wrist_pose, atol=1e-6)
    for contact in result.contacts:
        tip = (wrist @ robot.get_transform(f"{contact.finger}_tip", "wrist"))[:3, 3]
        assert np.linalg.norm(tip - contact.position) <= 0.002 + hand.pad_radius + 1e-9, contact.finger


def test_rotation_to_rpy_round_trip():
    rng = np.random.default_rng(5)
    for angles in rng.uniform([-np.pi, -np.pi / 2, -np.pi], [np.pi, np.pi / 2, np.pi], size=(20, 3)):
        rot = wrist_rotation(angles)
        np.testing.assert_allclose(wrist_rotation(np.array(rotation_to_rpy(rot))), rot, atol=1e-9)
    rot = wrist_rotation(np.array([0.3, np.pi / 2, -0.2]))  # gimbal lock
    np.testing.assert_allclose(wrist_rotation(np.array(rotation_to_rpy(rot))), rot, atol=1e-9)


def test_cli_writes_the_file(tmp_path, capsys, hand):
    from grasp_apso.tools.urdf_cli import main

    assert main(["--out", str(tmp_path)]) == 0
    written = tmp_path / "apso_paper_hand.urdf"
    assert written.read_text(encoding="utf-8") == hand_to_urdf(hand)
    assert str(written) in capsys.readouterr().out
    assert main([]) == 0
    assert capsys.readouterr().out == hand_to_urdf(hand)
    assert main(["--hand", str(tmp_path / "missing.yaml")]) == 2
    assert "missing.yaml" in capsys.readouterr().err


def test_write_urdf_names_the_file(tmp_path, hand):
    path = write_urdf(hand, tmp_path / "sub")
    assert path == tmp_path / "sub" / f"{hand.name}.urdf"
    with pytest.raises(ValueError, match="directory"):
        write_urdf(hand, path / "not_a_dir")
