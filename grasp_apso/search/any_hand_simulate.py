"""The simulation check inside a general hand's final selection (``simulate``): the
verified grasps are checked in MuJoCo (:func:`grasp_apso.simulation.any_hand.simulate_any_hand`,
the DexGraspBench protocol, the hand's own description) best first until ``max_grasps``
held. A grasp that drops is tried once more with a firmer squeeze
(:func:`.any_hand_squeeze.firmer_squeeze`); a grasp that holds is held only if it also holds
with DexGraspBench's own parameters
(:data:`grasp_apso.simulation.settings.DEXGRASPBENCH_PARAMETERS`: stiffer servos, softer
contacts, faster ramps), since a client's servos and contacts are not this check's.

Measured (``bench/held_rate.py --seeds 3 --simulate --dexgraspbench --hand H``, the 4
built-ins and 17 meshes on a table, 63 plans), best grasps held in this check / with
DexGraspBench's parameters, held in this check only -> in both: the Wuji hand 57 / 52 -> 57
/ 57 (candidates held with its parameters 252 -> 261), the Shadow 57 / 57 and the Schunk SVH
49 / 52 unchanged (docs/any-hand-measurements.md, "The stop of 2026-12-07, seventh").

MuJoCo is imported on the first check (:func:`.any_hand_squeeze.optional_module`), not
with the planner.
"""

from __future__ import annotations

from ..errors import SimulationError
from .any_hand_squeeze import FIRM_SQUEEZE, firmer_squeeze, optional_module, sim_settings

__all__ = ["simulate_any"]


def simulate_any(model, checked, pose, obj, scene, options, should_stop) -> tuple[list, list, str]:
    """Simulate the verified grasps in their order until ``max_grasps`` held (or every one
    was tried, or ``should_stop``); one that drops is simulated again with a firmer squeeze
    (:func:`.any_hand_squeeze.firmer_squeeze`, at most ``max_grasps`` of them), which its
    reply keeps when that holds; one that holds is simulated again with DexGraspBench's
    parameters (``SimulationSettings.dexgraspbench``) and held only if it holds there too
    (else dropped, with that check's result). Returns the grasps to rank (the held ones and
    those not simulated; when none held, the first dropped ones, those held with this
    check's parameters first), up to ``max_grasps``, their results (None: not simulated)
    and a note. The ``fallback`` grasps (below the others' class,
    last in ``checked``) are returned only when they held."""
    sim = optional_module("grasp_apso.simulation.any_hand")
    if sim is None:
        return checked[:options.max_grasps], [None] * min(len(checked), options.max_grasps), \
            "simulate: the MuJoCo check of a general hand is not available"
    held, other, softer = [], [], []  # softer: held with this check's parameters only
    stiff = sim_settings().dexgraspbench()
    # at most max_grasps dropped grasps are tried again (a search whose grasps all drop,
    # the bowl or the flat marker, would double its simulations)
    stopped, failure, firmed, retried = False, "", 0, 0
    for position, c in enumerate(checked):
        if len(held) >= options.max_grasps:
            break
        if stopped or (should_stop is not None and should_stop()):
            stopped = True
            other.append((c, None))
            continue
        d = c.decoded
        try:
            result = sim.simulate_any_hand(model.hand, obj, pose, pose @ d.root[0], d.q_pre[0], d.q[0],
                                           c.squeeze, scene, options.friction, should_stop=should_stop)
            if not result.held and retried < options.max_grasps:  # squeezed harder (FIRM_SQUEEZE)
                retried += 1
                squeeze, forces = firmer_squeeze(model, c, obj, options.friction)
                firm = sim.simulate_any_hand(model.hand, obj, pose, pose @ d.root[0], d.q_pre[0], d.q[0],
                                             squeeze, scene, options.friction, should_stop=should_stop)
                if firm.held:
                    c.squeeze, c.forces, result = squeeze, forces, firm
                    firmed += 1
            if result.held:  # held only if it holds with DexGraspBench's parameters too
                second = sim.simulate_any_hand(model.hand, obj, pose, pose @ d.root[0], d.q_pre[0], d.q[0],
                                               c.squeeze, scene, options.friction, settings=stiff,
                                               should_stop=should_stop)
                if not second.held:
                    softer.append((c, second))  # its verdict and shift: the check it failed
                    continue
        except SimulationError as exc:  # the grasps stay, not simulated, and the reply says why
            failure = str(exc)
            other.extend((k, None) for k in checked[position:])
            break
        (held if result.held else other).append((c, result))
    # with none held in both, the ones held with this check's parameters come first
    other = [(c, r) for c, r in softer if not c.fallback] + other
    # Grasps that dropped in the simulation are not returned next to ones that held (as
    # grasps without force closure are not next to ones with it); with none held, the
    # best of them are, their sim_result saying so.
    unsimulated = [(c, r) for c, r in other if r is None and not c.fallback]
    dropped = [(c, r) for c, r in other if r is not None]
    chosen = (held + unsimulated if held else [(c, r) for c, r in other if not c.fallback])[:options.max_grasps]
    note = "simulation stopped at the time bound" if stopped else ""
    if held and dropped:
        note = "; ".join(n for n in (note, f"{len(dropped)} {'grasp' if len(dropped) == 1 else 'grasps'} that "
                                           "dropped in the simulation left out") if n)
    if softer:
        note = "; ".join(n for n in (note, f"{len(softer)} held with this check's servos and contacts but dropped "
                                           "with DexGraspBench's (stiffer servos, softer contacts): counted as "
                                           "dropped") if n)
    if firmed:
        note = "; ".join(n for n in (note, f"{firmed} held with a firmer squeeze ({FIRM_SQUEEZE:.3g} of the force)")
                         if n)
    if failure:
        note = f"not simulated: {failure}"
    return [c for c, _ in chosen], [r for _, r in chosen], note
