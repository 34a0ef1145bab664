"""One plan as a JSON-ready record, and the experiment's definition of a valid grasp."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..model.hand import FINGER_NAMES, load_hand
from ..search.planner import GraspResult
from .stats import _finite, _round


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
        "links_touching": int(result.touching_links().sum()),
        # the swarm's best was not force closure: a less fit force-closure grasp was returned
        "runner_up": bool(result.runner_up),
        "best_history": [_round(h.best_fitness) for h in result.history],
        "evaluations_history": [int(h.evaluations) for h in result.history],
    }
