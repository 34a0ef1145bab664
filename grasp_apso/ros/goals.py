"""The action goals the node is working on, by goal id, and the cancels that came first.

rclpy calls the cancel callback for any active goal, also one whose execute callback has not
yet run and registered its job: such a cancel is remembered here (bounded) and the job is
cancelled as it is registered, so that a queued goal is still answered at once instead of
after the running plan.
"""

from __future__ import annotations

import threading

from .job import Job

__all__ = ["GoalRegistry", "EARLY_CANCELS"]

#: Cancelled goal ids kept for an execute callback yet to come (a cancel of a goal that has
#: just finished also lands here: bounded, oldest dropped first).
EARLY_CANCELS = 256


def _key(goal_handle) -> bytes:
    return bytes(goal_handle.goal_id.uuid)


class GoalRegistry:
    """Jobs by goal (its UUID) and the early cancels; thread-safe."""

    def __init__(self, remembered: int = EARLY_CANCELS) -> None:
        self._remembered = int(remembered)
        self._lock = threading.Lock()
        self._jobs: dict[bytes, Job] = {}
        self._early: dict[bytes, None] = {}  # insertion order: oldest first

    def register(self, goal_handle, job: Job) -> bool:
        """Register the goal's job; True when the goal's cancel came before (cancel the job).
        No goal (a service request): nothing, False."""
        if goal_handle is None:
            return False
        key = _key(goal_handle)
        with self._lock:
            self._jobs[key] = job
            early = key in self._early
            self._early.pop(key, None)
        return early or bool(goal_handle.is_cancel_requested)

    def to_cancel(self, goal_handle) -> Job | None:
        """The registered job of a goal being cancelled; None, and the cancel remembered for
        :meth:`register`, when it has none yet."""
        key = _key(goal_handle)
        with self._lock:
            job = self._jobs.get(key)
            if job is None:
                self._early[key] = None
                while len(self._early) > self._remembered:
                    self._early.pop(next(iter(self._early)))
            return job

    def remove(self, goal_handle) -> None:
        """Forget a finished goal's job (no goal: nothing)."""
        if goal_handle is None:
            return
        with self._lock:
            self._jobs.pop(_key(goal_handle), None)
