"""The closing of a general hand's grasp (issue 21.4): balanced squeezing forces
(:func:`grasp_apso.quality.closing.closing_forces`), the squeeze that exerts them
(:func:`grasp_apso.quality.closing.squeeze_toward_forces`), and what they change in a
seeded plan checked in MuJoCo (the Shadow hand, the cube on a table).

Independent references: hand-computed wrenches of simple contact sets; the pads' motion
from the hand's forward kinematics (not the Jacobian under test); MuJoCo's object state
after the squeeze (observer) for the uniform and the balanced squeeze.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from grasp_apso.model.builtin import builtin
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.scene import Scene
from grasp_apso.quality.closing import CONE_SHARE, FLOOR, balanced_forces, closing_forces, squeeze_toward_forces
from grasp_apso.quality.robustness import robust_epsilon
from grasp_apso.search.any_hand_select import MAX_IMBALANCE
from grasp_apso.search.options import PlanOptions
from grasp_apso.search.planner import plan
from grasp_apso.search.result import SIM_HELD
from grasp_apso.simulation.any_hand import simulate_any_hand, squeezed_positions
from grasp_apso.simulation.phases import angle_between, planned_reference
from hand_files import installed_hand, write_allegro_like


def test_antipodal_contacts_balance_with_equal_forces():
    points = np.array([[0.03, 0.0, 0.0], [-0.03, 0.0, 0.0]])
    normals = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    forces, imbalance = closing_forces(points, normals, np.zeros(3), 0.03, mean_force=2.0)
    assert imbalance < 1e-6
    assert forces == pytest.approx([2.0, 2.0], abs=1e-6)


def test_contacts_on_one_side_cannot_balance():
    points = np.array([[0.03, y, 0.0] for y in (-0.01, 0.0, 0.01)])
    normals = np.tile([1.0, 0.0, 0.0], (3, 1))  # every finger pushes along -x
    forces, imbalance = closing_forces(points, normals, np.zeros(3), 0.03, mean_force=2.0)
    assert imbalance > 0.99
    assert np.all(forces >= FLOOR * 2.0 - 1e-9)


def test_offset_pair_leaves_a_torque():
    # Opposed forces on parallel lines 2 cm apart: the net force cancels, a couple stays.
    points = np.array([[0.03, 0.01, 0.0], [-0.03, -0.01, 0.0]])
    normals = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    forces, imbalance = closing_forces(points, normals, np.zeros(3), 0.03, mean_force=1.0)
    torque = np.cross(points[0], -forces[0] * normals[0]) + np.cross(points[1], -forces[1] * normals[1])
    assert imbalance == pytest.approx(np.linalg.norm(torque) / 0.03 / forces.sum(), rel=1e-6)
    assert imbalance > 0.2


def _tilted_pair(degrees: float) -> tuple[np.ndarray, np.ndarray]:
    """Two contacts on a 3 cm circle, ``180 - degrees`` apart: their normal forces miss
    each other by ``degrees``."""
    a = np.radians([0.0, 180.0 - degrees])
    points = 0.03 * np.stack([np.cos(a), np.sin(a), np.zeros(2)], axis=1)
    return points, points / 0.03


def test_friction_balances_a_pair_the_normal_forces_cannot():
    points, normals = _tilted_pair(20.0)  # 10 degrees each side: inside the narrowed cone (16.7 degrees)
    assert closing_forces(points, normals, np.zeros(3), 0.03, mean_force=4.0)[1] > 0.1
    forces, imbalance = balanced_forces(points, normals, np.zeros(3), 0.03, mu=0.5, mean_force=4.0)
    # (the tangential parts are weighed against the balance: nearly, not exactly, zero)
    assert imbalance < 0.01
    # the net wrench recomputed from the returned vectors, independently of the solver's rows
    assert np.linalg.norm(forces.sum(axis=0)) < 0.01 * 8.0
    assert np.linalg.norm(np.cross(points, forces).sum(axis=0)) < 1e-8
    normal = np.einsum("ij,ij->i", forces, -normals)
    tangential = np.linalg.norm(forces + normal[:, None] * normals, axis=1)
    assert normal.mean() == pytest.approx(4.0, rel=0.01)
    assert np.all(tangential <= CONE_SHARE * 0.5 * normal + 1e-9)  # each inside its narrowed cone


def test_friction_is_used_only_as_the_balance_needs_it():
    forces, imbalance = balanced_forces(*_tilted_pair(0.0), np.zeros(3), 0.03, mu=0.5, mean_force=4.0)
    assert imbalance < 1e-9
    assert forces == pytest.approx(np.array([[-4.0, 0.0, 0.0], [4.0, 0.0, 0.0]]), abs=1e-6)  # along the normals


def test_friction_cannot_balance_a_pair_beyond_the_cone():
    points, normals = _tilted_pair(60.0)  # 30 degrees each side: outside even the full cone (26.6)
    assert balanced_forces(points, normals, np.zeros(3), 0.03, mu=0.5, mean_force=4.0)[1] > 0.05


@pytest.fixture(scope="module")
def allegro(tmp_path_factory):
    return load_hand(write_allegro_like(tmp_path_factory.mktemp("a"), "none"), spheres=False)


def test_squeeze_pushes_each_pad_into_the_surface(allegro):
    hand = allegro
    q = 0.5 * (np.asarray(hand.lower) + np.asarray(hand.upper))
    poses = hand.link_transforms(q)
    fingers = np.arange(len(hand.fingers))
    pads = np.array([(poses[f.pad_link] @ np.append(f.pad_center, 1.0))[:3] for f in hand.fingers])
    centre = pads.mean(axis=0)
    normals = (pads - centre) / np.linalg.norm(pads - centre, axis=1, keepdims=True)  # outward from the middle
    kp = 50.0  # stiff servos: a small, nearly linear step
    squeezed = squeeze_toward_forces(hand, q, fingers, pads, normals, np.full(len(pads), 1.0), kp)
    moved = hand.link_transforms(squeezed)
    for f, finger in enumerate(hand.fingers):
        shift = (moved[finger.pad_link] @ np.linalg.inv(poses[finger.pad_link]) @ np.append(pads[f], 1.0))[:3] - pads[f]
        assert np.dot(shift, -normals[f]) > 0.5 * np.linalg.norm(shift) > 0.0, finger.name  # mostly inward
        others = [hand.actuated_joints.index(j) for g in hand.fingers if g is not finger for j in g.joints
                  if j not in finger.joints]
        # each finger's step comes from its own force only: zero force elsewhere, same step
        alone = squeeze_toward_forces(hand, q, fingers[f:f + 1], pads[f:f + 1], normals[f:f + 1], [1.0], kp)
        assert np.allclose(alone[others], q[others])
    assert np.all(squeezed >= np.asarray(hand.lower) - 1e-12) and np.all(squeezed <= np.asarray(hand.upper) + 1e-12)
    # the same forces given as vectors along -n squeeze the same
    vectors = squeeze_toward_forces(hand, q, fingers, pads, normals, -1.0 * normals, kp)
    assert np.allclose(vectors, squeezed)


def test_each_joint_s_torque_is_clipped_to_its_own_servo_s_limit(allegro):
    """``max_torque`` per joint (a coupled leader's servo may exert more,
    ``HandModel.servo_force_scale``): a joint's step is its clipped torque over its gain,
    the others' as with no limit."""
    hand = allegro
    q = 0.5 * (np.asarray(hand.lower) + np.asarray(hand.upper))
    finger = hand.fingers[0]
    pad = (hand.link_transforms(q)[finger.pad_link] @ np.append(finger.pad_center, 1.0))[:3]
    normal = np.array([0.0, 0.0, 1.0])
    kp = 50.0
    free = squeeze_toward_forces(hand, q, [0], pad[None], normal[None], [20.0], kp)
    torque = (free - q) * kp  # (no joint at its limit: mid-range posture, a small step)
    loaded = int(np.argmax(np.abs(torque)))
    assert abs(torque[loaded]) > 0.1
    limits = np.full(len(q), 1e3)
    limits[loaded] = 0.25 * abs(torque[loaded])
    clipped = squeeze_toward_forces(hand, q, [0], pad[None], normal[None], [20.0], kp, max_torque=limits)
    assert (clipped[loaded] - q[loaded]) * kp == pytest.approx(np.sign(torque[loaded]) * limits[loaded])
    others = np.arange(len(q)) != loaded
    assert clipped[others] == pytest.approx(free[others])
    # one scalar limit clips every joint alike
    scalar = squeeze_toward_forces(hand, q, [0], pad[None], normal[None], [20.0], kp, max_torque=limits[loaded])
    assert np.all(np.abs(scalar - q) * kp <= limits[loaded] + 1e-9)


