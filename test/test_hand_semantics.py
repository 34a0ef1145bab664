"""Grasp semantics derived from real hands (issue 20), the override config, and the
refusal of bad descriptions with a message naming the element.

Pads and spheres are checked independently of the code that made them: the pad's
distance to the link surface with trimesh's signed distance; the spheres' cover on
trimesh surface samples and their stray with trimesh's signed distance of points spread
over each sphere.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from grasp_apso.errors import HandDescriptionError
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.hands.spheres import cover_link
from hand_files import installed_hand, write_allegro_like

NAMES = ("shadow", "adroit", "inspire", "fourier", "allegro", "paper")


@pytest.fixture(scope="module")
def allegro_file(tmp_path_factory):
    return write_allegro_like(tmp_path_factory.mktemp("allegro"), "mixed")


@pytest.fixture(scope="module")
def hands(allegro_file):
    files = {n: installed_hand(n) for n in NAMES[:4]}
    files.update(allegro=allegro_file, paper=None)
    return {n: load_hand(p, spheres=False) for n, p in files.items()}


def _link_mesh(hand, link: str) -> trimesh.Trimesh:
    return trimesh.util.concatenate([g.to_trimesh() for g in hand.collision[link]])


def _pads(hand, q):
    """finger -> (pad point, centre of the pad link's geometry), root frame."""
    poses = hand.link_transforms(q)
    out = {}
    for f in hand.fingers:
        T = poses[f.pad_link]
        centre = _link_mesh(hand, f.pad_link).bounds.mean(axis=0)
        out[f.name] = (T[:3, :3] @ f.pad_center + T[:3, 3], T[:3, :3] @ centre + T[:3, 3])
    return out


@pytest.mark.parametrize("name", NAMES)
def test_every_pad_is_on_the_palmar_surface_of_the_last_link(hands, name):
    hand = hands[name]
    for f in hand.fingers:
        assert f.pad_link == f.tip_link
        # Within 1 mm of the link's collision surface (trimesh: + inside).
        depth = min(abs(float(trimesh.proximity.signed_distance(g.to_trimesh(), f.pad_center[None])[0]))
                    for g in hand.collision[f.pad_link])
        assert depth <= 1e-3, (f.name, depth)
        assert 0.001 <= f.pad_radius <= 0.02
    # Straight fingers: the pad is on the palm's side of the fingertip link (in the upper
    # part of the link's extent along the palm normal).
    poses = hand.link_transforms(hand.open_configuration())
    for f in hand.fingers:
        if not f.is_thumb:
            T = poses[f.pad_link]
            heights = (_link_mesh(hand, f.pad_link).vertices @ T[:3, :3].T + T[:3, 3]) @ hand.palm_normal
            pad = (T[:3, :3] @ f.pad_center + T[:3, 3]) @ hand.palm_normal
            assert (pad - heights.min()) / np.ptp(heights) > 0.7, f.name
    # Closing: the thumb's pad faces the other fingers' pads.
    pads = _pads(hand, hand.closed_configuration(0.3))
    pad, centre = pads[hand.thumb.name]
    target = np.mean([p for n, (p, _) in pads.items() if n != hand.thumb.name], axis=0)
    assert np.dot(pad - centre, target - centre) > 0.0


#: The palm's side, known independently: the Shadow/Adroit touch-sensor sites of the palm
#: lie at -y of the palm frame; the Allegro-like palm box's front face is +x; the paper
#: hand's YAML says +z is out of the palm.
PALM_SIDES = {"shadow": (0, -1, 0), "adroit": (0, -1, 0), "allegro": (1, 0, 0), "paper": (0, 0, 1)}


@pytest.mark.parametrize("name", list(PALM_SIDES))
def test_the_palm_normal_is_the_palm_side(hands, name):
    assert np.dot(hands[name].palm_normal, PALM_SIDES[name]) > np.cos(np.radians(30))


@pytest.mark.parametrize("name", NAMES)
def test_fingers_close_toward_the_palm_normal_and_the_thumb(hands, name):
    """Closing moves every fingertip toward the thumb's tip (and the thumb toward the
    others): the pads end up closer together than with the fingers straight."""
    hand = hands[name]

    def spread(q):
        poses = hand.link_transforms(q)
        pts = np.array([poses[f.pad_link][:3, :3] @ f.pad_center + poses[f.pad_link][:3, 3] for f in hand.fingers])
        thumb = pts[[f.is_thumb for f in hand.fingers]][0]
        return np.linalg.norm(pts - thumb, axis=1).sum()

    assert spread(hand.closed_configuration(0.6)) < spread(hand.open_configuration())


@pytest.mark.parametrize("name", NAMES)
def test_spheres_cover_the_fingertips_and_stray_at_most_2mm(hands, name):
    hand = hands[name]
    rng = np.random.default_rng(7)
    for f in hand.fingers[:2]:
        geoms = hand.collision[f.tip_link]
        cover = cover_link(geoms, 0.002, np.random.default_rng(20))
        assert 1 <= len(cover.radii) <= 256  # a fingertip needs few
        meshes = [g.to_trimesh() for g in geoms]
        surface = np.vstack([m.sample(800, seed=int(rng.integers(1 << 30))) for m in meshes])
        gap = np.linalg.norm(surface[:, None] - cover.centers[None], axis=2) - cover.radii[None]
        assert np.mean(gap.min(axis=1) <= 1e-4) >= 0.995, f.tip_link
        unit = trimesh.creation.icosphere(subdivisions=2).vertices
        on_spheres = (cover.centers[:, None] + cover.radii[:, None, None] * unit[None]).reshape(-1, 3)
        outside = -np.max([trimesh.proximity.signed_distance(m, on_spheres) for m in meshes], axis=0)
        assert outside.max() <= 0.002 + 1e-4, (f.tip_link, outside.max())


# ----------------------------------------------------------------------- override config
def test_the_config_overrides_the_derivation(allegro_file):
    config = {"closing": {"index_joint_0": 1}, "thumb": "index", "palm_normal": [0, 0, 2],
              "pads": {"ring": {"link": "ring_distal", "center": [0.01, 0, 0.02], "radius": 0.007}}}
    hand = load_hand(allegro_file, config, spheres=False)
    assert hand.thumb.name == "index"
    assert hand.finger("index").closing[0] == 1
    np.testing.assert_allclose(hand.palm_normal, [0, 0, 1])
    ring = hand.finger("ring")
    assert (ring.pad_link, ring.pad_radius) == ("ring_distal", 0.007)
    assert load_hand(allegro_file, spheres=False).thumb.name == "thumb"  # cached separately


def test_the_config_can_name_the_root_and_hold_joints(tmp_path):
    path = installed_hand("shadow")
    hand = load_hand(path, {"hold": {"robot0:WRJ1": 0.1}}, spheres=False)
    assert hand.held_joints["robot0:WRJ1"] == 0.1
    cfg = tmp_path / "c.yaml"
    cfg.write_text("fingers: {first: robot0:ffdistal, thumb: robot0:thdistal}\n")
    two = load_hand(path, cfg, spheres=False)
    assert [f.name for f in two.fingers] == ["first", "thumb"]


@pytest.mark.parametrize("config, field", [
    ({"colour": 1}, "hand_config.colour"),
    ({"closing": {"index_joint_1": 2}}, "hand_config.closing.index_joint_1"),
    ({"closing": {"nope": 1}}, "hand_config.closing"),
    ({"thumb": "pinky"}, "hand_config.thumb"),
    ({"root_link": "nowhere"}, "hand_config.root_link"),
    ({"palm_normal": [0, 0, 0]}, "hand_config.palm_normal"),
    ({"pads": {"ring": {"link": "x"}}}, "hand_config.pads.ring"),
    # a link that does not move with the finger (another finger's tip): the search crashed
    ({"pads": {"ring": {"link": "index_tip", "center": [0, 0, 0], "radius": 0.01}}}, "hand_config.pads.ring"),
    ({"fingers": {"a": "index_tip", "b": "nowhere"}}, "hand_config.fingers"),
    ({"fingers": {"a": "index_tip", "b": "palm"}}, "hand_config.fingers"),
    ({"hold": {"index_joint_1": 0.1}}, "hand_config.hold"),
    ({"capsules": 1}, "hand_config.capsules"),
    ({"max_spheres": 0}, "hand_config.max_spheres"),
    ({"sphere_tolerance": 0.5}, "hand_config.sphere_tolerance"),
])
def test_a_bad_config_is_refused_naming_the_key(allegro_file, config, field):
    with pytest.raises(HandDescriptionError) as info:
        load_hand(allegro_file, config, spheres=False)
    assert info.value.field == field
    assert str(info.value).startswith(field)


# ----------------------------------------------------------------------- bad descriptions
def _edit(allegro_file: Path, tmp_path: Path, old: str, new: str, count: int = 1) -> Path:
    text = allegro_file.read_text()
    assert old in text
    out = allegro_file.parent / f"edited_{abs(hash((old, new)))}.urdf"
    out.write_text(text.replace(old, new, count))
    return out


def test_an_inertia_that_is_no_inertia_is_noted(allegro_file, tmp_path):
    """An <inertia> with a negative eigenvalue (Wonik's Allegro Hand V5 URDF gives six finger
    links an ixy about 1000 times too large): MuJoCo refuses such a link, so the simulation
    keeps its moments and drops its products of inertia (test_any_hand_simulation.py); the loader notes the link
    (the plan does not read inertias)."""
    path = _edit(allegro_file, tmp_path, '<link name="index_distal">',
                 '<link name="index_distal"><inertial><mass value="0.0366"/><inertia ixx="3.8e-06" '
                 'ixy="5.7e-03" ixz="0" iyy="1.45e-05" iyz="0" izz="1.29e-05"/></inertial>')
    notes = [n for n in load_hand(path, spheres=False).notes if "no physical inertia" in n]
    assert len(notes) == 1 and notes[0].startswith("link index_distal: its <inertia> is no physical inertia"), notes
    assert not any("no physical inertia" in n for n in load_hand(allegro_file, spheres=False).notes)


def test_not_a_hand_file(tmp_path):
    for name, content, match in [("hand.txt", "x", "not a URDF"), ("hand.urdf", "hello", "not a valid URDF"),
                                 ("hand.xml", "<robot/>", "MJCF")]:
        path = tmp_path / name
        path.write_text(content)
        with pytest.raises(HandDescriptionError, match=match) as info:
            load_hand(path, spheres=False)
        assert info.value.field == "hand_description"
    with pytest.raises(HandDescriptionError, match="cannot read"):
        load_hand(tmp_path / "missing.urdf")


def test_a_hand_in_xacro_is_named_as_such_and_an_expanded_one_loads(allegro_file, tmp_path):
    """Most ROS hand packages ship xacro (the Schunk SDH's, the Robotiq's): a ``.xacro``
    file, or a ``.urdf`` still holding ``<xacro:...>`` elements, is refused with what to do
    (expand it with xacro), not read in part. An expanded URDF that keeps the xacro namespace
    on its robot element and quotes a macro call in a comment (as the Robotiq's does) loads."""
    text = allegro_file.read_text()
    assert text.count("<robot ") == 1
    macro = text.replace("<robot ", '<robot xmlns:xacro="http://www.ros.org/wiki/xacro" ', 1).replace(
        "</robot>", '<xacro:macro name="hand" params="prefix"></xacro:macro>\n</robot>')
    for name in ("hand.urdf.xacro", "hand.urdf"):
        path = allegro_file.parent / f"xacro_{name}"
        path.write_text(macro)
        with pytest.raises(HandDescriptionError, match="xacro.*expand it first") as info:
            load_hand(path, spheres=False)
        assert info.value.field == "hand_description"
    expanded = allegro_file.parent / "expanded.urdf"
    expanded.write_text(text.replace("<robot ", '<robot xmlns:xacro="http://www.ros.org/wiki/xacro" ', 1).replace(
        "</robot>", '<!-- <xacro:hand prefix=""/> -->\n</robot>'))  # a macro call quoted in a comment
    assert [f.tip_link for f in load_hand(expanded, spheres=False).fingers] == \
        [f.tip_link for f in load_hand(allegro_file, spheres=False).fingers]


def test_a_linkage_closed_only_in_gazebo_is_refused_and_other_gazebo_elements_load(allegro_file):
    """Inspire's tactile hand closes its finger linkages with joints inside ``<gazebo>``
    elements (SDF joints between two of its links): the URDF tree alone leaves its linkage
    joints free. Such a file is refused, naming the loop-closing joints and what to give
    instead; ``<gazebo>`` elements that close no loop (a material, a plugin, a joint to the
    world) load."""
    text = allegro_file.read_text()
    loop = ('<gazebo><joint name="index_loop" type="revolute"><parent>palm</parent><child>index_middle</child>'
            '<axis>0 0 1</axis></joint></gazebo>\n')
    assert '<link name="palm">' in text and '<link name="index_middle">' in text
    closed = allegro_file.parent / "gazebo_closed.urdf"
    closed.write_text(text.replace("</robot>", loop + "</robot>"))
    with pytest.raises(HandDescriptionError, match=r"loops.*index_loop \(palm - index_middle\).*<mimic>") as info:
        load_hand(closed, spheres=False)
    assert info.value.field == "hand_description"
    harmless = ('<gazebo reference="palm"><material>Gazebo/Grey</material></gazebo>\n'
                '<gazebo><joint name="to_world" type="fixed"><parent>world</parent><child>palm</child></joint>'
                '<plugin name="p" filename="libp.so"/></gazebo>\n')
    opened = allegro_file.parent / "gazebo_open.urdf"
    opened.write_text(text.replace("</robot>", harmless + "</robot>"))
    assert [f.tip_link for f in load_hand(opened, spheres=False).fingers] == \
        [f.tip_link for f in load_hand(allegro_file, spheres=False).fingers]


def test_a_missing_collision_mesh_is_named_and_missing_visual_meshes_are_ignored(allegro_file, tmp_path):
    # The generated URDF's visual meshes (.dae) do not exist: it loads.
    assert not list(allegro_file.parent.rglob("*.dae"))
    edited = _edit(allegro_file, tmp_path, "meshes/ring_distal_0.stl", "meshes/gone.stl")
    with pytest.raises(HandDescriptionError, match="link ring_distal.*gone.stl not found") as info:
        load_hand(edited, spheres=False)
    assert "a file of that name" not in str(info.value)
    # An exporter's absolute path at the file system's root (the Linker L20's URDF): the
    # error names the file of that name in the description's meshes/ folder, and loads nothing.
    rooted = _edit(allegro_file, tmp_path, "package://allegro_like/meshes/ring_distal_0.stl", "/ring_distal_0.stl")
    with pytest.raises(HandDescriptionError, match=r"/ring_distal_0.stl not found \(a file of that name is at "
                                                   r".*meshes/ring_distal_0.stl: is the URDF's path wrong\?\)"):
        load_hand(rooted, spheres=False)


def test_a_git_lfs_pointer_instead_of_a_mesh_is_named(allegro_file, tmp_path):
    # A clone made without git-lfs holds pointer files where the meshes should be.
    pointer = allegro_file.parent / "meshes" / "lfs_pointer.stl"
    pointer.write_text("version https://git-lfs.github.com/spec/v1\noid sha256:615b48aa\nsize 7293684\n")
    edited = _edit(allegro_file, tmp_path, "meshes/ring_distal_0.stl", "meshes/lfs_pointer.stl")
    with pytest.raises(HandDescriptionError, match="link ring_distal.*lfs_pointer.stl is a Git LFS pointer"):
        load_hand(edited, spheres=False)


def test_a_collision_mesh_in_other_units_than_the_file_says_is_refused(allegro_file, tmp_path):
    # HOPE-Jr's URDF scales its STL files 0.1 where they need 0.0001: 27 m fingertips.
    edited = _edit(allegro_file, tmp_path, 'meshes/ring_distal_0.stl"/>', 'meshes/ring_distal_0.stl" scale="100 100 100"/>')
    with pytest.raises(HandDescriptionError, match=r"link ring_distal collision 0 \(ring_distal_0.stl\): .* m across, "
                                                   r"more than any part of a hand"):
        load_hand(edited, spheres=False)


def test_a_joint_without_limits_is_refused_and_continuous_joints_get_pi(allegro_file, tmp_path):
    edited = _edit(allegro_file, tmp_path, '<limit lower="-0.196" upper="1.61" effort="0.7" velocity="7"/>', "")
    with pytest.raises(HandDescriptionError, match="index_joint_1.*no limits") as info:
        load_hand(edited, spheres=False)
    assert info.value.field == "index_joint_1"
    cont = _edit(allegro_file, tmp_path, '<joint name="index_joint_0" type="revolute">',
                 '<joint name="index_joint_0" type="continuous">')
    hand = load_hand(cont, spheres=False)
    k = hand.actuated_joints.index("index_joint_0")
    assert (hand.lower[k], hand.upper[k]) == (-np.pi, np.pi)
    assert any("index_joint_0: continuous" in n for n in hand.notes)


def test_a_coupling_loop_is_refused(allegro_file, tmp_path):
    text = allegro_file.read_text()
    text = text.replace('<joint name="index_joint_2" type="revolute">',
                        '<joint name="index_joint_2" type="revolute"><mimic joint="index_joint_3"/>')
    text = text.replace('<joint name="index_joint_3" type="revolute">',
                        '<joint name="index_joint_3" type="revolute"><mimic joint="index_joint_2"/>')
    path = allegro_file.parent / "loop.urdf"
    path.write_text(text)
    with pytest.raises(HandDescriptionError, match="coupling loop"):
        load_hand(path, spheres=False)


def test_a_mimic_of_a_mimic_follows_its_chain_s_leader(allegro_file, tmp_path):
    """A follower that mimics another follower (LinkerHand L10's ``thumb_ip`` mimics
    ``thumb_mcp``, which mimics ``thumb_cmc_pitch``) moves with the chain's leader, its
    value the composition of the two couplings. Checked with yourdfpy on the file without
    the couplings, the chain's values set explicitly (yourdfpy itself follows no chain)."""
    import yourdfpy

    text = allegro_file.read_text()
    text = text.replace('<joint name="index_joint_2" type="revolute">',
                        '<joint name="index_joint_2" type="revolute"><mimic joint="index_joint_1" multiplier="0.8" '
                        'offset="0.05"/>')
    text = text.replace('<joint name="index_joint_3" type="revolute">',
                        '<joint name="index_joint_3" type="revolute"><mimic joint="index_joint_2" multiplier="1.1" '
                        'offset="-0.02"/>')
    path = allegro_file.parent / "chain.urdf"
    path.write_text(text)
    hand = load_hand(path, spheres=False)
    assert "index_joint_2" not in hand.actuated_joints and "index_joint_3" not in hand.actuated_joints
    # the leader's servo drives three joints: 1 + 0.8^2 + (1.1 * 0.8)^2 times an uncoupled one's gain
    assert hand.servo_weight[hand.actuated_joints.index("index_joint_1")] == pytest.approx(1 + 0.8 ** 2 + 0.88 ** 2)
    # ... and the leader itself moves farthest (1 against 0.8 and 0.88): its torque limit that many times too
    assert hand.servo_force_scale[hand.actuated_joints.index("index_joint_1")] == pytest.approx(1 + 0.8 ** 2 + 0.88 ** 2)
    plain = yourdfpy.URDF.load(str(allegro_file), load_meshes=False, build_collision_scene_graph=False,
                               load_collision_meshes=False)
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = np.clip(rng.uniform(hand.lower, hand.upper), hand.lower, hand.upper)
        q1 = float(np.clip(q[hand.actuated_joints.index("index_joint_1")], 0.0, 1.2))
        q[hand.actuated_joints.index("index_joint_1")] = q1
        cfg = dict(zip(hand.actuated_joints, map(float, q)))
        cfg["index_joint_2"] = 0.8 * q1 + 0.05
        cfg["index_joint_3"] = 1.1 * cfg["index_joint_2"] - 0.02
        plain.update_cfg({j: cfg.get(j, 0.0) for j in plain.actuated_joint_names})
        ours = hand.link_transforms(q)
        root = plain.get_transform(frame_to=hand.root_link, frame_from=plain.base_link)
        for link in ("index_middle", "index_distal", "index_tip"):
            want = np.linalg.inv(root) @ plain.get_transform(frame_to=link, frame_from=plain.base_link)
            np.testing.assert_allclose(ours[link], want, atol=1e-9, err_msg=link)


_MJCF = """<mujoco model="two">
  <asset>{assets}</asset>
  <worldbody>
    <body name="palm"><geom type="box" size="0.04 0.04 0.01"/>{visual}
      {fingers}
    </body>
  </worldbody>
</mujoco>"""
_FINGER = """<body name="f{i}_1" pos="{x} 0 0.01"><joint name="f{i}_j1" axis="0 1 0" range="0 1.5"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.04" size="0.008"/>
        <body name="f{i}_2" pos="0 0 0.04"><joint name="f{i}_j2" axis="0 1 0" range="0 1.5"/>
          <geom type="capsule" fromto="0 0 0 0 0 0.03" size="0.007"/>{tipmesh}</body></body>"""


def _mjcf(tmp_path, fingers: int, visual_missing=False, collision_missing=False) -> Path:
    assets, visual, tipmesh = "", "", ""
    if visual_missing:
        assets += '<mesh name="look" file="look.stl"/>'
        visual = '<geom type="mesh" mesh="look" contype="0" conaffinity="0"/>'
    if collision_missing:
        assets += '<mesh name="tip" file="tip.stl"/>'
        tipmesh = '<geom name="tipgeom" type="mesh" mesh="tip"/>'
    body = "\n".join(_FINGER.format(i=i, x=0.03 * (i - 0.5) * (1 if i % 2 else -1), tipmesh=tipmesh if i == 0 else "")
                     for i in range(fingers))
    path = tmp_path / f"two_{fingers}_{visual_missing}_{collision_missing}.xml"
    path.write_text(_MJCF.format(assets=assets, visual=visual, fingers=body))
    return path


def test_an_mjcf_using_materials_it_does_not_define_loads_and_simulates(tmp_path):
    """A hand file made to be included in a scene that defines its materials (an Inspire
    RH56DFTP's ``inspire_hand_right.xml``, included by its ``scene.xml``): MuJoCo refused the
    file alone ("material 'hand_white' not found"). A material only colours a geom: the
    geoms are drawn without it, with a note, and the hand loads and simulates as the same
    file with the materials defined."""
    from grasp_apso.model.builtin import builtin
    from grasp_apso.simulation.any_hand import prepare_any_hand

    defined = _mjcf(tmp_path, 2)
    text = defined.read_text()
    coloured = text.replace('<geom type="capsule" fromto="0 0 0 0 0 0.03" size="0.007"/>',
                            '<geom type="capsule" fromto="0 0 0 0 0 0.03" size="0.007" material="hand_dark"/>')
    coloured = coloured.replace('<geom type="box" size="0.04 0.04 0.01"/>',
                                '<geom type="box" size="0.04 0.04 0.01" material="hand_white"/>')
    undefined = tmp_path / "undefined_materials.xml"
    undefined.write_text(coloured)
    (tmp_path / "defined_materials.xml").write_text(coloured.replace(
        "<asset>", '<asset><material name="hand_dark" rgba="0.2 0.2 0.2 1"/><material name="hand_white"/>'))
    hand = load_hand(undefined, spheres=False)
    assert [n for n in hand.notes if n.startswith("material")] == [
        f"material {m}: not defined in the file (a scene including it defines it?): its geoms drawn without it"
        for m in ("hand_dark", "hand_white")]
    same = load_hand(tmp_path / "defined_materials.xml", spheres=False)
    assert not [n for n in same.notes if n.startswith("material")]
    assert hand.actuated_joints == same.actuated_joints
    assert [f.pad_center.tolist() for f in hand.fingers] == [f.pad_center.tolist() for f in same.fingers]
    sc, _ = prepare_any_hand(hand, builtin("sphere"), np.eye(4), np.eye(4), hand.open_configuration())
    assert sc.model.ngeom > 0


def test_a_urdf_mesh_in_a_folder_beside_the_urdfs_is_named(allegro_file, tmp_path):
    """An Inspire RH56DFTP URDF names its collision meshes as lying beside it
    (``right_base_link.obj``); they lie in ``../collision/``: the error names the file
    found in the tree above the URDF's folder, and loads nothing."""
    import shutil

    root = tmp_path / "Inspire_hand"
    (root / "urdf").mkdir(parents=True)
    shutil.copytree(allegro_file.parent / "meshes", root / "collision")
    urdf = root / "urdf" / "hand.urdf"
    urdf.write_text(allegro_file.read_text().replace('filename="meshes/', 'filename="'))
    with pytest.raises(HandDescriptionError, match=r"not found \(the URDF names \w+\.stl\) \(a file of that name "
                                                   r"is at .*Inspire_hand/collision/\w+\.stl: is the URDF's path wrong"):
        load_hand(urdf, spheres=False)


def test_a_closed_linkage_in_an_mjcf_is_noted(tmp_path):
    # A parallel gripper's four-bar (menagerie's Robotiq 2F-85): a connect equality closes a
    # loop the open-tree kinematics do not follow; the user is told when checking the hand.
    path = _mjcf(tmp_path, 2)
    text = path.read_text().replace("</mujoco>", '<equality><connect name="bar" body1="f0_2" body2="f1_2" '
                                    'anchor="0 0 0.03"/></equality>\n</mujoco>')
    path.write_text(text)
    hand = load_hand(path, spheres=False)
    assert [n for n in hand.notes if n.startswith("equality bar:")] == [
        "equality bar: connect of bodies f0_2 and f1_2 closes a kinematic loop, which is not modelled (the open "
        "chains are): the closing motion may not be the file's"]


def test_mjcf_meshes_fingers_and_size(tmp_path):
    hand = load_hand(_mjcf(tmp_path, 2, visual_missing=True), spheres=False)
    assert len(hand.fingers) == 2 and any("look.stl missing" in n for n in hand.notes)
    with pytest.raises(HandDescriptionError, match="tipgeom.*tip.stl not found") as info:
        load_hand(_mjcf(tmp_path, 2, collision_missing=True), spheres=False)
    assert "a file of that name" not in str(info.value)
    # the mesh lies in a folder of the description's tree its meshdir does not name (a
    # model file copied out of its folder): the error says where, and the meshdir to give
    (tmp_path / "robot" / "assets").mkdir(parents=True)
    trimesh.creation.box((0.01, 0.01, 0.01)).export(tmp_path / "robot" / "assets" / "tip.stl")
    with pytest.raises(HandDescriptionError, match=r"tip.stl not found \(a file of that name is at .*robot/assets/tip.stl: "
                       r'<compiler meshdir="robot/assets"/> would find it'):
        load_hand(_mjcf(tmp_path, 2, collision_missing=True), spheres=False)
    with pytest.raises(HandDescriptionError, match="fewer than two fingers"):
        load_hand(_mjcf(tmp_path, 1), spheres=False)
    with pytest.raises(HandDescriptionError, match="over the limit") as info:
        load_hand(_mjcf(tmp_path, 2), spheres=False, max_file_bytes=100)
    assert info.value.field == "hand_description"
    # A mesh over the limit (the file itself under it).
    path = _mjcf(tmp_path, 2, visual_missing=True)
    trimesh.creation.icosphere(subdivisions=3).export(tmp_path / "look.stl")
    limit = path.stat().st_size + 10
    assert (tmp_path / "look.stl").stat().st_size > limit
    with pytest.raises(HandDescriptionError, match="mesh look: look.stl is over the size limit"):
        load_hand(path, spheres=False, max_file_bytes=limit)


@pytest.mark.parametrize("change, outcome", [
    (('<joint name="f0_j1" axis="0 1 0" range="0 1.5"/>', '<joint name="f0_j1" axis="0 1 0"/>'),
     "note: joint f0_j1: continuous, range set to [-pi, pi]"),
    (('<joint name="f0_j1" axis="0 1 0" range="0 1.5"/>', '<joint name="f0_j1" type="slide" axis="0 1 0"/>'),
     "error: f0_j1.*no limits"),
    (('<joint name="f0_j1" axis="0 1 0" range="0 1.5"/>', '<joint name="f0_j1" type="ball"/>'),
     "error: f0_j1.*ball joints are not supported"),
    (('<body name="palm">', '<body name="palm"><freejoint name="float"/>'),
     "note: joint float: free joint of the hand's base, ignored"),
    (('<body name="palm">', '<body name="table" pos="1 0 0"><geom type="box" size="1 1 0.01"/></body><body name="palm">'),
     "note: body table: not part of the hand, ignored"),
])
def test_mjcf_joint_kinds(tmp_path, change, outcome):
    path = _mjcf(tmp_path, 2)
    text = path.read_text()
    assert change[0] in text
    path.write_text(text.replace(change[0], change[1], 1))
    kind, _, expected = outcome.partition(": ")
    if kind == "note":
        hand = load_hand(path, spheres=False)
        assert expected in hand.notes
        assert len(hand.fingers) == 2
    else:
        with pytest.raises(HandDescriptionError, match=expected):
            load_hand(path, spheres=False)


def test_slides_and_several_hinges_per_body_pose_as_mujoco_does(tmp_path):
    """The compiled forward kinematics (:mod:`grasp_apso.model.hands.fk_kernel`) on the
    motions the real hands lack: a slide joint, and a body carrying two hinges about
    off-origin anchors, checked against MuJoCo's own kinematics of the same file."""
    import mujoco

    path = _mjcf(tmp_path, 2)
    text = path.read_text()
    text = text.replace('<joint name="f0_j1" axis="0 1 0" range="0 1.5"/>',
                        '<joint name="f0_s" type="slide" axis="0.6 0 0.8" range="-0.01 0.02"/>'
                        '<joint name="f0_j1" axis="0 1 0" pos="0.003 0 0.005" range="0 1.5"/>', 1)
    text = text.replace('<joint name="f1_j2" axis="0 1 0" range="0 1.5"/>',
                        '<joint name="f1_j2" axis="0 1 0" pos="0 0.002 0.004" range="0 1.5"/>'
                        '<joint name="f1_j3" axis="1 0 0" pos="0.001 0 0.01" range="-0.5 0.5"/>', 1)
    path.write_text(text)
    hand = load_hand(path, spheres=False)
    assert {"f0_s", "f1_j3"} <= set(hand.actuated_joints)
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    q = np.random.default_rng(3).uniform(hand.lower, hand.upper, size=(12, hand.n_joints))
    batch = hand.link_transforms_batch(q)
    for k, row in enumerate(q):
        for name, value in zip(hand.joint_names, hand.full_positions(row)):
            data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
        mujoco.mj_kinematics(model, data)
        root = np.eye(4)
        root[:3, :3], root[:3, 3] = data.xmat[model.body("palm").id].reshape(3, 3), data.xpos[model.body("palm").id]
        for i, link in enumerate(hand.links):
            b = model.body(link).id
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = data.xmat[b].reshape(3, 3), data.xpos[b]
            np.testing.assert_allclose(batch[k, i], np.linalg.inv(root) @ pose, atol=1e-9, err_msg=link)


def test_a_joint_held_to_two_joints_by_mjcf_equalities_leads_them(tmp_path):
    """``f0_j1`` is ``joint1`` of two joint equalities, with ``f0_j2`` (a1 = 1) and ``f0_j3``
    (a1 = 2): MuJoCo constrains the pairs, so ``f0_j1`` leads both, each following it by the
    inverted relation, with a note (one of a Unitree G1 repository's Inspire hand files
    couples its thumb so). Before, the file was refused: "follows two joints"."""
    finger = """<body name="f{i}_1" pos="{x} 0 0.01"><joint name="f{i}_j1" axis="0 1 0" range="0 1.5"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.04" size="0.008"/>
        <body name="f{i}_2" pos="0 0 0.04"><joint name="f{i}_j2" axis="0 1 0" range="0 1.5"/>
          <geom type="capsule" fromto="0 0 0 0 0 0.03" size="0.007"/>
          <body name="f{i}_3" pos="0 0 0.03"><joint name="f{i}_j3" axis="0 1 0" range="0 1.5"/>
            <geom type="capsule" fromto="0 0 0 0 0 0.02" size="0.007"/></body></body></body>"""
    fingers = "\n".join(finger.format(i=i, x=0.015 * (1 if i else -1)) for i in range(2))
    path = tmp_path / "shared.xml"
    path.write_text(_MJCF.format(assets="", visual="", fingers=fingers).replace(
        "</mujoco>", '<equality><joint name="a" joint1="f0_j1" joint2="f0_j2" polycoef="0 1 0 0 0"/>'
                     '<joint name="b" joint1="f0_j1" joint2="f0_j3" polycoef="0 2 0 0 0"/></equality>\n</mujoco>'))
    hand = load_hand(path, spheres=False)
    got = {c.follower: (c.leader, c.multiplier, c.offset) for c in hand.couplings}
    assert got["f0_j2"] == ("f0_j1", 1.0, 0.0) and got["f0_j3"] == ("f0_j1", 0.5, 0.0), got
    assert "f0_j1" in hand.actuated_joints and not {"f0_j2", "f0_j3"} & set(hand.actuated_joints)
    assert any(n.startswith("joint f0_j1: joint1 of 2 joint equalities (a, b): it leads f0_j2, f0_j3")
               for n in hand.notes), hand.notes
