"""Turning decoded particles into :class:`~grasp_apso.search.result.GraspCandidate` s:
the grasp and pre-grasp postures, poses and the approach, in the planning frame.

The approach direction is the palm normal (+z of the palm frame) at the grasp; the
pre-grasp is the open pre-shape (the particle's finger values, before closing) with the
wrist retreated by ``approach_distance`` along minus the approach (DESIGN.md).
"""

from __future__ import annotations

import numpy as np

from ..model.hand import HandModel, rotation_to_wrist_angles
from ..model.particle import LAYOUT
from .result import SIM_DROPPED, SIM_HELD, SIM_NOT_RUN, Contact, GraspCandidate

__all__ = ["planning_joint_positions", "pre_grasp_pose", "finger_points", "make_candidate"]


def planning_joint_positions(values: np.ndarray, wrist_pose: np.ndarray) -> np.ndarray:
    """The 18 JointState values: the 15 finger values of ``values`` (D,) or (18,) and the
    wrist angles of ``wrist_pose`` (4, 4, planning frame), rad."""
    out = np.empty(18)
    out[LAYOUT.fingers] = np.asarray(values)[LAYOUT.fingers]
    out[LAYOUT.wrist] = rotation_to_wrist_angles(np.asarray(wrist_pose)[None, :3, :3])[0]
    return out


def pre_grasp_pose(wrist_pose: np.ndarray, approach_distance: float) -> np.ndarray:
    """``wrist_pose`` (4, 4) retreated ``approach_distance`` (m) along minus its +z."""
    out = np.array(wrist_pose, dtype=float)
    out[:3, 3] -= approach_distance * out[:3, 2]
    return out


def finger_points(hand: HandModel, values: np.ndarray, wrist_pose: np.ndarray) -> np.ndarray:
    """Finger points (base, PIP, DIP, tip) (5, 4, 3), m, of ``values`` (D,) at ``wrist_pose``."""
    frames = hand.finger_frames(np.asarray(values, dtype=float)[None, :])[0]  # (5, 4, 4, 4)
    pts = frames[..., :3, 3]
    return pts @ wrist_pose[:3, :3].T + wrist_pose[:3, 3]


def make_candidate(
    hand: HandModel,
    rank: int,
    open_values: np.ndarray,
    closed_values: np.ndarray,
    wrist_in_object: np.ndarray,
    pose: np.ndarray,
    approach_distance: float,
    *,
    grasp_quality: float,
    fitness: float,
    epsilon: float,
    force_closure: bool,
    valid: bool,
    contacts: tuple[Contact, ...],
    scene_distance: float = np.inf,
    sim=None,
) -> GraspCandidate:
    """Build one candidate.

    Parameters
    ----------
    open_values, closed_values : (D,) float
        The particle (the open pre-shape) and its decoded, closed configuration.
    wrist_in_object : (4, 4) float
        Palm frame in the object frame.
    pose : (4, 4) float
        Object -> planning frame.
    approach_distance : float, m
    sim : SimResult, optional
        The simulation check of this grasp (fills ``sim_result``, ``sim_max_shift``,
        ``sim_max_turn``); None = not simulated.
    """
    wrist_pose = pose @ wrist_in_object
    pre_pose = pre_grasp_pose(wrist_pose, approach_distance)
    return GraspCandidate(
        id=f"g{rank}",
        rank=rank,
        joint_positions=planning_joint_positions(closed_values, wrist_pose),
        pre_grasp_positions=planning_joint_positions(open_values, wrist_pose),
        wrist_pose=wrist_pose,
        pre_grasp_pose=pre_pose,
        approach=wrist_pose[:3, 2].copy(),
        approach_distance=float(approach_distance),
        grasp_quality=float(grasp_quality),
        fitness=float(fitness),
        epsilon=float(epsilon),
        force_closure=bool(force_closure),
        valid=bool(valid),
        contacts=contacts,
        scene_distance=float(scene_distance),
        sim_result=SIM_NOT_RUN if sim is None else (SIM_HELD if sim.held else SIM_DROPPED),
        sim_max_shift=np.nan if sim is None else float(sim.max_shift),
        sim_max_turn=np.nan if sim is None else float(sim.max_turn),
        wrist_in_object=np.array(wrist_in_object, dtype=float),
        joints=finger_points(hand, closed_values, wrist_pose),
        pre_grasp_joints=finger_points(hand, open_values, pre_pose),
    )
