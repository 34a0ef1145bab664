"""``planner_node --help``: the usage text, made from :mod:`grasp_apso.tunables` (no ROS
is started to print it)."""

from __future__ import annotations

import textwrap

from ..tunables import ros_tunables

__all__ = ["wants_help", "usage_text"]


def wants_help(argv: list[str]) -> bool:
    """True when ``-h`` / ``--help`` comes before any ``--ros-args`` (ROS's own arguments
    are not ours to interpret)."""
    for arg in argv:
        if arg == "--ros-args":
            return False
        if arg in ("-h", "--help"):
            return True
    return False


def usage_text() -> str:
    """The usage: how to start the node, its interface, and every parameter."""
    lines = [
        "usage: planner_node [-h] [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] "
        "[--log-level grasp_apso:=debug] ...]",
        "",
        "The grasp_apso node: plans precision grasps (APSO + GRG) for a five-fingered hand.",
        "Serves the service and the action ~/plan_grasp (grasp_apso_interfaces/PlanGrasp), publishes",
        "~/progress (GraspProgress, one per iteration) and ~/grasp_markers (MarkerArray). Says \"ready\"",
        "once its planner kernels are loaded. Stops cleanly on SIGINT / SIGTERM.",
        "",
        "parameters (set with --ros-args -p NAME:=VALUE, or a --params-file; read-only ones only at start):",
    ]
    for t in ros_tunables():
        unit = f" {t.unit}" if t.unit else ""
        flags = ", read-only" if t.read_only else ""
        head = f"  {t.name} ({t.kind.__name__}, default {t.default!r}{unit}, {t.range_text()}{flags})"
        lines.append(head)
        lines.extend(textwrap.wrap(t.description, width=96, initial_indent="      ", subsequent_indent="      "))
    lines += ["", "every default as a parameter file: config/grasp_apso.yaml"]
    return "\n".join(lines) + "\n"
