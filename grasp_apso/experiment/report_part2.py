"""The report's executable-grasp sections (:mod:`grasp_apso.experiment.part2`): the table
scenario, the ranked candidates and the simulation check, as Markdown lines."""

from __future__ import annotations

import math
from typing import Any

from .config import ALGORITHM_LABELS, ExperimentConfig

__all__ = ["part2_sections", "PROTOCOL"]

#: The simulation protocol in words (DESIGN.md "Simulation check"); numbers from the settings.
PROTOCOL = (
    "MuJoCo, the whole hand generated from the hand description and the object as a free body "
    "(mass {object_mass:g} kg, friction {friction:g} = the planner's mu, condim {condim}; non-convex meshes split "
    "into convex parts by CoACD). The wrist is fixed at the grasp pose; position servos drive the fingers from "
    "the pre-grasp to the grasp posture in {close_time:g} s, then {squeeze_deg:.0f} degrees further into the "
    "object (the squeeze); then a disturbance acceleration of {disturbance:g} m/s^2 along +x, -x, +y, -y, +z, "
    "-z in turn, {duration:g} s each from the same squeezed state (time step {timestep_ms:g} ms). **Held**: the "
    "object moves less than {shift_mm:.0f} mm and turns less than {turn_deg:.0f} degrees in every direction.")


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100.0 * x:.0f} %"


def _f(x: float | None, digits: int = 3) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


def _med(s: dict[str, Any], digits: int = 3) -> str:
    return "n/a" if not s or s.get("median") is None else f"{s['median']:.{digits}f}"


def _table_section(cfg: ExperimentConfig, sc: dict[str, Any], seeds: int) -> list[str]:
    L = ["## Resting on a table: against free space", "",
         f"Each object at the identity pose on a table (a support plane, normal +z, under its lowest point), "
         f"APSO with np = {cfg.particles}, nit = {cfg.iterations}, one grasp per plan, seeds 0..{seeds - 1}, "
         f"clearance {sc['clearance'] * 1000:g} mm. **Success** = a valid grasp (the definition above) whose "
         "whole hand keeps the clearance from the table at the grasp, the pre-grasp and along the approach "
         "(the planner's python-fcl check); in free space success = valid. *From above*: angle between the "
         "approach and straight down (median). Time: median plan time.", "",
         "| object | success free | success table | fitness free | fitness table | epsilon free | epsilon table | "
         "FC free | FC table | from above | time free (s) | time table (s) | table / free |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, v in sc["objects"].items():
        fr, tb = v["free"], v["table"]
        tf, tt = fr["planning_time"]["median"], tb["planning_time"]["median"]
        L.append(f"| {name} | {_pct(fr['success_rate'])} | {_pct(tb['success_rate'])} | {_med(fr['fitness'])} | "
                 f"{_med(tb['fitness'])} | {_med(fr['epsilon'], 4)} | {_med(tb['epsilon'], 4)} | "
                 f"{_pct(fr['force_closure_rate'])} | {_pct(tb['force_closure_rate'])} | "
                 f"{_med(tb['from_above_deg'], 0)} deg | {_f(tf)} | {_f(tt)} | "
                 f"{_f(tt / tf if tf and tt else None, 2)} |")
    return L + [""]


def _candidates_section(cfg: ExperimentConfig, sc: dict[str, Any], seeds: int) -> list[str]:
    k = sc["max_grasps"]
    L = ["## Ranked candidates", "",
         f"The same table scenario with `max_grasps` = {k} (seeds 0..{seeds - 1}): candidates returned per "
         f"request, quality by rank, distinctness (two candidates are distinct when their wrists differ by at "
         f"least {sc['min_orientation_gap_deg']:.0f} degrees or {sc['min_position_gap'] * 1000:.0f} mm) and the "
         f"plan time of {k} candidates against one grasp (medians).", "",
         "| object | candidates (median) | distinct pairs | least angle (deg) | least distance (mm) | "
         f"time {k} (s) | time 1 (s) | ratio |", "|---|---|---|---|---|---|---|---|"]
    for name, v in sc["objects"].items():
        c = v["candidates"]
        L.append(f"| {name} | {_med(c['n_candidates'], 0)} | {_pct(c['distinct_rate'])} of {c['pairs']} | "
                 f"{_f(c['min_angle_deg'], 0)} | {_f(None if c['min_distance'] is None else c['min_distance'] * 1000, 0)} | "
                 f"{_med(c['planning_time'])} | {_med(v['table']['planning_time'])} | {_f(c['time_ratio_to_one'], 2)} |")
    L += ["", "Quality by rank: median epsilon and force-closure share of the candidates at each rank "
          "(n = requests that returned that many).", "",
          "| object | " + " | ".join(f"rank {r} epsilon | rank {r} FC" for r in range(1, k + 1)) + " |",
          "|---|" + "---|---|" * k]
    for name, v in sc["objects"].items():
        cells = [f"{_med(b['epsilon'], 4)} | {_pct(b['force_closure_rate'])} (n = {b['n']})"
                 for b in v["candidates"]["by_rank"]]
        L.append(f"| {name} | " + " | ".join(cells) + " |")
    return L + [""]


def _simulation_section(cfg: ExperimentConfig, sim: dict[str, Any], seeds: int) -> list[str]:
    L = ["## Simulation: does the grasp hold?", ""]
    if not sim.get("available"):
        return L + [f"Not run: the simulation could not be imported ({sim.get('why_not')}). Install `mujoco` and "
                    "`coacd` (see the README) and run the experiment again.", ""]
    s = sim["settings"]
    L += [PROTOCOL.format(object_mass=s["object_mass"], friction=s["friction"], condim=s["condim"],
                          close_time=s["close_time"], squeeze_deg=math.degrees(s["squeeze"]),
                          disturbance=s["disturbance"], duration=s["duration"], timestep_ms=s["timestep"] * 1000,
                          shift_mm=s["max_shift"] * 1000, turn_deg=math.degrees(s["max_turn"])), "",
          f"The best grasp of each run in free space (np = {cfg.particles}; APSO and PSO nit = {cfg.iterations}; "
          f"pyswarms on APSO's median budget), seeds 0..{seeds - 1}; held rate over all runs (an invalid grasp "
          "is simulated too), median largest shift, median simulation time per grasp.", ""]
    keys = list(next(iter(sim["objects"].values()), {}))
    L += ["| object | " + " | ".join(f"{ALGORITHM_LABELS.get(k, k)} held" for k in keys) + " | "
          + " | ".join(f"{ALGORITHM_LABELS.get(k, k)} shift (mm)" for k in keys) + " | sim time (s) |",
          "|---|" + "---|" * (2 * len(keys) + 1)]
    for name, by in sim["objects"].items():
        shifts = [_f(None if by[k]["max_shift"]["median"] is None else by[k]["max_shift"]["median"] * 1000, 1)
                  for k in keys]
        L.append(f"| {name} | " + " | ".join(_pct(by[k]["held_rate"]) for k in keys) + " | " + " | ".join(shifts)
                 + f" | {_med(by['apso']['sim_time'], 2)} |")
    return L + [""]


def part2_sections(cfg: ExperimentConfig, data: dict[str, Any]) -> list[str]:
    """Markdown lines of the executable-grasp sections ([] when they were not run)."""
    p2 = data.get("part2")
    if not p2:
        return []
    L: list[str] = []
    if "scene" in p2:
        L += _table_section(cfg, p2["scene"], p2["seeds"])
        L += _candidates_section(cfg, p2["scene"], p2["seeds"])
    if "simulation" in p2:
        L += _simulation_section(cfg, p2["simulation"], p2["seeds"])
    return L
