"""The checked request: an immutable :class:`PlanRequest` built once by :mod:`.requests`.

Everything a job needs to run and to be answered, and nothing that changes while it runs
(its progress, cancel flag and Future are the job's state, :mod:`.job`). No ROS types
here: the frame and stamp are kept as plain values and turned back into a header by the
node when it answers.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from ..model.hand import HandModel
from ..model.object_source import ObjectSource
from ..model.scene import Scene
from ..search.options import PlanOptions

__all__ = ["PlanRequest", "RequestKind"]


class RequestKind(str, enum.Enum):
    """Which server took the request (clients are watched per kind)."""

    SERVICE = "service"
    ACTION = "action"


@dataclass(frozen=True, eq=False)
class PlanRequest:
    """A request that passed the cheap checks of :func:`~.requests.parse_request`.

    Attributes
    ----------
    request_id : str
        The reply's ``request_id`` (a UUID).
    frame_id : str
        The planning frame (``object_pose.header.frame_id``).
    stamp : (int, int)
        ``object_pose.header.stamp`` as (sec, nanosec), echoed in the reply.
    pose : (4, 4) float
        Object frame -> planning frame.
    source : InlineMesh, MeshFile or BuiltinObject
        Where the object comes from (:mod:`grasp_apso.model.object_source`).
    options : PlanOptions
    seed : int or None
        None = a fresh random seed.
    hand : HandModel
    timeout : float, s
        ``plan_timeout`` of the whole request (0 = none).
    scene : Scene or None
        Support planes and obstacles, planning frame.
    kind : RequestKind
    """

    request_id: str
    frame_id: str
    stamp: tuple[int, int]
    pose: np.ndarray
    source: ObjectSource
    options: PlanOptions
    seed: int | None
    hand: HandModel
    timeout: float
    scene: Scene | None = None
    kind: RequestKind = RequestKind.SERVICE

    @property
    def describe(self) -> str:
        """One line for the log: the object, the algorithm and the budget."""
        opts = self.options
        return (f"{self.source.describe()}, {opts.algorithm} {opts.particles} particles x {opts.iterations} "
                f"iterations, frame '{self.frame_id}'{', with a scene' if self.scene is not None else ''}")
