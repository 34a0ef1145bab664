"""Hand descriptions as the field writes them beyond the usual five-finger hand: tactile
sensor links fixed on the phalanges, a mimic joint whose own limits contradict its
leader's, and a three-finger claw whose fingers extend along the palm normal (dex-urdf's
Allegro with FSRs, its left Schunk SVH and its D'Claw have these; the files here are
written by the test, from the Allegro-like hand of ``hand_files`` or from scratch), also as
a gripper with flat fingertips whose fingers bend back (a Schunk SDH, a Robotiq three-finger).

The claw's plans are checked without the planner's geometry: python-fcl on the URDF's
own collision boxes and spheres placed by yourdfpy's kinematics against the table.
"""

from __future__ import annotations

import math
from pathlib import Path

import fcl
import numpy as np
import pytest
import yourdfpy

from grasp_apso.errors import HandDescriptionError
from grasp_apso.model.builtin import builtin
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.scene import Scene
from grasp_apso.search.planner import PlanOptions, plan
from hand_files import write_allegro_like


@pytest.fixture(scope="module")
def allegro_file(tmp_path_factory):
    return write_allegro_like(tmp_path_factory.mktemp("allegro"), "none")


def _sensor(name: str, parent: str, xyz: tuple, size: tuple) -> str:
    return (f'  <joint name="{name}_joint" type="fixed"><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" rpy="0 0 0"/>'
            f'<parent link="{parent}"/><child link="{name}"/></joint>\n'
            f'  <link name="{name}"><collision><origin xyz="0 0 0" rpy="0 0 0"/><geometry>'
            f'<box size="{size[0]} {size[1]} {size[2]}"/></geometry></collision></link>\n')


def test_sensor_links_on_the_phalanges_are_no_fingers(allegro_file, tmp_path):
    """A box fixed on every proximal and middle link (a tactile pad on a phalanx: a leaf
    with geometry and two or more joints above it) and one inside each fingertip sphere:
    the same four fingers, tips, closing senses and thumb as without them."""
    text = allegro_file.read_text()
    sensors = ""
    for f in ("index", "middle", "ring", "thumb"):
        for part in ("proximal", "middle"):
            sensors += _sensor(f"{f}_{part}_fsr", f"{f}_{part}", (0.011, 0.0, 0.02), (0.003, 0.02, 0.015))
        sensors += _sensor(f"{f}_tip_fsr", f"{f}_tip", (0.004, 0.0, 0.0), (0.003, 0.012, 0.012))
    path = tmp_path / "allegro_fsr.urdf"
    path.write_text(text.replace("</robot>", sensors + "</robot>"))
    plain, sensed = load_hand(allegro_file, spheres=False), load_hand(path, spheres=False)
    assert len(sensed.links) == len(plain.links) + 12
    # each sensor moves with its finger (before, those on the proximal and middle links
    # were read with the palm, where the open finger holds them)
    for finger in sensed.fingers:
        f = finger.tip_link.removesuffix("_tip")
        assert {f"{f}_proximal_fsr", f"{f}_middle_fsr", f"{f}_tip_fsr"} <= set(sensed.finger_links(finger))
    assert [f.tip_link for f in sensed.fingers] == [f.tip_link for f in plain.fingers]
    assert [f.closing for f in sensed.fingers] == [f.closing for f in plain.fingers]
    assert [f.is_thumb for f in sensed.fingers] == [f.is_thumb for f in plain.fingers]
    np.testing.assert_allclose(sensed.palm_normal, plain.palm_normal, atol=1e-9)


