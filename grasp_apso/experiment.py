"""The paper's experiment (section 5, Table 3), peer optimisers and planner speed.

Run ``python -m grasp_apso.experiment`` (or ``make experiment``) from the repository root.
It plans with APSO and the simple PSO on the four built-in objects (np = 60, nit = 50)
over fixed seeds 0..N-1 and writes, into ``--out`` (default ``docs/experiment/``):

- ``report.md``: Table 3 in numbers (global best at iterations 5, 20 and 50: median and
  inter-quartile range of the fitness; for the final grasp the contact count, epsilon,
  force-closure and valid rates, plan time and evaluations), the paper's claims checked
  with the numbers, PSO given APSO's evaluation budget, pyswarms' global- and local-best
  PSO on the same fitness and budget, and the planner's speed;
- ``results.json``: every number of the report and every run (per-iteration history);
- pictures: ``table3_<object>.png`` (best grasp at iterations 5, 20, 50, rows PSO and
  APSO, like the paper's Table 3), ``convergence.png`` (median best fitness per
  iteration with the inter-quartile band), ``convergence_evaluations.png`` (the same
  against evaluations, with the equal-budget PSO and pyswarms) and ``speed.png``.

Definitions used throughout:

- *valid* grasp: at least 3 fingertip contacts, no penetration beyond 1 mm by the
  python-fcl check, joint limits respected: ``n_contacts >= 3 and result.valid and
  result.fcl.legal`` plus an explicit check of ``joint_positions`` against the hand's
  limits;
- *evaluation*: one particle decoded (GRG candidates included), as counted by the planner;
- the global best at iteration k of a run is ``history[k - 1].best_fitness``; the grasp
  drawn for it comes from re-running the same seed with ``iterations=k``: a run's first k
  iterations do not depend on the iteration count, which the experiment verifies for
  every re-run (``determinism`` in the JSON).

pyswarms uses numpy's global random state: it is seeded with ``np.random.seed(seed)``
before each of its runs (their API).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from . import objects
from .hand import FINGER_NAMES, load_hand
from .planner import GraspResult, Objective, PlanOptions, plan

__all__ = [
    "ALGORITHM_LABELS",
    "ExperimentConfig",
    "SpeedConfig",
    "main",
    "run_experiment",
    "run_speed",
    "format_speed_tables",
    "plot_speed",
    "valid_grasp",
]

DEFAULT_OUT = os.path.join("docs", "experiment")
OBJECT_LABELS = {
    "sphere": "sphere (diameter 5 cm)",
    "cube": "cube (edge 7 cm)",
    "barrel": "barrel (11 x 3 cm)",
    "fish": "fish (29 x 6 x 7 cm)",
}
#: Keys of the approaches in ``results.json`` and their labels in the report.
ALGORITHM_LABELS = {
    "pso": "simple PSO",
    "apso": "APSO",
    "pso_equal_budget": "PSO, APSO's budget",
    "pyswarms_global": "pyswarms GlobalBestPSO",
    "pyswarms_local": "pyswarms LocalBestPSO",
}
_COLORS = {
    "apso": "#0072B2",
    "pso": "#D55E00",
    "pso_equal_budget": "#E69F00",
    "pyswarms_global": "#009E73",
    "pyswarms_local": "#CC79A7",
}
PENETRATION_LIMIT = 0.001  #: m, python-fcl check of the valid-grasp definition
#: pyswarms settings: our PSO's coefficients, positions clamped into the bounds like ours.
PYSWARMS_OPTIONS = {"c1": 1.0, "c2": 1.5, "w": 0.6}
PYSWARMS_LOCAL = {"k": 5, "p": 2}
PYSWARMS_BOUNDARY = "nearest"


# ----------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class SpeedConfig:
    """What the speed measurements sweep (see :func:`run_speed`)."""

    sweep_object: str = "sphere"
    particles: tuple[int, ...] = (15, 30, 60, 120)
    iterations: tuple[int, ...] = (10, 25, 50, 100)
    repeats: int = 5  #: runs (seeds 0..repeats-1) per point, median reported
    #: (label, kind, size): "icosphere" size = subdivisions, "uv" size = rings = segments.
    meshes: tuple[tuple[str, str, int], ...] = (
        ("icosphere s=3", "icosphere", 3),
        ("icosphere s=4", "icosphere", 4),
        ("uv-sphere 49x49", "uv", 49),
        ("icosphere s=5", "icosphere", 5),
        ("icosphere s=6", "icosphere", 6),
    )
    mesh_repeats: int = 3  #: plans per mesh: the first cold (caches cleared), the rest warm
    per_object_runs: int = 5  #: plans per built-in object and algorithm (bench script)

    @classmethod
    def quick(cls) -> "SpeedConfig":
        return cls(particles=(15, 30), iterations=(5, 10), repeats=1,
                   meshes=(("icosphere s=2", "icosphere", 2), ("icosphere s=3", "icosphere", 3)),
                   mesh_repeats=2, per_object_runs=1)


@dataclass(frozen=True)
class ExperimentConfig:
    seeds: int = 20
    objects: tuple[str, ...] = objects.BUILTIN_OBJECTS
    particles: int = 60
    iterations: int = 50
    snapshots: tuple[int, ...] = (5, 20, 50)
    equal_budget: bool = True
    peers: bool = True
    speed: SpeedConfig | None = field(default_factory=SpeedConfig)
    quick: bool = False
    dpi: int = 100
    command: str = "python -m grasp_apso.experiment"

    @classmethod
    def quick_config(cls, **kw: Any) -> "ExperimentConfig":
        base = dict(seeds=2, objects=("sphere", "cube"), particles=20, iterations=10, snapshots=(2, 5, 10),
                    speed=SpeedConfig.quick(), quick=True, dpi=70)
        base.update(kw)
        return cls(**base)

    def __post_init__(self) -> None:
        if self.seeds < 1:
            raise ValueError(f"seeds: expected >= 1, got {self.seeds}")
        unknown = [o for o in self.objects if o not in objects.BUILTIN_OBJECTS]
        if unknown or not self.objects:
            raise ValueError(f"objects: expected some of {objects.BUILTIN_OBJECTS}, got {self.objects}")
        if len(self.snapshots) != 3 or not all(1 <= k <= self.iterations for k in self.snapshots):
            raise ValueError(f"snapshots: expected 3 iterations within 1..{self.iterations}, got {self.snapshots}")


# ----------------------------------------------------------------------------- helpers
def _finite(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _stats(values: Sequence[float | None]) -> dict[str, Any]:
    """median, quartiles, min, max, mean and n of the finite values."""
    arr = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if arr.size == 0:
        return {"n": 0, "median": None, "q1": None, "q3": None, "min": None, "max": None, "mean": None}
    q1, med, q3 = np.percentile(arr, [25, 50, 75])
    return {"n": int(arr.size), "median": float(med), "q1": float(q1), "q3": float(q3),
            "min": float(arr.min()), "max": float(arr.max()), "mean": float(arr.mean())}


def _rate(flags: Sequence[bool]) -> float | None:
    return float(np.mean(flags)) if len(flags) else None


def valid_grasp(result: GraspResult, hand=None) -> bool:
    """The experiment's valid grasp: >= 3 fingertip contacts, no penetration beyond 1 mm by
    the python-fcl check (``result.fcl.legal``), the planner's own legality
    (``result.valid``) and the joint limits respected."""
    return bool(result.n_contacts >= 3 and result.valid and result.fcl.legal and _within_limits(result, hand))


def _within_limits(result: GraspResult, hand=None) -> bool:
    hand = hand or load_hand()
    q = np.asarray(result.joint_positions, float)
    return bool(np.all(q >= hand.lower - 1e-9) and np.all(q <= hand.upper + 1e-9))


def record_of(result: GraspResult, seed: int, hand=None, wall: float | None = None) -> dict[str, Any]:
    """A JSON-ready summary of one plan (history included)."""
    return {
        "seed": int(seed),
        "fitness": _finite(result.fitness),
        "epsilon": float(result.epsilon),
        "force_closure": bool(result.force_closure),
        "n_contacts": int(result.n_contacts),
        "fingers": [c.finger for c in result.contacts],
        "valid": valid_grasp(result, hand),
        "planner_valid": bool(result.valid),
        "fcl_legal": bool(result.fcl.legal),
        "joint_limits_ok": _within_limits(result, hand),
        "max_penetration_mm": float(result.max_penetration) * 1000.0,
        "planning_time": float(result.planning_time),
        "preparation_time": float(result.preparation_time),
        "wall_time": None if wall is None else float(wall),
        "evaluations": int(result.evaluations),
        "iterations_run": int(result.iterations_run),
        "thumb_contact": any(c.finger == "thumb" for c in result.contacts),
        "links_touching": _links_touching(result),
        "best_history": [_round(h.best_fitness) for h in result.history],
        "evaluations_history": [int(h.evaluations) for h in result.history],
    }


def _round(x: float, digits: int = 6) -> float | None:
    x = _finite(x)
    return None if x is None else round(x, digits)


def _links_touching(result: GraspResult, tolerance: float = 1e-4) -> int:
    """Links resting on the object (python-fcl distance 0) other than a contact's distal link
    (the rule of ``plotting``'s dotted links): not a pure fingertip grasp when > 0."""
    distance = getattr(result.fcl, "link_distance", None)
    if distance is None:
        return 0
    touching = np.asarray(distance, float) <= tolerance
    for c in result.contacts:
        if c.finger in FINGER_NAMES:
            touching[FINGER_NAMES.index(c.finger), -1] = False
    return int(touching.sum())


def _log(message: str) -> None:
    print(f"[experiment] {message}", file=sys.stderr, flush=True)


def _fmt(x: float | None, digits: int = 3) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100.0 * x:.0f} %"


