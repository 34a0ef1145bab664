"""The MuJoCo check for any hand (issue 21.3): the Allegro-like URDF and the Shadow MJCF
compiled from their own files, the root held at the root pose, servos that reach a
posture, an empty grasp that drops, a power grasp around a ball whose verdict agrees with
where MuJoCo has the object after each disturbance, the table out of the disturbances.

Independent references: the URDF's own elements (ElementTree) and the MJCF compiled on
its own by MuJoCo for the geometry; the raw MuJoCo state (``data.xpos``, ``data.qpos``)
through the observer for the root, the joints and the object.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import replace

import mujoco
import numpy as np
import pytest
import trimesh

from grasp_apso.errors import InputError
from grasp_apso.model.builtin import builtin
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.objects import from_arrays
from grasp_apso.model.scene import Scene
from grasp_apso.simulation import SimulationSettings
from grasp_apso.simulation.any_hand import SimOutcome, prepare_any_hand, simulate_any_hand, squeezed_positions
from grasp_apso.simulation.any_hand_model import OBJECT_BODY
from hand_files import installed_hand, write_allegro_like

#: Shorter disturbances for most tests (the full protocol, under 1 s here, runs in one).
QUICK = SimulationSettings(duration=0.5)
FAR = np.eye(4)
FAR[:3, 3] = [5.0, 5.0, 5.0]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hands")
    return {"allegro": write_allegro_like(folder / "a", "mixed"),
            "allegro_coupled": write_allegro_like(folder / "b", "all", coupled=True),
            "shadow": installed_hand("shadow")}


@pytest.fixture(scope="module")
def hands(files):
    return {name: load_hand(path, spheres=False) for name, path in files.items()}


def _ball(radius: float):
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    return from_arrays(mesh.vertices, mesh.faces, f"ball{radius}")


def _rotation(axis, angle: float) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


ROOT = np.eye(4)
ROOT[:3, :3] = _rotation((1.0, 2.0, -0.5), 2.1)
ROOT[:3, 3] = [0.3, -0.2, 0.8]


def _power_grasp(hand, radius: float, root_pose: np.ndarray = np.eye(4)):
    """A ball against the palm, in front of the fingers' bases (the palm surface found by
    a MuJoCo ray along the palm normal), the fingers closing around it: the object, its
    pose in the world, and the open / grasp / squeeze postures."""
    q_open = hand.open_configuration()
    poses = hand.link_transforms(q_open)
    normal = np.asarray(hand.palm_normal)
    bases = np.mean([poses[hand.finger_links(f)[0]][:3, 3] for f in hand.fingers if not f.is_thumb], axis=0)
    sc, _ = prepare_any_hand(hand, builtin("sphere"), FAR, np.eye(4), q_open)
    start = bases + 0.15 * normal
    geom = np.zeros(1, np.int32)
    distance = mujoco.mj_ray(sc.model, sc.data, start, -normal, None, 1, -1, geom)
    assert 0 < distance < 0.15 and sc.model.geom_bodyid[geom[0]] == sc.root_body  # the palm itself
    local = np.eye(4)
    local[:3, 3] = start - distance * normal + (radius + 0.002) * normal
    # The cage 80 % closed, squeezed as the planner squeezes (a fully closed squeeze rolls
    # the ball past the turn limit in the Shadow hand, whose distal joints close to 1.57 rad)
    q_grasp = hand.closed_configuration(0.8)
    return _ball(radius), root_pose @ local, q_open, q_grasp, squeezed_positions(hand, q_grasp)


class Recorder:
    """Observer: the raw MuJoCo state after each phase and direction."""

    def __init__(self, root_body_name: str):
        self.root_name = root_body_name
        self.root: dict[str, np.ndarray] = {}
        self.object: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def __call__(self, phase, model, data):
        root = model.body(self.root_name).id
        pose = np.eye(4)
        pose[:3, :3] = data.xmat[root].reshape(3, 3)
        pose[:3, 3] = data.xpos[root]
        self.root[phase] = pose
        body = model.body(OBJECT_BODY).id
        self.object[phase] = (data.xipos[body].copy(), data.xmat[body].reshape(3, 3).copy())


def _independent_held(rec: Recorder, obj, obj_pose: np.ndarray, settings: SimulationSettings) -> bool:
    """Held by where MuJoCo has the object at the end of the squeeze and of every
    direction: within the shift and turn limits of the planned pose."""
    planned = obj_pose[:3, :3] @ obj.center_of_mass + obj_pose[:3, 3]
    for phase in ("squeezed", "+x", "-x", "+y", "-y", "+z", "-z"):
        if phase not in rec.object:
            return False
        pos, rot = rec.object[phase]
        turn = math.acos(np.clip((np.trace(obj_pose[:3, :3].T @ rot) - 1) / 2, -1.0, 1.0))
        if np.linalg.norm(pos - planned) >= settings.max_shift or turn >= settings.max_turn:
            return False
    return True


# ------------------------------------------------------------------------- geometry
def test_urdf_hand_keeps_its_own_links_and_collisions(hands, files):
    robot = ET.parse(files["allegro"]).getroot()
    links = {link.get("name"): len(link.findall("collision")) for link in robot.findall("link")}
    sc, _ = prepare_any_hand(hands["allegro"], builtin("sphere"), FAR, ROOT, hands["allegro"].open_configuration())
    m = sc.model
    bodies = {m.body(b).name for b in range(1, m.nbody)} - {OBJECT_BODY}
    assert bodies == set(links)
    for name, count in links.items():
        assert int(np.sum(m.geom_bodyid == m.body(name).id)) == count, name
    # A box of the file with its own size: the palm, 0.0408 x 0.113 x 0.095.
    palm = [g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body("palm").id]
    np.testing.assert_allclose(m.geom_size[palm[0]], [0.0204, 0.0565, 0.0475], atol=1e-9)
    assert m.nu == hands["allegro"].n_joints


def test_mjcf_hand_keeps_its_own_bodies_geoms_and_tendons(hands, files):
    ref = mujoco.MjModel.from_xml_path(str(files["shadow"]))
    hand = hands["shadow"]
    sc, _ = prepare_any_hand(hand, builtin("sphere"), FAR, ROOT, hand.open_configuration())
    m = sc.model

    def geoms_by_body(model, names):
        out = {}
        for g in range(model.ngeom):
            body = model.body(model.geom_bodyid[g]).name
            if body in names:
                out.setdefault(body, []).append((int(model.geom_type[g]), *np.round(model.geom_size[g], 9)))
        return {k: sorted(v) for k, v in out.items()}

    top = ref.body("robot0:hand mount").id
    hand_bodies = {ref.body(b).name for b in range(ref.nbody) if ref.body_rootid[b] == top}
    assert {m.body(b).name for b in range(1, m.nbody)} - {OBJECT_BODY} == hand_bodies
    assert geoms_by_body(m, hand_bodies) == geoms_by_body(ref, hand_bodies)
    # The distal couplings (limited fixed tendons) are kept; the wrist's tendons go with the
    # held wrist joints.
    ref_tendons = {ref.tendon(t).name for t in range(ref.ntendon)}
    tendons = {m.tendon(t).name for t in range(m.ntendon)}
    assert {"robot0:T_FFJ1c", "robot0:T_MFJ1c"} <= tendons <= ref_tendons
    assert not any("WRJ" in t for t in tendons)
    assert m.nu == hand.n_joints == 18


# ------------------------------------------------------------------------- the root and the servos
@pytest.mark.parametrize("name", ["allegro", "shadow"])
def test_root_stays_at_the_root_pose_through_the_protocol(hands, name):
    hand = hands[name]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    rec = Recorder(hand.root_link)
    simulate_any_hand(hand, obj, pose, ROOT, q_pre, q_grasp, q_squeeze, friction=0.5, settings=QUICK, observer=rec)
    assert {"pre_grasp", "grasp", "squeezed", "+x"} <= set(rec.root)
    for phase, root in rec.root.items():
        assert np.linalg.norm(root[:3, 3] - ROOT[:3, 3]) < 1e-3, phase
        assert np.abs(root[:3, :3] - ROOT[:3, :3]).max() < 1e-3, phase
    # The compiled model is cached: another root pose moves a copy, not the cached one.
    other = np.eye(4)
    other[:3, 3] = [-0.4, 0.1, 0.05]
    sc, _ = prepare_any_hand(hand, obj, pose, other, q_pre)
    np.testing.assert_allclose(sc.data.xpos[sc.root_body], other[:3, 3], atol=1e-9)
    np.testing.assert_allclose(sc.data.xmat[sc.root_body].reshape(3, 3), np.eye(3), atol=1e-9)
    np.testing.assert_allclose(sc.data.xpos[sc.model.body(OBJECT_BODY).id], pose[:3, 3], atol=1e-9)


def test_squeeze_goes_along_the_closing_senses(hands):
    hand = hands["shadow"]
    q = hand.closed_configuration(0.5)
    squeezed = squeezed_positions(hand, q)
    for finger in hand.fingers:
        for joint, sense in zip(finger.joints, finger.closing):
            j = hand.actuated_joints.index(joint)
            expected = np.clip(q[j] + sense * math.radians(8.0), hand.lower[j], hand.upper[j])
            assert squeezed[j] == pytest.approx(expected), joint
    assert np.any(squeezed != q)


@pytest.mark.parametrize("name", ["shadow", "adroit", "inspire", "fourier", "jaco", "robotiq_s"])
def test_every_joint_closes_in_mujoco_where_the_hand_model_puts_it(name):
    """The hand model against the hand's own simulation, followers included: from the open
    hand, servo targets a fifth and two fifths of the way closed, far from anything (no
    contact). A coupling the model reads otherwise than MuJoCo moves the joint (the Shadow
    hand's distal joints at the middle of their tendons' play: 0.14 rad) fails here."""
    hand = load_hand(installed_hand(name), spheres=False)
    for fraction in (0.2, 0.4):
        target = hand.closed_configuration(fraction)
        sc, settings = prepare_any_hand(hand, builtin("sphere"), FAR, ROOT, hand.open_configuration())
        sc.data.ctrl[:] = target
        mujoco.mj_step(sc.model, sc.data, nstep=int(round(2.0 / settings.timestep)))
        assert sc.data.ncon == 0  # nothing touches: only the servos and the couplings move the joints
        m, model_q = sc.model, hand.full_positions(target)
        moved = {j: sc.data.qpos[m.jnt_qposadr[m.joint(j).id]] - q for j, q in zip(hand.joint_names, model_q)
                 if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) >= 0}
        assert len(moved) >= len(hand.actuated_joints)
        worst = max(moved, key=lambda j: abs(moved[j]))
        assert abs(moved[worst]) < 0.04, (fraction, worst, moved[worst])


@pytest.mark.parametrize("name", ["allegro_coupled", "shadow"])
def test_servos_reach_a_commanded_posture(hands, name):
    hand = hands[name]
    sc, settings = prepare_any_hand(hand, builtin("sphere"), FAR, ROOT, hand.open_configuration())
    target = hand.closed_configuration(0.5)
    sc.data.ctrl[:] = target
    mujoco.mj_step(sc.model, sc.data, nstep=int(round(1.0 / settings.timestep)))
    m = sc.model
    reached = np.array([sc.data.qpos[m.jnt_qposadr[m.joint(j).id]] for j in hand.actuated_joints])
    assert np.abs(reached - target).max() < 0.05, dict(zip(hand.actuated_joints, reached - target))
    # Followers move with their leaders through the file's own couplings: an equality
    # (URDF mimic) holds, a limited tendon (the Shadow's distal joints) stays in its range.
    assert hand.couplings
    for c in hand.couplings:
        leader = sc.data.qpos[m.jnt_qposadr[m.joint(c.leader).id]]
        follower = sc.data.qpos[m.jnt_qposadr[m.joint(c.follower).id]]
        if c.source.startswith("tendon "):
            t = m.tendon(c.source.split(" ", 1)[1]).id
            low, high = m.tendon_range[t]
            assert low - 1e-3 <= sc.data.ten_length[t] <= high + 1e-3, c
            assert follower > 0.2  # it moved with its leader (0 in the open posture)
            # ... dragged along the edge of its play that the hand model follows (the
            # middle of the range, 0.14 rad further, leaves the fingertips off their contacts)
            assert abs(follower - (c.multiplier * leader + c.offset)) < 0.03, c
        else:
            assert abs(follower - (c.multiplier * leader + c.offset)) < 0.02, c


def test_a_coupled_leader_s_servo_holds_each_joint_it_drives_as_stiffly_as_an_uncoupled_one(hands):
    """The allegro-like hand's distal joints mimic its middle ones (multiplier 1): a middle
    joint's servo drives two joints, so its gain is twice an uncoupled joint's (1 + the sum
    of its followers' squared multipliers, from the file's couplings), as the squeeze
    assumes; held in its own angle the chain would be half as stiff."""
    hand = hands["allegro_coupled"]
    sc, settings = prepare_any_hand(hand, builtin("sphere"), FAR, ROOT, hand.open_configuration())
    leaders = {c.leader for c in hand.couplings}
    assert leaders
    for name in hand.actuated_joints:
        ratios = [1.0] + [abs(c.multiplier) for c in hand.couplings if c.leader == name]
        weight = sum(r ** 2 for r in ratios)
        servo = sc.model.actuator(f"servo:{name}")
        assert servo.gainprm[0] == pytest.approx(settings.kp * weight), name
        assert (weight == 2.0) == (name in leaders)
        # Its torque limit: the servo's torque t loads joint i with t r_i / sum r^2, so the
        # most loaded joint bears an uncoupled servo's limit when t = max_torque sum r^2 / max r.
        limit = settings.max_torque * weight / max(ratios)
        assert servo.forcerange == pytest.approx([-limit, limit]), name
        assert servo.forcelimited


def test_an_mjcf_s_coupled_leader_keeps_one_servo_s_torque_limit(hands):
    """The Shadow hand's MJCF couples each distal joint to its middle one by a fixed tendon
    and actuates the middle joint alone: that one actuator's limit bounds the chain (a URDF
    mimic joint bears an effort limit of its own, an MJCF tendon does not), while its gain
    is weighted as any coupled leader's."""
    hand = hands["shadow"]
    sc, settings = prepare_any_hand(hand, builtin("sphere"), FAR, ROOT, hand.open_configuration())
    leaders = {c.leader for c in hand.couplings}
    assert len(leaders) == 4 and not any(c.own_effort for c in hand.couplings)
    for name in hand.actuated_joints:
        servo = sc.model.actuator(f"servo:{name}")
        assert servo.forcerange == pytest.approx([-settings.max_torque, settings.max_torque]), name
        assert (servo.gainprm[0] > 1.5 * settings.kp) == (name in leaders), name


