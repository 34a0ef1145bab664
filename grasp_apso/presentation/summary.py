"""Printed summaries of a plan, shared by the command line and the ROS node (no rclpy).

One wording for everyone:

- :func:`why_not_valid` -- why a result is not a valid grasp ("" when it is);
- :func:`grasp_summary` -- one line of figures (contacts, fitness, epsilon, closure,
  iterations, time, candidates, simulation);
- :func:`grasp_verdict` -- ``"grasp found: <summary>"`` or
  ``"no valid grasp found (<why>): <summary>"``, the node's reply message;
- :func:`format_report`, :func:`format_candidates`, :func:`format_comparison`,
  :func:`summary_line` -- the command line's tables (mm and degrees).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..model import poses
from ..model.hand import FINGER_NAMES, JOINT_KINDS
from ..search.result import PAPER_HAND_NAME, SIM_DROPPED, SIM_HELD, GraspCandidate, GraspResult

__all__ = [
    "FCL_TOLERANCE_MM", "COMPARE_AT", "LINK_NAMES", "touching_links", "why_not_valid", "grasp_summary",
    "grasp_verdict", "format_report", "format_candidates", "format_comparison", "summary_line",
    "sim_text", "approach_angle_from_above",
]

#: python-fcl penetration tolerance of the planner's verification (mm).
FCL_TOLERANCE_MM = 1.0
#: Iterations at which ``--algorithm both`` compares the best fitness.
COMPARE_AT = (5, 20, 50)
#: Link names per finger, base to tip.
LINK_NAMES: dict[str, tuple[str, str, str]] = {f: ("proximal", "middle", "distal") for f in FINGER_NAMES}
LINK_NAMES["thumb"] = ("metacarpal", "proximal", "distal")
_INITIAL = {"little": "L", "ring": "R", "middle": "M", "index": "I", "thumb": "T"}


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def _vec(v, fmt: str = "{:7.1f}") -> str:
    return "(" + ", ".join(fmt.format(float(x)) for x in v) + ")"


# ----------------------------------------------------------------------------- one wording
def touching_links(result: GraspResult, tolerance: float = 1e-4) -> list[str]:
    """Names of the links other than the contact fingertips that touch the object
    (:meth:`GraspResult.touching_links`). The quality measures count fingertip contacts
    only; a link resting on the object makes the real grasp partly an enveloping one."""
    return [f"{FINGER_NAMES[f]}_{LINK_NAMES[FINGER_NAMES[f]][k]}"
            for f, k in np.argwhere(result.touching_links(tolerance))]


def why_not_valid(result: GraspResult) -> str:
    """Why the best grasp of ``result`` is not valid, in words; "" when it is valid."""
    if result.valid:
        return ""
    reasons = []
    if result.n_contacts < 2:
        reasons.append(f"only {result.n_contacts} fingertip contact{'' if result.n_contacts == 1 else 's'}")
    if result.fcl is not None and not result.fcl.legal:
        reasons.append("the python-fcl collision check failed")
    if not reasons:
        reasons.append("a link penetrates the object or the hand is too close to the scene")
    return ", ".join(reasons)


def sim_text(candidate: GraspCandidate) -> str:
    """``held`` / ``dropped`` / ``not simulated``."""
    return {SIM_HELD: "held", SIM_DROPPED: "dropped"}.get(int(candidate.sim_result), "not simulated")


def grasp_summary(result: GraspResult, iterations: int | None = None, elapsed: float | None = None) -> str:
    """One line of figures: contacts, fitness, epsilon, force closure, iterations and time,
    then the candidates and the simulation when there are several / it ran.

    ``iterations`` is the requested count (default: the history's); ``elapsed`` the time to
    quote (default: ``result.planning_time``).
    """
    total = iterations if iterations is not None else (result.history[-1].iterations if result.history else "?")
    seconds = result.planning_time if elapsed is None else elapsed
    text = (f"{result.n_contacts} contacts, fitness {result.fitness:.3f}, epsilon {result.epsilon:.4f}, "
            f"force closure {_yes(result.force_closure)}, {result.iterations_run} of {total} iterations "
            f"in {seconds:.2f} s")
    cands = result.candidates
    if len(cands) > 1:
        fc = sum(c.force_closure for c in cands)
        text += f"; {len(cands)} candidates ({fc} force closure)"
    simulated = [c for c in cands if c.sim_result != -1]
    if simulated:
        held = sum(c.sim_result == SIM_HELD for c in simulated)
        text += f"; simulation: {held} of {len(simulated)} held"
    if result.candidates_message:
        text += f"; {result.candidates_message}"
    return text


def grasp_verdict(result: GraspResult, iterations: int | None = None, elapsed: float | None = None) -> str:
    """``"grasp found: <summary>"`` or ``"no valid grasp found (<why>): <summary>"``."""
    summary = grasp_summary(result, iterations, elapsed)
    why = why_not_valid(result)
    return f"no valid grasp found ({why}): {summary}" if why else f"grasp found: {summary}"


def approach_angle_from_above(approach: np.ndarray, up: np.ndarray) -> float:
    """Angle (deg) between an approach direction and straight down (``-up``): 0 = from above."""
    a = np.asarray(approach, float) / max(float(np.linalg.norm(approach)), 1e-12)
    u = np.asarray(up, float) / max(float(np.linalg.norm(up)), 1e-12)
    return math.degrees(math.acos(float(np.clip(-(a @ u), -1.0, 1.0))))


# ----------------------------------------------------------------------------- report
def _general_fcl_text(report) -> str:
    """A general hand's python-fcl report (:class:`grasp_apso.geometry.any_hand_fcl.AnyHandReport`)."""
    if report is None:
        return "not run (grasp_apso.geometry.any_hand_fcl not available)"
    if report.legal:
        return (f"legal: no link penetrates the object beyond {report.tolerance * 1000:g} mm, "
                "no links collide")
    parts = []
    if report.deepest_penetration > report.max_depth:
        parts.append(f"{report.deepest_link} {report.deepest_penetration * 1000:.1f} mm into the object")
    if report.link_pairs_colliding:
        parts.append("colliding links: " + ", ".join(f"{a}-{b}" for a, b in report.link_pairs_colliding))
    return "NOT legal: " + "; ".join(parts)


def _fcl_text(result: GraspResult) -> str:
    report = result.fcl
    if report is None or hasattr(report, "links"):
        return _general_fcl_text(report)
    if report.legal:
        return (f"legal: no link penetrates the object beyond {FCL_TOLERANCE_MM:g} mm, "
                "no fingers collide")
    parts = []
    links = [f"{FINGER_NAMES[f]} {LINK_NAMES[FINGER_NAMES[f]][k]}"
             for f, k in np.argwhere(np.asarray(report.link_penetrates))]
    if links:
        parts.append("links penetrating the object: " + ", ".join(links))
    if report.finger_pairs_colliding:
        parts.append("colliding fingers: " + ", ".join(f"{a}-{b}" for a, b in report.finger_pairs_colliding))
    return "NOT legal: " + "; ".join(parts)


def _heading(result: GraspResult) -> str:
    why = why_not_valid(result)
    if why:
        text = f"NO valid grasp ({why})"
    else:
        text = "valid grasp, " + ("force closure" if result.force_closure else "NOT force closure")
    if result.cancelled:
        text += f"; cancelled after {result.iterations_run} iterations"
    return text


def _approach_lines(result: GraspResult, up: np.ndarray | None) -> list[str]:
    if not result.candidates:
        return []
    c = result.candidates[0]
    pre = np.asarray(c.pre_grasp_pose, float)[:3, 3] * 1000
    lines = [f"  approach     {_vec(c.approach, '{:7.3f}')} (unit, the palm normal); pre-grasp "
             f"{c.approach_distance * 1000:.0f} mm back, wrist at {_vec(pre)} mm"]
    if up is not None:
        lines.append(f"  from above   {approach_angle_from_above(c.approach, up):.0f} deg from straight down "
                     "(toward the table)")
    if math.isfinite(c.scene_distance):
        lines.append(f"  scene        {c.scene_distance * 1000:.1f} mm least distance of the whole hand to the "
                     "table / obstacles (grasp, approach and pre-grasp; python-fcl)")
    return lines


def _general_configuration(result: GraspResult, hand) -> list[str]:
    """The grasp posture of a general hand: each finger's actuated joints by name, degrees,
    with the joint limits; then the joints of no finger."""
    names = list(result.joint_names)
    q = np.degrees(np.asarray(result.joint_positions, float))
    lower, upper = np.degrees(np.asarray(hand.lower, float)), np.degrees(np.asarray(hand.upper, float))
    lines = [f"Hand configuration ({hand.name}: {len(names)} actuated joints, JointState order), degrees, "
             "each value followed by its [limits] (* = at a limit):"]
    groups = [(f.name, [j for j in f.joints if j in names]) for f in hand.fingers]
    groups.append(("other", [j for j in names if all(j not in g for _, g in groups)]))
    width = max(len(n) for n in names) + 2
    shown: set[str] = set()
    for finger, joints in groups:
        for k, joint in enumerate(j for j in joints if j not in shown):
            shown.add(joint)
            i = names.index(joint)
            mark = "*" if min(q[i] - lower[i], upper[i] - q[i]) < 0.05 else " "
            lines.append(f"  {finger if k == 0 else '':<8}{joint:<{width}}{q[i]:8.1f}{mark}"
                         f"[{lower[i]:5.0f}, {upper[i]:4.0f}]")
    return lines


def format_report(result: GraspResult, hand, friction: float,
                  pose_note: str = "object frame (= planning frame)", up: np.ndarray | None = None) -> str:
    """The human-readable report of the best grasp (configuration, wrist and approach,
    contacts, quality). ``up``: the table normal, to say how far from above it comes.
    A general hand (:class:`grasp_apso.model.hands.HandModel`) lists its actuated joints by
    name per finger and its root link's pose."""
    lines = [f"{result.algorithm.upper()} result: {_heading(result)}", ""]
    if hasattr(hand, "actuated_joints"):
        return "\n".join(lines + _general_configuration(result, hand) + [""] + _pose_and_rest(result, friction,
                                                                                              pose_note, up, hand))
    lines.append("Hand configuration Cg, degrees, each value followed by its [Table 2 limits]:")
    lines.append(f"  {'finger':<8}" + "".join(f"{kind + ' (theta_i' + str(k + 1) + ')':>26}"
                                             for k, kind in enumerate(JOINT_KINDS)))
    lower, upper = np.degrees(hand.lower), np.degrees(hand.upper)
    q = np.degrees(np.asarray(result.joint_positions, float))

    def cell(j: int, prefix: str = "") -> str:
        mark = "*" if min(q[j] - lower[j], upper[j] - q[j]) < 0.05 else " "
        return f"{prefix}{q[j]:8.1f}{mark}[{lower[j]:5.0f}, {upper[j]:4.0f}]"

    for f, finger in enumerate(FINGER_NAMES):
        lines.append(f"  {finger:<8}" + "".join(f"{cell(3 * f + k):>26}" for k in range(3)))
    lines.append(f"  {'wrist':<8}" + "".join(f"{cell(15 + k, axis + ' '):>26}" for k, axis in enumerate("xyz")))
    lines.append("  (distal theta_i1 drives the last two joints, coupled 1.5:1; wrist: palm orientation "
                 "R = Rz Ry Rx; * = at a limit)")
    lines.append("")
    return "\n".join(lines + _pose_and_rest(result, friction, pose_note, up, hand))


def _general_touching(result: GraspResult, hand) -> list[str]:
    """A general hand's links that touch the object (python-fcl), except the pad bodies
    (the pad link and the links fixed to it) of the fingers that make the contacts."""
    from ..geometry.any_hand_tables import pad_body_links

    report = result.fcl
    if report is None or not hasattr(report, "touching"):
        return []
    fingers = {c.finger for c in result.contacts}
    pads = set().union(*(pad_body_links(hand, i) for i, f in enumerate(hand.fingers) if f.name in fingers))
    return [link for link, t in zip(report.links, report.touching) if t and link not in pads]


def _pose_and_rest(result: GraspResult, friction: float, pose_note: str, up: np.ndarray | None, hand) -> list[str]:
    """The report after the configuration: wrist pose, approach, contacts, quality."""
    lines: list[str] = []
    general = hasattr(hand, "actuated_joints")
    position, quat = poses.matrix_to_pose(result.wrist_pose)
    lines.append(f"Root link '{hand.root_link}' pose (the reply's grasp_pose) in the {pose_note}:" if general else
                 f"Wrist pose (palm frame: origin at the wrist, +x fingers, +z palm normal) in the {pose_note}:")
    lines.append(f"  position     {_vec(np.asarray(position) * 1000)} mm")
    lines.append(f"  quaternion   {_vec(quat, '{:7.4f}')} (x, y, z, w)")
    lines.append(f"  standoff     {result.standoff * 1000:+.1f} mm added by the swarm to the computed "
                 "palm-object standoff")
    lines += _approach_lines(result, up)
    lines.append("")
    lines.append(f"Contacts: {len(result.contacts)} fingertip contact(s), positions in the {pose_note}:")
    if result.contacts:
        lines.append(f"  {'finger':<8}{'position (mm)':>28}   {'outward surface normal':>26}")
        for c in result.contacts:
            lines.append(f"  {c.finger:<8}{_vec(np.asarray(c.position) * 1000):>28}   "
                         f"{_vec(c.normal, '{:6.3f}'):>26}")
    else:
        lines.append("  (none)")
    lines.append("")
    fingers = ", ".join(c.finger for c in result.contacts) or "none"
    touching = touching_links(result) if not general else _general_touching(result, hand)
    lines.append("Quality:")
    rows = [
        ("fitness", f"{result.fitness:.3f}", "maximised, in [0, 1] for a valid grasp (below 0: none found)"),
        ("epsilon", f"{result.epsilon:.4f}", f"Ferrari-Canny, friction mu {friction:g}; > 0 means force closure"),
        ("force closure", _yes(result.force_closure),
         "a runner-up: the global best was not force closure" if result.runner_up else ""),
        ("fingertip contacts", f"{len(result.contacts)}", fingers),
        ("max penetration", f"{result.max_penetration * 1000:.2f} mm", "deepest link into the object"),
        ("python-fcl check", _fcl_text(result), ""),
        ("other links touching",
         (", ".join(t.replace("_", " ") for t in touching) + " (not counted as contacts)") if touching else "none",
         ""),
        ("iterations", f"{result.iterations_run} of {result.history[-1].iterations if result.history else '?'}",
         "(cancelled)" if result.cancelled else ""),
        ("evaluations", f"{result.evaluations}", "particle decodes (GRG draws included)"),
        ("planning time", f"{result.planning_time:.2f} s", "swarm and verification"),
        ("preparation time", f"{result.preparation_time:.2f} s", "distance grid and shape class (cached per mesh)"),
    ]
    for name, value, note in rows:
        lines.append(f"  {name:<21}{value:<10}{('  ' + note) if note else ''}".rstrip())
    return lines


def _paper_fingers(result: GraspResult) -> bool:
    """The paper hand (its own path or its URDF), every contact by one of its five fingers:
    initials are then enough. Decided by the hand, not by which fingers touch in this plan,
    so that one hand's tables read alike in every plan (an Inspire plan whose pinky did not
    touch was printed with the paper hand's initials)."""
    return result.hand_name == PAPER_HAND_NAME and all(
        x.finger in _INITIAL for c in result.candidates for x in c.contacts)


def _contact_labels(result: GraspResult) -> list[str]:
    """The contacts column: the count, then the paper hand's initials (``3 MIT``) or, for any
    other hand, its own finger names (``3 thumb,index,middle``; names like ``3``, ``7``
    would run together as initials)."""
    cands = result.candidates
    if _paper_fingers(result):
        return [f"{c.n_contacts} " + "".join(_INITIAL[x.finger] for x in c.contacts) for c in cands]
    return [f"{c.n_contacts} " + ",".join(x.finger for x in c.contacts) for c in cands]


def format_candidates(result: GraspResult) -> str:
    """Table of the ranked candidates: rank, quality, epsilon, force closure, contacts,
    wrist position (mm), approach direction and, when simulated, held / shift / turn."""
    cands = result.candidates
    simulated = any(c.sim_result != -1 for c in cands)
    scene = any(math.isfinite(c.scene_distance) for c in cands)
    labels = _contact_labels(result)
    width = max([10] + [len(x) for x in labels])
    head = (f"  {'rank':>4} {'quality':>7} {'epsilon':>8} {'FC':>3} {'contacts':<{width}} "
            f"{'wrist position (mm)':>24}  {'approach (unit)':>22}")
    if scene:
        head += f" {'scene mm':>8}"
    if simulated:
        head += f"  {'simulation':<13} {'shift mm':>8} {'turn deg':>8}"
    legend = ("contacts L R M I T = little ring middle index thumb" if _paper_fingers(result)
              else "contacts: how many, then the fingers touching")
    lines = [f"Candidates: {len(cands)}, best first (quality = ranking score in [0, 1]; {legend}):", head]
    for c, label in zip(cands, labels):
        row = (f"  {c.rank + 1:>4} {c.grasp_quality:7.3f} {c.epsilon:8.4f} {_yes(c.force_closure):>3} "
               f"{label:<{width}} {_vec(np.asarray(c.wrist_pose)[:3, 3] * 1000):>24}  "
               f"{_vec(c.approach, '{:6.3f}'):>22}")
        if scene:
            row += f" {c.scene_distance * 1000:8.1f}"
        if simulated:
            shift = "-" if not math.isfinite(c.sim_max_shift) else f"{c.sim_max_shift * 1000:.1f}"
            turn = "-" if not math.isfinite(c.sim_max_turn) else f"{math.degrees(c.sim_max_turn):.1f}"
            row += f"  {sim_text(c):<13} {shift:>8} {turn:>8}"
        lines.append(row)
    if not cands:
        lines.append("  (none)")
    if result.candidates_message:
        lines.append(f"  {result.candidates_message}")
    if simulated:
        lines.append("  simulation: MuJoCo, fingers close and squeeze, then 10 m/s^2 along +-x, +-y, +-z for 2 s "
                     "each; held = the object moves < 50 mm and turns < 15 deg in every direction")
    return "\n".join(lines)


def _fitness_at(result: GraspResult, iteration: int) -> float | None:
    for stats in result.history:
        if stats.iteration == iteration:
            return float(stats.best_fitness)
    return None


def format_comparison(results: dict[str, GraspResult], seed: int) -> str:
    """Side-by-side table of the runs (same object, same seed)."""
    names = list(results)
    width = 12
    lines = [f"Comparison ({', '.join(n.upper() for n in names)}; same object, seed {seed}, "
             "same fitness; higher fitness is better):"]
    lines.append(f"  {'':<24}" + "".join(f"{n.upper():>{width}}" for n in names))

    def row(label: str, values: Sequence[str]) -> None:
        lines.append(f"  {label:<24}" + "".join(f"{v:>{width}}" for v in values))

    row("final best fitness", [f"{r.fitness:.3f}" for r in results.values()])
    longest = max(r.iterations_run for r in results.values())
    for k in COMPARE_AT:
        if k <= longest:
            vals = [_fitness_at(r, k) for r in results.values()]
            row(f"best fitness at iter. {k}", ["-" if v is None else f"{v:.3f}" for v in vals])
    row("epsilon", [f"{r.epsilon:.4f}" for r in results.values()])
    row("force closure", [_yes(r.force_closure) for r in results.values()])
    row("fingertip contacts", [str(len(r.contacts)) for r in results.values()])
    row("valid grasp", [_yes(r.valid) for r in results.values()])
    if any(len(r.candidates) > 1 for r in results.values()):
        row("candidates", [str(len(r.candidates)) for r in results.values()])
    row("planning time (s)", [f"{r.planning_time:.2f}" for r in results.values()])
    row("evaluations", [str(r.evaluations) for r in results.values()])
    if "apso" in results and "pso" in results and results["pso"].history:
        target = results["pso"].history[-1].best_fitness
        reached = next((s.iteration for s in results["apso"].history if s.best_fitness >= target), None)
        if reached is not None:
            lines.append(f"  APSO reached the final PSO fitness ({target:.3f}) at iteration {reached} "
                         f"of {results['apso'].iterations_run}.")
        else:
            lines.append(f"  APSO did not reach the final PSO fitness ({target:.3f}).")
    return "\n".join(lines)


def summary_line(result: GraspResult, object_name: str) -> str:
    """``--quiet``: one line per run."""
    fingers = ",".join(c.finger for c in result.contacts) or "none"
    text = (f"{object_name} {result.algorithm.upper()}: fitness {result.fitness:.3f}, "
            f"epsilon {result.epsilon:.4f}, force closure {_yes(result.force_closure)}, "
            f"valid {_yes(result.valid)}, contacts {len(result.contacts)} ({fingers}), "
            f"{result.iterations_run} iterations, {result.planning_time:.2f} s")
    if len(result.candidates) > 1:
        text += f", {len(result.candidates)} candidates"
    simulated = [c for c in result.candidates if c.sim_result != -1]
    if simulated:
        text += f", held {sum(c.sim_result == SIM_HELD for c in simulated)} of {len(simulated)}"
    return text