def test_a_tip_frame_marker_beyond_the_fingertip_leaves_the_fingertip_the_tip(allegro_file, tmp_path):
    """A 1 x 2 x 1 mm box fixed 1 mm beyond each fingertip sphere (the Linker hands mark
    their tip frames so): it reaches farther than the sphere but is no pad. The same tips,
    pads and thumb as without the markers."""
    text = allegro_file.read_text()
    hand_file = load_hand(allegro_file, spheres=False)
    markers = ""
    for f in ("index", "middle", "ring", "thumb"):
        radius = next(fi.pad_radius for fi in hand_file.fingers if fi.tip_link == f"{f}_tip")
        markers += _sensor(f"{f}_tip_frame", f"{f}_tip", (0.0, 0.0, radius + 0.0015), (0.001, 0.002, 0.001))
    path = tmp_path / "allegro_markers.urdf"
    path.write_text(text.replace("</robot>", markers + "</robot>"))
    marked = load_hand(path, spheres=False)
    assert len(marked.links) == len(hand_file.links) + 4
    assert [f.tip_link for f in marked.fingers] == [f.tip_link for f in hand_file.fingers]
    assert [f.pad_link for f in marked.fingers] == [f.pad_link for f in hand_file.fingers]
    np.testing.assert_allclose([f.pad_radius for f in marked.fingers], [f.pad_radius for f in hand_file.fingers])
    assert [f.is_thumb for f in marked.fingers] == [f.is_thumb for f in hand_file.fingers]


def test_a_fingertip_with_only_a_marker_for_geometry_is_noted(allegro_file, tmp_path):
    """The index finger's distal link and tip written without collision geometry and a
    1 x 2 x 1 mm marker fixed at the tip: the marker is all there is, so it is the index
    finger's tip, and a note names it and says how to give the fingertip."""
    import re

    text = allegro_file.read_text()
    for link in ("index_distal", "index_tip"):
        text = re.sub(rf'(<link name="{link}">)(.*?)(</link>)',
                      lambda m: m.group(1) + re.sub(r"<collision>.*?</collision>", "", m.group(2), flags=re.S)
                      + m.group(3), text, flags=re.S)
    text = text.replace("</robot>", _sensor("index_tip_frame", "index_tip", (0.0, 0.0, 0.0), (0.001, 0.002, 0.001))
                        + "</robot>")
    path = tmp_path / "allegro_bare_index.urdf"
    path.write_text(text)
    hand = load_hand(path, spheres=False)
    index = next(f for f in hand.fingers if f.tip_link == "index_tip_frame")
    notes = [n for n in hand.notes if n.startswith(f"finger {index.name}:")]
    assert len(notes) == 1 and "index_tip_frame" in notes[0] and "hand_config.fingers" in notes[0], hand.notes
    assert not any("frame marker or a sensor" in n for n in load_hand(allegro_file, spheres=False).notes)


def _write_covered(allegro_file: Path, folder: Path, thickness: float = 0.004, on_distal: bool = False) -> Path:
    """The Allegro-like hand with a skin on each fingertip: a box 8 mm along the finger and
    14 mm across fixed to the tip sphere over its pad, standing ``thickness`` proud of it
    (sunk 1 mm into the sphere). As on TetherIA's Aero Hand Open, whose cover links sit
    over the pad side of each distal phalanx, the fingertip reaches farther than its skin.
    ``on_distal``: each skin fixed to the distal phalanx beside the tip link, at the same
    place (DexRobot's DexHand021 fixes its tactile pad so, beside its fingertip's links)."""
    from scipy.spatial.transform import Rotation

    bare = load_hand(allegro_file, spheres=False)
    skins = ""
    for finger in bare.fingers:
        normal = np.asarray(finger.pad_center, float) / np.linalg.norm(finger.pad_center)  # the sphere's centre: 0
        along = np.array([0.0, 0.0, 1.0]) - normal[2] * normal  # the finger's axis across the normal
        along /= np.linalg.norm(along)
        rpy = Rotation.from_matrix(np.column_stack([along, np.cross(normal, along), normal])).as_euler("xyz")
        depth = thickness + 0.001
        at = np.asarray(finger.pad_center) + normal * (0.5 * depth - 0.001)
        parent = finger.pad_link
        if on_distal:  # the tip link hangs at (0, 0, length) from the distal link, unturned
            parent = finger.pad_link.replace("_tip", "_distal")
            at = at + bare.origins[bare.link_index(finger.pad_link)][:3, 3]
        skins += (f'  <joint name="{finger.pad_link}_skin_joint" type="fixed"><origin xyz="{at[0]} {at[1]} {at[2]}" '
                  f'rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/><parent link="{parent}"/>'
                  f'<child link="{finger.pad_link}_skin"/></joint>\n'
                  f'  <link name="{finger.pad_link}_skin"><collision><origin xyz="0 0 0" rpy="0 0 0"/><geometry>'
                  f'<box size="0.008 0.014 {depth}"/></geometry></collision></link>\n')
    path = folder / "allegro_skins.urdf"
    path.write_text(allegro_file.read_text().replace("</robot>", skins + "</robot>"))
    return path


