"""``simulate`` for a general hand holds a grasp only when it holds with DexGraspBench's
parameters too (:mod:`grasp_apso.search.any_hand_simulate`).

Real plans of the Allegro-like test hand (a URDF the tests write) on objects resting on a
table, each returned candidate replayed in MuJoCo from the reply alone (its wrist pose and
its three postures), once with the check's parameters and once with DexGraspBench's
(:meth:`~grasp_apso.simulation.settings.SimulationSettings.dexgraspbench`).
"""

from __future__ import annotations

import numpy as np
import pytest

from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.scene import Scene
from grasp_apso.search.planner import PlanOptions, plan
from grasp_apso.search.result import SIM_DROPPED, SIM_HELD
from grasp_apso.simulation.any_hand import simulate_any_hand
from grasp_apso.simulation.settings import DEXGRASPBENCH_PARAMETERS, SimulationSettings
from hand_files import write_allegro_like

#: A small swarm (as the other simulate tests) asking for two grasps.
OPTIONS = PlanOptions(particles=30, iterations=20, max_grasps=2, simulate=True)
#: The banana lying on a table, seed 2: its one returned grasp held with the check's
#: parameters and dropped with DexGraspBench's, and no grasp of its eight searches held in
#: both (found by a scan of 7 objects x seeds 0-2 with these options: the only such plan).
SOFTER_PLAN = ("banana", 2)


@pytest.fixture(scope="module")
def allegro(tmp_path_factory):
    return load_hand(write_allegro_like(tmp_path_factory.mktemp("hands"), "mixed"))


def _on_table(name: str):
    """A built-in or shipped object and a table under its lowest point."""
    from conftest import shipped_object

    obj = shipped_object(name)
    return obj, Scene.table_under(np.asarray(obj.mesh.vertices))


def _replay(hand, obj, table, cand, settings: SimulationSettings):
    """The reply's grasp simulated again from its own fields (not the planner's state)."""
    return simulate_any_hand(hand, obj, np.eye(4), cand.wrist_pose, cand.pre_grasp_positions, cand.joint_positions,
                             cand.squeeze_positions, table, OPTIONS.friction, settings=settings)


def test_the_dexgraspbench_settings_differ_from_the_checks_where_the_field_sets_them():
    ours, theirs = SimulationSettings(), SimulationSettings().dexgraspbench()
    assert set(DEXGRASPBENCH_PARAMETERS) == {"torsional_friction", "kp", "solref", "solimp", "hand_close_time",
                                             "hand_squeeze_time", "settle_time", "max_settle_time"}
    for name, value in DEXGRASPBENCH_PARAMETERS.items():
        assert getattr(theirs, name) == value
        assert getattr(ours, name) != value, name
    assert theirs.kp == 2.5 * ours.kp  # the stiffer servos a client may run the reply on
    assert (theirs.friction, theirs.max_shift, theirs.max_turn) == (ours.friction, ours.max_shift, ours.max_turn)


@pytest.mark.parametrize("name, seed", [("cube", 0), ("mug", 1)])
def test_every_grasp_reported_held_holds_with_both_parameter_sets(allegro, name, seed):
    obj, table = _on_table(name)
    result = plan(obj, options=OPTIONS, rng=np.random.default_rng(seed), hand=allegro, scene=table)
    held = [c for c in result.candidates if c.sim_result == SIM_HELD]
    assert held, [c.sim_result for c in result.candidates]
    for cand in held:
        for settings in (SimulationSettings(), SimulationSettings().dexgraspbench()):
            replay = _replay(allegro, obj, table, cand, settings)
            assert replay.held, (cand.id, settings.kp, replay.per_direction)


def test_a_grasp_that_holds_only_with_the_checks_parameters_is_reported_dropped(allegro):
    """It held in the check (a replay with its parameters holds), dropped with
    DexGraspBench's (a replay with them drops): the reply calls it dropped, gives the shift
    of the check it failed, and says why."""
    name, seed = SOFTER_PLAN
    obj, table = _on_table(name)
    result = plan(obj, options=OPTIONS, rng=np.random.default_rng(seed), hand=allegro, scene=table)
    assert "held with this check's servos and contacts but dropped with DexGraspBench's" in \
        result.candidates_message
    assert result.candidates and all(c.sim_result == SIM_DROPPED for c in result.candidates)
    softer = 0
    for cand in result.candidates:
        ours = _replay(allegro, obj, table, cand, SimulationSettings())
        theirs = _replay(allegro, obj, table, cand, SimulationSettings().dexgraspbench())
        assert not (ours.held and theirs.held), cand.id  # reported dropped: not held in both
        if ours.held:
            softer += 1
            assert not theirs.held
            assert cand.sim_max_shift == pytest.approx(theirs.max_shift)
            assert cand.sim_max_turn == pytest.approx(theirs.max_turn)
    assert softer >= 1