def _med_iqr(s: dict[str, Any], digits: int = 3) -> str:
    if not s or s.get("median") is None:
        return "n/a"
    return f"{s['median']:.{digits}f} [{s['q1']:.{digits}f}, {s['q3']:.{digits}f}]"


# ----------------------------------------------------------------------------- runs
def _plan_record(obj, options: PlanOptions, seed: int, hand) -> tuple[GraspResult, dict[str, Any]]:
    t0 = time.perf_counter()
    result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hand)
    return result, record_of(result, seed, hand, time.perf_counter() - t0)


def run_main(cfg: ExperimentConfig, hand) -> dict[str, dict[str, list[dict[str, Any]]]]:
    """APSO and the simple PSO (and PSO on APSO's budget) on every object and seed."""
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for name in cfg.objects:
        obj = objects.builtin(name)
        # Preparation (grid) once, outside the timed plans.
        plan(obj, options=PlanOptions(particles=cfg.particles, iterations=1), rng=np.random.default_rng(0), hand=hand)
        runs[name] = {"apso": [], "pso": []}
        for algorithm in ("apso", "pso"):
            t0 = time.perf_counter()
            options = PlanOptions(algorithm=algorithm, particles=cfg.particles, iterations=cfg.iterations)
            for seed in range(cfg.seeds):
                runs[name][algorithm].append(_plan_record(obj, options, seed, hand)[1])
            fits = [r["fitness"] for r in runs[name][algorithm]]
            _log(f"{name:6s} {algorithm:4s}: {cfg.seeds} seeds in {time.perf_counter() - t0:.1f} s, "
                 f"median fitness {_stats(fits)['median']:.3f}")
        if cfg.equal_budget:
            t0 = time.perf_counter()
            runs[name]["pso_equal_budget"] = []
            for seed, apso in enumerate(runs[name]["apso"]):
                options = PlanOptions(algorithm="pso", particles=cfg.particles, iterations=10000,
                                      max_evaluations=apso["evaluations"])
                rec = _plan_record(obj, options, seed, hand)[1]
                rec["budget"] = apso["evaluations"]
                runs[name]["pso_equal_budget"].append(rec)
            fits = [r["fitness"] for r in runs[name]["pso_equal_budget"]]
            _log(f"{name:6s} PSO on APSO's budget: {time.perf_counter() - t0:.1f} s, "
                 f"median fitness {_stats(fits)['median']:.3f}")
    return runs


def pyswarms_status() -> tuple[bool, str]:
    """(usable, version or the precise error) of pyswarms with the installed numpy."""
    try:
        import pyswarms  # noqa: F401
        from pyswarms.single import GlobalBestPSO, LocalBestPSO  # noqa: F401
    except Exception as exc:  # report precisely, do not hide
        return False, f"import failed: {type(exc).__name__}: {exc}"
    return True, str(getattr(pyswarms, "__version__", "?"))


def run_pyswarms(cfg: ExperimentConfig, runs: dict, hand) -> dict[str, Any]:
    """pyswarms GlobalBestPSO / LocalBestPSO on ``planner.Objective`` with APSO's median budget."""
    ok, version = pyswarms_status()
    info: dict[str, Any] = {"available": ok, "version": version, "options": dict(PYSWARMS_OPTIONS),
                            "local_options": dict(PYSWARMS_LOCAL), "bh_strategy": PYSWARMS_BOUNDARY,
                            "iterations": {}}
    if not ok:
        _log(f"pyswarms blocked: {version}")
        return info
    import logging

    from pyswarms.single import GlobalBestPSO, LocalBestPSO

    logging.getLogger("pyswarms").setLevel(logging.WARNING)
    for name in cfg.objects:
        obj = objects.builtin(name)
        budget = _stats([r["evaluations"] for r in runs[name]["apso"]])["median"]
        iters = max(1, int(round(budget / cfg.particles)))
        info["iterations"][name] = iters
        for key, cls, extra in (("pyswarms_global", GlobalBestPSO, {}),
                                ("pyswarms_local", LocalBestPSO, PYSWARMS_LOCAL)):
            t0 = time.perf_counter()
            records = []
            for seed in range(cfg.seeds):
                objective = Objective(obj, PlanOptions(particles=cfg.particles), hand=hand)
                np.random.seed(seed)  # pyswarms draws from numpy's global state
                start = time.perf_counter()
                optimizer = cls(n_particles=cfg.particles, dimensions=len(objective.lower),
                                options={**PYSWARMS_OPTIONS, **extra},
                                bounds=(np.asarray(objective.lower), np.asarray(objective.upper)),
                                bh_strategy=PYSWARMS_BOUNDARY)
                cost, pos = optimizer.optimize(lambda x: -objective(x), iters=iters, verbose=False)
                evaluations = objective.evaluations
                result = objective.result(pos, algorithm=key)
                wall = time.perf_counter() - start
                rec = record_of(result, seed, hand, wall)
                rec["planning_time"] = wall
                rec["evaluations"] = int(evaluations)
                rec["iterations_run"] = iters
                rec["optimizer_best"] = _finite(-float(cost))
                best = np.maximum.accumulate(-np.asarray(optimizer.cost_history, float))
                rec["best_history"] = [_round(v) for v in best]
                rec["evaluations_history"] = [int(cfg.particles * (i + 1)) for i in range(len(best))]
                records.append(rec)
            runs[name][key] = records
            _log(f"{name:6s} {key}: {iters} iterations x {cfg.particles} particles, {time.perf_counter() - t0:.1f} s, "
                 f"median fitness {_stats([r['fitness'] for r in records])['median']:.3f}")
    return info


# ----------------------------------------------------------------------------- summary
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


