"""The timing of a grasp's hand motion, shared by the reply's ``hand_trajectory``
(:mod:`.hand_trajectory`) and a general hand's simulation check
(:class:`grasp_apso.simulation.settings.SimulationSettings`), so that the check replays the
motion a client is given. A leaf module: imported by both without pulling in either."""

from __future__ import annotations

__all__ = ["CLOSE_TIME", "SQUEEZE_TIME"]

#: s, pre-grasp -> grasp posture. A real hand's position controllers follow a one-second
#: closing without overshoot into the object; in the simulation a 0.3 s closing from the
#: pre-grasp shoves and rolls the object while the servos catch up (Allegro, 21 objects on
#: a table: best grasps held 13 of 20 closing in 0.3 s, 15 of 21 in 1 s).
CLOSE_TIME = 1.0
#: s, grasp -> squeeze posture.
SQUEEZE_TIME = 0.5
