"""The wording of the node's replies and the :class:`Outcome` a job ends with.

One place for every message a client reads: busy, timed out (and in which stage),
cancelled, internal error, and the verdict of a plan (the CLI's wording,
:func:`grasp_apso.presentation.summary.grasp_verdict`). No ROS entities here.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..presentation.summary import grasp_summary, grasp_verdict
from ..search.result import GraspResult
from . import database_answers

__all__ = ["Outcome", "busy_message", "timeout_message", "internal_error_message", "plan_outcome",
           "LOADING_TIMEOUT_TAIL", "VERIFICATION_TIMEOUT_TAIL"]

LOADING_TIMEOUT_TAIL = ("; the node finishes loading this object in the background and keeps it, "
                        "so a repeat of the request is faster")
VERIFICATION_TIMEOUT_TAIL = " (the final verification did not end)"


@dataclass
class Outcome:
    """What a job answers (``source``: the reply's ``grasp_source``, "planned" or
    "database"; a database answer's ``result`` is a
    :class:`~.database_answers.StoredGrasps`; ``worker_time`` in s)."""

    success: bool
    message: str
    result: GraspResult | database_answers.StoredGrasps | None = None
    cancelled: bool = False
    worker_time: float = 0.0
    source: str = "planned"


def busy_message(waiting: int, workers: int, queue_length: int) -> str:
    return (f"busy: {waiting} requests queued behind the {workers} running plan(s) "
            f"(queue_length {queue_length}, workers {workers}); try again later")


def timeout_message(timeout: float, stage: str, tail: str = "") -> str:
    return f"timed out after {timeout:g} s (parameter plan_timeout) during {stage}{tail}"


def internal_error_message(stage: str, request_id: str) -> str:
    return f"internal error during {stage} (request {request_id}; the details are in the node's log)"


def plan_outcome(result: GraspResult, iterations: int, elapsed: float, *, stopping: bool, cancelled: bool,
                 timed_out: bool, timeout: float, max_grasps: int, note: str = "") -> Outcome:
    """The outcome of a finished plan.

    ``stopping``: the node shuts down; ``cancelled``: the client cancelled (or left);
    ``timed_out``: ``plan_timeout`` ran out (the swarm then stopped early); ``note``: why
    the grasp database did not answer.
    """
    summary = grasp_summary(result, iterations, elapsed)
    if stopping and result.cancelled:
        return Outcome(False, f"node shutting down: stopped after {summary}", result, True)
    if result.cancelled and cancelled:
        return Outcome(False, f"cancelled: {summary}", result, cancelled=True)
    if timed_out and result.cancelled:
        return Outcome(False, f"{timeout_message(timeout, 'planning')}: best so far {summary}", result)
    verdict = grasp_verdict(result, iterations, elapsed)  # the CLI's wording too
    if not result.valid:
        return Outcome(False, verdict, result)
    n = len(result.candidates)
    if n < max_grasps and not result.candidates_message:
        verdict += f"; {n} of the {max_grasps} requested distinct candidates found"
    return Outcome(True, f"{verdict}{'; ' + note if note else ''}", result)
