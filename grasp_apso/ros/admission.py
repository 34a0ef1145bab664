"""Admission and the queue's book-keeping: at most ``workers`` jobs run and
``queue_length`` wait; another request is answered "busy" at once.

A place is reserved before a job exists (:meth:`Admission.reserve`: an action goal is
accepted or rejected in the goal callback) and freed exactly once, by
:meth:`Admission.remove` of the registered job or :meth:`Admission.release` of a place
whose job never started. The registry answers the node's questions: which jobs a
departed client had, which are still queued.
"""

from __future__ import annotations

import threading
from typing import Callable

from .job import Job
from .plan_request import RequestKind
from .replies import busy_message

__all__ = ["Admission"]


class Admission:
    """Places (running + waiting) and the registry of admitted jobs; thread-safe."""

    def __init__(self, workers: int, queue_length: int) -> None:
        self.workers = int(workers)
        self.queue_length = int(queue_length)
        self.stopping = threading.Event()
        self._lock = threading.Lock()
        self._pending = 0
        self._jobs: dict[str, Job] = {}

    def reserve(self) -> str | None:
        """Reserve a place; None when admitted, else the "busy" (or shutting down) message."""
        with self._lock:
            if self.stopping.is_set():
                return "node shutting down"
            if self._pending >= self.workers + self.queue_length:
                return busy_message(max(0, self._pending - self.workers), self.workers, self.queue_length)
            self._pending += 1
            return None

    def release(self) -> None:
        """Give back a place whose job was never registered."""
        with self._lock:
            self._pending = max(0, self._pending - 1)

    @property
    def pending(self) -> int:
        """Jobs running or waiting (reserved places)."""
        with self._lock:
            return self._pending

    def add(self, job: Job) -> None:
        """Register a job on its reserved place."""
        with self._lock:
            self._jobs[job.request_id] = job

    def remove(self, job: Job) -> None:
        """Unregister a job and free its place (once; later calls do nothing)."""
        with self._lock:
            if self._jobs.pop(job.request_id, None) is not None:
                self._pending = max(0, self._pending - 1)

    def select(self, predicate: Callable[[Job], bool]) -> list[Job]:
        """The registered jobs for which ``predicate`` holds."""
        with self._lock:
            jobs = list(self._jobs.values())
        return [j for j in jobs if predicate(j)]

    def active_kinds(self) -> set[RequestKind]:
        """The kinds of the jobs queued or running."""
        with self._lock:
            return {j.kind for j in self._jobs.values()}
