"""Loading real hands (issue 20): the Shadow and Adroit hands (gymnasium-robotics MJCF), the
Inspire and Fourier hands (robosuite MJCF), the Allegro-like URDF the project writes, and
the paper's hand from its YAML and its generated URDF.

Forward kinematics is checked against independent implementations: MuJoCo's
``mj_kinematics`` on the compiled MJCF and yourdfpy's on the URDF, at 20 random
configurations, couplings applied to the followers in the reference.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
import yourdfpy

from grasp_apso.errors import HandDescriptionError
from grasp_apso.model.hand import FINGER_NAMES, load_hand as load_paper_dh
from grasp_apso.model.hands.description import lagging_couplings
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.hands.model import Coupling
from hand_files import installed_hand, write_allegro_like

ROOT = Path(__file__).resolve().parents[1]
PAPER_URDF = ROOT / "urdf" / "apso_paper_hand.urdf"
MJCF_HANDS = ("shadow", "adroit", "inspire", "fourier", "robotiq_s", "jaco")
#: name -> (finger count, thumb tip link, root link)
EXPECTED = {
    "shadow": (5, "robot0:thdistal", "robot0:palm"),
    "adroit": (5, "thdistal", "palm"),
    "inspire": (5, "r_thumb_distal", "r_palm"),
    "fourier": (5, "R_thumb_distal_link", "r_palm"),
    "robotiq_s": (3, "finger_middle_link_3", "palm"),
    "jaco": (3, "thumb_distal", "right_gripper"),
    "allegro": (4, "thumb_tip", "palm"),
    "allegro_coupled": (4, "thumb_tip", "palm"),
    "paper_yaml": (5, "thumb_tip", "palm"),
    "paper_urdf": (5, "thumb_tip", "palm"),
}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hands")
    out = {name: installed_hand(name) for name in MJCF_HANDS}
    out["allegro"] = write_allegro_like(folder / "a", "mixed")
    out["allegro_coupled"] = write_allegro_like(folder / "b", "all", coupled=True)
    out["paper_yaml"] = None
    out["paper_urdf"] = PAPER_URDF
    return out


@pytest.fixture(scope="module")
def hands(files):
    return {name: load_hand(path, spheres=False) for name, path in files.items()}


@pytest.mark.parametrize("name", list(EXPECTED))
def test_the_real_fingers_are_found(hands, name):
    hand = hands[name]
    count, thumb, root = EXPECTED[name]
    assert hand.root_link == root
    assert len(hand.fingers) == count
    assert hand.thumb is not None and hand.thumb.tip_link == thumb
    assert sum(f.is_thumb for f in hand.fingers) == 1
    for finger in hand.fingers:
        assert finger.tip_link in hand.collision
        assert len(finger.closing) == len(finger.joints)
        assert sum(c != 0 for c in finger.closing) >= 1, finger.name
    # Every actuated joint belongs to a finger; nothing above the root is actuated.
    in_fingers = {j for f in hand.fingers for j in f.joints}
    assert set(hand.actuated_joints) == in_fingers
    assert not set(hand.held_joints) & set(hand.actuated_joints)
    assert abs(np.linalg.norm(hand.palm_normal) - 1.0) < 1e-9


@pytest.mark.parametrize("name, names", [
    ("shadow", ["ff", "mf", "rf", "lf", "th"]),
    ("fourier", ["thumb", "index", "middle", "ring", "pinky"]),
    ("inspire", ["thumb", "index", "middle", "ring", "pinky"]),
    ("robotiq_s", ["1", "2", "middle"]),
    ("paper_urdf", ["little", "ring", "middle", "index", "thumb"]),
])
def test_fingers_are_named_from_their_links(hands, name, names):
    assert [f.name for f in hands[name].fingers] == names


def test_arm_and_wrist_joints_are_held(hands):
    assert set(hands["shadow"].held_joints) == {"robot0:WRJ1", "robot0:WRJ0"}
    assert {"ARTx", "ARRz", "WRJ0", "WRJ1"} <= set(hands["adroit"].held_joints)
    assert set(hands["paper_urdf"].held_joints) == {"wrist_x", "wrist_y", "wrist_z"}
    assert any("not part of the hand" in n for n in hands["adroit"].notes)


def test_shadow_distal_joints_follow_their_middle_joints(hands):
    hand = hands["shadow"]
    pairs = {(c.follower, c.leader) for c in hand.couplings}
    for f in ("FF", "MF", "RF", "LF"):
        assert (f"robot0:{f}J0", f"robot0:{f}J1") in pairs
        assert f"robot0:{f}J0" not in hand.actuated_joints
    c = next(c for c in hand.couplings if c.follower == "robot0:FFJ0")
    assert c.multiplier == pytest.approx(0.00805 / 0.00705)  # the tendon's coefficients
    # The tendon's length 0.00705 FFJ0 - 0.00805 FFJ1 may lie within +-0.001: FFJ0 has that
    # much play, and the closing (FFJ1 increasing) drags it along the lower edge.
    assert c.slack == pytest.approx(0.001 / 0.00705)
    assert c.offset == pytest.approx(-0.001 / 0.00705)
    # FFJ1's range keeps FFJ0 within its own [0, 1.571]
    k = hand.actuated_joints.index("robot0:FFJ1")
    assert hand.lower[k] == pytest.approx(0.001 / 0.00805)
    assert hand.upper[k] == pytest.approx((1.571 * 0.00705 + 0.001) / 0.00805)
    assert any("robot0:FFJ0: follows robot0:FFJ1 at the edge of its play" in n for n in hand.notes)


def _mujoco_reference(hand, model, q: np.ndarray) -> dict[str, np.ndarray]:
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    full = hand.full_positions(q)
    for name, value in zip(hand.joint_names, full):
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    # The followers, as the file's coupling says (independently of full_positions).
    for c in hand.couplings:
        leader = data.qpos[model.jnt_qposadr[model.joint(c.leader).id]]
        data.qpos[model.jnt_qposadr[model.joint(c.follower).id]] = c.multiplier * leader + c.offset
    mujoco.mj_kinematics(model, data)
    poses = {}
    for b in range(1, model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
        pose = np.eye(4)
        pose[:3, :3] = data.xmat[b].reshape(3, 3)
        pose[:3, 3] = data.xpos[b]
        poses[name] = pose
    root = np.linalg.inv(poses[hand.root_link])
    return {name: root @ pose for name, pose in poses.items()}


def test_a_urdf_mimic_bears_its_own_effort_and_an_mjcf_coupling_its_actuator_s(hands, files):
    """A URDF gives every joint, a mimic one too, its own ``<limit effort>``; an MJCF's
    tendon or joint equality passes its one actuator's force on. The coupled leader's servo
    torque scale follows (``sum r^2 / max |r|`` from the file's multipliers, else 1)."""
    import xml.etree.ElementTree as ET

    for name in ("allegro_coupled", "paper_urdf"):
        hand = hands[name]
        mimics = {j.get("name"): float(j.find("mimic").get("multiplier", 1.0))
                  for j in ET.parse(files[name]).getroot().iter("joint") if j.find("mimic") is not None}
        assert mimics and {c.follower for c in hand.couplings} == set(mimics), name
        assert all(c.own_effort for c in hand.couplings), name
        for leader in {c.leader for c in hand.couplings}:
            ratios = [1.0] + [abs(mimics[c.follower]) for c in hand.couplings if c.leader == leader]
            scale = hand.servo_force_scale[hand.actuated_joints.index(leader)]
            assert scale == pytest.approx(sum(r * r for r in ratios) / max(ratios)), (name, leader)
    for name in ("shadow", "adroit", "robotiq_s", "jaco"):  # tendons, joint equalities
        hand = hands[name]
        assert hand.couplings and not any(c.own_effort for c in hand.couplings), name
        assert np.all(hand.servo_force_scale == 1.0), name
        assert np.any(hand.servo_weight > 1.0), name  # (the gains are still weighted)


@pytest.mark.parametrize("name", MJCF_HANDS)
def test_link_transforms_match_mujoco(hands, files, name):
    hand = hands[name]
    model = mujoco.MjModel.from_xml_path(str(files[name]))
    rng = np.random.default_rng(20)
    for q in rng.uniform(hand.lower, hand.upper, size=(20, hand.n_joints)):
        ours = hand.link_transforms(q)
        ref = _mujoco_reference(hand, model, q)
        for link in hand.links:
            np.testing.assert_allclose(ours[link][:3, 3], ref[link][:3, 3], atol=1e-6, err_msg=link)
            np.testing.assert_allclose(ours[link][:3, :3], ref[link][:3, :3], atol=1e-6, err_msg=link)


@pytest.mark.parametrize("name", ["allegro", "allegro_coupled", "paper_urdf"])
def test_link_transforms_match_yourdfpy(hands, files, name):
    hand = hands[name]
    robot = yourdfpy.URDF.load(str(files[name]), build_scene_graph=True, load_meshes=False)
    rng = np.random.default_rng(21)
    for q in rng.uniform(hand.lower, hand.upper, size=(20, hand.n_joints)):
        cfg = {j: float(v) for j, v in zip(hand.actuated_joints, q)}
        cfg.update(hand.held_joints)
        robot.update_cfg(cfg)  # yourdfpy applies the mimic joints itself
        ours = hand.link_transforms(q)
        for link in hand.links:
            np.testing.assert_allclose(ours[link], robot.get_transform(link, hand.root_link), atol=1e-6,
                                       err_msg=link)


def test_mjcf_meshes_sit_where_the_file_puts_them(hands, files):
    """MuJoCo recentres meshes when it compiles them: the geometry read back must still be
    the STL file in the body frame (this geom has no pos/quat of its own)."""
    import trimesh

    ours = hands["inspire"].collision["r_index_distal"][0].to_trimesh()
    stl = trimesh.load(files["inspire"].parent / "meshes" / "inspire_hands" / "rh_Link16.STL")
    np.testing.assert_allclose(ours.bounds, stl.bounds, atol=1e-6)


@pytest.mark.parametrize("prefix", ["package://allegro_like/", "$(find allegro_like)/", "file://$(find allegro_like)/"])
def test_package_uris_resolve_in_a_copied_description(files, tmp_path, prefix):
    import shutil

    # Copied out of its package folder (not called allegro_like), the URDF in urdf/ beside meshes/.
    # xacro's $(find NAME) left in a published URDF (LEAP's leap_description) means the same.
    shutil.copytree(Path(files["allegro"]).parent / "meshes", tmp_path / "copy" / "meshes")
    (tmp_path / "copy" / "urdf").mkdir()
    text = Path(files["allegro"]).read_text().replace('filename="meshes/', f'filename="{prefix}meshes/')
    (tmp_path / "copy" / "urdf" / "hand.urdf").write_text(text)
    hand = load_hand(tmp_path / "copy" / "urdf" / "hand.urdf", spheres=False)
    assert len(hand.fingers) == 4
    assert any(g.kind == "mesh" for g in hand.collision["ring_distal"])


def test_a_package_uri_that_resolves_nowhere_is_named_with_where_it_was_looked_for(files, tmp_path):
    import shutil

    # The meshes one folder up from the URDF and under no folder the package is named for
    # (Unitree's copy of an Inspire hand; RuiYan's URDFs without their meshes): the error
    # named only the fallback path, not the address the URDF wrote nor the file nearby.
    shutil.copytree(Path(files["allegro"]).parent / "meshes", tmp_path / "copy" / "meshes")
    (tmp_path / "copy" / "a" / "b" / "c" / "d").mkdir(parents=True)
    flat = tmp_path / "copy" / "a" / "b" / "c"
    for stl in (tmp_path / "copy" / "meshes").glob("*.stl"):
        shutil.copy(stl, flat / stl.name)
    text = Path(files["allegro"]).read_text().replace('filename="meshes/', 'filename="package://no_such_pkg/meshes/')
    urdf = flat / "d" / "hand.urdf"
    urdf.write_text(text)
    with pytest.raises(HandDescriptionError) as err:
        load_hand(urdf, spheres=False)
    message = str(err.value)
    assert "the URDF names package://no_such_pkg/meshes/" in message
    assert f"no folder 'no_such_pkg' at or above {flat / 'd'}" in message
    assert f"a file of that name is at {flat}/" in message


def test_an_mjcf_whose_fingers_stand_beside_its_palm_is_refused_naming_them(tmp_path):
    # OYMotion's ROHand MJCF: a palm body without joints, each finger a world body of its
    # own; the hand was the subtree with the most joints (the thumb), refused as having
    # fewer than two fingers without saying why.
    fingers = "".join(f"""<body name="{f}_proximal" pos="{x} 0 0.05"><joint name="{f}_j1" axis="1 0 0" range="0 1.5"/>
        <geom type="capsule" size="0.008 0.015" pos="0 0 0.015"/>
        <body name="{f}_distal" pos="0 0 0.03"><joint name="{f}_j2" axis="1 0 0" range="0 1.5"/>
          <geom type="capsule" size="0.007 0.01" pos="0 0 0.01"/></body></body>"""
                      for f, x in (("index", 0.02), ("middle", 0.0), ("ring", -0.02)))
    xml = tmp_path / "hand.xml"
    xml.write_text(f"""<mujoco><worldbody><body name="palm"><geom type="box" size="0.04 0.01 0.045"/></body>
      {fingers}</worldbody></mujoco>""")
    with pytest.raises(HandDescriptionError, match=r"fewer than two fingers .* in hand\.xml: the hand was taken to be "
                                                   r"world body 'index_proximal' .* 2 other world bodies with joints "
                                                   r"\(middle_proximal, ring_proximal\) stand beside it"):
        load_hand(xml, spheres=False)


def test_batch_equals_single(hands):
    hand = hands["shadow"]
    q = np.random.default_rng(3).uniform(hand.lower, hand.upper, size=(4, hand.n_joints))
    batch = hand.link_transforms_batch(q)
    for p in range(4):
        single = hand.link_transforms(q[p])
        for i, link in enumerate(hand.links):
            np.testing.assert_array_equal(batch[p, i], single[link])


def test_paper_hand_yaml_and_urdf_agree(hands):
    a, b = hands["paper_yaml"], hands["paper_urdf"]
    assert a.actuated_joints == b.actuated_joints
    assert len(a.actuated_joints) == 15 and not any(j.startswith("wrist") for j in a.actuated_joints)
    assert [(f.name, f.tip_link, f.joints, f.closing, f.is_thumb) for f in a.fingers] == \
        [(f.name, f.tip_link, f.joints, f.closing, f.is_thumb) for f in b.fingers]
    for fa, fb in zip(a.fingers, b.fingers):
        np.testing.assert_allclose(fa.pad_center, fb.pad_center, atol=1e-12)
    np.testing.assert_allclose(a.palm_normal, b.palm_normal, atol=1e-12)
    q = np.random.default_rng(4).uniform(a.lower, a.upper, size=(20, 15))
    np.testing.assert_allclose(a.link_transforms_batch(q), b.link_transforms_batch(q), atol=1e-12)


def test_paper_hand_matches_the_planners_dh_model(hands):
    """The general model of the paper's hand puts each fingertip where the planner's DH
    chain does (an independent implementation of the same hand)."""
    general, dh = hands["paper_yaml"], load_paper_dh()
    rng = np.random.default_rng(5)
    q18 = rng.uniform(dh.lower, dh.upper, size=(20, 18))
    q18[:, 15:] = 0.0
    by_name = dict(zip(dh.joint_names, q18.T))
    q = np.stack([by_name[j] for j in general.actuated_joints], axis=1)
    poses = general.link_transforms_batch(q)
    tips = dh.fingertip_positions(q18)
    for f, finger in enumerate(FINGER_NAMES):
        np.testing.assert_allclose(poses[:, general.link_index(f"{finger}_tip"), :3, 3], tips[:, f], atol=1e-9)
    assert general.palm_normal == pytest.approx([0.0, 0.0, 1.0], abs=1e-6)  # the YAML's +z
    # The YAML: positive flexion curls toward +z; the pivot is abduction (pre-shape).
    for finger in general.fingers:
        kinds = [j.split("_", 1)[1] for j in finger.joints]
        assert dict(zip(kinds, finger.closing)) == {"pivot": 0, "proximal": 1, "distal": 1}


def test_loaded_once_and_cached_by_content(files, tmp_path):
    a = load_hand(files["inspire"], spheres=False)
    assert load_hand(files["inspire"], spheres=False) is a
    copy = tmp_path / "copy.urdf"
    copy.write_bytes(Path(files["allegro"]).read_bytes())
    with pytest.raises(HandDescriptionError, match="not found"):  # same content, other folder: no meshes
        load_hand(copy, spheres=False)
    with pytest.raises(ValueError):
        a.lower[0] = 1.0  # read-only
    with pytest.raises(TypeError):
        a.collision["r_palm"] = ()
    with pytest.raises(AttributeError):
        a.root_link = "x"


@pytest.mark.parametrize("multiplier, sense, edge", [(1.14, 1, -0.1), (1.14, -1, 0.3), (-1.14, 1, 0.3),
                                                     (-1.14, -1, -0.1)])
def test_a_follower_with_play_follows_the_edge_its_closing_drags_it_along(multiplier, sense, edge):
    """The follower lags its leader's closing: below the coupled value when that rises as the
    leader closes, above it when it falls."""
    coupling = Coupling("f", "l", multiplier, 0.1, "tendon t", 0.2)
    moved, notes = lagging_couplings([coupling], {"l": sense})
    assert moved[0].offset == pytest.approx(edge)
    assert (moved[0].multiplier, moved[0].slack) == (multiplier, 0.2)
    assert len(notes) == 1 and "joint f: follows l at the edge of its play" in notes[0]


def test_couplings_without_play_or_a_closing_leader_stay():
    assert lagging_couplings([Coupling("f", "l", 1.14, 0.1, "tendon t", 0.0)], {"l": 1}) is None
    assert lagging_couplings([Coupling("f", "l", 1.14, 0.1, "tendon t", 0.2)], {"l": 0}) is None
    assert lagging_couplings([Coupling("f", "l", 1.14, 0.1, "tendon t", 0.2)], {}) is None


def test_an_actuator_on_a_tendon_over_free_joints_is_noted(tmp_path):
    """As MuJoCo Menagerie's Shadow hand drives each finger's two distal joints: a position
    actuator on a fixed tendon (their sum). The planner moves the joints each on its own;
    the note tells the user that the hand's controller takes their sum."""
    from grasp_apso.model.hands.mjcf_loader import read_mjcf

    xml = tmp_path / "finger.xml"
    xml.write_text("""<mujoco><worldbody><body name="palm"><geom type="box" size="0.02 0.02 0.005"/>
      <body name="middle" pos="0 0 0.01"><joint name="j2" axis="1 0 0" range="0 1.57"/>
        <geom type="capsule" size="0.008 0.01" pos="0 0 0.01"/>
        <body name="distal" pos="0 0 0.025"><joint name="j1" axis="1 0 0" range="0 1.57"/>
          <geom type="capsule" size="0.008 0.01" pos="0 0 0.01"/></body></body></body></worldbody>
      <tendon><fixed name="t0"><joint joint="j2" coef="1"/><joint joint="j1" coef="1"/></fixed></tendon>
      <actuator><position name="a0" tendon="t0" ctrlrange="0 3.14"/></actuator></mujoco>""")
    raw = read_mjcf(xml, 10**6)
    assert not raw.couplings
    assert any(n.startswith("actuator a0 drives tendon t0 (j2 + j1)") and "commands only this sum" in n
               for n in raw.notes), raw.notes
    assert not any(n.startswith("actuator ") for n in load_hand(installed_hand("shadow"), spheres=False).notes)
