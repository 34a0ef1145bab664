"""The hand's own motion of a grasp: pre-grasp posture, grasp posture, squeeze (any hand).

A reply's ``Grasp.hand_trajectory`` (``trajectory_msgs/JointTrajectory``) is built from
:func:`hand_trajectory`: three points over the grasp's joint names (the hand's actuated
joints; the paper's hand: its 18 names, the wrist angles held constant), so that a
``joint_trajectory_controller`` or ``moveit_msgs/Grasp``'s postures take it as it is:

=====  =================================  =============================================
point  posture                            time from start
=====  =================================  =============================================
0      ``pre_grasp_positions``            0 s
1      ``joint_positions`` (closed)       :data:`CLOSE_TIME`
2      the squeeze                        :data:`CLOSE_TIME` + :data:`SQUEEZE_TIME`
=====  =================================  =============================================

The squeeze is the grasp posture pushed further along the closing senses, as the
simulation check does it: a general hand's candidates carry it
(``GraspCandidate.squeeze_positions``); for the paper's hand it is
:func:`grasp_apso.simulation.protocol.squeezed_posture` with the simulation's
``squeeze`` (:class:`~grasp_apso.simulation.settings.SimulationSettings`, 8 degrees on
every flexion, clipped to the limits) -- the one place that defines it.

No rclpy here; :mod:`grasp_apso.ros.conversions` turns the arrays into the message.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .motion_times import CLOSE_TIME, SQUEEZE_TIME

__all__ = ["CLOSE_TIME", "SQUEEZE_TIME", "hand_trajectory", "squeeze_positions"]


def _is_paper_hand(hand: Any) -> bool:
    from ..model.hand import HandModel as PaperHand

    return hand is None or isinstance(hand, PaperHand)


def squeeze_positions(candidate: Any, hand: Any = None) -> np.ndarray:
    """The squeeze posture of a candidate, over the same joints as ``joint_positions``.

    Parameters
    ----------
    candidate : GraspCandidate
    hand : grasp_apso.model.hand.HandModel (the paper's; None = the shipped one) or
        grasp_apso.model.hands.HandModel (a general hand)

    Returns
    -------
    (n,) float, rad (or m for a prismatic joint)
        A general hand: ``candidate.squeeze_positions`` (the grasp posture when the
        candidate carries none). The paper's hand (18 values): the 15 finger joints
        squeezed, the wrist angles unchanged.
    """
    q = np.asarray(candidate.joint_positions, dtype=float).reshape(-1)
    stored = np.asarray(getattr(candidate, "squeeze_positions", ()), dtype=float).reshape(-1)
    if stored.shape == q.shape:
        return stored
    if not _is_paper_hand(hand) or q.shape != (18,):
        return q.copy()
    from ..model.hand import load_hand
    from ..simulation.protocol import squeezed_posture
    from ..simulation.settings import SimulationSettings

    paper = load_hand() if hand is None else hand
    out = q.copy()
    out[:15] = squeezed_posture(paper, q, SimulationSettings().squeeze)
    return out


def hand_trajectory(candidate: Any, hand: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Times and postures of the hand's motion for one candidate.

    Returns
    -------
    times : (3,) float, s -- 0, CLOSE_TIME, CLOSE_TIME + SQUEEZE_TIME
    positions : (3, n) float -- pre-grasp, grasp, squeeze over the grasp's joint names
    """
    grasp = np.asarray(candidate.joint_positions, dtype=float).reshape(-1)
    pre = np.asarray(candidate.pre_grasp_positions, dtype=float).reshape(-1)
    if pre.shape != grasp.shape:
        raise ValueError(f"pre_grasp_positions: {pre.shape[0]} values, joint_positions {grasp.shape[0]}")
    times = np.array([0.0, CLOSE_TIME, CLOSE_TIME + SQUEEZE_TIME])
    return times, np.stack([pre, grasp, squeeze_positions(candidate, hand)])