def _median_curve(recs: list[dict[str, Any]], length: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows = []
    for r in recs:
        h = [np.nan if v is None else v for v in r["best_history"][:length]]
        h += [h[-1] if h else np.nan] * (length - len(h))  # a stopped run keeps its best
        rows.append(h)
    arr = np.array(rows, dtype=float)
    with np.errstate(all="ignore"):
        return tuple(np.nanpercentile(arr, q, axis=0) for q in (50, 25, 75))  # type: ignore[return-value]


def _mannwhitney(a: Sequence[float], b: Sequence[float]) -> float | None:
    """One-sided p-value that ``a`` tends to be larger than ``b`` (Mann-Whitney U)."""
    a = [x for x in a if x is not None]
    b = [x for x in b if x is not None]
    if len(a) < 2 or len(b) < 2:
        return None
    try:
        from scipy.stats import mannwhitneyu

        return float(mannwhitneyu(a, b, alternative="greater").pvalue)
    except Exception:  # pragma: no cover - scipy is a dependency
        return None


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


# ----------------------------------------------------------------------------- pictures
def _representative_seed(recs: list[dict[str, Any]]) -> int:
    """The seed whose final fitness is the (lower) median of the runs."""
    order = sorted(recs, key=lambda r: (-np.inf if r["fitness"] is None else r["fitness"], r["seed"]))
    return int(order[(len(order) - 1) // 2]["seed"])


def _crop_white(img: np.ndarray, pad: int = 4) -> np.ndarray:
    rgb = img[..., :3]
    mask = (rgb < 0.97).any(axis=-1)
    if img.shape[-1] == 4:
        mask &= img[..., 3] > 0.05
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return img
    r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, img.shape[0])
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, img.shape[1])
    return img[r0:r1, c0:c1]


def _savefig(fig, path: str, dpi: int) -> str:
    """Write a PNG with a 256-colour palette (a third of the size, no visible loss here)."""
    import io

    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    try:
        from PIL import Image

        buf.seek(0)
        image = Image.open(buf).convert("RGB")
        image.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
            path, optimize=True)
    except Exception:  # pillow comes with matplotlib; fall back to the plain PNG
        with open(path, "wb") as f:
            f.write(buf.getvalue())
    return path


def _grasp_cell(result: GraspResult, obj, hand, path: str, dpi: int) -> np.ndarray:
    """The grasp drawn by ``plotting.plot_grasp`` (fingertip view), legend cut off."""
    import matplotlib.image as mpimg

    from .plotting import plot_grasp

    plot_grasp(result, obj, path=path, title="", hand=hand, views=("fingertips",), dpi=dpi)
    img = mpimg.imread(path)
    img = img[: int(img.shape[0] * 0.915)]  # drop the legend band (bottom 8 % of the figure)
    return _crop_white(img)


def _caption(result: GraspResult, hand) -> str:
    fingers = ", ".join(c.finger for c in result.contacts) or "none"
    return (f"fitness {result.fitness:.3f}, epsilon {result.epsilon:.3f}\n"
            f"{result.n_contacts} contacts ({fingers})\n"
            f"force closure {'yes' if result.force_closure else 'no'}, "
            f"valid {'yes' if valid_grasp(result, hand) else 'no'}")


def _legend_handles():
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from .plotting import FINGER_COLORS

    handles = [Line2D([], [], color=FINGER_COLORS[n], linewidth=5, label=n) for n in FINGER_NAMES]
    handles += [
        Line2D([], [], marker="o", color="black", markerfacecolor="white", markeredgewidth=1.5,
               label="contact + surface normal"),
        Line2D([], [], marker="+", linestyle="none", color="#444444", markersize=9, label="centre of mass"),
        Patch(facecolor=(0.62, 0.66, 0.72), alpha=0.5, label="object"),
        Patch(facecolor="#C8A27A", edgecolor="#8A6A4A", alpha=0.6, label="palm"),
        Line2D([], [], color="0.5", alpha=0.3, linewidth=9, solid_capstyle="round", label="finger volume"),
        Line2D([], [], color="black", linewidth=1.3, linestyle=(0, (2, 1.5)),
               label="link touching the object (not a contact)"),
    ]
    return handles


def table3_figures(cfg: ExperimentConfig, runs: dict, out: str, hand) -> tuple[dict, list[dict[str, Any]]]:
    """Per object, the best grasp at the three snapshot iterations for PSO and APSO.

    Returns the picture paths per object and the determinism checks of the re-runs.
    """
    from matplotlib.figure import Figure

    paths: dict[str, Any] = {}
    checks: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in cfg.objects:
            obj = objects.builtin(name)
            cells: dict[tuple[str, int], tuple[np.ndarray, str]] = {}
            seeds = {}
            for alg in ("pso", "apso"):
                seed = _representative_seed(runs[name][alg])
                seeds[alg] = seed
                main = next(r for r in runs[name][alg] if r["seed"] == seed)
                for k in cfg.snapshots:
                    options = PlanOptions(algorithm=alg, particles=cfg.particles, iterations=k)
                    result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hand)
                    rerun = [_round(h.best_fitness) for h in result.history]
                    rerun_ev = [int(h.evaluations) for h in result.history]
                    same = rerun == main["best_history"][:k] and rerun_ev == main["evaluations_history"][:k]
                    checks.append({"object": name, "algorithm": alg, "seed": seed, "iterations": k,
                                   "prefix_identical": bool(same),
                                   "fitness_rerun": _finite(result.fitness),
                                   "history_best_at_k": main["best_history"][k - 1]})
                    img = _grasp_cell(result, obj, hand, os.path.join(tmp, f"{name}_{alg}_{k}.png"), dpi=70)
                    cells[(alg, k)] = (img, _caption(result, hand))
            fig = Figure(figsize=(13.5, 11.6))
            fig.suptitle(
                f"{OBJECT_LABELS.get(name, name)}: global best grasp at iterations "
                f"{', '.join(map(str, cfg.snapshots))} (np = {cfg.particles})\n"
                f"one run per approach: the seed with the median final fitness over {cfg.seeds} seeds "
                f"(PSO seed {seeds['pso']}, APSO seed {seeds['apso']}); view from beyond the fingertips",
                fontsize=12)
            for row, alg in enumerate(("pso", "apso")):
                for col, k in enumerate(cfg.snapshots):
                    ax = fig.add_axes([0.07 + col * 0.31, 0.585 - row * 0.46, 0.29, 0.335])
                    img, caption = cells[(alg, k)]
                    ax.imshow(img)
                    ax.set_axis_off()
                    ax.set_title(f"iteration {k}", fontsize=11, fontweight="bold")
                    ax.text(0.5, -0.02, caption, transform=ax.transAxes, ha="center", va="top", fontsize=9.5)
                fig.text(0.025, 0.75 - row * 0.46, ALGORITHM_LABELS[alg], rotation=90, ha="center",
                         va="center", fontsize=14, fontweight="bold")
            fig.legend(handles=_legend_handles(), loc="lower center", ncol=6, fontsize=9, frameon=False)
            path = os.path.join(out, f"table3_{name}.png")
            _savefig(fig, path, cfg.dpi)
            paths[name] = os.path.basename(path)
            _log(f"picture {path}")
    return paths, checks


