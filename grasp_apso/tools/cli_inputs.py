"""What ``grasp_apso_plan`` reads from its command line: the object, the algorithms and the
scene (``--table``, ``--obstacle``), and how library errors are named after the options.

Obstacle format (planning frame = the object frame on the command line; metres):

==========================  ===================================================================
``box:x,y,z,sx,sy,sz``      a box centred at (x, y, z), full sizes sx, sy, sz along the axes
``sphere:x,y,z,r``          a sphere centred at (x, y, z), radius r
``cylinder:x,y,z,h,r``      a cylinder centred at (x, y, z), axis along z, height h, radius r
==========================  ===================================================================

The same primitives and conventions as the ROS request (``shape_msgs/SolidPrimitive``:
BOX dimensions are full sizes, CYLINDER ``[height, radius]``); obstacles are axis-aligned
here (the Python API and the node take any pose).
"""

from __future__ import annotations

import argparse
import math
import re

import numpy as np

from ..errors import GraspApsoError, UsageError
from ..model.object_source import BuiltinObject, MeshFile, resolve_object
from ..model.scene import BOX, CYLINDER, SPHERE, Scene
from ..search.planner import ALGORITHMS

__all__ = [
    "OBSTACLE_FORMATS", "whole_number", "finite_number", "cli_message", "load_object",
    "algorithms", "safe_name", "parse_obstacle", "build_scene", "source_option",
]

#: ``kind -> (primitive type, the numbers after the centre, help text)``.
OBSTACLE_FORMATS: dict[str, tuple[int, tuple[str, ...], str]] = {
    "box": (BOX, ("sx", "sy", "sz"), "box:x,y,z,sx,sy,sz (centre, full sizes)"),
    "sphere": (SPHERE, ("r",), "sphere:x,y,z,r (centre, radius)"),
    "cylinder": (CYLINDER, ("h", "r"), "cylinder:x,y,z,h,r (centre, height along z, radius)"),
}

#: Request / option field -> command-line option, for messages of the library.
_OPTION_OF_FIELD = {
    "mesh_uri": "--mesh", "mesh": "--mesh", "object_name": "--object", "particles": "--particles",
    "iterations": "--iterations", "friction": "--friction", "algorithm": "--algorithm",
    "clearance": "--clearance", "approach_distance": "--approach-distance", "max_grasps": "--grasps",
    "simulate": "--simulate", "support_planes": "--table", "obstacle_poses": "--obstacle",
    "obstacles": "--obstacle", "hand description": "--hand", "hand_description": "--hand",
    "hand_config": "--hand-config",
}
#: Fields naming the object itself, whichever option gave it (``--object`` or ``--mesh``).
_OBJECT_FIELDS = ("object", "object_pose")
#: A scene item, as a message's field or inside its text (``... penetrates obstacles[1] ...``).
_REFERENCE = re.compile(r"\b(support_planes|obstacles|obstacle_poses)\[(\d+)\]")


def whole_number(text: str) -> int:
    """argparse type: an integer (its range is checked by the planner's options)."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None


def finite_number(text: str) -> float:
    """argparse type: a finite float."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _option_label(kind: str, index: str) -> str:
    """``obstacles``, ``"1"`` -> ``--obstacle 2`` (1-based, as given); planes -> ``--table``."""
    option = _OPTION_OF_FIELD[kind]
    return option if option == "--table" else f"{option} {int(index) + 1}"


