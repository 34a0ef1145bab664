"""The simulation check inside the final selection: every verified candidate is tested in
MuJoCo (:func:`grasp_apso.simulation.simulate_grasp`, the DexGraspBench protocol) when
``PlanOptions.simulate`` is set, so that held grasps rank first.

MuJoCo and CoACD take about 2 s to import, so :mod:`grasp_apso.simulation` is loaded on
the first plan that asks for it, not when the planner is imported (the node and the CLI
start without it).
"""

from __future__ import annotations

import numpy as np

from ..model.hand import HandModel
from ..model.particle import LAYOUT
from ..model.scene import Scene

__all__ = ["simulate_checked"]


def simulate_checked(hand: HandModel, obj, pose: np.ndarray, checked: list, scene: Scene | None,
                     friction: float) -> list:
    """Simulate each verified grasp.

    Parameters
    ----------
    hand : HandModel
    obj : GraspObject
    pose : (4, 4) float
        Object -> planning frame.
    checked : list of :class:`~grasp_apso.search.selection.Checked`
        ``x`` (the open pre-shape) and ``closed`` (the grasp) give the finger postures,
        ``wrist_in_object`` the palm.
    scene : Scene or None
        In the planning frame; its support planes are in the simulation.
    friction : float
        The planner's mu (also the simulation's friction).

    Returns
    -------
    list of SimResult, one per entry of ``checked``.
    """
    from ..simulation import SimulationSettings, simulate_grasp  # noqa: PLC0415 -- heavy import, on demand

    settings = SimulationSettings(friction=float(friction))
    planes = None if scene is None or not len(scene.planes) else np.asarray(scene.planes)
    return [
        simulate_grasp(hand, obj, pose, pose @ c.wrist_in_object, c.x[LAYOUT.fingers], c.closed[LAYOUT.fingers],
                       planes=planes, settings=settings)
        for c in checked
    ]
