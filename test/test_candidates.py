"""Ranked, distinct candidates (issue 12): the leaders' archive, the ranking, the list."""

from __future__ import annotations

import math

import numpy as np
import pytest

from grasp_apso.model.builtin import builtin
from grasp_apso.search.archive import LeaderArchive, distinct_mask, wrist_groups
from grasp_apso.search.planner import PlanOptions, plan
from grasp_apso.search.ranking import grasp_quality

OPTIONS = {"particles": 24, "iterations": 15}


def _rz(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(a.T @ b) - 1.0) / 2.0, -1.0, 1.0)))


def test_distinct_mask_keeps_the_fittest_of_each_neighbourhood():
    gap_o, gap_p = math.radians(20), 0.015
    rot = np.stack([_rz(0.0), _rz(math.radians(10)), _rz(math.radians(25)), _rz(0.0), _rz(0.0)])
    pos = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0.02, 0, 0], [0.01, 0, 0]], dtype=float)
    fitness = np.array([0.5, 0.9, 0.4, 0.3, 0.8])
    keep = distinct_mask(rot, pos, fitness, 10, gap_o, gap_p)
    # 1 (0.9) suppresses 0 (10 deg, same place) and 4 (10 deg, 1 cm); 2 is 15 deg from 1
    # -> suppressed too; 3 is 2 cm away -> kept.
    assert keep.tolist() == [False, True, False, True, False]
    assert distinct_mask(rot, pos, fitness, 1, gap_o, gap_p).tolist() == [False, True, False, False, False]


def test_wrist_groups_number_groups_and_members_in_order():
    """Each wrist joins the first earlier leader it is not distinct from (within both
    gaps), else leads a new group; members are counted within their group."""
    gap_o, gap_p = math.radians(20), 0.015
    rot = np.stack([_rz(0.0), _rz(math.radians(10)), _rz(math.radians(25)), _rz(0.0), _rz(math.radians(30)),
                    _rz(math.radians(5))])
    pos = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0.02, 0, 0], [0, 0, 0], [0.001, 0, 0]], dtype=float)
    group, member = wrist_groups(rot, pos, gap_o, gap_p)
    # 1 joins 0 (10 deg); 2 is 25 deg from 0: a new group, which 4 (5 deg from 2) joins;
    # 3 is 2 cm away: a new group; 5 (5 deg, 1 mm) joins 0
    assert group.tolist() == [0, 0, 1, 2, 1, 0]
    assert member.tolist() == [0, 1, 0, 0, 1, 2]


def test_archive_is_bounded_sorted_and_ignores_inactive():
    arc = LeaderArchive(3, math.radians(20), 0.015)
    wrist = np.tile(np.eye(4), (6, 1, 1))
    wrist[:, 0, 3] = np.arange(6) * 0.05  # all distinct
    x = np.arange(6, dtype=float)[:, None] * np.ones((6, 19))
    fitness = np.array([0.1, 0.6, 0.3, 0.9, 0.8, 0.95])
    active = np.array([True, True, True, True, True, False])
    arc.offer(x, fitness, active, wrist)
    assert len(arc) == 3
    assert arc.fitness.tolist() == [0.9, 0.8, 0.6]
    assert arc.x[:, 0].tolist() == [3.0, 4.0, 1.0]


def test_grasp_quality_tiers():
    q = grasp_quality(np.array([0.5, 0.9, 0.99, 0.2]), np.array([True, True, False, True]),
                      np.array([True, False, True, True]))
    assert np.all((q >= 0) & (q <= 1))
    assert q[0] > q[1] > q[2]           # force closure before valid before invalid
    assert q[0] > q[3]                  # within a tier, the fitter first
    held = grasp_quality(np.array([0.2, 0.9]), np.array([True, True]), np.array([True, True]),
                         held=np.array([True, False]))
    assert held[0] > held[1]
    # robust force closure (closure survives edge/corner normal uncertainty) before fragile
    robust = grasp_quality(np.array([0.3, 0.95, 0.99]), np.array([True, True, True]),
                           np.array([True, True, False]), robust=np.array([True, False, False]))
    assert robust[0] > robust[1] > robust[2]
    # the simulation outranks everything: a held fragile grasp before a dropped robust one
    both = grasp_quality(np.array([0.1, 0.99]), np.array([True, True]), np.array([True, True]),
                         held=np.array([True, False]), robust=np.array([False, True]))
    assert both[0] > both[1]
    assert np.all((both >= 0) & (both <= 1))


@pytest.fixture(scope="module")
def five():
    return plan(builtin("cube"), options=PlanOptions(max_grasps=5, **OPTIONS), rng=np.random.default_rng(4))


def test_candidates_sorted_distinct_and_first_is_top_level(five):
    res = five
    cands = res.candidates
    assert len(cands) == 5, res.candidates_message
    assert res.candidates_message == ""
    assert [c.rank for c in cands] == list(range(5))
    assert len({c.id for c in cands}) == 5
    quality = [c.grasp_quality for c in cands]
    assert all(0.0 <= q <= 1.0 for q in quality)
    assert quality[1:] == sorted(quality[1:], reverse=True)
    closure = [c.force_closure for c in cands[1:]]
    assert closure == sorted(closure, reverse=True)  # force closure first
    gap_o, gap_p = PlanOptions().min_orientation_gap, PlanOptions().min_position_gap
    for i in range(5):
        for j in range(i + 1, 5):
            a, b = cands[i].wrist_pose, cands[j].wrist_pose
            assert (_angle(a[:3, :3], b[:3, :3]) >= gap_o - 1e-9
                    or np.linalg.norm(a[:3, 3] - b[:3, 3]) >= gap_p - 1e-12), (i, j)
    best = cands[0]
    np.testing.assert_array_equal(best.joint_positions, res.joint_positions)
    np.testing.assert_array_equal(best.wrist_pose, res.wrist_pose)
    assert (best.fitness, best.epsilon, best.force_closure, best.valid) == (
        res.fitness, res.epsilon, res.force_closure, res.valid)
    assert [c.finger for c in best.contacts] == [c.finger for c in res.contacts]
    assert all(c.valid for c in cands)
    assert res.history[-1].distinct_candidates >= 5


def test_more_candidates_do_not_change_the_best(five):
    one = plan(builtin("cube"), options=PlanOptions(max_grasps=1, **OPTIONS), rng=np.random.default_rng(4))
    assert len(one.candidates) == 1
    assert one.fitness == five.fitness
    np.testing.assert_array_equal(one.joint_positions, five.joint_positions)


def test_same_seed_same_list(five):
    again = plan(builtin("cube"), options=PlanOptions(max_grasps=5, **OPTIONS), rng=np.random.default_rng(4))
    assert [c.fitness for c in again.candidates] == [c.fitness for c in five.candidates]
    for a, b in zip(again.candidates, five.candidates):
        np.testing.assert_array_equal(a.joint_positions, b.joint_positions)
        np.testing.assert_array_equal(a.wrist_pose, b.wrist_pose)


def test_more_grasps_than_exist_gives_fewer_and_a_message():
    res = plan(builtin("sphere"), options=PlanOptions(max_grasps=50, particles=6, iterations=3,
                                                      neighborhood_size=3),
               rng=np.random.default_rng(0))
    assert 1 <= len(res.candidates) < 50
    assert res.candidates_message.startswith(f"{len(res.candidates)} of 50 grasps")
