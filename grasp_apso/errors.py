"""Every exception type of grasp_apso, in one place.

Each error names the request field (or command-line option, or parameter) at fault in
``field`` and starts its message with it (``"mesh: triangle 3 index 99 out of range"``).
Front ends map *types* to exit codes and reply texts (the CLI: 2 for any
:class:`GraspApsoError`; the node: ``success: false`` with the message), never substrings.

All are ``ValueError`` subclasses, so code that caught ``ValueError`` before keeps working.

=========================  ==============================================================
type                       raised for
=========================  ==============================================================
``GraspApsoError``         base class; never raised itself
``InputError``             a bad option or argument value (``PlanOptions``, scene, API)
``ObjectError``            a bad mesh, mesh file, object name or object pose
``HandDescriptionError``   a hand description file that is not a valid hand
``SceneError``             a bad support plane / obstacle, or an object placed into them
``PlanningError``          a valid request that cannot be planned (object too large or
                           small for the hand, no valid or collision-free grasp)
``ObjectTooLargeError``    the ``PlanningError`` for an object wider than the hand opens
``RequestError``           a ROS request field that is malformed (node side)
``TimeoutExceeded``        a request ran out of its time budget (names the stage)
``DatabaseError``          an unreadable, corrupt or locked grasp database
``SimulationError``        the physics check could not be built or run
``UsageError``             bad command-line usage (the CLI prints it as one line)
=========================  ==============================================================
"""

from __future__ import annotations

__all__ = [
    "GraspApsoError", "InputError", "ObjectError", "HandDescriptionError", "SceneError",
    "PlanningError", "ObjectTooLargeError", "RequestError", "TimeoutExceeded", "DatabaseError",
    "SimulationError", "UsageError",
]


class GraspApsoError(ValueError):
    """Base of every grasp_apso error; ``field`` is the offending field, if one is known."""

    def __init__(self, message: str, field: str | None = None):
        super().__init__(message)
        if field is None and ":" in message:
            head = message.split(":", 1)[0]
            field = head if head and " " not in head.strip() else None
        self.field = field


class InputError(GraspApsoError):
    """A bad option or argument value."""


class ObjectError(GraspApsoError):
    """An invalid object: bad mesh, mesh file, object name or object pose.

    The message starts with the request field at fault (``mesh``, ``mesh_uri``,
    ``object_name``, ``object_pose``) and names the problem.
    """


class HandDescriptionError(GraspApsoError):
    """A hand description that is not a valid hand (never echoes the file's content)."""


class SceneError(GraspApsoError):
    """A bad scene: support plane, obstacle, clearance, or the object placed into them."""


class PlanningError(GraspApsoError):
    """The request cannot be planned (object unsuitable for the hand, no valid grasp)."""


class ObjectTooLargeError(PlanningError):
    """The object is wider than the hand opens (a mesh in millimetres, often)."""


class RequestError(GraspApsoError):
    """A malformed ROS request field (node side); the message names the field."""


class TimeoutExceeded(GraspApsoError):
    """A request ran out of time; ``stage`` says where (reading, validation, preparation,
    planning, simulation)."""

    def __init__(self, message: str, stage: str, field: str | None = "plan_timeout"):
        super().__init__(message, field)
        self.stage = stage


class DatabaseError(GraspApsoError):
    """A grasp database that cannot be used (corrupt, unreadable, locked by another writer)."""


class SimulationError(GraspApsoError):
    """The physics check could not be built or run."""


class UsageError(InputError):
    """Bad command-line usage: printed as one line, exit status 2."""