@pytest.mark.parametrize("on_distal", [False, True], ids=["on_the_tip", "beside_the_tip"])
def test_a_cover_fixed_over_a_fingertips_pad_carries_the_pad(allegro_file, tmp_path, on_distal):
    """A skin link fixed over each fingertip's pad, 4 mm proud of it (the Aero Hand Open's
    covers): the pad moves onto the skin's outer face, the fingertips stay the tips, a note
    says so per finger; and the plans of the cube on a table touch with the skins: each
    contacting finger's skin within 2 mm of the cube by python-fcl on the URDF's own boxes
    placed by yourdfpy. Before, the pad stayed 4 mm under the skin. The same with each skin
    fixed to the distal phalanx beside the tip link (DexRobot's DexHand021 fixes its
    fingertip's tactile pad and nail so): the skin is the finger's (it moves with it), and
    carries the pad. Before, such a skin was no link of the finger's, read with the palm
    where the open finger holds it, and the pad stayed under it."""
    bare = load_hand(allegro_file, spheres=False)
    path = _write_covered(allegro_file, tmp_path, on_distal=on_distal)
    hand = load_hand(path)
    assert [f.tip_link for f in hand.fingers] == [f.tip_link for f in bare.fingers]
    assert [f.pad_link for f in hand.fingers] == [f"{f.pad_link}_skin" for f in bare.fingers]
    assert all(f.pad_link in hand.finger_links(f) for f in hand.fingers)
    for finger in hand.fingers:  # on the outer face (z = +2.5 mm in the skin's frame), near its middle
        assert abs(float(finger.pad_center[2]) - 0.0025) < 5e-4, finger.pad_center
        assert np.linalg.norm(np.asarray(finger.pad_center)[:2]) < 0.004, finger.pad_center
    assert sum("covers the pad" in n for n in hand.notes) == len(hand.fingers), hand.notes
    assert not any("covers the pad" in n for n in bare.notes)
    # a pad given in hand_config (here on the skin, its centre moved) is taken as given,
    # with no note for that finger
    index = next(f for f in hand.fingers if f.tip_link == "index_tip")
    given = load_hand(path, config={"pads": {index.name: {"link": "index_tip_skin", "center": [0.001, 0.0, 0.0025],
                                                          "radius": 0.007}}}, spheres=False)
    np.testing.assert_allclose(given.finger(index.name).pad_center, [0.001, 0.0, 0.0025])
    assert not any(n.startswith(f"finger {index.name}:") and "covers the pad" in n for n in given.notes)
    assert sum("covers the pad" in n for n in given.notes) == len(hand.fingers) - 1

    obj = builtin("cube")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    result = plan(obj, options=PlanOptions(particles=30, iterations=20, max_grasps=3), rng=np.random.default_rng(0),
                  hand=hand, scene=table)
    assert result.candidates and result.candidates[0].force_closure
    urdf = yourdfpy.URDF.load(str(path), build_collision_scene_graph=False, load_meshes=False)
    half = 0.5 * np.ptp(np.asarray(obj.mesh.vertices), axis=0)
    cube = fcl.CollisionObject(fcl.Box(*(2.0 * half)), fcl.Transform(np.asarray(obj.mesh.vertices).mean(axis=0)))
    for cand in result.candidates:
        urdf.update_cfg({j: float(v) for j, v in zip(hand.actuated_joints, cand.joint_positions)})
        for contact in cand.contacts:
            skin = hand.finger(contact.finger).pad_link
            at = np.asarray(cand.wrist_pose) @ urdf.get_transform(skin, urdf.base_link) \
                @ urdf.link_map[skin].collisions[0].origin
            box = fcl.CollisionObject(fcl.Box(*urdf.link_map[skin].collisions[0].geometry.box.size),
                                      fcl.Transform(at[:3, :3], at[:3, 3]))
            gap = fcl.distance(box, cube, fcl.DistanceRequest(), fcl.DistanceResult())
            assert gap <= 0.002, (contact.finger, gap)


