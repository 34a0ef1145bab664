"""What the runs show: statistics per object and approach, the paper's claims checked with
the numbers, and suspicious planner behaviour found in the runs."""

from __future__ import annotations

from typing import Any

import numpy as np

from .config import ALGORITHM_LABELS, PENETRATION_LIMIT, ExperimentConfig
from .stats import _mannwhitney, _median_curve, _rate, _stats


def summarise(cfg: ExperimentConfig, runs: dict) -> dict[str, dict[str, dict[str, Any]]]:
    summary: dict[str, dict[str, dict[str, Any]]] = {}
    for name, by_alg in runs.items():
        summary[name] = {}
        for alg, recs in by_alg.items():
            at = {}
            for k in cfg.snapshots:
                at[str(k)] = _stats([r["best_history"][k - 1] if len(r["best_history"]) >= k else None for r in recs])
            summary[name][alg] = {
                "runs": len(recs),
                "fitness_at": at if alg in ("apso", "pso") else {},
                "fitness": _stats([r["fitness"] for r in recs]),
                "n_contacts": _stats([r["n_contacts"] for r in recs]),
                "epsilon": _stats([r["epsilon"] for r in recs]),
                "force_closure_rate": _rate([r["force_closure"] for r in recs]),
                "valid_rate": _rate([r["valid"] for r in recs]),
                "valid_and_fc_rate": _rate([r["valid"] and r["force_closure"] for r in recs]),
                "thumb_rate": _rate([r["thumb_contact"] for r in recs]),
                "links_touching_rate": _rate([r["links_touching"] > 0 for r in recs]),
                "planning_time": _stats([r["planning_time"] for r in recs]),
                "evaluations": _stats([r["evaluations"] for r in recs]),
                "evaluations_per_second": _stats([r["evaluations"] / r["planning_time"] for r in recs
                                                  if r["planning_time"] > 0]),
                "max_penetration_mm": _stats([r["max_penetration_mm"] for r in recs]),
            }
            if alg in ("apso", "pso"):
                k_mid = cfg.snapshots[1]
                summary[name][alg]["evaluations_at"] = {
                    str(k): _stats([r["evaluations_history"][k - 1] for r in recs
                                    if len(r["evaluations_history"]) >= k]) for k in cfg.snapshots}
                summary[name][alg]["evaluations_at_mid"] = summary[name][alg]["evaluations_at"][str(k_mid)]
    return summary


