"""JSON-ready dictionaries of a plan (SI units: metres, radians, seconds), for
``grasp_apso_plan --json`` and scripts."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..model import poses
from ..model.hand import FINGER_NAMES
from ..search.result import GraspCandidate, GraspResult
from ..presentation.summary import LINK_NAMES, sim_text, touching_links

__all__ = ["result_to_dict", "candidate_to_dict", "scene_to_dict"]


def _floats(a) -> list:
    return np.asarray(a, float).tolist()


def _finite_or_none(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _pose(matrix) -> dict[str, Any]:
    position, quat = poses.matrix_to_pose(np.asarray(matrix, float))
    return {"position": _floats(position), "orientation_xyzw": _floats(quat), "matrix": _floats(matrix)}


def candidate_to_dict(c: GraspCandidate) -> dict[str, Any]:
    """One ranked candidate (the fields of ``grasp_apso_interfaces/Grasp``)."""
    return {
        "id": c.id,
        "rank": int(c.rank),
        "grasp_quality": float(c.grasp_quality),
        "fitness": float(c.fitness),
        "epsilon": float(c.epsilon),
        "force_closure": bool(c.force_closure),
        "valid": bool(c.valid),
        "joint_positions": _floats(c.joint_positions),
        "pre_grasp_positions": _floats(c.pre_grasp_positions),
        "wrist_pose": _pose(c.wrist_pose),
        "pre_grasp_pose": _pose(c.pre_grasp_pose),
        "approach_direction": _floats(c.approach),
        "approach_distance": float(c.approach_distance),
        "contacts": [{"finger": x.finger, "position": _floats(x.position), "normal": _floats(x.normal)}
                     for x in c.contacts],
        "n_contacts": c.n_contacts,
        "scene_distance": _finite_or_none(c.scene_distance),
        "sim_result": int(c.sim_result),
        "sim": sim_text(c),
        "sim_max_shift": _finite_or_none(c.sim_max_shift),
        "sim_max_turn": _finite_or_none(c.sim_max_turn),
    }


def scene_to_dict(scene) -> dict[str, Any] | None:
    """Support planes and obstacles (planning frame), or None without a scene."""
    if scene is None:
        return None
    return {
        "support_planes": _floats(scene.planes),
        "obstacles": [{"type": o.name, "dimensions": [float(d) for d in o.dimensions],
                       "pose": _floats(o.pose)} for o in scene.obstacles],
    }


def _fcl_dict(result: GraspResult) -> dict[str, Any] | None:
    """The python-fcl verification: the paper hand's per finger link, a general hand's per
    link (:class:`grasp_apso.geometry.any_hand_fcl.AnyHandReport`); None when it did not run."""
    fcl = result.fcl
    if fcl is None:
        return None
    if hasattr(fcl, "links"):
        return {"legal": bool(fcl.legal), "links": list(fcl.links), "link_distance": _floats(fcl.link_distance),
                "touching": [bool(t) for t in fcl.touching], "deepest_link": fcl.deepest_link,
                "deepest_penetration": float(fcl.deepest_penetration),
                "colliding_link_pairs": [list(p) for p in fcl.link_pairs_colliding],
                "colliding_finger_pairs": [list(p) for p in fcl.finger_pairs_colliding]}
    return {
        "legal": bool(fcl.legal),
        "penetrating_links": [f"{FINGER_NAMES[f]}_{LINK_NAMES[FINGER_NAMES[f]][k]}"
                              for f, k in np.argwhere(np.asarray(fcl.link_penetrates))],
        "colliding_finger_pairs": [list(p) for p in fcl.finger_pairs_colliding],
        "link_distance": _floats(fcl.link_distance),
        "touching_links": touching_links(result),
    }


def result_to_dict(result: GraspResult, friction: float | None = None) -> dict[str, Any]:
    """JSON-ready summary of a plan: the best grasp's fields, every candidate, the history."""
    wrist = _pose(result.wrist_pose)
    return {
        "algorithm": result.algorithm,
        "valid": bool(result.valid),
        "cancelled": bool(result.cancelled),
        "joint_names": list(result.joint_names),
        "joint_positions": _floats(result.joint_positions),
        "configuration": _floats(result.configuration),
        "wrist_pose": wrist,
        "standoff": float(result.standoff),
        "fitness": float(result.fitness),
        "epsilon": float(result.epsilon),
        "friction": friction,
        "force_closure": bool(result.force_closure),
        "contacts": [{"finger": c.finger, "position": _floats(c.position), "normal": _floats(c.normal)}
                     for c in result.contacts],
        "n_contacts": len(result.contacts),
        "max_penetration": float(result.max_penetration),
        "fcl": _fcl_dict(result),
        "hand_name": str(result.hand_name),
        "hand_hash": str(result.hand_hash),
        "candidates": [candidate_to_dict(c) for c in result.candidates],
        "candidates_message": result.candidates_message,
        "shape_class": result.shape_class,
        "iterations_run": int(result.iterations_run),
        "evaluations": int(result.evaluations),
        "planning_time": float(result.planning_time),
        "preparation_time": float(result.preparation_time),
        "history": [
            {"iteration": int(s.iteration), "best_fitness": float(s.best_fitness),
             "mean_fitness": float(s.mean_fitness), "active_particles": int(s.active_particles),
             "best_contacts": int(s.best_contacts), "evaluations": int(s.evaluations),
             "elapsed": float(s.elapsed)}
            for s in result.history
        ],
    }