# ------------------------------------------------------------------------- verdicts
@pytest.mark.parametrize("name", ["allegro", "shadow"])
def test_empty_grasp_drops(hands, name):
    """The hand closes 20 cm away from the ball: nothing holds it."""
    hand = hands[name]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    away = pose.copy()
    away[:3, 3] += 0.2 * (ROOT[:3, :3] @ np.asarray(hand.palm_normal))
    rec = Recorder(hand.root_link)
    res = simulate_any_hand(hand, obj, away, ROOT, q_pre, q_grasp, q_squeeze, settings=QUICK, observer=rec)
    assert isinstance(res, SimOutcome)
    assert not res.held and not any(h for *_, h in res.per_direction)
    planned = away[:3, 3]
    assert np.linalg.norm(rec.object["squeezed"][0] - planned) < 1e-6  # untouched by the closing
    for d, *_ in res.per_direction:
        assert np.linalg.norm(rec.object[d][0] - planned) >= 0.05, d


def test_physics_that_blows_up_is_never_held(hands, monkeypatch, tmp_path):
    """Servos far too stiff for the time step blow the simulation up in the closing: MuJoCo
    resets the state, which puts the object back on its planned pose when that is where
    the compiled model has it (the identity here). The check must not read that as held."""
    from grasp_apso.simulation.phases import instabilities

    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warning log to the working directory
    hand = hands["shadow"]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    root = np.linalg.inv(pose) @ ROOT  # the same grasp, the object at the identity
    settings = SimulationSettings(pregrasp_fraction=1.0, hand_close_time=0.3, hand_squeeze_time=0.1, duration=0.2,
                                  kp=1e4, timestep=0.02, max_torque=1e3)
    seen: dict[str, int] = {}
    res = simulate_any_hand(hand, obj, np.eye(4), root, q_pre, q_grasp, q_squeeze, settings=settings,
                            observer=lambda phase, model, data: seen.setdefault(phase, instabilities(data)))
    assert seen["squeezed"] > 0  # it did blow up, before the disturbances
    assert not res.held and not any(h for *_, h in res.per_direction), res
    # the same grasp with sound servos holds (the failure above is the blow-up's)
    sound = replace(settings, kp=SimulationSettings().kp, timestep=SimulationSettings().timestep,
                    max_torque=SimulationSettings().max_torque)
    assert simulate_any_hand(hand, obj, np.eye(4), root, q_pre, q_grasp, q_squeeze, settings=sound).held