def cli_message(exc: BaseException, object_option: str = "--object") -> str:
    """The first line of an error with the request fields renamed to the options.

    ``clearance: ...`` -> ``--clearance: ...``; ``obstacles[1]: ...`` -> ``--obstacle 2: ...``;
    a placement error of the object (``object_pose: the object penetrates obstacles[1] ...``)
    is put on the scene item it names (``--obstacle 2: the object penetrates this obstacle
    ...``); other errors about the object name ``object_option`` (``--object`` or ``--mesh``).
    """
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    head, sep, rest = text.partition(":")
    if not sep:
        return text
    field = head.strip()  # grasp_apso errors start with their field
    if field in _OBJECT_FIELDS:
        ref = _REFERENCE.search(rest)
        if ref is not None:  # the object against one scene item: name that item's option
            this = "the table" if ref.group(1) == "support_planes" else "this obstacle"
            rest = rest[:ref.start()] + this + rest[ref.end():]
            field = f"{ref.group(1)}[{ref.group(2)}]"
        else:
            return object_option + ":" + _REFERENCE.sub(lambda m: _option_label(*m.groups()), rest)
    rest = _REFERENCE.sub(lambda m: _option_label(*m.groups()), rest)
    indexed = _REFERENCE.fullmatch(field)
    if indexed:
        return _option_label(*indexed.groups()) + ":" + rest
    if field in _OPTION_OF_FIELD:
        return _OPTION_OF_FIELD[field] + ":" + rest
    base, dot, key = field.partition(".")  # hand_config.thumb: ... -> --hand-config: thumb: ...
    if dot and base in _OPTION_OF_FIELD:
        return f"{_OPTION_OF_FIELD[base]}: {key}:" + rest
    return head + ":" + rest


def source_option(args: argparse.Namespace | None) -> str:
    """The option that gave the object: ``--mesh`` or ``--object`` (also the default sphere)."""
    return "--mesh" if args is not None and getattr(args, "mesh", None) is not None else "--object"


def load_object(args: argparse.Namespace):
    """The object of ``--object`` / ``--mesh`` (``--mesh-scale``) and a word on its source."""
    if args.mesh is not None:
        if args.mesh_scale <= 0:
            raise UsageError(f"--mesh-scale: expected a positive number, got {args.mesh_scale:g}")
        return resolve_object(MeshFile(args.mesh, scale=args.mesh_scale)), "mesh file " + args.mesh
    name = args.object if args.object is not None else "sphere"
    return resolve_object(BuiltinObject(name.strip().lower())), "built-in"


def algorithms(text: str) -> tuple[str, ...]:
    """``--algorithm``: apso, pso or both."""
    text = text.strip().lower()
    if text == "both":
        return ALGORITHMS
    if text in ALGORITHMS:
        return (text,)
    raise UsageError(f"--algorithm: unknown '{text}' (expected apso, pso or both)")


def safe_name(name: str) -> str:
    """A file-name-safe stem of an object name."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "object"


def parse_obstacle(text: str) -> tuple[int, tuple[float, ...], np.ndarray]:
    """One ``--obstacle`` value -> (primitive type, dimensions, 4x4 pose of its centre).

    Only the syntax is checked here; the dimensions' values (positive, finite) are checked
    by :meth:`Scene.from_primitives`, whose message then names the obstacle.
    """
    kind, sep, numbers = text.partition(":")
    kind = kind.strip().lower()
    if not sep or kind not in OBSTACLE_FORMATS:
        raise UsageError(f"--obstacle: '{text}': expected one of "
                         + ", ".join(f[2] for f in OBSTACLE_FORMATS.values()) + " (metres)")
    primitive, names, form = OBSTACLE_FORMATS[kind]
    try:
        values = [float(v) for v in numbers.split(",")]
    except ValueError:
        raise UsageError(f"--obstacle: '{text}': expected numbers, {form}") from None
    if len(values) != 3 + len(names):
        raise UsageError(f"--obstacle: '{text}': a {kind} takes {3 + len(names)} numbers, {form}; "
                         f"got {len(values)}")
    if not all(math.isfinite(v) for v in values):
        raise UsageError(f"--obstacle: '{text}': numbers must be finite")
    pose = np.eye(4)
    pose[:3, 3] = values[:3]
    return primitive, tuple(values[3:]), pose


def build_scene(obj, table: bool, obstacles: list[str] | None) -> Scene | None:
    """The scene of ``--table`` and ``--obstacle`` in the planning frame (= the object
    frame here), or None when neither is given.

    ``--table``: a support plane, normal +z, through the object's lowest point.
    """
    obstacles = list(obstacles or [])
    if not table and not obstacles:
        return None
    parsed = [parse_obstacle(t) for t in obstacles]
    planes = []
    if table:
        planes = list(Scene.table_under(np.asarray(obj.mesh.vertices, float)).planes)
    try:
        return Scene.from_primitives(planes=planes, obstacles=[(k, d) for k, d, _ in parsed],
                                     obstacle_poses=[p for _, _, p in parsed])
    except GraspApsoError as exc:
        raise UsageError(cli_message(exc)) from None
