"""The node's worker: ``workers`` planning threads behind :class:`~.admission.Admission`,
the whole-request time bound, cancellation, and the one rule that every job is answered.

A job goes through the stages of :class:`~.job.Stage`: ``queued`` -> ``reading`` (a mesh
file) -> ``validation`` (mesh checks, placement in the scene) -> ``database lookup``
(with ``grasp_database``) -> ``preparation`` (the planner's distance grid, shape class)
-> ``planning`` (GRG's first particles, the swarm, the verification). Running it is
:func:`~.run_job.run_job`; the wording of the replies is :mod:`.replies`.

Time bound: ``plan_timeout`` counts from the moment a thread takes the job. When it runs
out in ``planning``, GRG and the swarm stop at their next poll (one batch, one iteration)
and the reply carries the best grasp so far; it is sent at the latest
:data:`TIMEOUT_GRACE` s later. A stage that cannot be interrupted (reading, validating,
preparing a large mesh) is answered at once "timed out during <stage>" and finishes in
the background, its object kept in the cache so that a repeat is fast; its thread stays
counted as busy until then.

Cancel: a queued job is answered at once and leaves the queue; a running one stops
within one iteration (or is answered at once when it is not planning yet).

Every job is answered: whatever raises -- the run, a hook, the log, a timer, the
completion -- ends in a reply (``success: false``, "internal error ...", the traceback
in the log) and frees its place. The job's rclpy Future is completed through
``executor.create_task`` (a Future completed from another thread does not wake the
awaiting coroutine).
"""

from __future__ import annotations

import sys
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable

from rclpy.executors import Executor
from rclpy.task import Future

from ..cache import BoundedCache
from ..errors import GraspApsoError
from ..model.objects import GraspObject
from ..model.planning_hand import is_general_hand
from ..search.any_hand_planner import warm_up_any_hand
from ..search.planner import warm_up
from .admission import Admission
from .job import LOADING_STAGES, Deadline, Job, Stage
from .replies import (LOADING_TIMEOUT_TAIL, VERIFICATION_TIMEOUT_TAIL, Outcome, internal_error_message,
                      timeout_message)
from .run_job import Hooks, run_job

__all__ = ["Outcome", "Worker", "OBJECT_CACHE_ENTRIES", "OBJECT_CACHE_BYTES", "TIMEOUT_GRACE"]

#: Objects (inline meshes and mesh files) kept, at most this many and this many bytes.
OBJECT_CACHE_ENTRIES = 32
OBJECT_CACHE_BYTES = 256 * 1024 * 1024
#: After plan_timeout in the planning stage, the swarm stops at its next iteration and
#: the best grasp so far is verified; a reply is sent at the latest this much later.
TIMEOUT_GRACE = 1.0


def _complete(future: Future, outcome: Outcome, executor: Executor) -> None:
    """Executor task: complete ``future``, then wake the executor once more (so that the
    awaiting coroutine is resumed now, not at the next unrelated event)."""
    if not future.done():
        future.set_result(outcome)
    try:
        executor.create_task(_nothing)
    except Exception:  # noqa: BLE001 -- executor shut down
        pass


def _nothing() -> None:
    """A task that does nothing (its creation wakes the executor)."""


