"""The simulation keeps the time bound (issue 19, part 4): the convex decomposition of a new
mesh runs in a process of its own, bounded, once per mesh, kept on disk; a plan whose
time is up returns its verified candidates unsimulated (``sim_result`` -1) and says why.

Meshes are new to every cache: tori with seeded vertex noise (seeds used nowhere else),
decomposed into a temporary cache folder.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import trimesh

pytest.importorskip("mujoco")
pytest.importorskip("coacd")

from grasp_apso.model.objects import from_arrays  # noqa: E402
from grasp_apso.search.planner import PlanOptions, plan, prepare, warm_up  # noqa: E402
from grasp_apso.search.result import SIM_DROPPED, SIM_HELD, SIM_NOT_RUN  # noqa: E402
from grasp_apso.simulation import convex  # noqa: E402
from grasp_apso.simulation.convex import ConvexSettings, decompose  # noqa: E402


def _torus(seed: int, major_sections: int = 48, minor_sections: int = 24):
    """A non-convex object (volume 72 % of its hull), 8.4 x 8.4 x 2.4 cm, new to every cache."""
    t = trimesh.creation.torus(major_radius=0.03, minor_radius=0.012, major_sections=major_sections,
                               minor_sections=minor_sections)
    noise = np.random.default_rng(seed).normal(0.0, 2e-4, t.vertices.shape)
    return from_arrays(t.vertices + noise, t.faces, name=f"torus{seed}")


@pytest.fixture()
def cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("GRASP_APSO_CACHE", str(tmp_path))
    convex.clear_memory_cache()
    yield tmp_path
    convex.cancel_background()
    assert convex.wait_for_background(30.0)
    convex.clear_memory_cache()


def test_decomposition_runs_in_the_background_once_and_is_kept_on_disk(cache_dir):
    obj = _torus(seed=190401)
    t0 = time.monotonic()
    first = decompose(obj, should_stop=lambda: True)   # the caller cannot wait at all
    assert time.monotonic() - t0 < 0.5
    assert first.parts is None and first.method == "pending" and "did not end in time" in first.note
    assert convex.wait_for_background(120.0)          # it went on without the caller
    files = list((cache_dir / "coacd").glob("*.npz"))
    assert len(files) == 1 and files[0].name.startswith(obj.mesh_hash)
    done = decompose(obj, should_stop=lambda: True)
    assert done.method == "coacd" and len(done.parts) >= 2
    convex.clear_memory_cache()                       # as a restarted node: from the disk
    again = decompose(obj, should_stop=lambda: True)
    assert again.method == "coacd" and len(again.parts) == len(done.parts)
    for a, b in zip(again.parts, done.parts):
        np.testing.assert_array_equal(a, b)
    # independent check: the parts cover the torus (their hulls hold every vertex) and
    # leave its hole open (the centre is in no part)
    hulls = [trimesh.convex.convex_hull(p) for p in done.parts]
    vertices = np.asarray(obj.mesh.vertices)
    inside = np.zeros(len(vertices), dtype=bool)
    for h in hulls:
        inside |= h.contains(vertices) | (np.abs(trimesh.proximity.signed_distance(h, vertices)) < 2e-3)
    assert inside.mean() > 0.99
    assert not any(h.contains([[0.0, 0.0, 0.0]])[0] for h in hulls)


def test_decomposition_out_of_time_is_a_stored_failure_not_a_hull(cache_dir):
    obj = _torus(seed=190402)
    settings = ConvexSettings(timeout=0.01)           # no child process starts that fast
    t0 = time.monotonic()
    found = decompose(obj, settings)
    assert time.monotonic() - t0 < 10.0
    # the torus fills 72 % of its hull: simulating the hull would be dishonest
    assert found.parts is None and found.method == "failed"
    assert "did not finish within 0.01 s" in found.note and "decomposition_timeout" in found.note
    assert len(list((cache_dir / "coacd").glob("*.npz"))) == 1     # the failure is kept ...
    convex.clear_memory_cache()
    assert decompose(obj, settings).method == "failed"               # ... and not redone
    longer = decompose(obj, ConvexSettings(timeout=0.02), should_stop=lambda: True)
    assert longer.method == "pending"                                # a longer bound retries


def test_plan_with_simulate_on_a_new_mesh_answers_within_its_time_bound(cache_dir):
    """A new non-convex mesh whose decomposition takes far longer (about 10 s on an idle
    machine here) than the plan's bound: the verified candidates come back within the
    bound, unsimulated, with the reason. (A 12,288-triangle torus took 3.8 s on an idle
    machine, within reach of the bound.)"""
    warm_up()
    obj = _torus(seed=190403, major_sections=192, minor_sections=96)  # 36,864 triangles
    prepare(obj)            # the distance grid: not the part under test (plan_timeout covers it in the node)
    bound = 4.0
    t0 = time.monotonic()
    deadline = t0 + bound
    # the search and the verification take about 1 s: the rest is the wait for the decomposition
    result = plan(obj, options=PlanOptions(particles=20, iterations=30, max_grasps=3, simulate=True),
                  rng=np.random.default_rng(19), should_stop=lambda: time.monotonic() >= deadline)
    elapsed = time.monotonic() - t0
    print(f"plan with simulate on a new 36,864-triangle torus: {elapsed:.3f} s for a bound of {bound} s")
    assert result.iterations_run == 30 and not result.cancelled          # the search was not cut
    assert elapsed < bound + 0.25, elapsed                              # the wait was
    assert result.candidates and result.valid
    verdicts = [c.sim_result for c in result.candidates]
    assert set(verdicts) <= {SIM_NOT_RUN, SIM_DROPPED, SIM_HELD}
    if SIM_NOT_RUN in verdicts:
        assert "not simulated" in result.candidates_message or "simulation stopped" in result.candidates_message
    # the decomposition had no time to end: nothing was simulated
    assert verdicts == [SIM_NOT_RUN] * len(verdicts)
    assert "did not end in time" in result.candidates_message


def test_plan_whose_time_is_up_before_the_simulation_returns_unsimulated_candidates(cache_dir):
    from grasp_apso.model.builtin import builtin

    result = plan(builtin("sphere"), options=PlanOptions(particles=20, iterations=5, max_grasps=3, simulate=True),
                  rng=np.random.default_rng(4), should_stop=lambda: True)
    assert result.candidates
    assert all(c.sim_result == SIM_NOT_RUN for c in result.candidates)
    assert "not simulated: the time bound was reached" in result.candidates_message


def test_a_simulation_stopped_between_grasps_keeps_the_rest_unsimulated(cache_dir):
    """The stop predicate turns true after the first simulated grasp: that one carries its
    verdict, the others -1, and the message says where it stopped."""
    from grasp_apso.model.builtin import builtin

    options = PlanOptions(particles=20, iterations=5, max_grasps=3)
    calls = [0]

    def counting() -> bool:
        calls[0] += 1
        return False

    plan(builtin("sphere"), options=options, rng=np.random.default_rng(5), should_stop=counting)
    swarm_polls = calls[0]
    calls[0] = 0

    def after_one_grasp() -> bool:   # polls: the swarm's, the simulation's start, grasp 1, grasp 2 ...
        calls[0] += 1
        return calls[0] > swarm_polls + 2

    result = plan(builtin("sphere"), options=PlanOptions(**{**options.__dict__, "simulate": True}),
                  rng=np.random.default_rng(5), should_stop=after_one_grasp)
    verdicts = sorted(c.sim_result for c in result.candidates)
    assert len(verdicts) == 3 and verdicts.count(SIM_NOT_RUN) == 2 and verdicts[-1] in (SIM_DROPPED, SIM_HELD)
    assert "simulation stopped at the time bound after 1 of" in result.candidates_message
