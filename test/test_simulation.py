"""MuJoCo check of a grasp (issue 13, part 2): known outcomes, determinism, inputs.

The postures come from seeded plans (particles 30, iterations 20); a tripod or a pinch
keeps the named fingers of the plan and opens the others (flexions 0). The pre-grasp is
the grasp posture opened by 0.4 rad on every flexion, clipped to the limits.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("mujoco")

from grasp_apso.model.hand import FINGER_NAMES, load_hand  # noqa: E402
from grasp_apso.search.planner import PlanOptions, plan  # noqa: E402
from grasp_apso.simulation import (  # noqa: E402
    ConvexSettings, SimResult, SimulationSettings, convex_parts, simulate_grasp,
)
from grasp_apso.simulation import convex as convex_module  # noqa: E402

try:
    from grasp_apso.model.objects import builtin
except ImportError:
    from grasp_apso.model.builtin import builtin


@pytest.fixture(scope="module")
def hand():
    return load_hand()


def _plan(name: str, seed: int):
    return plan(builtin(name), options=PlanOptions(particles=30, iterations=20), rng=np.random.default_rng(seed))


def _keep(q: np.ndarray, fingers: set[str]) -> np.ndarray:
    """Open (flexions 0) every finger not in ``fingers``."""
    q = np.array(q[:15], dtype=float)
    for f, name in enumerate(FINGER_NAMES):
        if name not in fingers:
            q[3 * f] = q[3 * f + 1] = 0.0
    return q


def _pre(hand, q: np.ndarray) -> np.ndarray:
    out = np.array(q[:15], dtype=float)
    out[0::3] -= 0.4
    out[1::3] -= 0.4
    return np.clip(out, hand.lower[:15], hand.upper[:15])


@pytest.fixture(scope="module")
def sphere_tripod(hand):
    """Seed 6 on the sphere: contacts of thumb, index, middle (and ring, opened here)."""
    result = _plan("sphere", 6)
    fingers = {c.finger for c in result.contacts}
    assert {"thumb", "index", "middle"} <= fingers
    return result


@pytest.fixture(scope="module")
def sphere_four(hand):
    """Seed 7 on the sphere: thumb, index, middle and ring; its own posture holds."""
    result = _plan("sphere", 7)
    assert {"thumb", "index", "middle", "ring"} <= {c.finger for c in result.contacts}
    return result


def test_four_finger_grasp_on_the_sphere_holds(hand, sphere_four):
    grasp = sphere_four.joint_positions[:15]
    res = simulate_grasp(hand, builtin("sphere"), np.eye(4), sphere_four.wrist_pose, _pre(hand, grasp), grasp)
    assert isinstance(res, SimResult)
    assert res.held, res
    assert [d[0] for d in res.per_direction] == ["+x", "-x", "+y", "-y", "+z", "-z"]
    assert res.max_shift < 0.05 and res.max_turn < math.radians(15)
    assert res.sim_time > 0


def test_tripod_that_rolls_the_sphere_while_closing_drops(hand, sphere_tripod):
    """Measured from the planned pose, the sphere turned 15 degrees by the closing fingers
    counts (DexGraspBench); from the squeezed state it held."""
    grasp = _keep(sphere_tripod.joint_positions, {"thumb", "index", "middle"})
    res = simulate_grasp(hand, builtin("sphere"), np.eye(4), sphere_tripod.wrist_pose, _pre(hand, grasp), grasp)
    assert not res.held, res
    assert res.max_turn >= math.radians(15) and res.max_shift < 0.05


def test_two_contacts_on_the_same_side_drop(hand, sphere_tripod):
    grasp = _keep(sphere_tripod.joint_positions, {"index", "middle"})
    res = simulate_grasp(hand, builtin("sphere"), np.eye(4), sphere_tripod.wrist_pose, _pre(hand, grasp), grasp)
    assert not res.held, res
    assert any(not held for *_, held in res.per_direction)


def test_open_hand_drops(hand, sphere_tripod):
    open_q = np.clip(np.zeros(15), hand.lower[:15], hand.upper[:15])
    res = simulate_grasp(hand, builtin("sphere"), np.eye(4), sphere_tripod.wrist_pose, open_q, open_q)
    assert not res.held
    # Nothing touches the object: the first direction already carries it away.
    assert res.per_direction[0][1] >= 0.05


def test_pinch_of_the_cube_holds(hand):
    result = _plan("cube", 8)
    by_finger = {c.finger: c for c in result.contacts}
    assert {"thumb", "index", "middle"} <= set(by_finger)
    # Opposite faces: thumb against index and middle.
    for finger in ("index", "middle"):
        assert float(np.dot(by_finger["thumb"].normal, by_finger[finger].normal)) < -0.9
    grasp = _keep(result.joint_positions, {"thumb", "index", "middle"})
    res = simulate_grasp(hand, builtin("cube"), np.eye(4), result.wrist_pose, _pre(hand, grasp), grasp)
    assert res.held, res


def test_the_closing_counts_and_the_check_is_deterministic(hand):
    """Seed 3's own grasp turns the sphere 18 degrees while closing: dropped even with no
    disturbance at all (the shift and turn are measured from the planned pose)."""
    result = _plan("sphere", 3)
    grasp = result.joint_positions[:15]
    args = (hand, builtin("sphere"), np.eye(4), result.wrist_pose, _pre(hand, grasp), grasp)
    first = simulate_grasp(*args)
    second = simulate_grasp(*args)
    assert not first.held, first
    assert first.per_direction == second.per_direction
    assert (first.max_shift, first.max_turn) == (second.max_shift, second.max_turn)
    still = simulate_grasp(*args, settings=SimulationSettings(disturbance=0.0))
    assert not still.held and still.max_turn >= math.radians(15), still


def test_support_plane_does_not_carry_the_object(hand, sphere_tripod):
    """Open hand, the sphere resting on a table (normal +z through its lowest point): the
    table takes part in the closing only, so pushing the sphere down (-z) carries it away
    as much as pushing it along +x (before issue 21 the table held it in -z)."""
    open_q = np.zeros(15)
    sphere = builtin("sphere")
    bottom = float(sphere.mesh.bounds[0, 2])  # about -0.025: the centre is at the origin
    table = np.array([[0.0, 0.0, 1.0, -bottom]])  # z - bottom >= 0 is free space
    res = simulate_grasp(hand, sphere, np.eye(4), sphere_tripod.wrist_pose, open_q, open_q, planes=table)
    by_name = {name: (shift, held) for name, shift, _, held in res.per_direction}
    assert not by_name["-z"][1] and by_name["-z"][0] >= 0.05
    assert not by_name["+x"][1]


def test_pose_of_the_object_is_honoured(hand, sphere_four):
    """Moving object and wrist together by a rigid transform gives the same verdict."""
    grasp = sphere_four.joint_positions[:15]
    move = np.eye(4)
    move[:3, 3] = [0.3, -0.2, 0.7]
    res = simulate_grasp(hand, builtin("sphere"), move, move @ sphere_four.wrist_pose, _pre(hand, grasp), grasp)
    assert res.held, res


def test_bad_inputs_name_the_field(hand, sphere_tripod):
    obj = builtin("sphere")
    q = np.zeros(15)
    with pytest.raises(ValueError, match="pose"):
        simulate_grasp(hand, obj, np.eye(3), sphere_tripod.wrist_pose, q, q)
    with pytest.raises(ValueError, match="wrist_pose"):
        simulate_grasp(hand, obj, np.eye(4), np.full((4, 4), np.nan), q, q)
    with pytest.raises(ValueError, match="grasp_q"):
        simulate_grasp(hand, obj, np.eye(4), sphere_tripod.wrist_pose, q, np.zeros(7))
    bad = q.copy()
    bad[1] = 3.0
    with pytest.raises(ValueError, match="pre_grasp_q: little_proximal"):
        simulate_grasp(hand, obj, np.eye(4), sphere_tripod.wrist_pose, bad, q)
    with pytest.raises(ValueError, match="planes"):
        simulate_grasp(hand, obj, np.eye(4), sphere_tripod.wrist_pose, q, q, planes=np.zeros((1, 4)))
    with pytest.raises(ValueError, match="settings.friction"):
        SimulationSettings(friction=-1.0)
    with pytest.raises(ValueError, match="settings.condim"):
        SimulationSettings(condim=5)


def test_convex_objects_are_not_decomposed(tmp_path, monkeypatch):
    monkeypatch.setenv("GRASP_APSO_CACHE", str(tmp_path))
    convex_module.clear_memory_cache()
    for name in ("sphere", "cube", "barrel"):
        assert len(convex_parts(builtin(name))) == 1
    assert not (tmp_path / "coacd").exists()  # hulls are not written to disk


def test_fish_is_decomposed_and_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("GRASP_APSO_CACHE", str(tmp_path))
    convex_module.clear_memory_cache()
    fish = builtin("fish")
    parts = convex_parts(fish)
    assert len(parts) >= 2
    files = list((tmp_path / "coacd").glob("*.npz"))
    assert len(files) == 1 and files[0].name.startswith(fish.mesh_hash)
    assert convex_parts(fish) is parts  # memory cache
    convex_module.clear_memory_cache()
    again = convex_parts(fish)  # disk cache
    assert len(again) == len(parts)
    for a, b in zip(again, parts):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="decomposition.threshold"):
        ConvexSettings(threshold=5.0)


def test_plan_with_simulate_fills_every_candidate_and_ranks_held_first():
    """PlanOptions.simulate: every candidate carries the MuJoCo verdict; held ones come first."""
    from grasp_apso.model.builtin import builtin
    from grasp_apso.search.planner import PlanOptions, plan
    from grasp_apso.search.result import SIM_DROPPED, SIM_HELD

    result = plan(builtin("sphere"), options=PlanOptions(particles=30, iterations=15, max_grasps=3, simulate=True),
                  rng=np.random.default_rng(3))
    assert len(result.candidates) >= 2
    verdicts = [c.sim_result for c in result.candidates]
    assert all(v in (SIM_HELD, SIM_DROPPED) for v in verdicts)
    assert all(np.isfinite(c.sim_max_shift) and np.isfinite(c.sim_max_turn) for c in result.candidates)
    # held first: no dropped candidate before a held one, and the quality is sorted
    assert verdicts == sorted(verdicts, reverse=True)
    quality = [c.grasp_quality for c in result.candidates]
    assert quality == sorted(quality, reverse=True)
    held = [c for c in result.candidates if c.sim_result == SIM_HELD]
    assert all(c.grasp_quality >= 0.5 for c in held)  # (4 held + c + f) / 8