def test_no_joint_damping_is_a_setting_not_a_crash(hands):
    """``joint_damping`` 0 is within its range: the servos keep the gain as set (it raised
    ZeroDivisionError when the gain was matched to a damped joint's time constant)."""
    hand = hands["allegro"]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    res = simulate_any_hand(hand, obj, pose, ROOT, q_pre, q_grasp, q_squeeze,
                            settings=replace(QUICK, joint_damping=0.0, duration=0.1))
    assert len(res.per_direction) == 6


def test_table_takes_no_part_in_the_disturbance(hands):
    """The ball rests on a table far from the hand: the table does not stop a push down."""
    hand = hands["allegro"]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    away = pose.copy()
    away[:3, 3] += 0.2 * (ROOT[:3, :3] @ np.asarray(hand.palm_normal))
    table = Scene.table_under(np.asarray(obj.mesh.vertices) @ away[:3, :3].T + away[:3, 3])
    rec = Recorder(hand.root_link)
    res = simulate_any_hand(hand, obj, away, ROOT, q_pre, q_grasp, q_squeeze, scene=table, settings=QUICK,
                            observer=rec)
    down = dict((d, (s, h)) for d, s, _, h in res.per_direction)["-z"]
    assert not down[1] and down[0] >= 0.05
    assert rec.object["-z"][0][2] < away[2, 3] - 0.04  # below the table top