def test_limits_that_let_a_finger_close_through_the_palm_are_noted(allegro_file, tmp_path):
    """The thumb's flexion joints given the range [0, pi] (as the Robotiq three-finger URDF
    of TAMS-Group gives every phalanx): 70 % of the way closed its pad lies inside the
    palm, and a note names the finger and asks whether its limits are right. The hand as
    written has no such note."""
    import re

    text = allegro_file.read_text()
    for k in (1, 2, 3):
        text, n = re.subn(rf'(<joint name="thumb_joint_{k}".*?<limit lower=")[^"]*(" upper=")[^"]*',
                          r"\g<1>0\g<2>3.1416", text, flags=re.S)
        assert n == 1
    path = tmp_path / "allegro_thumb_pi.urdf"
    path.write_text(text)
    notes = [n for n in load_hand(path, spheres=False).notes if "inside the palm" in n]
    assert len(notes) == 1 and notes[0].startswith("finger thumb:") and "joint limits" in notes[0], notes
    assert not any("inside the palm" in n for n in load_hand(allegro_file, spheres=False).notes)


def test_a_leader_that_its_followers_limits_leave_no_range_is_held(tmp_path):
    """The coupled Allegro-like hand with the index distal joint (mimic of the middle one,
    multiplier 1) limited to [-1.709, -0.174]: the middle joint's own range [-0.174, 1.709]
    leaves one value, -0.174. The middle joint is held there (no longer actuated, a note),
    and the follower stays within its limits in every posture of the hand."""
    path = write_allegro_like(tmp_path, "none", coupled=True)
    text = path.read_text()
    old = '<mimic joint="index_joint_2"'
    assert old in text
    head, tail = text.split(old)
    limit = head.rsplit("<limit", 1)
    head = limit[0] + '<limit lower="-1.709" upper="-0.174" effort="0.7" velocity="7"/>\n    '
    path.write_text(head + old + tail)
    hand = load_hand(path, spheres=False)
    assert "index_joint_2" not in hand.actuated_joints
    assert any("index_joint_2" in note and "held" in note for note in hand.notes)
    rng = np.random.default_rng(0)
    q = rng.uniform(hand.lower, hand.upper, (200, len(hand.lower)))
    full = np.stack([hand.full_positions(row) for row in q])
    follower = hand.joint_names.index("index_joint_3")
    assert np.all(full[:, follower] <= -0.174 + 1e-9) and np.all(full[:, follower] >= -1.709 - 1e-9)
    index = next(f for f in hand.fingers if f.tip_link == "index_tip")
    assert "index_joint_2" not in index.joints and len(index.joints) >= 2


def test_a_joint_the_file_locks_is_held_not_refused(allegro_file, tmp_path):
    """The index finger's abduction with equal limits (0, 0), as files lock a joint: the hand
    loads, that joint is held at 0 (a note) and the index finger keeps its flexion joints;
    a lower limit above the upper one is still refused, naming the joint."""
    text = allegro_file.read_text()
    head, tail = text.split('<joint name="index_joint_0"')
    limit_at = tail.index("<limit")
    end = tail.index("/>", limit_at) + 2
    locked = tmp_path / "locked.urdf"
    locked.write_text(head + '<joint name="index_joint_0"' + tail[:limit_at]
                      + '<limit lower="0" upper="0" effort="0.7" velocity="7"/>' + tail[end:])
    hand = load_hand(locked, spheres=False)
    assert "index_joint_0" not in hand.actuated_joints
    assert any("index_joint_0" in note and "equal" in note for note in hand.notes)
    index = next(f for f in hand.fingers if f.tip_link == "index_tip")
    assert index.joints == ("index_joint_1", "index_joint_2", "index_joint_3")
    full = hand.full_positions(np.clip(0.3, hand.lower, hand.upper))
    assert full[hand.joint_names.index("index_joint_0")] == 0.0
    crossed = tmp_path / "crossed.urdf"
    crossed.write_text(head + '<joint name="index_joint_0"' + tail[:limit_at]
                       + '<limit lower="0.2" upper="0.1" effort="0.7" velocity="7"/>' + tail[end:])
    with pytest.raises(HandDescriptionError, match="index_joint_0"):
        load_hand(crossed, spheres=False)


