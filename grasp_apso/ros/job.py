"""A job's mutable state while the node serves one :class:`~.plan_request.PlanRequest`,
and its deadline.

:class:`Stage` says where the job is (a timeout or a cancel names it). ``answered`` is
claimed once (:meth:`Job.claim_answer`) by whichever of the worker, the deadline or a
cancel answers first; the others then do nothing. :class:`Deadline` runs the two timers
of ``plan_timeout``: at the timeout, and ``grace`` seconds later when the final
verification has not ended.
"""

from __future__ import annotations

import enum
import threading
from dataclasses import dataclass, field
from typing import Callable

from rclpy.action.server import ServerGoalHandle
from rclpy.executors import Executor
from rclpy.task import Future

from .plan_request import PlanRequest, RequestKind

__all__ = ["Stage", "LOADING_STAGES", "Job", "Deadline"]


class Stage(str, enum.Enum):
    """Where a job is; the values are the words of the messages."""

    QUEUED = "queued"
    READING = "reading"                  # a mesh file
    VALIDATION = "validation"            # mesh checks, placement in the scene
    PREPARATION = "preparation"          # distance grid, shape class, GRG's first particles
    DATABASE_LOOKUP = "database lookup"
    PLANNING = "planning"                # the swarm's iterations and the final verification


#: Stages a job cannot be interrupted in: a timeout or cancel answers at once.
LOADING_STAGES = frozenset({Stage.READING, Stage.VALIDATION, Stage.PREPARATION, Stage.DATABASE_LOOKUP})


@dataclass(eq=False)
class Job:
    """The running state of one request (created when it is admitted)."""

    request: PlanRequest
    goal_handle: ServerGoalHandle | None = None
    client: bytes | None = None              # the client's request writer GUID, when known
    future: Future | None = None             # the rclpy Future the node's callback awaits
    executor: Executor | None = None         # the executor that completes it
    stage: Stage = Stage.QUEUED
    started: bool = False
    cancelled: bool = False
    timed_out: bool = False
    answered: bool = False
    database_note: str = ""                  # why the grasp database did not answer
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    @property
    def request_id(self) -> str:
        return self.request.request_id

    @property
    def kind(self) -> RequestKind:
        return self.request.kind

    def claim_answer(self) -> bool:
        """True exactly once: the caller then answers the job."""
        with self.lock:
            if self.answered:
                return False
            self.answered = True
            return True

    def set_stage(self, name: str | Stage) -> None:
        """``on_stage`` callback of the object resolver (stage names are the values)."""
        self.stage = Stage(name)

    def cancel_requested(self) -> bool:
        """Cancelled by the node (a departed client, a cancel) or by the action's client."""
        goal = self.goal_handle
        return self.cancelled or (goal is not None and goal.is_cancel_requested)


class Deadline:
    """``plan_timeout`` of one job: ``on_timeout(job)`` after ``timeout`` s; when it returns
    True (the job is planning: it stops at its next poll), ``on_grace(job)`` follows
    ``grace`` s later unless :meth:`cancel` came first. Daemon timer threads;
    ``timeout <= 0`` means no deadline."""

    def __init__(self, job: Job, timeout: float, on_timeout: Callable[[Job], bool],
                 grace: float, on_grace: Callable[[Job], None]) -> None:
        self._job, self._grace = job, grace
        self._on_timeout, self._on_grace = on_timeout, on_grace
        self._lock = threading.Lock()
        self._cancelled = False
        self._timers: list[threading.Timer] = []
        if timeout > 0:
            self._add(timeout, self._fire)

    def _add(self, seconds: float, callback: Callable[[Job], None]) -> None:
        with self._lock:
            if self._cancelled:
                return
            timer = threading.Timer(seconds, callback, (self._job,))
            timer.daemon = True
            self._timers.append(timer)
            timer.start()

    def _fire(self, job: Job) -> None:
        if self._on_timeout(job):
            self._add(self._grace, self._on_grace)

    def cancel(self) -> None:
        with self._lock:
            self._cancelled = True
            timers = list(self._timers)
        for timer in timers:
            timer.cancel()