@pytest.mark.parametrize("name", ["allegro", "shadow"])
def test_power_grasp_verdict_matches_the_object_in_mujoco(hands, name):
    hand = hands[name]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    rec = Recorder(hand.root_link)
    # A caging posture (80 % closed), not a touching one: the fingers close from the open hand,
    # quickly (a slow wrap lets the ball roll out before the cage closes).
    settings = replace(QUICK, pregrasp_fraction=1.0, hand_close_time=0.3, hand_squeeze_time=0.1)
    res = simulate_any_hand(hand, obj, pose, ROOT, q_pre, q_grasp, q_squeeze, settings=settings, observer=rec)
    assert res.held == _independent_held(rec, obj, pose, settings), res
    if name == "shadow":  # the Shadow hand's fingers and thumb cage the ball against its palm
        assert res.held, res


def test_full_protocol_shadow_power_grasp_holds_and_is_deterministic(hands):
    hand = hands["shadow"]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    rec = Recorder(hand.root_link)
    # a caging posture: closing quickly from the open hand
    settings = SimulationSettings(pregrasp_fraction=1.0, hand_close_time=0.3, hand_squeeze_time=0.1)
    first = simulate_any_hand(hand, obj, pose, ROOT, q_pre, q_grasp, q_squeeze, settings=settings, observer=rec)
    second = simulate_any_hand(hand, obj, pose, ROOT, q_pre, q_grasp, q_squeeze, settings=settings)
    assert first.held and _independent_held(rec, obj, pose, settings), first
    assert first.per_direction == second.per_direction


def test_the_closing_starts_at_the_given_pre_grasp_by_default(hands):
    """The default protocol replays the candidate's own pre-grasp posture (the planner
    makes it a near one, DexGraspBench replays it as it is)."""
    hand = hands["shadow"]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    starts = []
    settings = replace(QUICK, duration=0.05, pregrasp_fraction=SimulationSettings().pregrasp_fraction)
    assert settings.pregrasp_fraction == 1.0
    simulate_any_hand(hand, obj, FAR, ROOT, q_pre, q_grasp, q_squeeze, settings=settings,
                      observer=lambda phase, model, data: starts.append(np.array(data.ctrl)) if phase == "pre_grasp"
                      else None)
    assert np.allclose(starts[0], q_pre, atol=1e-9)


def test_the_fingers_start_near_the_grasp_unless_that_is_inside_the_object(hands):
    """``pregrasp_fraction`` below 1: the closing starts that far from the grasp posture
    back to the pre-grasp when the hand is clear of the object there (the ball far away),
    and further back when a link would start inside it (a caging posture around a ball)."""
    hand = hands["shadow"]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    starts = {}

    def start_of(name):
        def observe(phase, model, data):
            if phase == "pre_grasp":
                starts[name] = np.array(data.ctrl, dtype=float)
        return observe

    settings = replace(QUICK, duration=0.05, pregrasp_fraction=0.25)
    simulate_any_hand(hand, obj, FAR, ROOT, q_pre, q_grasp, q_squeeze, settings=settings, observer=start_of("far"))
    simulate_any_hand(hand, obj, pose, ROOT, q_pre, q_grasp, q_squeeze, settings=settings, observer=start_of("caged"))
    quarter = q_grasp + settings.pregrasp_fraction * (q_pre - q_grasp)
    assert np.allclose(starts["far"], quarter, atol=1e-9)
    caged = starts["caged"]
    assert not np.allclose(caged, quarter, atol=1e-6)
    assert np.allclose(caged, q_grasp + 0.5 * (q_pre - q_grasp), atol=1e-9) or np.allclose(caged, q_pre, atol=1e-9)