@pytest.fixture(scope="module")
def shadow_cube():
    hand = load_hand(installed_hand("shadow"))
    obj = builtin("cube")
    scene = Scene.table_under(np.asarray(obj.mesh.vertices))
    result = plan(obj, np.eye(4), PlanOptions(particles=30, iterations=20), np.random.default_rng(0), hand=hand,
                  scene=scene)
    return hand, obj, scene, result


def _squeezed_state(hand, obj, scene, cand, squeeze):
    ref_pos, ref_quat = planned_reference(np.eye(4), obj.center_of_mass)
    seen = {}

    def observe(phase, model, data):
        if phase == "squeezed":
            b = model.body("grasp_object").id
            seen["shift"] = float(np.linalg.norm(data.xipos[b] - ref_pos))
            seen["turn"] = angle_between(ref_quat, data.xquat[b])

    simulate_any_hand(hand, obj, np.eye(4), cand.wrist_pose, cand.pre_grasp_positions, cand.joint_positions,
                      squeeze, scene, 0.5, observer=observe, stop_at_first_failure=True)
    return seen["shift"], seen["turn"]


def test_balanced_squeeze_shoves_the_object_less_than_the_uniform_one(shadow_cube):
    hand, obj, scene, result = shadow_cube
    balanced, uniform = [], []
    for cand in result.candidates:
        balanced.append(_squeezed_state(hand, obj, scene, cand, cand.squeeze_positions))
        uniform.append(_squeezed_state(hand, obj, scene, cand, squeezed_positions(hand, cand.joint_positions)))
    b_shift, b_turn = np.array(balanced).T
    u_shift, u_turn = np.array(uniform).T
    # Measured (seed 0): the uniform 8 degree squeeze shoves the cube 7-28 mm and turns it up
    # to 14 degrees before any disturbance; the balanced one about a third of that.
    assert b_shift.sum() < 0.6 * u_shift.sum()
    assert b_turn.max() < math.radians(15.0)
    assert b_turn.sum() < u_turn.sum()


