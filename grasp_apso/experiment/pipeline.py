"""The whole experiment in order: runs, peers, statistics, claims, pictures, speed, then
``report.md`` and ``results.json``."""

from __future__ import annotations

import os
import time
from dataclasses import asdict
from typing import Any

from ..model.hand import load_hand
from .analysis import evaluate_claims, find_anomalies, summarise
from .config import ExperimentConfig
from .figures import plot_convergence_panels, plot_evaluation_panels, plot_speed, table3_figures
from .machine import _machine
from .part2 import run_part2
from .progress import _log
from .report import _notes, _targets, write_report
from .results_json import _compact_json
from .runs import run_main, run_pyswarms
from .speed import run_speed


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
    part2 = run_part2(cfg, hand, runs, peers)
    wall = time.perf_counter() - t_start
    data = {
        "meta": {"command": cfg.command, "config": asdict(cfg), "machine": machine, "wall_time_s": wall,
                 "valid_definition": "n_contacts >= 3 and result.valid and result.fcl.legal and joint limits",
                 "spread": "q1/q3 = 25th/75th percentiles (numpy linear interpolation)"},
        "summary": summary, "claims": claims, "pyswarms": peers, "determinism": determinism,
        "pictures": pictures, "speed": speed, "runs": runs, "part2": part2,
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