def test_quick_check_is_deterministic(hands):
    hand = hands["allegro"]
    obj, pose, q_pre, q_grasp, q_squeeze = _power_grasp(hand, 0.03, ROOT)
    settings = replace(QUICK, duration=0.2)
    a = simulate_any_hand(hand, obj, pose, ROOT, q_pre, q_grasp, q_squeeze, settings=settings)
    b = simulate_any_hand(hand, obj, pose, ROOT, q_pre, q_grasp, q_squeeze, settings=settings)
    assert a.per_direction == b.per_direction


# ------------------------------------------------------------------------- inputs
def test_bad_inputs_name_the_field(hands):
    hand = hands["allegro"]
    q = hand.open_configuration()
    obj = builtin("sphere")
    with pytest.raises(InputError, match="q_grasp"):
        simulate_any_hand(hand, obj, FAR, ROOT, q, q[:-1], q)
    bad = q.copy()
    bad[1] = hand.upper[1] + 0.5
    with pytest.raises(InputError, match=f"q_pre: {hand.actuated_joints[1]}"):
        simulate_any_hand(hand, obj, FAR, ROOT, bad, q, q)
    with pytest.raises(InputError, match="root_pose"):
        simulate_any_hand(hand, obj, FAR, np.eye(3), q, q, q)
    with pytest.raises(InputError, match="obj"):
        simulate_any_hand(hand, "sphere", FAR, ROOT, q, q, q)
    with pytest.raises(InputError, match="friction"):
        simulate_any_hand(hand, obj, FAR, ROOT, q, q, q, friction=-1.0)
    from grasp_apso.model.hand import load_hand as load_paper_hand

    with pytest.raises(InputError, match="hand"):
        simulate_any_hand(load_paper_hand(), obj, FAR, ROOT, q, q, q)
    from grasp_apso.errors import TimeoutExceeded

    with pytest.raises(TimeoutExceeded):
        simulate_any_hand(hand, obj, FAR, ROOT, q, q, q, should_stop=lambda: True)


def test_urdf_with_unphysical_inertia_compiles(tmp_path):
    # Real URDFs (dex-urdf's Allegro) carry inertias with A + B < C, which MuJoCo refuses
    # unless asked to balance them.
    path = write_allegro_like(tmp_path, "none")
    root = ET.parse(path)
    link = next(l for l in root.getroot().iter("link") if l.get("name") == "index_proximal")
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "mass", value="0.05")
    ET.SubElement(inertial, "inertia", ixx="1e-6", iyy="1e-6", izz="1e-4", ixy="0", ixz="0", iyz="0")
    root.write(path)
    hand = load_hand(path, spheres=False)
    sc, _ = prepare_any_hand(hand, builtin("sphere"), FAR, np.eye(4), hand.open_configuration())
    inertia = sc.model.body_inertia[sc.model.body("index_proximal").id]
    assert sc.model.body_mass[sc.model.body("index_proximal").id] == pytest.approx(0.05)
    a, b, c = np.sort(inertia)
    assert a + b >= c * (1 - 1e-9)


def test_a_urdf_inertia_with_a_negative_moment_is_raised_and_simulates(tmp_path):
    """Wonik's Allegro Hand V5 URDF gives finger links an ixy about 1000 times too large (a
    principal moment of -5.7e-3 kg m^2), which MuJoCo refuses to compile and balanceinertia
    does not mend: the simulation drops the products of inertia and keeps the moments and
    the mass; the other links' inertias as written."""
    path = write_allegro_like(tmp_path, "none")
    root = ET.parse(path)
    for name, ixy in (("index_distal", "5.7e-03"), ("middle_distal", "0")):
        link = next(l for l in root.getroot().iter("link") if l.get("name") == name)
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "mass", value="0.0366")
        ET.SubElement(inertial, "inertia", ixx="3.8e-06", ixy=ixy, ixz="0", iyy="1.45e-05", iyz="0", izz="1.29e-05")
    root.write(path)
    hand = load_hand(path, spheres=False)
    sc, _ = prepare_any_hand(hand, builtin("sphere"), FAR, np.eye(4), hand.open_configuration())
    bad, good = sc.model.body("index_distal").id, sc.model.body("middle_distal").id
    assert sc.model.body_mass[bad] == pytest.approx(0.0366)
    assert np.sort(sc.model.body_inertia[good]) == pytest.approx([3.8e-06, 1.29e-05, 1.45e-05])
    a, b, c = np.sort(sc.model.body_inertia[bad])  # the file's moments, balanced (A + B >= C) by MuJoCo
    assert a > 0.0 and a + b >= c * (1 - 1e-9) and c < 2e-5
    q = hand.open_configuration()
    result = simulate_any_hand(hand, builtin("sphere"), np.eye(4), FAR, q, q, q, settings=QUICK)
    assert not result.held and np.isfinite(result.max_shift)  # it runs: an empty hand drops the sphere


