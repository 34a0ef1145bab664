"""The runs: APSO, the simple PSO and PSO on APSO's evaluation budget over the seeds, and
pyswarms' GlobalBestPSO / LocalBestPSO on the planner's fitness; each run kept as a record."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..model import builtin as builtin_objects
from ..search.planner import GraspResult, Objective, PlanOptions, plan
from .config import PYSWARMS_BOUNDARY, PYSWARMS_LOCAL, PYSWARMS_OPTIONS, ExperimentConfig
from .progress import _log
from .records import record_of
from .stats import _finite, _round, _stats


def _plan_record(obj, options: PlanOptions, seed: int, hand) -> tuple[GraspResult, dict[str, Any]]:
    t0 = time.perf_counter()
    result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hand)
    return result, record_of(result, seed, hand, time.perf_counter() - t0)


def run_main(cfg: ExperimentConfig, hand) -> dict[str, dict[str, list[dict[str, Any]]]]:
    """APSO and the simple PSO (and PSO on APSO's budget) on every object and seed."""
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for name in cfg.objects:
        obj = builtin_objects.builtin(name)
        # Preparation (grid) once, outside the timed plans.
        plan(obj, options=PlanOptions(particles=cfg.particles, iterations=1), rng=np.random.default_rng(0), hand=hand)
        runs[name] = {"apso": [], "pso": []}
        for algorithm in ("apso", "pso"):
            t0 = time.perf_counter()
            options = PlanOptions(algorithm=algorithm, particles=cfg.particles, iterations=cfg.iterations,
                                  max_grasps=1)  # the paper's setting: one grasp per plan
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
                                      max_evaluations=apso["evaluations"], max_grasps=1)
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


#: The pyswarms optimisers compared (keys of ``results.json``).
PYSWARMS_KEYS = ("pyswarms_global", "pyswarms_local")


def pyswarms_once(obj, key: str, particles: int, iterations: int, seed: int, hand,
                  options: PlanOptions | None = None) -> tuple[GraspResult, dict[str, Any]]:
    """One pyswarms run (``key`` in :data:`PYSWARMS_KEYS`) on the planner's fitness, its final
    particle verified by ``Objective.result``; returns the result and its record."""
    import logging

    from pyswarms.single import GlobalBestPSO, LocalBestPSO

    logging.getLogger("pyswarms").setLevel(logging.WARNING)
    cls, extra = {"pyswarms_global": (GlobalBestPSO, {}), "pyswarms_local": (LocalBestPSO, PYSWARMS_LOCAL)}[key]
    objective = Objective(obj, options or PlanOptions(particles=particles), hand=hand)
    np.random.seed(seed)  # pyswarms draws from numpy's global state
    start = time.perf_counter()
    optimizer = cls(n_particles=particles, dimensions=len(objective.lower), options={**PYSWARMS_OPTIONS, **extra},
                    bounds=(np.asarray(objective.lower), np.asarray(objective.upper)), bh_strategy=PYSWARMS_BOUNDARY)
    cost, pos = optimizer.optimize(lambda x: -objective(x), iters=iterations, verbose=False)
    evaluations = objective.evaluations
    result = objective.result(pos, algorithm=key)
    wall = time.perf_counter() - start
    rec = record_of(result, seed, hand, wall)
    rec["planning_time"] = wall
    rec["evaluations"] = int(evaluations)
    rec["iterations_run"] = iterations
    rec["optimizer_best"] = _finite(-float(cost))
    best = np.maximum.accumulate(-np.asarray(optimizer.cost_history, float))
    rec["best_history"] = [_round(v) for v in best]
    rec["evaluations_history"] = [int(particles * (i + 1)) for i in range(len(best))]
    return result, rec


def run_pyswarms(cfg: ExperimentConfig, runs: dict, hand) -> dict[str, Any]:
    """pyswarms GlobalBestPSO / LocalBestPSO on ``planner.Objective`` with APSO's median budget."""
    ok, version = pyswarms_status()
    info: dict[str, Any] = {"available": ok, "version": version, "options": dict(PYSWARMS_OPTIONS),
                            "local_options": dict(PYSWARMS_LOCAL), "bh_strategy": PYSWARMS_BOUNDARY,
                            "iterations": {}}
    if not ok:
        _log(f"pyswarms blocked: {version}")
        return info
    for name in cfg.objects:
        obj = builtin_objects.builtin(name)
        budget = _stats([r["evaluations"] for r in runs[name]["apso"]])["median"]
        iters = max(1, int(round(budget / cfg.particles)))
        info["iterations"][name] = iters
        for key in PYSWARMS_KEYS:
            t0 = time.perf_counter()
            records = [pyswarms_once(obj, key, cfg.particles, iters, seed, hand)[1] for seed in range(cfg.seeds)]
            runs[name][key] = records
            _log(f"{name:6s} {key}: {iters} iterations x {cfg.particles} particles, {time.perf_counter() - t0:.1f} s, "
                 f"median fitness {_stats([r['fitness'] for r in records])['median']:.3f}")
    return info