def test_balanced_robust_grasps_rank_first(shadow_cube):
    hand, obj, scene, result = shadow_cube
    flags = []
    for cand in result.candidates:
        p = np.array([c.position for c in cand.contacts])
        n = np.array([c.normal for c in cand.contacts])
        imbalance = closing_forces(p, n, obj.center_of_mass, obj.characteristic_radius)[1]
        robust = robust_epsilon(obj, p, n, mu=0.5, torque_scale=float(obj.characteristic_radius)) \
            if cand.force_closure else 0.0
        flags.append(bool(cand.force_closure and robust > 0.0 and imbalance <= MAX_IMBALANCE))
    assert flags[0]
    assert flags == sorted(flags, reverse=True)  # no balanced grasp after an unbalanced one


def test_simulate_puts_a_held_grasp_first_on_the_shadow_hand(shadow_cube):
    hand, obj, scene, _ = shadow_cube
    result = plan(obj, np.eye(4), PlanOptions(particles=30, iterations=20, simulate=True), np.random.default_rng(0),
                  hand=hand, scene=scene)
    best = result.candidates[0]
    assert best.sim_result == SIM_HELD
    again = simulate_any_hand(hand, obj, np.eye(4), best.wrist_pose, best.pre_grasp_positions, best.joint_positions,
                              best.squeeze_positions, scene, 0.5)
    assert again.held and again.max_turn < math.radians(15.0) and again.max_shift < 0.05


def test_squeeze_takes_up_a_pad_gap_along_the_normal(allegro):
    hand = allegro
    q = 0.5 * (np.asarray(hand.lower) + np.asarray(hand.upper))
    poses = hand.link_transforms(q)
    finger = hand.fingers[0]
    pad = (poses[finger.pad_link] @ np.append(finger.pad_center, 1.0))[:3]
    normal = -np.asarray(hand.palm_normal, float)  # any direction the finger can reach along
    for gap in (0.002, -0.002):  # 2 mm short of the surface, 2 mm deep in it
        squeezed = squeeze_toward_forces(hand, q, [0], pad[None], normal[None], [0.0], kp=2.0, gaps=[gap])
        moved = hand.link_transforms(squeezed)[finger.pad_link] @ np.linalg.inv(poses[finger.pad_link])
        shift = (moved @ np.append(pad, 1.0))[:3] - pad
        assert np.dot(shift, -normal) == pytest.approx(gap, rel=0.15)