def test_a_urdf_inertia_with_a_zero_moment_is_raised_and_simulates(tmp_path):
    """A CAD export rounding its inertias to 1e-6 leaves moments of zero (DexHand's URDF,
    ``iotdesignshop/dexhand_description``: ``ixx="1e-06" ... izz="0.0"`` on 12 finger links,
    all zero on two): MuJoCo refused the whole hand ("inertia must have positive
    eigenvalues") before its ``boundinertia`` could raise them, and ``simulate`` checked no
    grasp. The zero moment is raised to the simulation's floor about the same axes (a
    rotated one too), the others kept; an all-zero inertia is left to MuJoCo."""
    path = write_allegro_like(tmp_path, "none")
    root = ET.parse(path)
    c, s = math.cos(0.5), math.sin(0.5)  # the zero moment's axis turned 0.5 rad about z
    turned = 1e-6 * np.array([[s * s, -c * s, 0.0], [-c * s, c * c, 0.0], [0.0, 0.0, 1.0]])
    values = {"index_distal": dict(ixx="1e-06", ixy="-0.0", ixz="-0.0", iyy="1e-06", iyz="-0.0", izz="0.0"),
              "middle_distal": dict(ixx="0.0", ixy="0.0", ixz="0.0", iyy="0.0", iyz="0.0", izz="0.0"),
              "ring_distal": {k: repr(float(turned[i, j])) for k, (i, j) in
                              zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
                                  ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))}}
    for name, inertia in values.items():
        link = next(l for l in root.getroot().iter("link") if l.get("name") == name)
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "mass", value="0.016")
        ET.SubElement(inertial, "inertia", **inertia)
    root.write(path)
    hand = load_hand(path, spheres=False)
    sc, _ = prepare_any_hand(hand, builtin("sphere"), FAR, np.eye(4), hand.open_configuration())
    floor = 1e-8  # (the simulation's _MIN_INERTIA, MuJoCo's boundinertia)
    for name in values:
        body = sc.model.body(name).id
        assert sc.model.body_mass[body] == pytest.approx(0.016), name
        assert np.min(sc.model.body_inertia[body]) >= floor * (1 - 1e-9), name
    assert np.sort(sc.model.body_inertia[sc.model.body("index_distal").id]) == pytest.approx([floor, 1e-6, 1e-6])
    assert np.sort(sc.model.body_inertia[sc.model.body("ring_distal").id]) == pytest.approx([floor, 1e-6, 1e-6])
    q = hand.open_configuration()
    result = simulate_any_hand(hand, builtin("sphere"), np.eye(4), FAR, q, q, q, settings=QUICK)
    assert not result.held and np.isfinite(result.max_shift)  # it runs


def test_gazebo_tuned_joint_friction_and_damping_are_capped_and_the_fingers_close(tmp_path):
    """Wonik's Allegro V5 URDF gives its finger joints ``<dynamics friction>`` of 5-12 N m
    and damping of 3-10 N m s/rad (for its own 15 N m actuators): against this check's
    servos (``max_torque`` 1 N m) the fingers never moved, and the servo gain, raised with
    the damping to keep its time constant, was 100 times what the squeeze is computed for.
    Both are capped (``settings.max_joint_friction``, ``max_joint_damping``); smaller ones
    (the Shadow's friction 0.001) are kept; the servos then reach a commanded posture."""
    path = write_allegro_like(tmp_path, "none")
    root = ET.parse(path)
    for joint in root.getroot().iter("joint"):
        if joint.get("type") == "revolute":
            thumb = joint.get("name").startswith("thumb")
            ET.SubElement(joint, "dynamics", damping="0.3" if thumb else "10", friction="0.001" if thumb else "10")
    root.write(path)
    hand = load_hand(path, spheres=False)
    sc, settings = prepare_any_hand(hand, builtin("sphere"), FAR, ROOT, hand.open_configuration())
    m = sc.model
    dof = {j: m.jnt_dofadr[m.joint(j).id] for j in hand.actuated_joints}
    assert m.dof_frictionloss[dof["index_joint_1"]] == pytest.approx(settings.max_joint_friction)
    assert m.dof_frictionloss[dof["thumb_joint_1"]] == pytest.approx(0.001)
    assert m.dof_damping[dof["index_joint_1"]] == pytest.approx(settings.max_joint_damping)
    assert m.dof_damping[dof["thumb_joint_1"]] == pytest.approx(0.3)
    gain = m.actuator_gainprm[m.actuator("servo:index_joint_1").id, 0]
    assert gain == pytest.approx(settings.max_joint_damping / (settings.joint_damping / settings.kp))
    target = hand.closed_configuration(0.5)
    sc.data.ctrl[:] = target
    # (3 s: a servo at its torque limit against damping 1 turns at most 1 rad/s)
    mujoco.mj_step(m, sc.data, nstep=int(round(3.0 / settings.timestep)))
    reached = np.array([sc.data.qpos[m.jnt_qposadr[m.joint(j).id]] for j in hand.actuated_joints])
    assert np.abs(reached - target).max() < 0.05, dict(zip(hand.actuated_joints, reached - target))


def _two_fingers(model: str, palm_half_x: float = 0.04, first_from: float = 0.0, upper: float = 1.5,
                 defaults: str = "") -> str:
    """An MJCF hand: a palm box and two fingers of two hinges (capsules along +z at zero),
    mirrored about the palm's middle (angles in radians); ``first_from`` (m) where the first
    capsule starts above its hinge, ``upper`` (rad) the hinges' upper limit."""
    fingers = ""
    for k, (x, axis) in enumerate(((0.02, "0 1 0"), (-0.02, "0 -1 0"))):
        fingers += (f'      <body name="f{k}_1" pos="{x} 0 0.01"><joint name="f{k}_j1" axis="{axis}" range="0 {upper}"/>\n'
                    f'        <geom type="capsule" fromto="0 0 {first_from} 0 0 0.04" size="0.008"/>\n'
                    f'        <body name="f{k}_2" pos="0 0 0.04"><joint name="f{k}_j2" axis="{axis}" range="0 {upper}"/>\n'
                    '          <geom type="capsule" fromto="0 0 0 0 0 0.03" size="0.007"/></body></body>\n')
    return (f'<mujoco model="{model}">\n  <compiler angle="radian"/>\n{defaults}  <worldbody>\n'
            f'    <body name="palm"><geom type="box" size="{palm_half_x} 0.04 0.01"/>\n'
            + fingers + "    </body>\n  </worldbody>\n</mujoco>")


