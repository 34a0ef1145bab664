"""Every tunable of grasp_apso, defined once: name, type, default, range, unit, description.

Everything else is derived from (or checked against) this table:

- :class:`grasp_apso.search.swarm.SwarmOptions` and :class:`grasp_apso.search.planner.PlanOptions`
  take their defaults from :func:`default` and validate with :func:`check`;
- the ROS node declares one parameter per entry whose ``ros`` flag is set, with a
  descriptor built from it (:mod:`grasp_apso.ros.parameters`);
- ``config/grasp_apso.yaml`` and the README's parameter table are checked against it by
  ``test/test_tunables.py`` (``python -m grasp_apso.tunables yaml`` prints the YAML).

Scopes: ``swarm`` (the optimiser), ``grasp`` (decoding and quality), ``scene`` (scene
and approach), ``candidates`` (the ranked list), ``simulation``, ``node`` (the ROS node
only: requests, limits, security). ``read_only`` parameters are security or resource
limits: the node reads them at start-up and refuses any change at run time.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InputError

__all__ = ["Tunable", "TUNABLES", "default", "check", "spec", "ros_tunables", "yaml_text"]

_INT64_MAX = 2**63 - 1


@dataclass(frozen=True)
class Tunable:
    """One tunable value.

    Attributes
    ----------
    name : str
    kind : type
        ``int``, ``float``, ``str`` or ``bool``.
    default : Any
    description : str
        One sentence, used for the ROS descriptor, the YAML comment and the README table.
    lo, hi : float or None
        Inclusive range (``lo_open``: the lower bound is exclusive).
    choices : tuple of str or None
        Accepted strings.
    unit : str
        SI unit ("m", "s", "rad", "bytes", ...) or "".
    scope : str
    ros : bool
        Declared as a ROS parameter of the node.
    read_only : bool
        A security or resource limit: fixed after the node starts.
    """

    name: str
    kind: type
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple[str, ...] | None = None
    unit: str = ""
    scope: str = "grasp"
    ros: bool = True
    read_only: bool = False

    def range_text(self) -> str:
        """``[lo, hi]`` / ``(lo, hi]`` / ``one of a, b`` / ``""``."""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.lo is None or self.hi is None:
            return ""
        return f"{'(' if self.lo_open else '['}{_fmt(self.lo)}, {_fmt(self.hi)}]"

    def check(self, value: Any, field: str | None = None) -> Any:
        """Return ``value`` converted to ``kind``, or raise :class:`InputError` naming the field."""
        name = field or self.name
        if self.kind is bool:
            if not isinstance(value, (bool, np.bool_)):
                raise InputError(f"{name}: expected true or false, got {value!r}", name)
            return bool(value)
        if self.kind is str:
            if not isinstance(value, str):
                raise InputError(f"{name}: expected a string, got {value!r}", name)
            if self.choices and value not in self.choices:
                raise InputError(f"{name}: unknown '{value}' (expected one of {', '.join(self.choices)})", name)
            return value
        if self.kind is int:
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                raise InputError(f"{name}: expected an integer in {self.range_text()}, got {value!r}", name)
            value = int(value)
        else:
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise InputError(f"{name}: expected a number in {self.range_text()}, got {value!r}", name)
            value = float(value)
            if not math.isfinite(value):
                raise InputError(f"{name}: expected a finite number, got {value!r}", name)
        if self.lo is not None and (value < self.lo or (self.lo_open and value == self.lo)):
            raise InputError(f"{name}: {value!r} is outside {self.range_text()}{_unit(self.unit)}", name)
        if self.hi is not None and value > self.hi:
            raise InputError(f"{name}: {value!r} is outside {self.range_text()}{_unit(self.unit)}", name)
        return value


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else repr(float(x))


def _unit(unit: str) -> str:
    return f" {unit}" if unit else ""


def _t(*args: Any, **kwargs: Any) -> Tunable:
    return Tunable(*args, **kwargs)


#: The table. Order = the order of the YAML file and the README table.
TUNABLES: tuple[Tunable, ...] = (
    # --- swarm ---------------------------------------------------------------------
    _t("algorithm", str, "apso", "Algorithm: apso (adaptive, GRG start) or pso (the simple PSO baseline).",
       choices=("apso", "pso"), scope="swarm"),
    _t("particles", int, 60, "Swarm size np.", 2, 1000, scope="swarm"),
    _t("iterations", int, 50, "Iterations nit (a general hand without `simulate`: 0.7 of them in its first search, "
       "half in a second one when it runs).", 1, 10000, scope="swarm"),
    _t("seed", int, -1, "Random seed; -1 = a fresh random seed per request.", -1, _INT64_MAX,
       scope="swarm"),
    _t("neighborhood_size", int, 5, "Particles per APSO neighbourhood (clamped to the swarm size).",
       1, 1000, scope="swarm"),
    _t("c1", float, 1.0, "Acceleration constant toward each particle's personal best.", 0.0, 4.0,
       scope="swarm"),
    _t("c2", float, 1.5, "Acceleration constant toward the global best.", 0.0, 4.0, scope="swarm"),
    _t("inertia", float, 0.6, "Inertia weight w applied to the velocity after each step.", 0.0, 1.0,
       scope="swarm"),
    _t("stall_iterations", int, 3, "APSO: iterations without improvement before a neighbourhood's "
       "worst particle is replaced by a new GRG particle.", 1, 1000, scope="swarm"),
    _t("improvement", float, 1e-3, "Fitness gain that counts as an improvement.", 0.0, 1.0,
       scope="swarm", ros=False),
    _t("velocity_init", float, 0.05, "Initial velocities, as a fraction of each dimension's range.",
       0.0, 1.0, scope="swarm", ros=False),
    _t("velocity_max", float, 0.25, "Velocity clamp, as a fraction of each dimension's range.",
       0.0, 1.0, lo_open=True, scope="swarm", ros=False),
    _t("max_replacements", float, 0.1, "APSO: largest fraction of the swarm replaced per iteration "
       "for stalling.", 0.0, 1.0, scope="swarm", ros=False),
    _t("max_evaluations", int, 0, "Cap on particle decodes (0 = none), for equal-budget comparisons.",
       0, 10_000_000, scope="swarm", ros=False),
    # --- grasp: decoding and quality -------------------------------------------------
    _t("contact_tolerance", float, 0.002, "A fingertip pad this close to the surface is a contact.",
       0.0, 0.02, lo_open=True, unit="m"),
    _t("friction", float, 0.5, "Coulomb friction coefficient mu of the friction cones.", 0.0, 5.0,
       lo_open=True),
    _t("friction_edges", int, 8, "Edges of the linearised friction cones (epsilon quality).", 3, 64),
    _t("closure_candidates", int, 30, "When the global best is not force closure, how many of the "
       "best distinct personal bests are checked for a force-closure grasp (1 = the global best only).",
       1, 100),
    # --- scene and approach ----------------------------------------------------------
    _t("clearance", float, 0.005, "Least distance between any hand part and the support planes or "
       "obstacles, at the grasp and along the approach (a request's 0 = this).", 0.0, 0.1,
       unit="m", scope="scene"),
    _t("approach_distance", float, 0.08, "Distance the pre-grasp wrist is retreated along minus the "
       "approach direction (a request's 0 = this).", 0.0, 0.5, lo_open=True, unit="m", scope="scene"),
    # --- candidates ------------------------------------------------------------------
    _t("max_grasps", int, 5, "Ranked, distinct candidates per request (a request's 0 = this).",
       1, 50, scope="candidates"),
    _t("min_orientation_gap", float, math.radians(20.0), "Two candidates are distinct when their "
       "wrist orientations differ by at least this, or their positions by min_position_gap.",
       0.0, math.pi, unit="rad", scope="candidates"),
    _t("min_position_gap", float, 0.015, "Two candidates are distinct when their wrist positions "
       "differ by at least this, or their orientations by min_orientation_gap.", 0.0, 0.5,
       unit="m", scope="candidates"),
    # --- simulation ------------------------------------------------------------------
    _t("decomposition_timeout", float, 60.0, "Longest the convex decomposition of a new non-convex mesh "
       "(CoACD, once per mesh, kept on disk) may run in its own process, then again with coarser settings; "
       "a request never waits for it past its own time bound (its candidates are then not simulated).",
       0.0, 3600.0, lo_open=True, unit="s", scope="simulation"),
    # --- node: resources and security ----------------------------------------------
    _t("hand_description", str, "", "Path of the hand description: a URDF (.urdf), MJCF (.xml) or the "
       "project's YAML (.yaml) (a xacro file is refused: expand it first, `xacro hand.urdf.xacro > "
       "hand.urdf`); empty = the paper's hand shipped in the package. Loaded once at start-up; "
       "every request plans with it and replies over its actuated joints.",
       scope="node", read_only=True),
    _t("hand_config", str, "", "Path of a YAML file overriding what is derived from the hand "
       "description (root link, fingers, thumb, closing senses, palm normal, pads); empty = none.",
       scope="node", read_only=True),
    _t("max_hand_file_bytes", int, 20_000_000, "Largest accepted hand description file and collision "
       "mesh file.", 1, 2_000_000_000, unit="bytes", scope="node", ros=False),
    _t("allowed_mesh_dir", str, "", "Directory mesh_uri files must lie in (symlinks and '..' "
       "resolved); empty = mesh files are refused.", scope="node", read_only=True),
    _t("max_mesh_triangles", int, 200_000, "Largest accepted mesh (inline or file), triangles.",
       4, 10_000_000, scope="node", read_only=True),
    _t("max_mesh_bytes", int, 50_000_000, "Largest accepted mesh file.", 1, 2_000_000_000,
       unit="bytes", scope="node", read_only=True),
    _t("queue_length", int, 4, "Requests that may wait behind the running plans; more are answered "
       "'busy' at once.", 0, 1000, scope="node", read_only=True),
    _t("workers", int, 1, "Plans that run at the same time, each on a thread of its own (the "
       "kernels release the GIL); more requests wait in the queue.", 1, 16, scope="node",
       read_only=True),
    _t("grasp_database", str, "", "Path of a grasp database written by grasp_apso_batch: requests "
       "for a stored object and hand are answered from it when a stored grasp survives the "
       "request's scene; empty = none.", scope="node", read_only=True),
    _t("cache_directory", str, "", "Folder of the on-disk caches (convex decompositions, a hand's sphere covers "
       "and pads, objects' distance grids); empty = $GRASP_APSO_CACHE, else $XDG_CACHE_HOME/grasp_apso, else "
       "~/.cache/grasp_apso.", scope="node", read_only=True),
    _t("plan_timeout", float, 60.0, "Seconds a request may spend in the worker (reading, validation, "
       "preparation, planning); it is answered 'timed out' naming the stage. 0 = no limit.",
       0.0, 86400.0, unit="s", scope="node"),
)

_BY_NAME: dict[str, Tunable] = {t.name: t for t in TUNABLES}


def spec(name: str) -> Tunable:
    """The :class:`Tunable` called ``name`` (KeyError for an unknown name)."""
    return _BY_NAME[name]


def default(name: str) -> Any:
    """The default value of ``name``."""
    return _BY_NAME[name].default


def check(name: str, value: Any, field: str | None = None) -> Any:
    """Validate ``value`` for the tunable ``name``; returns it converted."""
    return _BY_NAME[name].check(value, field)


def ros_tunables() -> tuple[Tunable, ...]:
    """The entries declared as ROS parameters, in table order."""
    return tuple(t for t in TUNABLES if t.ros)


def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '""' if value == "" else value
    if isinstance(value, float):
        return repr(value)
    return str(value)


def yaml_text() -> str:
    """The node's parameter file (``config/grasp_apso.yaml``), generated from the table."""
    lines = [
        "# Parameters of the grasp_apso node with their defaults. GENERATED from",
        "# grasp_apso/tunables.py (python -m grasp_apso.tunables yaml); a test checks it.",
        "# Use:  planner_node --ros-args --params-file config/grasp_apso.yaml",
        "# Every value is checked at start-up and on `ros2 param set`; read-only ones (security",
        "# and resource limits) cannot be changed after start-up. Units: SI.",
        "grasp_apso:",
        "  ros__parameters:",
    ]
    scope = None
    for t in ros_tunables():
        if t.scope != scope:
            scope = t.scope
            lines.append(f"    # --- {scope} ---")
        notes = [t.range_text(), t.unit, "read-only" if t.read_only else ""]
        note = ", ".join(n for n in notes if n)
        lines.append(f"    {t.name}: {_yaml_value(t.default)}  # {note}".rstrip())
    return "\n".join(lines) + "\n"


def markdown_table() -> str:
    """The README's parameter table, generated from the table."""
    rows = ["| parameter | type | default | range | description |", "|---|---|---|---|---|"]
    for t in ros_tunables():
        kind = {int: "int", float: "double", str: "string", bool: "bool"}[t.kind]
        unit = f", {t.unit}" if t.unit else ""
        ro = " (read-only)" if t.read_only else ""
        default_text = '""' if t.default == "" else _yaml_value(t.default)
        rows.append(f"| `{t.name}` | {kind}{unit}{ro} | {default_text} | {t.range_text()} | {t.description} |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":  # python -m grasp_apso.tunables yaml|markdown
    what = sys.argv[1] if len(sys.argv) > 1 else "yaml"
    sys.stdout.write(markdown_table() if what == "markdown" else yaml_text())
