"""Executable grasps (DESIGN.md Part 2) measured: the paper's objects resting on a table
against free space, ranked candidates (quality by rank, distinctness, time against one
grasp) and the MuJoCo held rate of APSO, the simple PSO and the pyswarms peers.

Every plan uses the experiment's swarm (np, nit) and seeds 0..``part2.seeds - 1``; the
table is a support plane (normal +z) under the object's lowest point, the object at the
identity pose, the clearance and approach distance the planner's defaults.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ..model import builtin as builtin_objects
from ..model.scene import Scene
from ..search.planner import GraspResult, PlanOptions, plan
from ..tunables import default
from .config import ExperimentConfig
from .progress import _log
from .records import record_of
from .runs import PYSWARMS_KEYS, pyswarms_once, pyswarms_status
from .stats import _rate, _stats

__all__ = ["run_part2", "simulation_status", "pairwise_gaps", "table_scene"]


def table_scene(obj) -> Scene:
    """A support plane (normal +z) under the object's lowest point (object frame)."""
    return Scene.table_under(np.asarray(obj.mesh.vertices, float))


def _clearance_ok(result: GraspResult, clearance: float) -> bool:
    return all(c.scene_distance >= clearance - 1e-9 for c in result.candidates)


def _record(result: GraspResult, seed: int, hand, wall: float, clearance: float) -> dict[str, Any]:
    rec = record_of(result, seed, hand, wall)
    best = result.candidates[0] if result.candidates else None
    rec["scene_distance"] = None if best is None or not math.isfinite(best.scene_distance) else best.scene_distance
    rec["clear"] = _clearance_ok(result, clearance)
    rec["success"] = bool(rec["valid"] and rec["clear"])
    rec["from_above_deg"] = None if best is None else math.degrees(math.acos(float(np.clip(-best.approach[2], -1, 1))))
    return rec


def _plan_timed(obj, options: PlanOptions, seed: int, hand, scene: Scene | None) -> tuple[GraspResult, float]:
    t0 = time.perf_counter()
    result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hand, scene=scene)
    return result, time.perf_counter() - t0


def pairwise_gaps(result: GraspResult) -> list[tuple[float, float]]:
    """(orientation angle deg, position distance m) between every two candidates' wrists."""
    out = []
    cands = result.candidates
    for i in range(len(cands)):
        for j in range(i + 1, len(cands)):
            a, b = np.asarray(cands[i].wrist_pose, float), np.asarray(cands[j].wrist_pose, float)
            cos = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
            out.append((math.degrees(math.acos(float(np.clip(cos, -1.0, 1.0)))),
                        float(np.linalg.norm(a[:3, 3] - b[:3, 3]))))
    return out


def _summary(recs: list[dict[str, Any]]) -> dict[str, Any]:
    return {"runs": len(recs), "success_rate": _rate([r["success"] for r in recs]),
            "valid_rate": _rate([r["valid"] for r in recs]), "clear_rate": _rate([r["clear"] for r in recs]),
            "fitness": _stats([r["fitness"] for r in recs]), "epsilon": _stats([r["epsilon"] for r in recs]),
            "force_closure_rate": _rate([r["force_closure"] for r in recs]),
            "planning_time": _stats([r["planning_time"] for r in recs]),
            "from_above_deg": _stats([r["from_above_deg"] for r in recs])}


def _table_and_candidates(cfg: ExperimentConfig, hand) -> dict[str, Any]:
    """Per object: free space and table with one grasp; the table with ``max_grasps``."""
    p2 = cfg.part2
    clearance = default("clearance")
    out: dict[str, Any] = {"objects": {}, "clearance": clearance, "max_grasps": p2.max_grasps,
                           "min_orientation_gap_deg": math.degrees(default("min_orientation_gap")),
                           "min_position_gap": default("min_position_gap")}
    for name in cfg.objects:
        obj = builtin_objects.builtin(name)
        scene = table_scene(obj)
        one = PlanOptions(particles=cfg.particles, iterations=cfg.iterations, max_grasps=1)
        many = PlanOptions(particles=cfg.particles, iterations=cfg.iterations, max_grasps=p2.max_grasps)
        plan(obj, options=PlanOptions(particles=cfg.particles, iterations=1), rng=np.random.default_rng(0),
             hand=hand, scene=scene)  # preparation outside the timed plans
        runs: dict[str, list] = {"free": [], "table": [], "table_candidates": []}
        ranks: list[list[dict[str, Any]]] = []
        gaps: list[tuple[float, float]] = []
        for seed in range(p2.seeds):
            for key, options, sc in (("free", one, None), ("table", one, scene), ("table_candidates", many, scene)):
                result, wall = _plan_timed(obj, options, seed, hand, sc)
                rec = _record(result, seed, hand, wall, clearance)
                if key == "table_candidates":
                    rec["n_candidates"] = len(result.candidates)
                    rec["candidates_message"] = result.candidates_message
                    ranks.append([{"epsilon": c.epsilon, "force_closure": bool(c.force_closure),
                                   "grasp_quality": c.grasp_quality, "valid": bool(c.valid)}
                                  for c in result.candidates])
                    gaps += pairwise_gaps(result)
                runs[key].append(rec)
        by_rank = []
        for k in range(p2.max_grasps):
            at = [r[k] for r in ranks if len(r) > k]
            by_rank.append({"rank": k + 1, "n": len(at), "epsilon": _stats([c["epsilon"] for c in at]),
                            "force_closure_rate": _rate([c["force_closure"] for c in at]),
                            "grasp_quality": _stats([c["grasp_quality"] for c in at])})
        distinct = [a >= out["min_orientation_gap_deg"] - 1e-6 or d >= out["min_position_gap"] - 1e-9 for a, d in gaps]
        t_one = _stats([r["planning_time"] for r in runs["table"]])["median"]
        t_many = _stats([r["planning_time"] for r in runs["table_candidates"]])["median"]
        out["objects"][name] = {
            "free": _summary(runs["free"]), "table": _summary(runs["table"]),
            "candidates": {**_summary(runs["table_candidates"]),
                           "n_candidates": _stats([r["n_candidates"] for r in runs["table_candidates"]]),
                           "by_rank": by_rank, "pairs": len(gaps), "distinct_rate": _rate(distinct),
                           "min_angle_deg": min((a for a, _ in gaps), default=None),
                           "min_distance": min((d for _, d in gaps), default=None),
                           "time_ratio_to_one": (t_many / t_one) if t_one and t_many else None},
            "runs": runs,
        }
        s = out["objects"][name]
        _log(f"part 2 {name:6s}: table success {s['table']['success_rate']:.0%} vs free {s['free']['success_rate']:.0%}, "
             f"{s['candidates']['n_candidates']['median']:.0f} candidates in "
             f"{s['candidates']['time_ratio_to_one'] or float('nan'):.2f} x one grasp's time")
    return out