_MM_DEFAULTS = _two_fingers("mm_defaults", defaults='  <default><mesh scale="0.001 0.001 0.001"/><geom margin="0.01"/></default>\n')


def test_an_mjcfs_defaults_do_not_reach_the_object(tmp_path):
    # The ORCA hand's MJCF gives every mesh scale 0.001 by default (its STL files are in
    # mm): the object's parts, added to that file, came out 1000 times smaller and MuJoCo
    # refused the scene (an inertia without positive eigenvalues).
    path = tmp_path / "mm_defaults.xml"
    path.write_text(_MM_DEFAULTS)
    hand = load_hand(path, spheres=False)
    obj = builtin("sphere")
    sc, _ = prepare_any_hand(hand, obj, FAR, np.eye(4), hand.open_configuration())
    m = sc.model
    body = m.body(OBJECT_BODY).id
    geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] == body]
    verts = np.vstack([m.mesh_vert[m.mesh_vertadr[m.geom_dataid[g]]:][:m.mesh_vertnum[m.geom_dataid[g]]]
                       for g in geoms])
    np.testing.assert_allclose(np.ptp(verts, axis=0), obj.mesh.extents, rtol=0.02)
    assert all(m.geom_margin[g] == 0.0 for g in geoms)


_SWINGING = _two_fingers("swinging", palm_half_x=0.08, first_from=0.009, upper=2.2)


@pytest.mark.parametrize("ranges", ["open at zero", "bent open"])
def test_the_hands_links_collide_with_the_object_and_never_with_one_another(tmp_path, ranges):
    """MuJoCo collides a mesh as its convex hull, which reaches far beyond a concave link
    (DexHand's URDF: at its planned orange grasp a thumb base 21 mm inside a palm part's
    hull, two phalanges 7.6 mm inside each other's, the index finger held at 1 of its 22.5
    degrees, no finger on the object). The planner checks the hand against itself on its
    exact geometry, so the check leaves hand self-contacts out, whatever the posture: a first
    link swung into the palm it hinges on (LEAP's thumb base), a distal link bent into the
    palm, both fingers crossed into each other, and a hand whose open posture is already
    bent into its palm (joint ranges without 0); the servos then hold their targets. The
    object still collides with the links."""
    text = _SWINGING
    if ranges == "bent open":
        text = (text.replace('name="f0_j1" axis="0 1 0" range="0 2.2"', 'name="f0_j1" axis="0 1 0" range="0.8 2.2"')
                .replace('name="f0_j2" axis="0 1 0" range="0 2.2"', 'name="f0_j2" axis="0 1 0" range="2.0 2.2"'))
    path = tmp_path / "swinging.xml"
    path.write_text(text)
    hand = load_hand(path, spheres=False)
    sc, _ = prepare_any_hand(hand, builtin("sphere"), FAR, np.eye(4), hand.open_configuration())
    m, d = sc.model, sc.data
    hand_bodies = {m.body(n).id for n in ("palm", "f0_1", "f0_2", "f1_1", "f1_2")}

    def touching(q: dict) -> set:
        for name, value in q.items():
            d.qpos[m.jnt_qposadr[m.joint(name).id]] = value
        mujoco.mj_forward(m, d)
        return {frozenset((int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])))
                for c in d.contact[:d.ncon] if c.dist < 0}

    low = 0.8 if ranges == "bent open" else 0.0
    for q in ({"f0_j1": max(low, 1.5), "f0_j2": 2.0 if low else 0.0},   # the first link swung into the palm
              {"f0_j1": max(low, 0.8), "f0_j2": 2.0, "f1_j1": 0.8, "f1_j2": 2.0},  # distal links bent into it
              {"f0_j1": 2.2, "f0_j2": 2.2, "f1_j1": 2.2, "f1_j2": 2.2}):  # both fingers crossed
        assert not [pair for pair in touching(q) if pair <= hand_bodies], q
    # the servos hold a posture that crosses the fingers into the palm and each other
    target = {"f0_j1": 2.2, "f0_j2": 2.2, "f1_j1": 2.2, "f1_j2": 2.2}
    d.ctrl[:] = [target[j] for j in hand.actuated_joints]
    mujoco.mj_step(m, d, nstep=500)
    for name, value in target.items():
        assert d.qpos[m.jnt_qposadr[m.joint(name).id]] == pytest.approx(value, abs=0.02), name
    # the object (its centre at the distal link's joint: the 5 cm sphere holds the joint's
    # two links in part) still collides with them
    m2, d2 = sc.model, mujoco.MjData(sc.model)
    mujoco.mj_forward(m2, d2)
    obj = m2.body(OBJECT_BODY).id
    adr = m2.jnt_qposadr[m2.body_jntadr[obj]]
    d2.qpos[adr:adr + 3] = d2.xpos[m2.body("f1_2").id]
    mujoco.mj_forward(m2, d2)
    assert {frozenset((int(m2.geom_bodyid[c.geom1]), int(m2.geom_bodyid[c.geom2]))) for c in d2.contact[:d2.ncon]} \
        == {frozenset((obj, m2.body(n).id)) for n in ("f1_1", "f1_2")}


