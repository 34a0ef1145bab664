"""The simulation check inside the final selection: every verified candidate is tested in
MuJoCo (:func:`grasp_apso.simulation.simulate_grasp`, the DexGraspBench protocol) when
``PlanOptions.simulate`` is set, so that held grasps rank first.

MuJoCo and CoACD take about 2 s to import, so :mod:`grasp_apso.simulation` is loaded on
the first plan that asks for it, not when the planner is imported (the node and the CLI
start without it).
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from ..model.hand import HandModel
from ..model.particle import LAYOUT
from ..model.scene import Scene
from .ranking import grasp_quality, rank_order

__all__ = ["simulate_checked", "simulate_until_held", "SIMULATION_SPARE"]

#: With ``simulate``, the selection verifies up to this many times ``max_grasps`` grasps,
#: and simulates them best first until ``max_grasps`` held (bounded: at most that many
#: simulations, about 0.2 s each).
SIMULATION_SPARE = 3


def simulate_checked(hand: HandModel, obj, pose: np.ndarray, checked: list, scene: Scene | None,
                     friction: float, decomposition_timeout: float | None = None) -> list:
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
    decomposition_timeout : float, s, optional
        Bound of the convex decomposition (:mod:`grasp_apso.simulation.convex`).

    Returns
    -------
    list of SimResult, one per entry of ``checked``.
    """
    from ..simulation import simulate_grasp  # noqa: PLC0415 -- heavy import, on demand

    settings = _settings(friction, decomposition_timeout)
    planes = None if scene is None or not len(scene.planes) else np.asarray(scene.planes)
    return [
        simulate_grasp(hand, obj, pose, pose @ c.wrist_in_object, c.x[LAYOUT.fingers], c.closed[LAYOUT.fingers],
                       planes=planes, settings=settings)
        for c in checked
    ]


def _settings(friction: float, decomposition_timeout: float | None):
    from ..simulation import ConvexSettings, SimulationSettings  # noqa: PLC0415 -- heavy import, on demand

    decomposition = ConvexSettings() if decomposition_timeout is None else ConvexSettings(
        timeout=float(decomposition_timeout))
    return SimulationSettings(friction=float(friction), decomposition=decomposition)


def simulate_until_held(hand: HandModel, obj, pose: np.ndarray, checked: list, scene: Scene | None,
                        friction: float, max_grasps: int, pinned_first: bool,
                        should_stop: Callable[[], bool] | None = None, deadline: float | None = None,
                        decomposition_timeout: float | None = None) -> tuple[list, list | None, str]:
    """Simulate verified grasps best first until ``max_grasps`` of them held, or the time
    is up.

    ``checked`` may hold up to :data:`SIMULATION_SPARE` times ``max_grasps`` grasps; they
    are simulated in their ranking order without the simulation (``checked[0]`` first when
    ``pinned_first``), one at a time, and the loop stops once ``max_grasps`` held or every
    grasp was tried. Returns the simulated grasps and their results: every held one, then
    the best dropped ones to fill up to ``max_grasps`` (the ranking puts held ones first).

    Time: before the convex decomposition of the object (waited for at most until then)
    and before each grasp, ``should_stop()`` and ``deadline`` (``time.monotonic()``) are
    looked at; once either says stop, the grasps not simulated yet keep ``None`` results
    (``sim_result`` -1) and the note says why. Bounded by one grasp's simulation (about
    0.2 s) after the stop.

    Returns
    -------
    (grasps, results, note)
        ``results`` is None when nothing was simulated (then ``grasps`` are ``checked``
        in their order, up to ``max_grasps``); otherwise one SimResult or None (not
        simulated) per grasp. ``note``: "" when every grasp that was needed ran.
    """
    if not checked:
        return [], None, ""
    from ..simulation.convex import decompose  # noqa: PLC0415 -- heavy import, on demand

    def stop() -> bool:
        return (should_stop is not None and should_stop()) or (deadline is not None and time.monotonic() >= deadline)

    quality = grasp_quality(np.array([c.fitness for c in checked]), np.array([c.valid for c in checked]),
                            np.array([c.force_closure for c in checked]),
                            robust=np.array([getattr(c, "robust", c.force_closure) for c in checked]))
    eps = np.array([c.epsilon for c in checked])
    order = list(rank_order(quality, eps))
    if pinned_first:
        order.remove(0)
        order.insert(0, 0)
    unsimulated = [checked[i] for i in order[:max_grasps]]
    if stop():
        return unsimulated, None, "not simulated: the time bound was reached before the simulation"
    parts = decompose(obj, _settings(friction, decomposition_timeout).decomposition, should_stop=should_stop,
                      deadline=deadline)
    if parts.parts is None:
        return unsimulated, None, f"not simulated: {parts.note}"
    held, dropped, note = [], [], ""
    for i in order:
        if stop():
            note = (f"simulation stopped at the time bound after {len(held) + len(dropped)} of "
                    f"{len(order)} grasps")
            break
        result = simulate_checked(hand, obj, pose, [checked[i]], scene, friction, decomposition_timeout)[0]
        (held if result.held else dropped).append((checked[i], result))
        if len(held) >= max_grasps:
            break
    chosen = held + dropped[:max(0, max_grasps - len(held))]
    if parts.note:
        note = "; ".join(n for n in (note, f"the object was {parts.note}") if n)
    if len(chosen) < max_grasps and note.startswith("simulation stopped"):
        tried = {id(c) for c, _ in held + dropped}
        rest = [checked[i] for i in order if id(checked[i]) not in tried][:max_grasps - len(chosen)]
        if not chosen:  # none simulated: ranked as without the simulation
            return rest, None, note
        return [c for c, _ in chosen] + rest, [r for _, r in chosen] + [None] * len(rest), note
    return [c for c, _ in chosen], [r for _, r in chosen], note
