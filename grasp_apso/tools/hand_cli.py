"""Command line ``grasp_apso_hand``: load a hand and show what was derived from it.

Examples::

    grasp_apso_hand my_hand.urdf                       # the derivation, as text
    grasp_apso_hand shadow/reach.xml --hand-config shadow.yaml --json
    grasp_apso_hand my_hand.urdf --picture hand.png     # open and closed, pads, spheres

Prints the root link (the palm), the palm normal, each finger with its joints and their
closing senses (+1/-1, 0 = pre-shape), its pad (link, centre, radius), the collision
spheres per link and how far they stray outside the exact geometry, the couplings, the
joints held above the palm (or beside it: the rest of a robot the hand is part of) and the
loader's notes. A user checks a new hand with it before planning. Exit status: 0 ok, 2 a
bad description or config (one line naming the element). Also runnable as
``python -m grasp_apso.tools.hand_cli``.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any, Sequence

import numpy as np

from ..errors import GraspApsoError

PROG = "grasp_apso_hand"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description="Load a hand description (URDF .urdf, MJCF .xml "
                                     "or the project's YAML) and print its derived grasp semantics.")
    parser.add_argument("file", metavar="FILE", help="the hand description")
    parser.add_argument("--hand-config", metavar="FILE", default=None,
                        help="YAML overriding the derivation (docs/hands.md)")
    parser.add_argument("--json", action="store_true", help="print JSON (for scripts)")
    parser.add_argument("--picture", metavar="PNG", default=None,
                        help="draw the hand open and closed with pads, palm normal and spheres")
    return parser


def _r(values, digits: int = 5) -> list[float]:
    return [round(float(v), digits) + 0.0 for v in np.ravel(values)]  # + 0.0: no "-0.0"


def summary(hand) -> dict[str, Any]:
    """The derivation as plain data (what --json prints)."""
    limits = dict(zip(hand.actuated_joints, zip(_r(hand.lower), _r(hand.upper))))
    return {
        "name": hand.name,
        "root_link": hand.root_link,
        "palm_normal": _r(hand.palm_normal, 4),
        "actuated_joints": list(hand.actuated_joints),
        "limits": {j: list(v) for j, v in limits.items()},
        "fingers": [{
            "name": f.name, "thumb": f.is_thumb, "tip_link": f.tip_link, "joints": list(f.joints),
            "closing": list(f.closing), "pad_link": f.pad_link, "pad_center": _r(f.pad_center),
            "pad_radius": round(float(f.pad_radius), 5)} for f in hand.fingers],
        "spheres": {link: {"count": int(len(c.radii)), "max_stray_m": round(float(c.max_stray), 6),
                           "uncovered": round(float(c.uncovered), 6)} for link, c in hand.spheres.items()},
        "couplings": [{"follower": c.follower, "leader": c.leader, "multiplier": round(c.multiplier, 6),
                       "offset": round(c.offset, 6), "source": c.source, "own_effort": c.own_effort}
                      for c in hand.couplings],
        # the simulation's servo on each actuated joint, relative to an uncoupled one's
        "servo_gain_scale": {j: round(float(w), 4) for j, w in zip(hand.actuated_joints, hand.servo_weight)},
        "servo_torque_scale": {j: round(float(w), 4) for j, w in zip(hand.actuated_joints, hand.servo_force_scale)},
        "held_joints": {j: round(float(v), 6) for j, v in hand.held_joints.items()},
        "notes": list(hand.notes),
        "source_hash": hand.source_hash,
    }


def _sense(c: int) -> str:
    return {1: "+1 closes", -1: "-1 closes", 0: "pre-shape"}[int(c)]


def text(data: dict[str, Any]) -> str:
    """The derivation as text for a person."""
    out = [f"hand {data['name']}  ({len(data['actuated_joints'])} actuated joints, {len(data['fingers'])} fingers)",
           f"root link (palm): {data['root_link']}   palm normal (root frame): {data['palm_normal']}"]
    if data["held_joints"]:
        held = ", ".join(f"{j}={v:g}" for j, v in data["held_joints"].items())
        out.append(f"held above or beside the palm (fixed, not actuated for grasping): {held}")
    for f in data["fingers"]:
        out.append(f"finger {f['name']}{' (thumb)' if f['thumb'] else ''}: tip {f['tip_link']}")
        for joint, c in zip(f["joints"], f["closing"]):
            lo, hi = data["limits"][joint]
            out.append(f"    {joint:<32} {_sense(c):<10} [{lo:g}, {hi:g}]")
        out.append(f"    pad on {f['pad_link']} at {f['pad_center']} m, radius {f['pad_radius'] * 1000:.1f} mm")
    for c in data["couplings"]:
        effort = "; its own effort limit" if c["own_effort"] else ""
        out.append(f"coupling: {c['follower']} = {c['multiplier']:g} * {c['leader']} + {c['offset']:g}  "
                   f"({c['source']}{effort})")
    scaled = [j for j in data["actuated_joints"] if data["servo_gain_scale"][j] != 1.0]
    for j in scaled:
        out.append(f"servo on {j}: gain x{data['servo_gain_scale'][j]:g}, torque limit "
                   f"x{data['servo_torque_scale'][j]:g} (it drives coupled joints)")
    if data["spheres"]:
        total = sum(s["count"] for s in data["spheres"].values())
        worst = max(s["max_stray_m"] for s in data["spheres"].values())
        out.append(f"collision spheres: {total} over {len(data['spheres'])} links, largest stray {worst * 1000:.2f} mm")
        for link, s in data["spheres"].items():
            extra = f", {s['uncovered'] * 100:.2f} % of the surface uncovered" if s["uncovered"] > 0 else ""
            out.append(f"    {link:<32} {s['count']:>4} spheres, stray {s['max_stray_m'] * 1000:.2f} mm{extra}")
    for note in data["notes"]:
        out.append(f"note: {note}")
    return "\n".join(out) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (0 ok, 2 bad input)."""
    args = _parser().parse_args(argv)
    from ..model.hands.load import load_hand

    try:
        hand = load_hand(args.file, args.hand_config)
    except GraspApsoError as exc:
        print(f"{PROG}: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    data = summary(hand)
    sys.stdout.write(json.dumps(data, indent=2) + "\n" if args.json else text(data))
    if args.picture:
        from .hand_picture import draw_hand

        try:
            draw_hand(hand, args.picture)
        except OSError as exc:
            print(f"{PROG}: error: --picture: cannot write {args.picture}: {exc.strerror or exc}", file=sys.stderr)
            return 2
        if not args.json:
            print(f"picture: {args.picture}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