# ---------------------------------------------------------------------------- the claw
_CLAW_RADIUS = 0.045
_CLAW_LENGTHS = (0.07, 0.06)
_CLAW_TIP = 0.011


def _write_claw(folder: Path, radius: float = _CLAW_RADIUS, tip_box: tuple | None = None,
                name: str = "claw") -> Path:
    """Three fingers at 120 degrees around the palm normal (+z), ``radius`` from it, each a
    base joint turning it sideways and two flexion joints of range [-1.57, 1.57] (the
    ranges do not say which way closes), straight along +z at zero; the second finger's
    flexion axes point the other way (as the D'Claw's do), so the same joint sign closes
    one finger and opens another. The tips are spheres, or with ``tip_box`` (width along
    the flexion axis, thickness, length; m) flat boxes as a gripper's (a Robotiq or
    Schunk SDH fingertip)."""
    lines = ['<?xml version="1.0"?>', f'<robot name="{name}">',
             '  <link name="base"><collision><origin xyz="0 0 -0.01" rpy="0 0 0"/><geometry>'
             '<cylinder radius="0.07" length="0.02"/></geometry></collision></link>']
    for f in range(3):
        angle = 2.0 * math.pi * f / 3.0
        radial = np.array([math.cos(angle), math.sin(angle), 0.0])
        tangent = np.cross([0.0, 0.0, 1.0], radial)
        sign = -1.0 if f == 1 else 1.0
        parent, xyz = "base", radius * radial
        for k, length in enumerate((0.02, *_CLAW_LENGTHS)):
            link = f"f{f}_link{k}"
            axis = radial if k == 0 else sign * tangent
            limits = (-0.3, 0.3) if k == 0 else (-1.57, 1.57)
            lines.append(f'  <joint name="f{f}_joint{k}" type="revolute"><origin xyz="{xyz[0]:.9g} {xyz[1]:.9g} '
                         f'{xyz[2]:.9g}" rpy="0 0 0"/><parent link="{parent}"/><child link="{link}"/>'
                         f'<axis xyz="{axis[0]:.9g} {axis[1]:.9g} {axis[2]:.9g}"/>'
                         f'<limit lower="{limits[0]}" upper="{limits[1]}" effort="2" velocity="5"/></joint>')
            lines.append(f'  <link name="{link}"><collision><origin xyz="0 0 {length / 2:.9g}" rpy="0 0 0"/>'
                         f'<geometry><box size="0.016 0.016 {length:.9g}"/></geometry></collision></link>')
            parent, xyz = link, (0.0, 0.0, length)
        lines.append(f'  <joint name="f{f}_tip_joint" type="fixed"><origin xyz="0 0 {_CLAW_LENGTHS[-1]:.9g}" '
                     f'rpy="0 0 0"/><parent link="{parent}"/><child link="f{f}_tip"/></joint>')
        if tip_box is None:
            tip = f'<origin xyz="0 0 0" rpy="0 0 0"/><geometry><sphere radius="{_CLAW_TIP}"/></geometry>'
        else:  # the box's width along the flexion axis (link frame: the tangent turned onto x)
            width, thick, length = tip_box
            yaw = math.atan2(tangent[1], tangent[0])
            tip = (f'<origin xyz="0 0 {length / 2:.9g}" rpy="0 0 {yaw:.9g}"/><geometry><box size="{width:.9g} '
                   f'{thick:.9g} {length:.9g}"/></geometry>')
        lines.append(f'  <link name="f{f}_tip"><collision>{tip}</collision></link>')
    lines.append("</robot>")
    path = folder / f"{name}.urdf"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def claw_file(tmp_path_factory):
    return _write_claw(tmp_path_factory.mktemp("claw"))