def plot_convergence_panels(cfg: ExperimentConfig, runs: dict, path: str) -> str:
    """Median best fitness per iteration with the inter-quartile band, APSO vs PSO."""
    from matplotlib.figure import Figure

    n = len(cfg.objects)
    ncols = 2 if n > 1 else 1
    nrows = int(math.ceil(n / ncols))
    fig = Figure(figsize=(6.2 * ncols, 4.4 * nrows + 0.6))
    its = np.arange(1, cfg.iterations + 1)
    k20, k50 = cfg.snapshots[1], cfg.snapshots[2]
    for i, name in enumerate(cfg.objects):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        for alg in ("pso", "apso"):
            med, q1, q3 = _median_curve(runs[name][alg], cfg.iterations)
            ax.fill_between(its, q1, q3, color=_COLORS[alg], alpha=0.2, linewidth=0)
            ax.plot(its, med, color=_COLORS[alg], linewidth=2.2,
                    label=f"{ALGORITHM_LABELS[alg]}: median (final {med[-1]:.3f})")
        pso_med = _median_curve(runs[name]["pso"], cfg.iterations)[0]
        apso_med = _median_curve(runs[name]["apso"], cfg.iterations)[0]
        ax.axhline(pso_med[k50 - 1], color=_COLORS["pso"], linestyle=":", linewidth=1.2)
        ax.plot([k20], [apso_med[k20 - 1]], marker="o", color=_COLORS["apso"], markersize=7,
                markeredgecolor="black", linestyle="none",
                label=f"APSO at iteration {k20}: {apso_med[k20 - 1]:.3f} vs PSO at {k50}: {pso_med[k50 - 1]:.3f}")
        for k in cfg.snapshots:
            ax.axvline(k, color="0.75", linewidth=0.8, zorder=0)
        lows = [_median_curve(runs[name][a], cfg.iterations)[j][min(4, cfg.iterations - 1):]
                for a in ("pso", "apso") for j in (0, 1)]
        ax.set_ylim(bottom=float(np.nanmin(np.concatenate(lows))) - 0.03)
        ax.set_title(OBJECT_LABELS.get(name, name), fontsize=11)
        ax.set_xlabel("iteration")
        ax.set_ylabel("global best fitness (maximised)")
        ax.set_xlim(1, cfg.iterations)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower right", fontsize=8.5)
    fig.suptitle(f"Convergence over {cfg.seeds} seeds (np = {cfg.particles}): median global best fitness, "
                 "band = inter-quartile range;\ndotted line: PSO's median at the last iteration; grey lines: "
                 f"iterations {', '.join(map(str, cfg.snapshots))}; the y axis starts near the lowest quartile "
                 f"from iteration {min(5, cfg.iterations)} on", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    _savefig(fig, path, cfg.dpi)
    return path


def _curve_on_evaluations(recs: list[dict[str, Any]], grid: np.ndarray) -> tuple[np.ndarray, ...]:
    """Median and quartiles of the best fitness found within ``grid`` evaluations.

    A run that ended keeps its final best (it found it within fewer evaluations); the
    curve stops at the median of the runs' final evaluation counts; before a run's first
    recorded iteration (GRG's initial draws cost evaluations) it has no value.
    """
    import warnings

    rows = []
    for r in recs:
        ev = np.asarray(r["evaluations_history"], float)
        best = np.array([np.nan if v is None else v for v in r["best_history"]], float)
        idx = np.searchsorted(ev, grid, side="right") - 1
        rows.append(np.where(idx >= 0, best[np.clip(idx, 0, None)], np.nan))
    arr = np.array(rows)
    end = float(np.median([r["evaluations_history"][-1] for r in recs]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        enough = (np.sum(np.isfinite(arr), axis=0) >= max(1, (len(recs) + 1) // 2)) & (grid <= end * 1.0001)
        out = [np.where(enough, np.nanpercentile(arr, q, axis=0), np.nan) for q in (50, 25, 75)]
    return tuple(out)


def plot_evaluation_panels(cfg: ExperimentConfig, runs: dict, path: str) -> str:
    """Median best fitness against evaluations: APSO, PSO on APSO's budget, pyswarms."""
    from matplotlib.figure import Figure

    n = len(cfg.objects)
    ncols = 2 if n > 1 else 1
    nrows = int(math.ceil(n / ncols))
    fig = Figure(figsize=(6.2 * ncols, 4.4 * nrows + 0.6))
    for i, name in enumerate(cfg.objects):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        top = max(max(r["evaluations_history"][-1] for r in recs) for recs in runs[name].values())
        grid = np.linspace(cfg.particles, top, 400)
        lows: list[float] = []
        for alg in ("apso", "pso_equal_budget", "pso", "pyswarms_global", "pyswarms_local"):
            if alg not in runs[name]:
                continue
            med, q1, q3 = _curve_on_evaluations(runs[name][alg], grid)
            style = "--" if alg == "pso" else "-"
            if alg in ("apso", "pso_equal_budget"):
                ax.fill_between(grid, q1, q3, color=_COLORS[alg], alpha=0.15, linewidth=0)
            final = _stats([r["fitness"] for r in runs[name][alg]])["median"]
            label = f"{ALGORITHM_LABELS[alg]}" + (f" (final median {final:.3f})" if final is not None else "")
            if alg in ("apso", "pso"):
                start = max(len(med) // 10, 1)
                lows.append(np.nanmin(np.where(np.isfinite(q1[start:]), q1[start:], np.inf)))
            ax.plot(grid, med, color=_COLORS[alg], linewidth=2.0, linestyle=style, label=label)
        ax.set_title(OBJECT_LABELS.get(name, name), fontsize=11)
        if lows and np.isfinite(min(lows)):
            ax.set_ylim(bottom=float(min(lows)) - 0.03)
        ax.set_xlabel("evaluations (particle decodes, GRG draws included)")
        ax.set_ylabel("global best fitness (maximised)")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower right", fontsize=8.5)
    fig.suptitle(f"Fitness against evaluations over {cfg.seeds} seeds (np = {cfg.particles}): median, band = "
                 "inter-quartile range (APSO and PSO on APSO's budget);\nthe y axis starts near the lowest "
                 "APSO/PSO quartile after the first tenth of the budget", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    _savefig(fig, path, cfg.dpi)
    return path


# ----------------------------------------------------------------------------- speed
def _sweep_mesh(kind: str, size: int):
    import trimesh

    if kind == "icosphere":
        return trimesh.creation.icosphere(subdivisions=size, radius=0.025)
    if kind == "uv":
        return trimesh.creation.uv_sphere(radius=0.025, count=[size, size])
    raise ValueError(f"mesh kind: {kind!r}")


def _clear_caches() -> None:
    from . import planner, sdf

    with sdf._CACHE_LOCK:
        sdf._CACHE.clear()
    with planner._BVH_LOCK:
        planner._BVH_CACHE.clear()


def run_speed(speed: SpeedConfig, hand=None, per_object: dict | None = None,
              objects_: Sequence[str] = objects.BUILTIN_OBJECTS, log: Callable[[str], None] = _log) -> dict[str, Any]:
    """Plan time per object, and how it grows with particles, iterations and triangles.

    ``per_object``: plan times already measured (``{object: {algorithm: [records]}}``);
    otherwise ``speed.per_object_runs`` plans per object and algorithm are timed here.
    Mesh sweep: spheres of 5 cm diameter; per mesh the object construction (validation),
    the preparation (signed-distance grid; caches cleared first), a cold plan (includes the
    python-fcl BVH build) and warm plans are timed separately (APSO, np = 60, nit = 50).
    """
    hand = hand or load_hand()
    result: dict[str, Any] = {"config": asdict(speed), "per_object": {}, "particles": [], "iterations": [],
                              "meshes": []}

    def timed(obj, options, seed):
        r = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hand)
        return r

    for name in objects_:
        obj = objects.builtin(name)
        result["per_object"][name] = {}
        for alg in ("apso", "pso"):
            if per_object is not None:
                recs = per_object[name][alg]
                times = [r["planning_time"] for r in recs]
                evals = [r["evaluations"] for r in recs]
            else:
                timed(obj, PlanOptions(iterations=1), 0)  # preparation outside the timing
                rs = [timed(obj, PlanOptions(algorithm=alg), s) for s in range(speed.per_object_runs)]
                times = [r.planning_time for r in rs]
                evals = [r.evaluations for r in rs]
            result["per_object"][name][alg] = {
                "runs": len(times), "planning_time": _stats(times), "evaluations": _stats(evals),
                "evaluations_per_second": _stats([e / t for e, t in zip(evals, times) if t > 0]),
            }
        log(f"speed {name}: APSO {result['per_object'][name]['apso']['planning_time']['median']:.3f} s, "
            f"PSO {result['per_object'][name]['pso']['planning_time']['median']:.3f} s (median)")

    obj = objects.builtin(speed.sweep_object)
    timed(obj, PlanOptions(iterations=1), 0)
    for key, values in (("particles", speed.particles), ("iterations", speed.iterations)):
        for v in values:
            for alg in ("apso", "pso"):
                options = PlanOptions(algorithm=alg, **{key: int(v)})
                rs = [timed(obj, options, s) for s in range(speed.repeats)]
                times = [r.planning_time for r in rs]
                evals = [r.evaluations for r in rs]
                result[key].append({
                    key: int(v), "algorithm": alg, "planning_time": _stats(times),
                    "evaluations": _stats(evals),
                    "evaluations_per_second": _stats([e / t for e, t in zip(evals, times) if t > 0]),
                })
        log(f"speed sweep over {key} done")

    for label, kind, size in speed.meshes:
        mesh = _sweep_mesh(kind, size)
        t0 = time.perf_counter()
        obj = objects.from_arrays(np.asarray(mesh.vertices), np.asarray(mesh.faces), name=f"{kind}{size}")
        construct = time.perf_counter() - t0
        _clear_caches()
        rs = [timed(obj, PlanOptions(), s) for s in range(max(1, speed.mesh_repeats))]
        warm = [r.planning_time for r in rs[1:]] or [rs[0].planning_time]
        entry = {
            "label": label, "triangles": int(len(obj.mesh.faces)), "vertices": int(len(obj.mesh.vertices)),
            "hull_vertices": int(len(obj.hull_vertices)), "closed": bool(obj.mesh.is_watertight),
            "construction_time": construct, "preparation_time": rs[0].preparation_time,
            "plan_time_cold": rs[0].planning_time, "plan_time_warm": _stats(warm)["median"],
            "total_cold": construct + rs[0].preparation_time + rs[0].planning_time,
            "prep_plus_plan": rs[0].preparation_time + rs[0].planning_time,
            "evaluations": _stats([r.evaluations for r in rs])["median"],
            "fitness": _stats([r.fitness for r in rs])["median"],
        }
        result["meshes"].append(entry)
        log(f"speed mesh {label} ({entry['triangles']} triangles): prep {entry['preparation_time']:.2f} s, "
            f"plan cold {entry['plan_time_cold']:.2f} s, warm {entry['plan_time_warm']:.2f} s")
    _clear_caches()
    return result


def format_speed_tables(speed: dict[str, Any]) -> str:
    """Markdown tables of :func:`run_speed`'s result."""
    lines = ["Plan time per object (np = 60, nit = 50; geometry prepared; median over the runs):", "",
             "| object | APSO time (s) | PSO time (s) | APSO evaluations | PSO evaluations | APSO evals/s | PSO evals/s | runs |",
             "|---|---|---|---|---|---|---|---|"]
    for name, by in speed["per_object"].items():
        a, p = by["apso"], by["pso"]
        lines.append(f"| {name} | {_fmt(a['planning_time']['median'])} | {_fmt(p['planning_time']['median'])} | "
                     f"{_fmt(a['evaluations']['median'], 0)} | {_fmt(p['evaluations']['median'], 0)} | "
                     f"{_fmt(a['evaluations_per_second']['median'], 0)} | "
                     f"{_fmt(p['evaluations_per_second']['median'], 0)} | {a['runs']} |")
    cfg = speed["config"]
    for key, fixed in (("particles", "nit = 50"), ("iterations", "np = 60")):
        lines += ["", f"Plan time against {key} ({cfg['sweep_object']}, {fixed}, median of {cfg['repeats']} runs):", "",
                  f"| {key} | APSO time (s) | PSO time (s) | APSO evaluations | PSO evaluations | APSO evals/s | PSO evals/s |",
                  "|---|---|---|---|---|---|---|"]
        values = sorted({e[key] for e in speed[key]})
        for v in values:
            a = next(e for e in speed[key] if e[key] == v and e["algorithm"] == "apso")
            p = next(e for e in speed[key] if e[key] == v and e["algorithm"] == "pso")
            lines.append(f"| {v} | {_fmt(a['planning_time']['median'])} | {_fmt(p['planning_time']['median'])} | "
                         f"{_fmt(a['evaluations']['median'], 0)} | {_fmt(p['evaluations']['median'], 0)} | "
                         f"{_fmt(a['evaluations_per_second']['median'], 0)} | "
                         f"{_fmt(p['evaluations_per_second']['median'], 0)} |")
    lines += ["", "Mesh size (spheres of 5 cm diameter, APSO np = 60, nit = 50; caches cleared before the "
              "preparation; cold plan = first plan, includes the python-fcl BVH build; warm = median of the "
              "later plans):", "",
              "| mesh | triangles | hull vertices | construction (s) | preparation (s) | plan cold (s) | plan warm (s) | preparation + plan (s) |",
              "|---|---|---|---|---|---|---|---|"]
    for m in speed["meshes"]:
        lines.append(f"| {m['label']}{'' if m['closed'] else ' (not closed)'} | {m['triangles']} | "
                     f"{m['hull_vertices']} | {m['construction_time']:.3f} | {m['preparation_time']:.3f} | "
                     f"{m['plan_time_cold']:.3f} | {m['plan_time_warm']:.3f} | {m['prep_plus_plan']:.3f} |")
    return "\n".join(lines)


def plot_speed(speed: dict[str, Any], path: str, dpi: int = 100) -> str:
    """Plan time against particles, iterations and mesh triangles (one figure, 3 panels)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(15.0, 4.8))
    cfg = speed["config"]
    for i, (key, fixed) in enumerate((("particles", "nit = 50"), ("iterations", "np = 60"))):
        ax = fig.add_subplot(1, 3, i + 1)
        for alg in ("apso", "pso"):
            pts = sorted((e[key], e["planning_time"]) for e in speed[key] if e["algorithm"] == alg)
            xs = [p[0] for p in pts]
            med = [p[1]["median"] for p in pts]
            lo = [p[1]["median"] - p[1]["min"] for p in pts]
            hi = [p[1]["max"] - p[1]["median"] for p in pts]
            ax.errorbar(xs, med, yerr=[lo, hi], marker="o", capsize=3, color=_COLORS[alg],
                        label=f"{ALGORITHM_LABELS[alg]} (median, bars min-max)")
        ax.axhline(0.3, color="0.4", linestyle=":", linewidth=1.2, label="0.3 s target (np 60, nit 50)")
        ax.set_xlabel(f"number of {key}")
        ax.set_ylabel("plan time (s)")
        ax.set_title(f"plan time vs {key} ({cfg['sweep_object']}, {fixed}, {cfg['repeats']} run(s) per point)",
                     fontsize=10)
        ax.set_xticks(sorted({e[key] for e in speed[key]}))
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8.5, loc="upper left")
    ax = fig.add_subplot(1, 3, 3)
    ms = sorted(speed["meshes"], key=lambda m: m["triangles"])
    tri = [m["triangles"] for m in ms]
    for key, label, color, style in (
        ("preparation_time", "preparation (signed-distance grid)", "#009E73", "o-"),
        ("plan_time_warm", "plan, warm (geometry prepared)", _COLORS["apso"], "s-"),
        ("prep_plus_plan", "preparation + first plan", "#000000", "^--"),
        ("construction_time", "object construction (mesh validation)", "#999999", "v:"),
    ):
        ax.plot(tri, [m[key] for m in ms], style, color=color, label=label)
    ax.axhline(1.0, color="0.4", linestyle=":", linewidth=1.2, label="1 s target incl. preparation (10k triangles)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(tri)
    ax.set_xticklabels([f"{t / 1000:.1f}k" if t < 10_000 else f"{t / 1000:.0f}k" for t in tri])
    ax.minorticks_off()
    ax.grid(True, which="major", alpha=0.3)
    ax.set_xlabel("mesh triangles (5 cm spheres)")
    ax.set_ylabel("time (s)")
    ax.set_title("time vs mesh size (APSO, np = 60, nit = 50)", fontsize=10)
    ax.legend(fontsize=8, loc="best")
    fig.suptitle("Planner speed on this machine", fontsize=12)
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    _savefig(fig, path, dpi)
    return path


# ----------------------------------------------------------------------------- report
def _machine() -> dict[str, Any]:
    info: dict[str, Any] = {"python": platform.python_version(), "numpy": np.__version__,
                            "cpus": os.cpu_count(), "platform": platform.platform()}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    info["cpu"] = line.split(":", 1)[1].strip()
                    break
        info["load_average_at_start"] = list(os.getloadavg())
    except OSError:
        pass
    # The commit of the sources (GRASP_APSO_GIT_COMMIT names it for a copy outside git) and
    # whether the planner's sources differ from it.
    here = os.path.dirname(os.path.abspath(__file__))
    info["git_commit"] = os.environ.get("GRASP_APSO_GIT_COMMIT")
    if not info["git_commit"]:
        try:
            git = ["git", "-C", here]
            info["git_commit"] = subprocess.run(git + ["rev-parse", "--short", "HEAD"], capture_output=True,
                                                text=True, timeout=5).stdout.strip() or None
            changed = subprocess.run(git + ["status", "--porcelain", "--", "."], capture_output=True, text=True,
                                     timeout=5).stdout.split("\n")
            info["uncommitted_sources"] = sorted(line[3:] for line in changed if line.strip())
        except Exception:
            info["git_commit"] = None
    return info


def _holds(flag: bool) -> str:
    return "holds" if flag else "does NOT hold"


def headline_table(summary: dict[str, Any]) -> str:
    """Markdown: per object, APSO vs PSO final fitness (median [IQR]), FC and valid rates, time."""
    lines = ["| object | APSO final fitness | PSO final fitness | APSO FC | PSO FC | APSO valid | PSO valid | "
             "APSO time (s) | PSO time (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for name, by in summary.items():
        a, p = by["apso"], by["pso"]
        lines.append(f"| {name} | {_med_iqr(a['fitness'])} | {_med_iqr(p['fitness'])} | "
                     f"{_pct(a['force_closure_rate'])} | {_pct(p['force_closure_rate'])} | {_pct(a['valid_rate'])} | "
                     f"{_pct(p['valid_rate'])} | {_fmt(a['planning_time']['median'])} | "
                     f"{_fmt(p['planning_time']['median'])} |")
    return "\n".join(lines)


def write_report(cfg: ExperimentConfig, data: dict[str, Any], path: str) -> str:
    s, c = data["summary"], data["claims"]
    k5, k20, k50 = cfg.snapshots
    L: list[str] = []
    meta = data["meta"]
    L += ["# APSO vs simple PSO: the paper's experiment (section 5, Table 3)", "",
          f"Generated by `{cfg.command}` in {meta['wall_time_s']:.0f} s on {meta['machine'].get('cpus')} CPUs "
          f"({meta['machine'].get('cpu', '?')}; load average at start "
          f"{', '.join(f'{x:.1f}' for x in meta['machine'].get('load_average_at_start', []))}); "
          f"git {meta['machine'].get('git_commit')}"
          + (" with uncommitted changes in " + ", ".join(meta['machine']['uncommitted_sources'])
             if meta['machine'].get('uncommitted_sources') else "")
          + f"; numpy {meta['machine']['numpy']}"
          + (f", pyswarms {data['pyswarms']['version']}" if data.get("pyswarms", {}).get("available") else "") + ".",
          "",
          f"Setup: objects {', '.join(cfg.objects)}; np = {cfg.particles}, nit = {cfg.iterations}, "
          f"neighbourhoods of 5, fixed seeds 0..{cfg.seeds - 1} (`numpy.random.default_rng(seed)`). "
          "Fitness is maximised (a valid grasp scores in [0, 1]). **Valid** = at least 3 fingertip contacts, "
          "no penetration beyond 1 mm by the python-fcl check, the planner's own legality and the joint "
          "limits. **FC** = force closure by the Ferrari-Canny epsilon (friction 0.5, 8-edge cones). "
          "Spreads are the inter-quartile range [25 %, 75 %]; all numbers are in `results.json`.", ""]
    if cfg.quick:
        L += ["**Quick mode (CI): few seeds, objects and iterations; the numbers are not the experiment's.**", ""]

    # Headline
    L += ["## Headline", "", headline_table(s), ""]

    # Claims
    L += ["## The paper's claims, measured", ""]
    acc = c["accuracy"]
    L += [f"**Accuracy (APSO's final fitness above PSO's, median over seeds): {_holds(all(v['holds'] for v in acc.values()))} "
          f"for every object ({c['accuracy_holds_on']} objects).**", ""]
    for name, v in acc.items():
        pv = v["p_value_mannwhitney"]
        L.append(f"- {name}: APSO {_fmt(v['apso_median'])} vs PSO {_fmt(v['pso_median'])}, {_holds(v['holds'])}; "
                 f"APSO better in {v['apso_better_seeds']} of {v['seeds']} seeds"
                 + (f"; one-sided Mann-Whitney p = {pv:.2g}" if pv is not None else "") + ".")
    conv = c["convergence"]
    n_conv = sum(v["holds"] for v in conv.values())
    L += ["", f"**Convergence speed (APSO's median at iteration {k20} >= PSO's median at iteration {k50}): "
          f"{_holds(n_conv >= min(3, len(conv)))} — on {n_conv} of {len(conv)} objects (claim: at least 3 of 4).**", ""]
    for name, v in conv.items():
        first = v["apso_first_iteration_reaching_pso_final"]
        L.append(f"- {name}: APSO at {k20} {_fmt(v['apso_at_mid'])} vs PSO at {k50} {_fmt(v['pso_at_end'])}, "
                 f"{_holds(v['holds'])}; APSO's median first reaches PSO's final median at iteration "
                 f"{first if first is not None else 'never'}; per seed, APSO at {k20} >= PSO at {k50} in "
                 f"{_pct(v['seed_pairs_apso_mid_ge_pso_end'])} of the seed pairs. In evaluations: APSO has used "
                 f"{_fmt(v['apso_evaluations_at_mid'], 0)} by iteration {k20}, PSO {_fmt(v['pso_evaluations_at_end'], 0)} "
                 f"by iteration {k50}.")
    rel = c["reliability"]
    L += ["", f"**Reliability (APSO >= 95 % valid and >= 90 % force closure): met on {c['reliability_holds_on']} "
          "objects.** Spread = inter-quartile range of the final fitness; worst = lowest final fitness over the seeds.", "",
          "| object | APSO valid | APSO FC | PSO valid | PSO FC | APSO spread | PSO spread | APSO worst | PSO worst |",
          "|---|---|---|---|---|---|---|---|---|"]
    for name, v in rel.items():
        L.append(f"| {name} | {_pct(v['apso_valid_rate'])} | {_pct(v['apso_fc_rate'])} | {_pct(v['pso_valid_rate'])} | "
                 f"{_pct(v['pso_fc_rate'])} | {_fmt(v['apso_iqr'])} | {_fmt(v['pso_iqr'])} | {_fmt(v['apso_worst'])} | "
                 f"{_fmt(v['pso_worst'])} |")
    sp = c["speed"]
    ratio_t = np.median([v["apso_time"] / v["pso_time"] for v in sp.values()])
    ratio_e = np.median([v["apso_evaluations"] / v["pso_evaluations"] for v in sp.values()])
    ratio_r = np.median([v["apso_evals_per_s"] / v["pso_evals_per_s"] for v in sp.values()])
    L += ["", f"**PSO faster per run (median plan time): {_holds(all(v['holds'] for v in sp.values()))} "
          f"({c['speed_holds_on']} objects).** APSO takes {ratio_t:.2f} times PSO's time (median over the "
          f"objects) for {ratio_e:.2f} times its evaluations (GRG's initial draws, replacements and their "
          f"verification); per evaluation APSO runs at {ratio_r:.2f} times PSO's rate.", "",
          "| object | APSO time (s) | PSO time (s) | APSO evaluations | PSO evaluations | APSO evals/s | PSO evals/s | APSO <= 0.3 s |",
          "|---|---|---|---|---|---|---|---|"]
    for name, v in sp.items():
        L.append(f"| {name} | {_fmt(v['apso_time'])} | {_fmt(v['pso_time'])} | {_fmt(v['apso_evaluations'], 0)} | "
                 f"{_fmt(v['pso_evaluations'], 0)} | {_fmt(v['apso_evals_per_s'], 0)} | {_fmt(v['pso_evals_per_s'], 0)} | "
                 f"{'yes' if v['apso_meets_0_3_s'] else 'no'} |")
    if c["equal_budget"]:
        eb = c["equal_budget"]
        L += ["", f"**Fair budget (PSO given the same evaluations as APSO, seed by seed): APSO still better on "
              f"{c['equal_budget_holds_on']} objects.**", "",
              "| object | APSO final | PSO, APSO's budget | its evaluations | its FC | its valid | p (APSO greater) |",
              "|---|---|---|---|---|---|---|"]
        for name, v in eb.items():
            pv = v["p_value_mannwhitney"]
            L.append(f"| {name} | {_fmt(v['apso_median'])} | {_fmt(v['pso_equal_median'])} | "
                     f"{_fmt(v['pso_equal_evaluations'], 0)} | {_pct(v['pso_equal_fc_rate'])} | "
                     f"{_pct(v['pso_equal_valid_rate'])} | {'n/a' if pv is None else f'{pv:.2g}'} |")
        changed = [n for n in eb if acc[n]["holds"] != eb[n]["holds"]]
        L += ["", ("The conclusion changes with an equal budget on: " + ", ".join(changed) + ".") if changed
              else "The accuracy conclusion does not change with an equal budget."]
    L += [""]

    # Table 3 numbers
    L += ["## Table 3 in numbers", "",
          f"Global best fitness at iterations {k5}, {k20}, {k50}: median [25 %, 75 %] over {cfg.seeds} seeds; "
          "the final grasp: median contacts, median epsilon [IQR], rates, median plan time and evaluations.", "",
          f"| object | approach | fitness @{k5} | fitness @{k20} | fitness @{k50} | contacts | epsilon | FC | valid | "
          "thumb | other link touching | time (s) | evaluations |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in cfg.objects:
        for alg in ("pso", "apso"):
            v = s[name][alg]
            L.append(f"| {name} | {ALGORITHM_LABELS[alg]} | " + " | ".join(_med_iqr(v["fitness_at"][str(k)]) for k in cfg.snapshots)
                     + f" | {_fmt(v['n_contacts']['median'], 0)} | {_med_iqr(v['epsilon'])} | "
                     f"{_pct(v['force_closure_rate'])} | {_pct(v['valid_rate'])} | {_pct(v['thumb_rate'])} | "
                     f"{_pct(v['links_touching_rate'])} | {_fmt(v['planning_time']['median'])} | "
                     f"{_fmt(v['evaluations']['median'], 0)} |")
    L += ["", "*thumb*: share of final grasps with the thumb among the contacts; *other link touching*: share "
          "of final grasps where a link other than a contacting fingertip rests on the object (python-fcl "
          "distance 0; drawn dashed in the pictures), i.e. not a pure fingertip grasp.", "",
          "Min-max of the final fitness: " + "; ".join(
        f"{n} PSO {_fmt(s[n]['pso']['fitness']['min'])}-{_fmt(s[n]['pso']['fitness']['max'])}, "
        f"APSO {_fmt(s[n]['apso']['fitness']['min'])}-{_fmt(s[n]['apso']['fitness']['max'])}" for n in cfg.objects) + ".", ""]

    # Pictures
    L += ["## Table 3 in pictures", "",
          f"For each object and approach, the run with the median final fitness; its global best at iterations "
          f"{k5}, {k20} and {k50} (the same seed re-run with `iterations=k`; "
          f"{sum(d['prefix_identical'] for d in data['determinism'])} of {len(data['determinism'])} re-runs "
          "reproduce the first k iterations of the full run exactly).", ""]
    for name, pic in data["pictures"]["table3"].items():
        L += [f"### {name}", "", f"![{name}: best grasp at iterations {k5}, {k20}, {k50}]({pic})", ""]
    L += ["## Convergence", "", f"![convergence]({data['pictures']['convergence']})", "",
          "The same against evaluations (GRG's draws count), with PSO on APSO's budget and pyswarms:", "",
          f"![fitness against evaluations]({data['pictures']['convergence_evaluations']})", ""]

    # Peers
    ps = data.get("pyswarms", {})
    L += ["## Peer optimisers: pyswarms", ""]
    if not ps.get("available"):
        L += [f"pyswarms could not be used: {ps.get('version')}.", ""]
    else:
        L += [f"pyswarms {ps['version']} `GlobalBestPSO` and `LocalBestPSO` (ring of k = {PYSWARMS_LOCAL['k']} "
              f"neighbours, p = {PYSWARMS_LOCAL['p']}) minimise `-Objective(x)` over the planner's bounds with "
              f"{cfg.particles} particles, options c1 = {PYSWARMS_OPTIONS['c1']}, c2 = {PYSWARMS_OPTIONS['c2']}, "
              f"w = {PYSWARMS_OPTIONS['w']} (our PSO's), `bh_strategy='{PYSWARMS_BOUNDARY}'` (clamp into the "
              "bounds like ours), no velocity clamp (their default); iterations = APSO's median evaluations / "
              f"{cfg.particles} per object ({', '.join(f'{k}: {v}' for k, v in ps['iterations'].items())}). "
              "pyswarms draws from numpy's global random state: `np.random.seed(seed)` before each run (their "
              "API). The final particle is verified with `Objective.result` exactly as `plan` verifies its best.", "",
              "| object | optimiser | final fitness | FC | valid | evaluations | time (s) | APSO better? (p) |",
              "|---|---|---|---|---|---|---|---|"]
        for name in cfg.objects:
            for alg in ("apso", "pso_equal_budget", "pyswarms_global", "pyswarms_local"):
                if alg not in s[name]:
                    continue
                v = s[name][alg]
                cmp = ""
                if alg.startswith("pyswarms"):
                    pc = c["peers"][name][alg]
                    pv = pc["p_value_apso_greater"]
                    cmp = f"{'yes' if pc['apso_better'] else 'no'} ({'n/a' if pv is None else f'{pv:.2g}'})"
                L.append(f"| {name} | {ALGORITHM_LABELS[alg]} | {_med_iqr(v['fitness'])} | {_pct(v['force_closure_rate'])} | "
                         f"{_pct(v['valid_rate'])} | {_fmt(v['evaluations']['median'], 0)} | "
                         f"{_fmt(v['planning_time']['median'])} | {cmp} |")
        L += ["", "pyswarms times include its own overhead (LocalBestPSO builds a k-d tree of the particles every "
              "iteration) and the final verification.", ""]

    # Speed
    if data.get("speed"):
        load = meta["machine"].get("load_average_at_end")
        L += ["## Speed", "",
              "Wall-clock times on a shared 2-core machine (other processes ran at the same time: load average "
              f"{', '.join(f'{x:.1f}' for x in meta['machine'].get('load_average_at_start', []))} at the start"
              + (f", {', '.join(f'{x:.1f}' for x in load)} at the end" if load else "")
              + "); the same plan can take 1.5 times longer from one run to the next. "
              "`bench/bench_planner.py` repeats these measurements alone.", "", format_speed_tables(data["speed"]), "",
              f"![speed]({data['pictures']['speed']})", ""]
        tgt = data["claims"].get("targets", {})
        if tgt:
            L += [f"Targets: 0.3 s per plan (np = 60, nit = 50, prepared geometry): APSO meets it on "
                  f"{tgt['plan_0_3_s']}; 1 s including the preparation of a ~10,000-triangle mesh: "
                  f"{tgt['prep_plus_plan_10k']}.", ""]

    # Observations
    L += ["## Observations", ""]
    if data["anomalies"]:
        L += [f"{len(data['anomalies'])} suspicious results found automatically (first 20):", ""]
        L += [f"- {a}" for a in data["anomalies"][:20]]
    else:
        L += ["No automatic check flagged a run (global best never decreases, the verified final fitness equals "
              "the swarm's global best, no valid grasp with a python-fcl collision, penetration above 1 mm, "
              "force closure with epsilon <= 0 or a joint beyond its limit)."]
    L += [""] + [f"- {note}" for note in data.get("notes", [])] + [""]
    with open(path, "w") as f:
        f.write("\n".join(L))
    return path


def _targets(speed: dict[str, Any] | None, claims: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    sp = claims["speed"]
    met = [n for n, v in sp.items() if v["apso_meets_0_3_s"]]
    out["plan_0_3_s"] = f"{len(met)} of {len(sp)} objects" + (f" ({', '.join(met)})" if met else "")
    if speed and speed.get("meshes"):
        near = min(speed["meshes"], key=lambda m: abs(m["triangles"] - 10_000))
        t = near["prep_plus_plan"]
        out["prep_plus_plan_10k"] = (f"{'met' if t <= 1.0 else 'NOT met'}: {t:.2f} s for {near['triangles']} "
                                     f"triangles ({near['preparation_time']:.2f} s preparation + "
                                     f"{near['plan_time_cold']:.2f} s first plan)")
    return out


def _notes(data: dict[str, Any]) -> list[str]:
    """Observations derived from the numbers: thumb use, links resting on the object, the
    mesh-size scaling of the plan time."""
    notes = []
    summary = data["summary"]
    rare = [f"{n} {summary[n]['apso']['thumb_rate'] * 100:.0f} %" for n in summary
            if (summary[n]["apso"]["thumb_rate"] or 0) < 0.5]
    if rare:
        notes.append("APSO's final grasp seldom uses the thumb on: " + ", ".join(rare) + " of the runs (the "
                     "contacts are then the four fingers alone, wrapped around the object; the fitness and the "
                     "epsilon still call most of them force closure). PSO's thumb use: " + ", ".join(
                         f"{n} {summary[n]['pso']['thumb_rate'] * 100:.0f} %" for n in summary) + ".")
    runs = data["runs"]
    try:
        from scipy.stats import spearmanr
    except Exception:  # pragma: no cover - scipy is a dependency
        spearmanr = None
    above, rhos = [], []
    for n in runs:
        recs = [r for r in runs[n]["apso"] if r["fitness"] is not None]
        fc_fit = [r["fitness"] for r in recs if r["force_closure"]]
        non = [r["fitness"] for r in recs if not r["force_closure"]]
        if non and fc_fit:
            high = sum(f >= float(np.median(fc_fit)) for f in non)
            if high:
                above.append(f"{n} {high} of {len(non)}")
        if spearmanr is not None and len(recs) >= 5 and len({r["epsilon"] for r in recs}) > 1:
            rho = spearmanr([r["fitness"] for r in recs], [r["epsilon"] for r in recs]).statistic
            rhos.append(f"{n} {rho:.2f}")
    if above or rhos:
        notes.append("Fitness and force closure: " + (
            "APSO's final grasps without force closure that score at or above the median force-closure grasp: "
            + ", ".join(above) + ". " if above else "") + (
            "Rank correlation (Spearman) of fitness with epsilon over APSO's final grasps: " + ", ".join(rhos)
            + " (near 0: among good grasps the fitness does not follow the epsilon quality)." if rhos else ""))
    invalid = [f"{n} {ALGORITHM_LABELS[a]} seed {r['seed']} (fitness {_fmt(r['fitness'])}, {r['n_contacts']} contacts)"
               for n in runs for a in ("apso", "pso") for r in runs[n][a] if not r["valid"]]
    if invalid:
        notes.append("Final grasps that are not valid: " + "; ".join(invalid) + ".")
    touching = [f"{n} {ALGORITHM_LABELS[a]} {summary[n][a]['links_touching_rate'] * 100:.0f} %"
                for n in summary for a in ("apso", "pso") if (summary[n][a]["links_touching_rate"] or 0) > 0.2]
    if touching:
        notes.append("Final grasps with a link other than a contacting fingertip resting on the object "
                     "(python-fcl distance 0; not counted as contacts, so not a pure precision grasp): "
                     + ", ".join(touching) + ".")
    speed = data.get("speed")
    if speed and len(speed.get("meshes", [])) >= 2:
        ms = sorted(speed["meshes"], key=lambda m: m["triangles"])
        lo, hi = ms[0], ms[-1]
        if hi["preparation_time"] > 3.0 * lo["preparation_time"]:
            notes.append(
                f"The preparation (signed-distance grid) grows with the mesh: {lo['preparation_time']:.2f} s at "
                f"{lo['triangles']} triangles to {hi['preparation_time']:.2f} s at {hi['triangles']}.")
        if hi["plan_time_warm"] > 2.0 * lo["plan_time_warm"]:
            notes.append(
                f"The plan time (geometry already prepared) grows with the mesh: {lo['plan_time_warm']:.2f} s at "
                f"{lo['triangles']} triangles ({lo['hull_vertices']} hull vertices) to {hi['plan_time_warm']:.2f} s at "
                f"{hi['triangles']} ({hi['hull_vertices']} hull vertices), although the fitness reads a "
                "signed-distance grid. A profile of one plan on a 20k-triangle UV sphere put the largest share in "
                "the wrist placement (`contacts.wrist_transforms`: the object's support toward the palm taken "
                "over every convex-hull vertex for every particle decode).")
    return notes


def run_experiment(cfg: ExperimentConfig, out: str) -> dict[str, Any]:
    """Run everything and write ``report.md``, ``results.json`` and the pictures into ``out``."""
    os.makedirs(out, exist_ok=True)
    t_start = time.perf_counter()
    hand = load_hand()
    machine = _machine()
    _log(f"{len(cfg.objects)} objects x {cfg.seeds} seeds, np = {cfg.particles}, nit = {cfg.iterations} -> {out}")
    runs = run_main(cfg, hand)
    peers = run_pyswarms(cfg, runs, hand) if cfg.peers else {"available": False, "version": "not run (--no-peers)"}
    summary = summarise(cfg, runs)
    claims = evaluate_claims(cfg, runs, summary)
    table3, determinism = table3_figures(cfg, runs, out, hand)
    pictures: dict[str, Any] = {"table3": table3}
    pictures["convergence"] = os.path.basename(plot_convergence_panels(cfg, runs, os.path.join(out, "convergence.png")))
    pictures["convergence_evaluations"] = os.path.basename(
        plot_evaluation_panels(cfg, runs, os.path.join(out, "convergence_evaluations.png")))
    speed = None
    if cfg.speed is not None:
        speed = run_speed(cfg.speed, hand, per_object={n: runs[n] for n in cfg.objects}, objects_=cfg.objects)
        pictures["speed"] = os.path.basename(plot_speed(speed, os.path.join(out, "speed.png"), dpi=cfg.dpi))
    claims["targets"] = _targets(speed, claims)
    wall = time.perf_counter() - t_start
    data = {
        "meta": {"command": cfg.command, "config": asdict(cfg), "machine": machine, "wall_time_s": wall,
                 "valid_definition": "n_contacts >= 3 and result.valid and result.fcl.legal and joint limits",
                 "spread": "q1/q3 = 25th/75th percentiles (numpy linear interpolation)"},
        "summary": summary, "claims": claims, "pyswarms": peers, "determinism": determinism,
        "pictures": pictures, "speed": speed, "runs": runs,
    }
    data["anomalies"] = find_anomalies(runs)
    if not all(d["prefix_identical"] for d in determinism):
        data["anomalies"].insert(0, "re-running a seed with fewer iterations did NOT reproduce the first k "
                                    "iterations of the full run: the Table 3 pictures may not show that run's best")
    try:
        data["meta"]["machine"]["load_average_at_end"] = list(os.getloadavg())
    except OSError:
        pass
    data["notes"] = _notes(data)
    write_report(cfg, data, os.path.join(out, "report.md"))
    with open(os.path.join(out, "results.json"), "w") as f:
        f.write(_compact_json(data))
    _log(f"done in {wall:.0f} s: {os.path.join(out, 'report.md')}")
    return data


def _compact_json(data: Any) -> str:
    """Indented JSON with lists of numbers kept on one line."""
    import re

    text = json.dumps(data, indent=1, default=_json_default)
    return re.sub(r"\[\s*((?:-?[0-9][0-9.eE+-]*|null)(?:,\s*(?:-?[0-9][0-9.eE+-]*|null))*)\s*\]",
                  lambda m: "[" + re.sub(r"\s+", "", m.group(1)).replace(",", ", ") + "]", text)


def _json_default(o: Any) -> Any:
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return _finite(float(o))
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (set, tuple)):
        return list(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


# ----------------------------------------------------------------------------- command line
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m grasp_apso.experiment",
        description="APSO vs simple PSO on the paper's four objects (Table 3), pyswarms peers and speed; "
                    "writes report.md, results.json and pictures.")
    p.add_argument("--seeds", type=int, default=None, help="seeds 0..N-1 (default 20; quick: 2)")
    p.add_argument("--out", default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    p.add_argument("--quick", action="store_true",
                   help="CI mode: 2 seeds, sphere and cube, np = 20, nit = 10, small speed sweeps")
    p.add_argument("--objects", default=None, help="comma-separated subset of sphere,cube,barrel,fish")
    p.add_argument("--no-peers", action="store_true", help="skip pyswarms")
    p.add_argument("--no-speed", action="store_true", help="skip the speed measurements")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    given = list(sys.argv[1:] if argv is None else argv)
    kw: dict[str, Any] = {"command": " ".join(["python -m grasp_apso.experiment", *given])}
    if args.seeds is not None:
        kw["seeds"] = args.seeds
    if args.objects:
        kw["objects"] = tuple(o.strip() for o in args.objects.split(",") if o.strip())
    if args.no_peers:
        kw["peers"] = False
    if args.no_speed:
        kw["speed"] = None
    try:
        cfg = ExperimentConfig.quick_config(**kw) if args.quick else ExperimentConfig(**kw)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    run_experiment(cfg, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