def evaluate_claims(cfg: ExperimentConfig, runs: dict, summary: dict) -> dict[str, Any]:
    """The paper's claims, checked object by object with the numbers."""
    k5, k20, k50 = cfg.snapshots
    claims: dict[str, Any] = {"accuracy": {}, "convergence": {}, "reliability": {}, "speed": {},
                              "equal_budget": {}, "peers": {}}
    for name in runs:
        s = summary[name]
        apso, pso = s["apso"], s["pso"]
        a_fit = [r["fitness"] for r in runs[name]["apso"]]
        p_fit = [r["fitness"] for r in runs[name]["pso"]]
        wins = sum(1 for a, p in zip(a_fit, p_fit) if a is not None and p is not None and a > p)
        claims["accuracy"][name] = {
            "apso_median": apso["fitness"]["median"], "pso_median": pso["fitness"]["median"],
            "holds": apso["fitness"]["median"] > pso["fitness"]["median"],
            "apso_better_seeds": wins, "seeds": len(a_fit),
            "p_value_mannwhitney": _mannwhitney(a_fit, p_fit),
        }
        apso_curve = _median_curve(runs[name]["apso"], cfg.iterations)[0]
        pso_final = pso["fitness_at"][str(k50)]["median"]
        reach = np.flatnonzero(apso_curve >= pso_final)
        per_seed = np.mean([
            (ra["best_history"][k20 - 1] or -np.inf) >= (rp["best_history"][k50 - 1] or -np.inf)
            for ra, rp in zip(runs[name]["apso"], runs[name]["pso"])])
        claims["convergence"][name] = {
            "apso_at_mid": apso["fitness_at"][str(k20)]["median"], "pso_at_end": pso_final,
            "holds": apso["fitness_at"][str(k20)]["median"] >= pso_final,
            "apso_first_iteration_reaching_pso_final": int(reach[0]) + 1 if reach.size else None,
            "apso_evaluations_at_mid": apso["evaluations_at"][str(k20)]["median"],
            "pso_evaluations_at_end": pso["evaluations_at"][str(k50)]["median"],
            "seed_pairs_apso_mid_ge_pso_end": float(per_seed),
        }
        claims["reliability"][name] = {
            "apso_valid_rate": apso["valid_rate"], "pso_valid_rate": pso["valid_rate"],
            "apso_fc_rate": apso["force_closure_rate"], "pso_fc_rate": pso["force_closure_rate"],
            "apso_iqr": None if apso["fitness"]["median"] is None else apso["fitness"]["q3"] - apso["fitness"]["q1"],
            "pso_iqr": None if pso["fitness"]["median"] is None else pso["fitness"]["q3"] - pso["fitness"]["q1"],
            "apso_worst": apso["fitness"]["min"], "pso_worst": pso["fitness"]["min"],
            "meets_targets": (apso["valid_rate"] or 0) >= 0.95 and (apso["force_closure_rate"] or 0) >= 0.90,
        }
        claims["speed"][name] = {
            "apso_time": apso["planning_time"]["median"], "pso_time": pso["planning_time"]["median"],
            "holds": pso["planning_time"]["median"] < apso["planning_time"]["median"],
            "apso_evaluations": apso["evaluations"]["median"], "pso_evaluations": pso["evaluations"]["median"],
            "apso_evals_per_s": apso["evaluations_per_second"]["median"],
            "pso_evals_per_s": pso["evaluations_per_second"]["median"],
            "apso_meets_0_3_s": apso["planning_time"]["median"] <= 0.3,
        }
        if "pso_equal_budget" in s:
            eq = s["pso_equal_budget"]
            e_fit = [r["fitness"] for r in runs[name]["pso_equal_budget"]]
            claims["equal_budget"][name] = {
                "apso_median": apso["fitness"]["median"], "pso_equal_median": eq["fitness"]["median"],
                "pso_equal_evaluations": eq["evaluations"]["median"],
                "holds": apso["fitness"]["median"] > eq["fitness"]["median"],
                "p_value_mannwhitney": _mannwhitney(a_fit, e_fit),
                "pso_equal_fc_rate": eq["force_closure_rate"], "pso_equal_valid_rate": eq["valid_rate"],
            }
        for key in ("pyswarms_global", "pyswarms_local"):
            if key in s:
                claims["peers"].setdefault(name, {})[key] = {
                    "median": s[key]["fitness"]["median"],
                    "apso_better": apso["fitness"]["median"] > s[key]["fitness"]["median"],
                    "p_value_apso_greater": _mannwhitney(a_fit, [r["fitness"] for r in runs[name][key]]),
                }
    for part in ("accuracy", "convergence", "speed", "equal_budget"):
        held = [v["holds"] for v in claims[part].values()]
        claims[part + "_holds_on"] = f"{sum(held)} of {len(held)}"
    claims["reliability_holds_on"] = (
        f"{sum(v['meets_targets'] for v in claims['reliability'].values())} of {len(claims['reliability'])}")
    return claims


def find_anomalies(runs: dict) -> list[str]:
    """Plain-text observations of suspicious planner behaviour found in the runs."""
    notes: list[str] = []
    for name, by_alg in runs.items():
        for alg, recs in by_alg.items():
            label = f"{name}/{ALGORITHM_LABELS.get(alg, alg)}"
            for r in recs:
                h = [v for v in r["best_history"] if v is not None]
                if any(b < a - 1e-12 for a, b in zip(h, h[1:])):
                    notes.append(f"{label} seed {r['seed']}: the global best fitness decreases during the run")
                if alg in ("apso", "pso", "pso_equal_budget") and h and r["fitness"] is not None \
                        and abs(h[-1] - r["fitness"]) > 1e-6:
                    notes.append(f"{label} seed {r['seed']}: final fitness {r['fitness']:.4f} differs from the "
                                 f"swarm's global best {h[-1]:.4f}")
                if r["planner_valid"] and not r["fcl_legal"]:
                    notes.append(f"{label} seed {r['seed']}: the planner marks the grasp valid but python-fcl "
                                 "finds an illegal collision")
                if r["valid"] and r["max_penetration_mm"] > PENETRATION_LIMIT * 1000 + 1e-9:
                    notes.append(f"{label} seed {r['seed']}: valid grasp with {r['max_penetration_mm']:.2f} mm "
                                 "penetration by the planner's own (grid) measure")
                if r["force_closure"] and r["epsilon"] <= 0:
                    notes.append(f"{label} seed {r['seed']}: force closure with epsilon <= 0")
                if not r["joint_limits_ok"]:
                    notes.append(f"{label} seed {r['seed']}: joint limits violated")
                if r.get("optimizer_best") is not None and r["fitness"] is not None \
                        and abs(r["optimizer_best"] - r["fitness"]) > 1e-6:
                    notes.append(f"{label} seed {r['seed']}: Objective.result fitness {r['fitness']:.4f} differs "
                                 f"from the optimiser's best {r['optimizer_best']:.4f}")
    return notes