def _tip_centres(hand, q: np.ndarray) -> np.ndarray:
    poses = hand.link_transforms_batch(q[None])[0]
    return np.array([poses[hand.link_index(f.tip_link), :3, 3] for f in hand.fingers])


def test_a_claw_closes_its_fingers_toward_each_other(claw_file):
    """Closing moves every tip toward the claw's axis (the open tips stand 45 mm off it),
    whatever the sign of its flexion axes, and the palm normal is the axis (+z)."""
    hand = load_hand(claw_file, spheres=False)
    assert len(hand.fingers) == 3
    np.testing.assert_allclose(hand.palm_normal, [0.0, 0.0, 1.0], atol=0.05)
    open_tips = _tip_centres(hand, np.clip(0.0, hand.lower, hand.upper))
    np.testing.assert_allclose(np.linalg.norm(open_tips[:, :2], axis=1), _CLAW_RADIUS, atol=1e-9)
    half = _tip_centres(hand, hand.closed_configuration(0.1))  # 18 degrees of each flexion joint
    assert np.all(np.linalg.norm(half[:, :2], axis=1) < _CLAW_RADIUS - 0.02)


def test_a_claw_reaches_ahead_of_its_palm_and_a_hand_does_not(claw_file, allegro_file):
    """The claw's standoff range reaches its open pads (150 mm in front of the base's face)
    and GRG pre-shapes it less closed (``closes_ahead``); the Allegro-like hand keeps the
    reach-based range (at most STANDOFF_MAX) and its pre-shapes."""
    from grasp_apso.geometry.any_hand_decoder import make_any_hand_model
    from grasp_apso.geometry.any_hand_tables import STANDOFF_MAX
    from grasp_apso.search.any_hand_grg import CLAW_OPEN_FRACTION, OPEN_FRACTION, _open_fraction

    sphere = builtin("sphere")
    claw = make_any_hand_model(load_hand(claw_file), sphere)
    hand = make_any_hand_model(load_hand(allegro_file), sphere)
    assert claw.tables.closes_ahead and not hand.tables.closes_ahead
    assert claw.tables.upper[claw.layout.standoff] >= sum(_CLAW_LENGTHS) + 0.02 - 1e-3  # base face at z 0
    assert hand.tables.upper[hand.layout.standoff] <= STANDOFF_MAX
    assert (_open_fraction(claw), _open_fraction(hand)) == (CLAW_OPEN_FRACTION, OPEN_FRACTION)


def test_a_claws_preshape_joints_are_drawn_anywhere_and_a_hands_abduction_near_open(claw_file, allegro_file):
    """GRG draws a claw's pre-shape joints (the base joints turning its fingers sideways)
    anywhere in their range, as a thumb's: a claw's fingers stand apart around its palm, and
    those joints set the grasp's type (the Schunk SDH's knuckle: two fingers facing the
    thumb, or a triangle). A hand's abduction stays near its open value (within
    ``SPREAD_FRACTION`` of its range): spread fingers collide."""
    from grasp_apso.geometry.any_hand_decoder import make_any_hand_model
    from grasp_apso.search.any_hand_grg import SPREAD_FRACTION, _preshape

    sphere = builtin("sphere")
    for path, claw in ((claw_file, True), (allegro_file, False)):
        model = make_any_hand_model(load_hand(path), sphere)
        hand = model.hand
        q = _preshape(model, 2000, np.random.default_rng(0), 0.5)
        for finger in hand.fingers:
            if finger.is_thumb:
                continue
            for joint, sense in zip(finger.joints, finger.closing):
                if sense:
                    continue
                j = hand.actuated_joints.index(joint)
                low, high = hand.lower[j], hand.upper[j]
                span = float(np.ptp(q[:, j]))
                if claw:
                    assert span > 0.9 * (high - low), (joint, span, high - low)
                else:
                    assert span <= 2.0 * SPREAD_FRACTION * (high - low) + 1e-9, (joint, span, high - low)