def simulation_status() -> tuple[bool, str]:
    """(usable, why not) of :mod:`grasp_apso.simulation` with mujoco."""
    try:
        import mujoco  # noqa: F401

        from ..simulation import SimulationSettings, simulate_grasp  # noqa: F401
    except Exception as exc:  # report precisely, do not hide
        return False, f"{type(exc).__name__}: {exc}"
    return True, ""


def _simulated(result: GraspResult, obj, hand) -> dict[str, Any]:
    from ..simulation import simulate_grasp

    if not result.candidates:
        return {"held": False, "max_shift": None, "max_turn": None, "sim_time": 0.0, "valid": False}
    c = result.candidates[0]
    sim = simulate_grasp(hand, obj, np.eye(4), c.wrist_pose, c.pre_grasp_positions, c.joint_positions)
    return {"held": bool(sim.held), "max_shift": float(sim.max_shift), "max_turn": float(sim.max_turn),
            "sim_time": float(sim.sim_time), "valid": bool(result.valid)}


def _simulation(cfg: ExperimentConfig, hand, runs: dict, peers: dict) -> dict[str, Any]:
    """The best grasp of each approach and seed (free space), checked in MuJoCo."""
    ok, why = simulation_status()
    out: dict[str, Any] = {"available": ok, "why_not": why, "objects": {}}
    if not ok:
        _log(f"simulation not run: {why}")
        return out
    from dataclasses import asdict

    from ..simulation import SimulationSettings

    out["settings"] = {k: v for k, v in asdict(SimulationSettings()).items() if not isinstance(v, dict)}
    use_peers = cfg.peers and pyswarms_status()[0]
    for name in cfg.objects:
        obj = builtin_objects.builtin(name)
        iters = (peers.get("iterations") or {}).get(name) or max(
            1, int(round(_stats([r["evaluations"] for r in runs[name]["apso"]])["median"] / cfg.particles)))
        by: dict[str, Any] = {}
        for key in ("apso", "pso") + (PYSWARMS_KEYS if use_peers else ()):
            recs = []
            for seed in range(cfg.part2.seeds):
                if key in PYSWARMS_KEYS:
                    result = pyswarms_once(obj, key, cfg.particles, iters, seed, hand,
                                           PlanOptions(particles=cfg.particles, max_grasps=1))[0]
                else:
                    options = PlanOptions(algorithm=key, particles=cfg.particles, iterations=cfg.iterations,
                                          max_grasps=1)
                    result = _plan_timed(obj, options, seed, hand, None)[0]
                recs.append({"seed": seed, **_simulated(result, obj, hand)})
            by[key] = {"runs": recs, "held_rate": _rate([r["held"] for r in recs]),
                       "max_shift": _stats([r["max_shift"] for r in recs]),
                       "sim_time": _stats([r["sim_time"] for r in recs])}
        out["objects"][name] = by
        _log(f"simulation {name:6s}: held " + ", ".join(f"{k} {v['held_rate']:.0%}" for k, v in by.items()))
    return out


def run_part2(cfg: ExperimentConfig, hand, runs: dict, peers: dict) -> dict[str, Any] | None:
    """The table scenario, the candidates and the simulation (those ``cfg.part2`` enables)."""
    p2 = cfg.part2
    if p2 is None:
        return None
    data: dict[str, Any] = {"seeds": p2.seeds}
    if p2.table or p2.candidates:
        data["scene"] = _table_and_candidates(cfg, hand)
    if p2.simulation:
        data["simulation"] = _simulation(cfg, hand, runs, peers)
    return data
