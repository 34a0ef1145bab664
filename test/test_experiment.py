"""The experiment report (grasp_apso.experiment) in its quick mode: it runs, and the report,
the JSON and the pictures have what the full experiment writes (CI keeps the code working;
the numbers are checked only for shape and sanity, not for the paper's claims)."""

import json
import os

import pytest

from grasp_apso import experiment

pytestmark = pytest.mark.timeout(300)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("experiment")
    status = experiment.main(["--quick", "--out", str(out)])
    assert status == 0
    return out


def test_writes_report_json_and_pictures(quick_run):
    names = set(os.listdir(quick_run))
    assert {"report.md", "results.json", "convergence.png", "convergence_evaluations.png", "speed.png",
            "table3_sphere.png", "table3_cube.png"} <= names
    for name in names:
        if name.endswith(".png"):
            with open(quick_run / name, "rb") as f:
                assert f.read(8) == b"\x89PNG\r\n\x1a\n", name
            assert 10_000 < os.path.getsize(quick_run / name) < 2_000_000, name


def test_json_has_the_table3_numbers(quick_run):
    data = json.loads((quick_run / "results.json").read_text())
    assert {"meta", "summary", "claims", "runs", "pyswarms", "determinism", "pictures", "speed", "anomalies"} <= set(data)
    cfg = data["meta"]["config"]
    assert cfg["quick"] is True and cfg["seeds"] == 2
    for obj in ("sphere", "cube"):
        for alg in ("apso", "pso", "pso_equal_budget"):
            s = data["summary"][obj][alg]
            for key in ("fitness", "n_contacts", "epsilon", "force_closure_rate", "valid_rate", "planning_time",
                        "evaluations", "evaluations_per_second"):
                assert key in s, (obj, alg, key)
            assert s["runs"] == 2
            assert 0.0 <= s["force_closure_rate"] <= 1.0 and 0.0 <= s["valid_rate"] <= 1.0
        for alg in ("apso", "pso"):
            at = data["summary"][obj][alg]["fitness_at"]
            assert set(at) == {str(k) for k in cfg["snapshots"]}
            assert all(at[k]["median"] is not None and at[k]["q1"] <= at[k]["median"] <= at[k]["q3"] for k in at)
            for run in data["runs"][obj][alg]:
                assert len(run["best_history"]) == cfg["iterations"]
                if run["runner_up"]:  # a less fit force-closure grasp replaced the swarm's best
                    assert run["fitness"] <= run["best_history"][-1] + 1e-6
                else:
                    assert run["best_history"][-1] == pytest.approx(run["fitness"], abs=1e-6)
        # PSO on APSO's budget stops within one iteration of APSO's evaluations.
        for apso, eq in zip(data["runs"][obj]["apso"], data["runs"][obj]["pso_equal_budget"]):
            assert eq["budget"] == apso["evaluations"]
            assert apso["evaluations"] <= eq["evaluations"] < apso["evaluations"] + cfg["particles"]
    for part in ("accuracy", "convergence", "reliability", "speed", "equal_budget"):
        assert set(data["claims"][part]) == {"sphere", "cube"}
    # Re-running a seed with fewer iterations reproduces the full run's first iterations.
    assert data["determinism"] and all(d["prefix_identical"] for d in data["determinism"])
    speed = data["speed"]
    assert speed["particles"] and speed["iterations"] and speed["meshes"]
    assert all(m["preparation_time"] > 0 and m["plan_time_cold"] > 0 for m in speed["meshes"])


def test_pyswarms_peers_ran_or_say_why(quick_run):
    data = json.loads((quick_run / "results.json").read_text())
    peers = data["pyswarms"]
    if not peers["available"]:
        pytest.skip(f"pyswarms unavailable: {peers['version']}")
    for obj in ("sphere", "cube"):
        iters = peers["iterations"][obj]
        for key in ("pyswarms_global", "pyswarms_local"):
            runs = data["runs"][obj][key]
            assert len(runs) == 2
            for run in runs:
                # the optimiser's evaluations (counted before the verification)
                assert run["evaluations"] == iters * data["meta"]["config"]["particles"]
                assert run["fitness"] == pytest.approx(run["optimizer_best"], abs=1e-6)


def test_report_has_the_sections_and_columns(quick_run):
    text = (quick_run / "report.md").read_text()
    for heading in ("## Headline", "## The paper's claims, measured", "## Table 3 in numbers",
                    "## Table 3 in pictures", "## Convergence", "## Peer optimisers: pyswarms", "## Speed"):
        assert heading in text, heading
    for column in ("fitness @2", "fitness @5", "fitness @10", "contacts", "epsilon", "FC", "valid", "time (s)",
                   "evaluations"):
        assert column in text, column
    for claim in ("Accuracy", "Convergence speed", "Reliability", "PSO faster per run", "Fair budget"):
        assert claim in text, claim
    assert "![convergence](convergence.png)" in text and "(table3_sphere.png)" in text
    assert "Quick mode" in text


def test_bad_arguments_are_refused(capsys):
    assert experiment.main(["--objects", "teapot", "--quick"]) == 2
    assert "objects" in capsys.readouterr().err


def test_part2_table_candidates_and_simulation(quick_run):
    """The executable-grasp sections: the table against free space, the ranked candidates and
    the simulation's held rate (or why it did not run), in the JSON and the report."""
    data = json.loads((quick_run / "results.json").read_text())
    p2 = data["part2"]
    assert p2["seeds"] == 1
    sc = p2["scene"]
    assert set(sc["objects"]) == {"sphere", "cube"} and sc["max_grasps"] == 3
    for name, v in sc["objects"].items():
        for key in ("free", "table"):
            assert v[key]["runs"] == 1 and 0.0 <= v[key]["success_rate"] <= 1.0
        for rec in v["runs"]["table"] + v["runs"]["table_candidates"]:
            # success on a table means the whole hand kept the clearance (python-fcl, every candidate)
            if rec["success"]:
                assert rec["valid"] and rec["scene_distance"] >= sc["clearance"] - 1e-9
        for rec in v["runs"]["free"]:
            assert rec["scene_distance"] is None and rec["success"] == rec["valid"]
        cand = v["candidates"]
        assert 1 <= cand["n_candidates"]["median"] <= 3
        assert [b["rank"] for b in cand["by_rank"]] == [1, 2, 3]
        assert cand["by_rank"][0]["n"] == 1
        if cand["pairs"]:
            assert cand["distinct_rate"] == 1.0  # the planner's contract: distinct candidates
        assert cand["time_ratio_to_one"] > 0
    sim = p2["simulation"]
    text = (quick_run / "report.md").read_text()
    for heading in ("## Resting on a table: against free space", "## Ranked candidates",
                    "## Simulation: does the grasp hold?"):
        assert heading in text, heading
    if sim["available"]:
        for name in ("sphere", "cube"):
            for key in ("apso", "pso"):
                assert 0.0 <= sim["objects"][name][key]["held_rate"] <= 1.0
        assert "10 m/s^2 along +x, -x, +y, -y, +z, -z" in text and "**Held**" in text
    else:
        assert "Not run: the simulation could not be imported" in text