def _table_distance(urdf: yourdfpy.URDF, wrist: np.ndarray, table_z: float) -> float:
    """Least python-fcl distance (m) of the URDF's own collision boxes, cylinders and
    spheres, placed by yourdfpy at the grasp, to a 4 m box whose top face is the table."""
    top = fcl.CollisionObject(fcl.Box(4.0, 4.0, 1.0), fcl.Transform(np.array([0.0, 0.0, table_z - 0.5])))
    least = math.inf
    for name, link in urdf.link_map.items():
        pose = wrist @ urdf.get_transform(name, urdf.base_link)
        for c in link.collisions:
            g = c.geometry
            shape = (fcl.Box(*g.box.size) if g.box is not None else fcl.Cylinder(g.cylinder.radius, g.cylinder.length)
                     if g.cylinder is not None else fcl.Sphere(g.sphere.radius))
            at = pose @ (c.origin if c.origin is not None else np.eye(4))
            obj = fcl.CollisionObject(shape, fcl.Transform(at[:3, :3], at[:3, 3]))
            least = min(least, fcl.distance(obj, top, fcl.DistanceRequest(), fcl.DistanceResult()))
    return least


def _plan_clear_of_the_table(path: Path, name: str):
    """The hand of ``path`` plans the built-in ``name`` resting on a table (30 particles x
    20 iterations, 3 grasps, seed 0): the best grasp has force closure, every one two or
    more contacts, its joints within their limits and the whole hand (the URDF's own
    geometry, yourdfpy's kinematics, python-fcl) at least the clearance above the table.
    Returns (hand, result)."""
    hand = load_hand(path)
    obj = builtin(name)
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    options = PlanOptions(particles=30, iterations=20, max_grasps=3)
    result = plan(obj, options=options, rng=np.random.default_rng(0), hand=hand, scene=table)
    assert result.candidates and result.candidates[0].force_closure
    urdf = yourdfpy.URDF.load(str(path), build_collision_scene_graph=False, load_meshes=False)
    table_z = float(np.asarray(obj.mesh.vertices)[:, 2].min())
    for cand in result.candidates:
        assert len(cand.contacts) >= 2
        q = np.asarray(cand.joint_positions)
        assert np.all(q >= hand.lower - 1e-9) and np.all(q <= hand.upper + 1e-9)
        urdf.update_cfg({j: float(v) for j, v in zip(hand.actuated_joints, q)})
        assert _table_distance(urdf, np.asarray(cand.wrist_pose), table_z) >= options.clearance - 5e-4
    return hand, result


def test_a_claw_plans_grasps_clear_of_the_table(claw_file):
    """The claw plans the built-in sphere resting on a table (:func:`_plan_clear_of_the_table`)."""
    _plan_clear_of_the_table(claw_file, "sphere")


def test_a_flat_fingertip_has_its_pad_in_the_middle_of_its_width(tmp_path):
    """Box fingertips 30 mm wide along the flexion axis: the pad sits in the middle of the
    width (the farthest point of such a tip is a corner; the probe once put the pad there,
    12 mm off), on every finger, also the one whose flexion axes point the other way."""
    hand = load_hand(_write_claw(tmp_path, tip_box=(0.03, 0.01, 0.025), name="flat"), spheres=False)
    assert len(hand.fingers) == 3
    for finger in hand.fingers:
        angle = 2.0 * math.pi * int(finger.tip_link[1]) / 3.0
        tangent = np.array([-math.sin(angle), math.cos(angle), 0.0])  # the flexion axis (link frame at zero)
        assert abs(float(np.asarray(finger.pad_center) @ tangent)) < 0.002, (finger.name, finger.pad_center)
        assert float(np.asarray(finger.pad_center)[2]) > 0.01  # toward the tip's far end