def test_opened_pre_grasp_moves_closing_joints_to_their_opening_limits(allegro):
    from grasp_apso.search.any_hand_select import opened

    hand = allegro
    q = 0.5 * (np.asarray(hand.lower) + np.asarray(hand.upper))
    wide = opened(hand, q, 1.0)
    assert np.array_equal(opened(hand, q, 0.0), q)
    for finger in hand.fingers:
        for joint, sense in zip(finger.joints, finger.closing):
            j = hand.actuated_joints.index(joint)
            expected = q[j] if sense == 0 else (hand.lower[j] if sense > 0 else hand.upper[j])
            assert wide[j] == pytest.approx(expected), joint


def test_hold_score_orders_fragile_grasps_by_epsilon_not_fitness():
    from grasp_apso.quality.closure_proof import Epsilon
    from grasp_apso.search.any_hand_select import AnyChecked, hold_score

    def checked(fitness, epsilon, robust, imbalance, closure=True):
        return AnyChecked(None, fitness, True, True, 0.01, None, imbalance=imbalance,
                          closure=Epsilon.known(epsilon if closure else 0.0), robust=Epsilon.known(robust))

    # The Allegro hand's bowl (seed 0): no grasp robust; the fittest had the smallest epsilon
    # and dropped, the next ones held.
    fragile = [checked(0.610, 0.009, 0.0, 0.58), checked(0.585, 0.048, 0.0, 0.30), checked(0.584, 0.019, 0.0, 0.32)]
    assert list(np.argsort(-hold_score(fragile))) == [1, 2, 0]
    # robust grasps keep their robust epsilon; without force closure the score is the fitness share only
    robust = [checked(0.9, 0.2, 0.01, 0.1), checked(0.5, 0.05, 0.04, 0.1)]
    assert list(np.argsort(-hold_score(robust))) == [1, 0]
    none = hold_score([checked(0.9, 0.3, 0.0, 0.0, closure=False)])
    assert none[0] == pytest.approx(0.01 * 0.9)



def _closing_problem(rng, n):
    """A closing_forces problem of n random contacts: (7, n) rows, target, bounds."""
    p = rng.normal(size=(n, 3)) * 0.04
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    a = np.vstack([u.T, (np.cross(p, u) / 0.04).T, np.ones((1, n)) / n])
    b = np.zeros(7)
    b[6] = 2.4
    return a, b, FLOOR * 2.4, 3.0 * 2.4


@pytest.mark.parametrize('shape', ['closing', 'cone edges', 'random', 'rank deficient'])
def test_the_compiled_bounded_least_squares_is_scipys(shape):
    """``bounded_lsq`` against SciPy's ``lsq_linear(method="bvls")`` (the reference it
    replaces) on 300 problems of each shape the closing solves (a column per contact; eight
    per contact, more columns than rows) and of random ones: the same solution to 1e-12,
    with bounds active in most (SciPy's BVLS loops exercised, not only its first solve)."""
    from scipy.optimize import lsq_linear

    from grasp_apso.quality.bounded_lsq import bounded_lsq

    rng = np.random.default_rng(21)
    active = 0
    for _ in range(300):
        n = int(rng.integers(2, 7))
        if shape == 'closing':
            a, b, lb, ub = _closing_problem(rng, n)
        elif shape == 'cone edges':
            a = rng.normal(size=(6 + 3 * n + 1, 8 * n))
            b = np.zeros(len(a))
            b[-1] = 2.4
            lb, ub = FLOOR * 2.4 / 8, 3.0 * 2.4 / 8
        elif shape == 'random':
            a, b, lb, ub = rng.normal(size=(7, n)), 3.0 * rng.normal(size=7), -0.5, 1.0
        else:  # two equal columns: the solution is not unique; both take the least-norm steps
            a = rng.normal(size=(7, n))
            a[:, -1] = a[:, 0]
            b, lb, ub = 3.0 * rng.normal(size=7), -0.5, 1.0
        expected = lsq_linear(a, b, bounds=(lb, ub), method='bvls').x
        got = bounded_lsq(a, b, lb, ub)
        np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-12)
        active += bool(np.any(np.isclose(expected, lb) | np.isclose(expected, ub)))
    assert active >= 150, active


def test_the_bounded_least_squares_names_bad_input():
    from grasp_apso.quality.bounded_lsq import bounded_lsq

    with pytest.raises(ValueError, match='a, b'):
        bounded_lsq(np.ones((3, 2)), np.ones(2), 0.0, 1.0)
    with pytest.raises(ValueError, match='lb, ub'):
        bounded_lsq(np.ones((3, 2)), np.ones(3), 1.0, 1.0)
