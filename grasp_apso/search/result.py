"""What a plan returns: ranked :class:`GraspCandidate` s inside a :class:`GraspResult`.

Frames: everything is in the planning frame of the ``pose`` given to
:func:`~grasp_apso.search.planner.plan` (SI: metres, radians), except the fields named
``*_in_object``. Wrist angles in joint vectors are the palm orientation in the planning
frame (``R = Rz(wrist_z) Ry(wrist_y) Rx(wrist_x)``), so that a JointState and a URDF of the
hand agree with ``wrist_pose`` also when the object is rotated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..geometry.collision import FclReport
from ..model.hand import FINGER_NAMES
from .swarm import IterationStats

__all__ = ["Contact", "GraspCandidate", "GraspResult", "SIM_NOT_RUN", "SIM_DROPPED", "SIM_HELD", "PAPER_HAND_NAME"]

#: ``GraspCandidate.sim_result`` values (``grasp_apso_interfaces/Grasp.sim_result``).
SIM_NOT_RUN, SIM_DROPPED, SIM_HELD = -1, 0, 1
#: The paper hand's name in a result (its own path; its URDF's robot name is the same).
PAPER_HAND_NAME = "apso_paper_hand"


@dataclass(frozen=True)
class Contact:
    """A fingertip contact in the planning frame (position m, outward unit normal)."""

    finger: str
    position: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True)
class GraspCandidate:
    """One ranked grasp, ready for an arm (``moveit_msgs/Grasp`` field by field).

    Attributes
    ----------
    id : str
        Stable within a result (``"g<rank>"``).
    rank : int
        0 = best.
    joint_positions : (18,) float, rad
        The grasp posture (the closed fingers) and the wrist angles (planning frame).
    pre_grasp_positions : (18,) float, rad
        The open pre-shape (the fingers before closing), same wrist angles.
    wrist_pose : (4, 4) float
        Palm frame at the grasp in the planning frame (``grasp_pose``).
    pre_grasp_pose : (4, 4) float
        ``wrist_pose`` retreated by ``approach_distance`` along minus ``approach``.
    approach : (3,) float
        Unit approach direction (the palm normal, +z of the palm frame), planning frame.
    approach_distance : float, m
    grasp_quality : float in [0, 1]
        The ranking score (:func:`grasp_apso.search.ranking.grasp_quality`).
    fitness, epsilon : float
        Swarm fitness and Ferrari-Canny epsilon.
    force_closure, valid : bool
    contacts : tuple of Contact
    scene_distance : float, m
        Least distance between the whole hand (python-fcl) and the scene, over the grasp,
        the pre-grasp and the approach path; ``inf`` without a scene.
    sim_result : int
        ``SIM_NOT_RUN`` (-1), ``SIM_DROPPED`` (0) or ``SIM_HELD`` (1).
    sim_max_shift : float, m
    sim_max_turn : float, rad
        Largest displacement and rotation of the object over the simulated disturbances
        (NaN when not simulated).
    wrist_in_object : (4, 4) float
        ``wrist_pose`` in the object frame.
    joints : (5, 4, 3) float, m
        Finger points (base, PIP, DIP, tip) at the grasp, planning frame (for drawing).
    pre_grasp_joints : (5, 4, 3) float, m
        The same at the pre-grasp.
    """

    id: str
    rank: int
    joint_positions: np.ndarray
    pre_grasp_positions: np.ndarray
    wrist_pose: np.ndarray
    pre_grasp_pose: np.ndarray
    approach: np.ndarray
    approach_distance: float
    grasp_quality: float
    fitness: float
    epsilon: float
    force_closure: bool
    valid: bool
    contacts: tuple[Contact, ...]
    scene_distance: float = math.inf
    sim_result: int = SIM_NOT_RUN
    sim_max_shift: float = math.nan
    sim_max_turn: float = math.nan
    wrist_in_object: np.ndarray = field(default_factory=lambda: np.eye(4), repr=False)
    joints: np.ndarray = field(default_factory=lambda: np.zeros((5, 4, 3)), repr=False)
    pre_grasp_joints: np.ndarray = field(default_factory=lambda: np.zeros((5, 4, 3)), repr=False)
    #: (n,) the grasp posture pushed further along the closing senses (the simulation's
    #: squeeze); empty when not computed.
    squeeze_positions: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def n_contacts(self) -> int:
        return len(self.contacts)


@dataclass(frozen=True)
class GraspResult:
    """A planned grasp; see ``docs/architecture.md`` for the field list."""

    configuration: np.ndarray
    joint_names: tuple[str, ...]
    joint_positions: np.ndarray
    standoff: float
    wrist_pose: np.ndarray
    wrist_in_object: np.ndarray
    fitness: float
    epsilon: float
    force_closure: bool
    contacts: tuple[Contact, ...]
    valid: bool
    history: tuple[IterationStats, ...]
    iterations_run: int
    evaluations: int
    planning_time: float
    preparation_time: float
    cancelled: bool
    algorithm: str
    shape_class: str
    fcl: FclReport
    joints: np.ndarray
    max_penetration: float
    tip_gaps: np.ndarray = field(repr=False)
    #: True when the global best was not force closure and a runner-up was returned.
    runner_up: bool = False
    #: The ranked candidates, best first; ``candidates[0]`` is the grasp described by the
    #: top-level fields. Empty only when no grasp was decoded at all.
    candidates: tuple[GraspCandidate, ...] = ()
    #: Why fewer than ``max_grasps`` candidates came back ("" when all did).
    candidates_message: str = ""
    #: The hand planned with and the sha256 of its description (and config).
    hand_name: str = PAPER_HAND_NAME
    hand_hash: str = ""

    @property
    def n_contacts(self) -> int:
        return len(self.contacts)

    def touching_links(self, tolerance: float = 1e-4) -> np.ndarray:
        """(5, 3) bool: links (proximal, middle, distal per finger) resting on the object
        (python-fcl distance at most ``tolerance``, m), except the distal link of a finger
        whose fingertip is a contact. Any True: not a pure fingertip grasp."""
        distance = getattr(self.fcl, "link_distance", None)
        if distance is None:
            return np.zeros((5, 3), dtype=bool)
        touching = np.asarray(distance, dtype=float) <= tolerance
        for c in self.contacts:
            if c.finger in FINGER_NAMES:
                touching[FINGER_NAMES.index(c.finger), 2] = False
        return touching