def test_a_gripper_opens_its_fingers_past_straight_to_take_a_wide_object(tmp_path):
    """A claw whose straight fingers stand 35 mm apart (20 mm from its axis, as a Schunk
    SDH's stand 6 cm apart) and bend back as far as they close: the 70 mm cube on a table
    fits between them only with the fingers opened past straight. GRG draws a claw's
    closing joints from half their opening on; the plans take the cube as
    :func:`_plan_clear_of_the_table` requires. Drawn from straight on, no draw made two
    legal contacts."""
    hand, result = _plan_clear_of_the_table(_write_claw(tmp_path, radius=0.02, name="gripper"), "cube")
    # the best grasp's pre-grasp bends a finger back past straight (against its closing sense)
    pre = np.asarray(result.candidates[0].pre_grasp_positions)
    past = [sense * pre[hand.actuated_joints.index(joint)] for f in hand.fingers
            for joint, sense in zip(f.joints, f.closing) if sense]
    assert min(past) < -0.1, past


def _limb(name: str, parent: str, child: str, xyz: tuple, size: tuple) -> str:
    """A revolute joint ``name`` (about y, +-1 rad) from ``parent`` to a new link ``child``
    holding a box of ``size`` (m)."""
    return (f'  <joint name="{name}" type="revolute"><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" rpy="0 0 0"/>'
            f'<parent link="{parent}"/><child link="{child}"/><axis xyz="0 1 0"/>'
            f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>\n'
            f'  <link name="{child}"><collision><origin xyz="0 0 -0.05" rpy="0 0 0"/><geometry>'
            f'<box size="{size[0]} {size[1]} {size[2]}"/></geometry></collision></link>\n')


def test_a_robot_holding_two_hands_is_refused_naming_their_palms(allegro_file, tmp_path):
    """Two Allegro-like hands on the arms of a torso that also has a leg (a humanoid with
    hands, as Unitree's G1 MJCF with hands): the derivation took the torso for the palm and
    the foot for a finger; now the file is refused, naming both palms and
    ``hand_config.root_link``. With ``root_link: palm`` it is the one hand: its four fingers
    and joints, the rest of the robot (arms, leg, the other hand's fingers) held."""
    import re

    text = allegro_file.read_text()
    body = text[text.index("<robot"):text.index("</robot>")]
    body = body[body.index(">") + 1:]
    other = re.sub(r'\b(name|link|joint)="([^"]+)"', r'\1="l_\2"', body)
    robot = ('<?xml version="1.0"?>\n<robot name="two_hands">\n'
             '  <link name="torso"><collision><geometry><box size="0.2 0.3 0.4"/></geometry></collision></link>\n'
             + _limb("r_shoulder", "torso", "r_arm", (0.0, -0.2, 0.2), (0.05, 0.05, 0.1))
             + _limb("l_shoulder", "torso", "l_arm", (0.0, 0.2, 0.2), (0.05, 0.05, 0.1))
             + _limb("hip", "torso", "thigh", (0.0, 0.0, -0.2), (0.05, 0.05, 0.1))
             + _limb("knee", "thigh", "foot", (0.0, 0.0, -0.1), (0.05, 0.05, 0.1))
             + '  <joint name="r_mount" type="fixed"><origin xyz="0 0 -0.1"/><parent link="r_arm"/>'
               '<child link="palm"/></joint>\n'
             + '  <joint name="l_mount" type="fixed"><origin xyz="0 0 -0.1"/><parent link="l_arm"/>'
               '<child link="l_palm"/></joint>\n'
             + body + other + "</robot>\n")
    path = tmp_path / "two_hands.urdf"
    path.write_text(robot)
    with pytest.raises(HandDescriptionError) as info:
        load_hand(path, spheres=False)
    assert info.value.field == "hand_description"
    assert "2 hands" in str(info.value) and "l_palm" in str(info.value) and "hand_config.root_link" in str(info.value)
    assert re.search(r"\bpalm\b", str(info.value).replace("l_palm", "")), str(info.value)
    plain = load_hand(allegro_file, spheres=False)
    one = load_hand(path, {"root_link": "palm"}, spheres=False)
    assert [f.tip_link for f in one.fingers] == [f.tip_link for f in plain.fingers]
    assert one.actuated_joints == plain.actuated_joints
    assert {"r_shoulder", "l_shoulder", "hip", "knee", "l_index_joint_1"} <= set(one.held_joints)