def test_a_urdf_with_collada_meshes_in_mm_loads_and_simulates(tmp_path):
    # ROS descriptions often give collision meshes as COLLADA files, whose <unit> says how
    # long a unit is (RViz applies it): the loader reads them in metres, and the simulation,
    # whose MuJoCo decodes no COLLADA, gets an STL copy of the same mesh.
    path = write_allegro_like(tmp_path, "mixed")
    stl = path.parent / "meshes" / "ring_distal_0.stl"
    reference = trimesh.load(stl, force="mesh")
    text = reference.copy().apply_scale(1000.0).export(file_type="dae")
    text = text.decode() if isinstance(text, bytes) else text
    assert "<asset>" in text and "<unit" not in text
    (path.parent / "meshes" / "ring_distal_0.dae").write_text(
        text.replace("<asset>", '<asset><unit meter="0.001" name="millimeter"/>', 1))
    path.write_text(path.read_text().replace("meshes/ring_distal_0.stl", "meshes/ring_distal_0.dae"))
    hand = load_hand(path, spheres=False)
    (geom,) = hand.collision["ring_distal"]
    np.testing.assert_allclose(geom.mesh.extents, reference.extents, rtol=1e-6)
    sc, _ = prepare_any_hand(hand, builtin("sphere"), FAR, np.eye(4), hand.open_configuration())
    m = sc.model
    body = m.body("ring_distal").id
    (g,) = [g for g in range(m.ngeom) if m.geom_bodyid[g] == body and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]
    d = m.geom_dataid[g]
    verts = m.mesh_vert[m.mesh_vertadr[d]:m.mesh_vertadr[d] + m.mesh_vertnum[d]]
    assert np.ptp(verts, axis=0).max() == pytest.approx(reference.extents.max(), rel=1e-3)



def _three_finger_mjcf(fused: bool) -> str:
    """Two fingers and a thumb on a box palm; with ``fused`` the palm's geom and the three
    fingers sit directly under <worldbody> (beside a floor and a light), as MuJoCo writes a
    URDF whose base link is fixed."""
    def finger(name, x, y, axis):
        return (f'<body name="{name}_proximal" pos="{x} {y} 0.01"><joint name="{name}_1" axis="{axis}" range="0 1.57"/>'
                f'<geom type="capsule" size="0.008 0.015" pos="0 0 0.015"/>'
                f'<body name="{name}_distal" pos="0 0 0.03"><joint name="{name}_2" axis="{axis}" range="0 1.57"/>'
                f'<geom type="capsule" size="0.008 0.012" pos="0 0 0.012"/></body></body>')
    fingers = (finger("index", 0.02, 0.02, "0 -1 0") + finger("middle", 0.02, -0.02, "0 -1 0")
               + finger("thumb", -0.02, 0.0, "0 1 0"))
    palm = '<geom name="palm" type="box" size="0.03 0.04 0.01"/>'
    world = ('<geom name="floor" type="plane" size="1 1 0.1" pos="0 0 -0.5"/><light pos="0 0 2"/>'
             + (palm + fingers if fused else f'<body name="palm">{palm}{fingers}</body>'))
    return f'<mujoco model="claw"><worldbody>{world}</worldbody></mujoco>'


def test_a_hand_whose_base_is_fused_into_the_world_is_the_same_hand(tmp_path):
    """MuJoCo writes a URDF with a fixed base link as its palm's geoms and its fingers
    directly under <worldbody>. Loaded, that hand is the one whose palm is a body: the same
    fingers, joints, closing senses, thumb, palm normal and link poses, its root the base
    lifted into a body; the simulation holds that root at the root pose, the floor left out."""
    based, fused = tmp_path / "based.xml", tmp_path / "fused.xml"
    based.write_text(_three_finger_mjcf(False))
    fused.write_text(_three_finger_mjcf(True))
    a, b = load_hand(based, spheres=False), load_hand(fused, spheres=False)
    assert a.root_link == "palm" and b.root_link == "claw_base"
    assert any("fused into the world body" in n and "claw_base" in n for n in b.notes), b.notes
    assert b.actuated_joints == a.actuated_joints
    assert [(f.tip_link, f.joints, f.closing, f.is_thumb) for f in b.fingers] == \
        [(f.tip_link, f.joints, f.closing, f.is_thumb) for f in a.fingers]
    assert sum(f.is_thumb for f in b.fingers) == 1
    np.testing.assert_allclose(b.palm_normal, a.palm_normal, atol=1e-9)
    q = np.random.default_rng(0).uniform(a.lower, a.upper)
    pa, pb = a.link_transforms(q), b.link_transforms(q)
    for link in pa:
        np.testing.assert_allclose(pb["claw_base" if link == "palm" else link], pa[link], atol=1e-12)
    sc, _ = prepare_any_hand(b, _ball(0.02), FAR, ROOT, b.open_configuration())
    m, d = sc.model, sc.data
    np.testing.assert_allclose(d.xpos[sc.root_body], ROOT[:3, 3], atol=1e-9)
    np.testing.assert_allclose(d.xmat[sc.root_body].reshape(3, 3), ROOT[:3, :3], atol=1e-9)
    palm = m.geom("palm").id
    assert m.geom_bodyid[palm] == sc.root_body
    np.testing.assert_allclose(d.geom_xpos[palm], ROOT[:3, 3], atol=1e-9)
    assert "floor" not in {m.geom(i).name for i in range(m.ngeom)}
