"""The planner API and the swarm: determinism, callbacks, cancel, replacement, errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from grasp_apso.errors import InputError
from grasp_apso.model.hand import JOINT_NAMES, load_hand
from grasp_apso.model.objects import from_arrays
from grasp_apso.model.builtin import builtin
from grasp_apso.model.poses import pose_to_matrix
from grasp_apso.search.planner import PlanOptions, PlanningError, plan
from grasp_apso.search.swarm import SwarmOptions, run_swarm

SMALL = dict(particles=20, iterations=8)
REPO_ROOT = Path(__file__).resolve().parents[1]


def test_same_seed_same_result_and_different_seed_differs():
    obj = builtin("sphere")
    a = plan(obj, options=PlanOptions(**SMALL), rng=np.random.default_rng(42))
    b = plan(obj, options=PlanOptions(**SMALL), rng=np.random.default_rng(42))
    c = plan(obj, options=PlanOptions(**SMALL), rng=np.random.default_rng(43))
    np.testing.assert_array_equal(a.joint_positions, b.joint_positions)
    assert a.fitness == b.fitness
    assert [h.best_fitness for h in a.history] == [h.best_fitness for h in b.history]
    assert not np.array_equal(a.joint_positions, c.joint_positions)


def test_result_is_a_valid_grasp_in_the_planning_frame():
    obj = builtin("sphere")
    pose = pose_to_matrix([0.4, -0.1, 0.8], [0.0, 0.0, np.sin(0.4), np.cos(0.4)])
    hand = load_hand()
    res = plan(obj, pose=pose, options=PlanOptions(particles=40, iterations=15), rng=np.random.default_rng(1))
    assert res.valid and res.n_contacts >= 3
    assert res.joint_names == JOINT_NAMES
    assert np.all(res.joint_positions >= hand.lower - 1e-9) and np.all(res.joint_positions <= hand.upper + 1e-9)
    np.testing.assert_allclose(res.wrist_pose, pose @ res.wrist_in_object, atol=1e-12)
    np.testing.assert_allclose(res.configuration.reshape(-1), res.joint_positions)
    centre = pose[:3, 3]
    for c in res.contacts:  # on the 25 mm sphere, in the planning frame, normals radial
        assert abs(np.linalg.norm(c.position - centre) - 0.025) < 1e-3
        radial = (c.position - centre) / np.linalg.norm(c.position - centre)
        assert radial @ c.normal > np.cos(np.radians(5))
    assert res.max_penetration <= 0.001 and res.fcl.legal


def test_progress_is_called_once_per_iteration_and_cancel_stops_within_one():
    seen = []
    res = plan(builtin("cube"), options=PlanOptions(**SMALL), rng=np.random.default_rng(0), progress=seen.append)
    assert [s.iteration for s in seen] == list(range(1, 9))
    assert res.iterations_run == 8 and len(res.history) == 8
    assert all(b.best_fitness >= a.best_fitness for a, b in zip(seen, seen[1:]))

    calls = []
    stop_after = 3
    res = plan(
        builtin("cube"), options=PlanOptions(particles=20, iterations=200), rng=np.random.default_rng(0),
        progress=calls.append, should_stop=lambda: len(calls) >= stop_after,
    )
    assert res.cancelled
    assert res.iterations_run == stop_after == len(calls)


def test_evaluation_cap_is_respected_for_equal_budget_comparisons():
    res = plan(builtin("sphere"), options=PlanOptions(algorithm="pso", particles=20, iterations=1000,
                                                       max_evaluations=200), rng=np.random.default_rng(0))
    assert res.evaluations == 200
    assert res.iterations_run == 10


def test_impossible_requests_fail_clearly():
    big = trimesh.creation.box(extents=[0.5, 0.5, 0.5])
    with pytest.raises(PlanningError, match="too large"):
        plan(from_arrays(big.vertices, big.faces), options=PlanOptions(**SMALL), rng=np.random.default_rng(0))
    tiny = trimesh.creation.box(extents=[0.003, 0.003, 0.003])
    with pytest.raises(PlanningError, match="too small"):
        plan(from_arrays(tiny.vertices, tiny.faces), options=PlanOptions(**SMALL), rng=np.random.default_rng(0))


@pytest.mark.parametrize(
    "kwargs, field",
    [({"algorithm": "ga"}, "algorithm"), ({"particles": 0}, "particles"), ({"iterations": 0}, "iterations"),
     ({"inertia": 1.5}, "inertia"), ({"friction": 0.0}, "friction"), ({"contact_tolerance": 0.5}, "contact_tolerance"),
     ({"wrist_position": (0.0, float("nan"), 0.0)}, "wrist_position"), ({"particles": True}, "particles")],
)
def test_invalid_options_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        PlanOptions(**kwargs)


class _Synthetic:
    """A 2-D problem: particles with x0 < 0 are inactive; GRG particles sit at x0 = 0.5."""

    lower = np.array([-1.0, -1.0])
    upper = np.array([1.0, 1.0])

    def __init__(self):
        self.evaluations = 0
        self.guided_calls = []

    def evaluate(self, x):
        self.evaluations += len(x)
        active = x[:, 0] >= 0
        fit = np.where(active, -np.sum((x - 0.3) ** 2, axis=1), -10.0)
        return fit, active, active.astype(int) * 3

    def guided(self, k):
        self.guided_calls.append(k)
        return np.tile([0.5, 0.5], (k, 1))


def test_apso_replaces_inactive_particles_and_pso_does_not():
    opts = SwarmOptions(particles=20, iterations=1, max_replacements=1.0, stall_iterations=5)
    problem = _Synthetic()
    # GRG initialisation gives all-active particles: move half of them out by hand via a
    # first plain-PSO call is not possible, so start APSO from guided particles and check
    # that after a uniform PSO start the inactive ones are counted and kept.
    pso = run_swarm(problem, opts, np.random.default_rng(0), adaptive=False)
    assert problem.guided_calls == []
    assert pso.history[0].replaced == 0
    n_inactive = 20 - pso.history[0].active_particles
    assert n_inactive > 0

    class _HalfInactiveStart(_Synthetic):
        def guided(self, k):
            self.guided_calls.append(k)
            if len(self.guided_calls) == 1:  # the initial population: half inactive
                return np.where(np.arange(k)[:, None] % 2 == 0, [[-0.5, 0.0]], [[0.5, 0.5]])
            return np.tile([0.5, 0.5], (k, 1))

    problem = _HalfInactiveStart()
    apso = run_swarm(problem, opts, np.random.default_rng(0), adaptive=True)
    assert apso.history[0].active_particles == 10
    assert apso.history[0].replaced == 10
    assert problem.guided_calls == [20, 10]


class _TwoBasins:
    """A 1-D problem with two peaks: 1.0 at x = -0.6 and 0.9 at x = 0.6; GRG draws the first
    neighbourhood around the higher peak and the second around the lower one."""

    lower = np.array([-1.0])
    upper = np.array([1.0])

    def __init__(self):
        self.evaluations = 0
        self.calls = 0

    def evaluate(self, x):
        self.evaluations += len(x)
        fit = np.maximum(1.0 - 2.0 * np.abs(x[:, 0] + 0.6), 0.9 - 2.0 * np.abs(x[:, 0] - 0.6))
        return fit, np.ones(len(x), dtype=bool), np.full(len(x), 3)

    def guided(self, k):
        self.calls += 1
        centre = np.where(np.arange(k) < k // 2, -0.6, 0.6)
        return (centre + np.linspace(-0.1, 0.1, k))[:, None]


def test_a_local_best_swarm_keeps_its_neighbourhoods_apart():
    """With ``local_best`` (here for all the iterations) each neighbourhood follows its own
    best: the neighbourhood drawn on the lower peak stays there; with the swarm's best (the
    paper's update) it is drawn to the higher peak. The swarm's best is the higher peak
    either way."""
    opts = SwarmOptions(particles=10, iterations=40, neighborhood_size=5, improvement=0.0, stall_iterations=1)
    ends = {}
    for local in (0.0, 1.0):
        problem = _TwoBasins()
        rng = np.random.default_rng(0)
        res = run_swarm(problem, opts, rng, adaptive=True, local_best=local)
        assert problem.calls == 1  # no replacements: both runs are the update alone
        assert res.best_fitness == pytest.approx(1.0, abs=0.02) and res.best[0] == pytest.approx(-0.6, abs=0.01)
        ends[local] = res.personal_best[5:, 0]
    assert np.all(ends[1.0] > 0.4)  # the second neighbourhood stayed on its own peak
    assert np.all(ends[0.0] < 0.0)  # drawn over to the swarm's best
    with pytest.raises(InputError, match="local_best"):
        run_swarm(_TwoBasins(), opts, np.random.default_rng(0), adaptive=True, local_best=1.5)


def test_apso_replaces_the_worst_of_a_stalled_neighbourhood():
    opts = SwarmOptions(particles=10, iterations=6, neighborhood_size=5, stall_iterations=2,
                        improvement=1.0, max_replacements=1.0, c1=0.0, c2=0.0)
    problem = _Synthetic()
    res = run_swarm(problem, opts, np.random.default_rng(0), adaptive=True)
    # improvement=1 is never met on this problem: after the stall window each neighbourhood loses
    # its worst particle, then its window restarts.
    replaced = [h.replaced for h in res.history]
    assert replaced[:2] == [0, 0]
    assert replaced[2] == 2
    assert sum(replaced) >= 4


def test_a_force_closure_runner_up_replaces_a_global_best_that_is_not():
    # Fish, seed 19: the swarm's global best has 3 contacts but epsilon 0 (measured).
    obj = builtin("fish")
    only_best = plan(obj, options=PlanOptions(closure_candidates=1), rng=np.random.default_rng(19))
    assert only_best.valid and not only_best.force_closure and not only_best.runner_up
    chosen = plan(obj, options=PlanOptions(), rng=np.random.default_rng(19))
    assert chosen.runner_up and chosen.valid and chosen.force_closure and chosen.epsilon > 0.0
    # Same swarm (same seed), so a runner-up is no fitter than the global best.
    assert [h.best_fitness for h in chosen.history] == [h.best_fitness for h in only_best.history]
    assert chosen.fitness <= only_best.fitness + 1e-12
    assert chosen.fitness > only_best.fitness - 0.05


def test_closure_candidates_is_validated():
    with pytest.raises(ValueError, match="closure_candidates"):
        PlanOptions(closure_candidates=0)


def test_warm_up_loads_every_kernel_a_plan_uses():
    # In a process of its own: here the other tests have compiled the kernels already.
    script = (
        "from numba.core.registry import CPUDispatcher\n"
        "from grasp_apso.geometry import kernels, palm_kernels, scene_kernels\n"
        "from grasp_apso.quality import kernels as quality_kernels\n"
        "from grasp_apso.search.planner import warm_up\n"
        "seconds = warm_up()\n"
        "assert seconds > 0.0\n"
        "print(sorted(n for m in (kernels, scene_kernels, palm_kernels, quality_kernels) for n, f in vars(m).items()\n"
        "             if isinstance(f, CPUDispatcher) and not n.startswith('_') and not f.signatures))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], cwd=REPO_ROOT, capture_output=True, text=True,
                         timeout=120, check=True).stdout
    # Only the loops behind the validating functions of quality (for callers and tests;
    # planning calls the fused ones) are left to compile on first use (the final
    # verification's finger-pair pre-filter uses segment_distances).
    assert out.strip() == str(sorted(["polygon_batch", "antipodal_batch", "balance_batch", "wrench_batch"]))