class Worker:
    """Runs jobs on ``workers`` threads with ``queue_length`` waiting places; answers stored
    objects from ``database`` (a :class:`~grasp_apso.database.lookup.GraspDatabase`) when given."""

    def __init__(self, hooks: Hooks, workers: int = 1, queue_length: int = 4, database: Any = None,
                 hand: Any = None) -> None:
        self._hooks = hooks
        self._hand = hand  # the node's planning hand (None: the paper's), warmed up before "ready"
        self.database = database
        self.admission = Admission(workers, queue_length)
        self.objects: BoundedCache[GraspObject] = BoundedCache(OBJECT_CACHE_ENTRIES, OBJECT_CACHE_BYTES)
        self._pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="grasp_apso_planner")

    @property
    def workers(self) -> int:
        return self.admission.workers

    @property
    def queue_length(self) -> int:
        return self.admission.queue_length

    @property
    def pending(self) -> int:
        """Jobs running or waiting (reserved places)."""
        return self.admission.pending

    def reserve(self) -> str | None:
        """Reserve a place for one request; None when admitted, else the "busy" message."""
        return self.admission.reserve()

    def release(self) -> None:
        """Give a reserved place back (its job was never submitted)."""
        self.admission.release()

    def log(self, level: str, text: str) -> None:
        """Log through the node; never raises (a failing log must not lose a reply)."""
        try:
            self._hooks.log(level, text)
        except Exception:  # noqa: BLE001 -- last resort: stderr
            print(f"[grasp_apso] {level}: {text}\n(logging failed: {traceback.format_exc()})", file=sys.stderr)

    # ------------------------------------------------------------------ submitting
    def submit(self, job: Job, executor: Executor) -> Future:
        """Queue a job whose place was reserved; returns the Future of its :class:`Outcome`."""
        job.future, job.executor = Future(), executor
        self.admission.add(job)
        try:
            self._pool.submit(self._run, job)
        except RuntimeError:  # the pool is shut down
            self._answer(job, Outcome(False, "node shutting down"))
            self.admission.remove(job)
        return job.future

    # ------------------------------------------------------------------ cancellation
    def cancel(self, job: Job, reason: str = "cancelled") -> None:
        """Cancel a job: queued -> answered now and its place freed; reading or validating
        -> answered now (it finishes in the background); planning -> stops within one
        iteration and answers with the best grasp so far."""
        with job.lock:
            job.cancelled = True
            queued = not job.started and not job.answered
            loading = job.started and job.stage in LOADING_STAGES
        if queued:
            if self._answer(job, Outcome(False, f"{reason} while queued", cancelled=True)):
                self.admission.remove(job)
        elif loading:
            self._answer(job, Outcome(False, f"{reason} during {job.stage.value}", cancelled=True))

    def cancel_where(self, predicate: Callable[[Job], bool], reason: str) -> int:
        """Cancel every queued or running job for which ``predicate`` holds; how many."""
        jobs = self.admission.select(lambda j: predicate(j) and not j.cancelled)
        for job in jobs:
            self.cancel(job, reason)
        return len(jobs)

    def active_kinds(self) -> set:
        """The kinds of the jobs queued or running."""
        return self.admission.active_kinds()

    # ------------------------------------------------------------------ answering
    def _answer(self, job: Job, outcome: Outcome) -> bool:
        """Complete the job's Future once (the first answer wins); True when this did."""
        if not job.claim_answer():
            return False
        executor = job.executor
        if executor is not None:
            try:
                executor.create_task(_complete, job.future, outcome, executor)
                return True
            except Exception:  # noqa: BLE001 -- executor shut down: nobody awaits any more
                pass
        try:
            if job.future is not None and not job.future.done():
                job.future.set_result(outcome)
        except Exception:  # noqa: BLE001 -- a done callback failed: the result is set
            self.log("error", f"request {job.request_id}: completing the reply failed\n{traceback.format_exc()}")
        return True

    def _internal_error(self, job: Job, where: str) -> None:
        """Log the current exception and answer the job "internal error" (when unanswered)."""
        self.log("error", f"request {job.request_id}: internal error {where}\n{traceback.format_exc()}")
        self._answer(job, Outcome(False, internal_error_message(job.stage.value, job.request_id)))

    # ------------------------------------------------------------------ running
    def _run(self, job: Job) -> None:
        """A planning thread: run one job; always answers it and frees its place."""
        try:
            with job.lock:
                if job.answered or job.cancelled:
                    return  # cancelled while queued: already answered
                job.started = True
                job.stage = Stage.VALIDATION  # the object source is checked first
            self._run_started(job)
        except BaseException:  # noqa: BLE001 -- the last line of defence: a reply, always
            self._internal_error(job, "in the worker")
        finally:
            self.admission.remove(job)
            self.log("debug", f"request {job.request_id}: finished ({job.stage.value}), its place is free")

    def _run_started(self, job: Job) -> None:
        deadline = Deadline(job, job.request.timeout, self._guarded(self._on_deadline),
                            TIMEOUT_GRACE, self._guarded(self._on_grace))
        t0 = time.perf_counter()
        try:
            outcome = run_job(job, objects=self.objects, database=self.database, hooks=self._hooks,
                              should_stop=lambda: self._should_stop(job),
                              stopping=self.admission.stopping.is_set, t0=t0)
        except GraspApsoError as exc:
            detail = getattr(exc, "detail", "")
            self.log("info", f"request {job.request_id}: {exc}{f' ({detail})' if detail else ''}")
            note = job.database_note
            outcome = Outcome(False, f"{exc} ({note})" if note else str(exc))
            if job.cancel_requested():  # stopped before any grasp was found (GRG's start)
                outcome = Outcome(False, f"cancelled during {job.stage.value}", cancelled=True)
        except Exception:  # noqa: BLE001 -- request boundary: a worker thread never dies
            self.log("error", f"request {job.request_id}: internal error\n{traceback.format_exc()}")
            outcome = Outcome(False, internal_error_message(job.stage.value, job.request_id))
        finally:
            deadline.cancel()
        outcome.worker_time = time.perf_counter() - t0
        if job.timed_out and not outcome.success and outcome.result is None and not job.answered:
            outcome.message = timeout_message(job.request.timeout, job.stage.value)
        self._answer(job, outcome)

    def _guarded(self, callback: Callable[[Job], Any]) -> Callable[[Job], Any]:
        """A timer callback that answers "internal error" instead of dying silently."""
        def run(job: Job) -> Any:
            try:
                return callback(job)
            except BaseException:  # noqa: BLE001 -- a timer thread must not lose a reply
                self._internal_error(job, "in the time bound")
                return False
        return run

    def _on_deadline(self, job: Job) -> bool:
        """Timer thread: plan_timeout ran out. True when the job plans (it stops at its
        next poll; the grace timer follows)."""
        job.timed_out = True
        stage = job.stage
        if stage == Stage.PLANNING:
            return True
        if self._answer(job, Outcome(False, timeout_message(job.request.timeout, stage.value, LOADING_TIMEOUT_TAIL))):
            self.log("info", f"request {job.request_id}: timed out during {stage.value}")
        return False

    def _on_grace(self, job: Job) -> None:
        if self._answer(job, Outcome(False, timeout_message(job.request.timeout, Stage.PLANNING.value,
                                                            VERIFICATION_TIMEOUT_TAIL))):
            self.log("info", f"request {job.request_id}: timed out, answered without the verification")

    def _should_stop(self, job: Job) -> bool:
        """The planner's stop predicate (GRG's start, every iteration): the job is planning."""
        job.stage = Stage.PLANNING
        return bool(self.admission.stopping.is_set() or job.timed_out or job.answered or job.cancel_requested())

    # ------------------------------------------------------------------ life cycle
    def warm_up(self) -> float | None:
        """Load the planner's compiled kernels now (the node does it before it says
        "ready"); seconds, or None when it failed (logged; requests then report it)."""
        try:
            if is_general_hand(self._hand):
                return warm_up_any_hand(self._hand)
            return warm_up()
        except Exception:  # noqa: BLE001 -- the node still starts and answers
            self.log("error", f"warm-up failed\n{traceback.format_exc()}")
            return None

    def stop(self, wait: bool = True) -> None:
        """Stop the running plans (within one iteration), drop queued ones, join the threads."""
        self.admission.stopping.set()
        for job in self.admission.select(lambda j: not j.started):
            self.cancel(job, "node shutting down")
        self._pool.shutdown(wait=wait, cancel_futures=True)
        # Loaded only by a simulate request, maybe still being imported by another thread
        # at this moment: a module whose import has not reached cancel_background has not
        # started any decomposition either.
        convex = sys.modules.get("grasp_apso.simulation.convex")
        cancel = getattr(convex, "cancel_background", None)
        if cancel is not None:
            cancel()
