"""The node's worker: admission, a bounded queue, ``workers`` planning threads, the time
bound of a whole request, cancellation and the object cache. No ROS entities here; the
node hands jobs in and gets rclpy Futures back.

Admission: at most ``workers`` jobs run and ``queue_length`` wait; another request is
answered "busy" at once (:meth:`Worker.reserve`). A job goes through the stages
``queued`` -> ``reading`` (a mesh file) -> ``validation`` (mesh checks, placement in the
scene) -> ``preparation`` (the planner's signed-distance grid, shape class) ->
``planning`` (the swarm and the verification). With a grasp database (parameter
``grasp_database``), a stored object is answered after ``validation`` from the stored
grasps that survive the request's scene (stage ``database lookup``, milliseconds); it is
planned only when none does (:mod:`.database_answers`).

Time bound: ``plan_timeout`` counts from the moment a thread takes the job. When it runs
out the swarm stops at its next iteration and the reply carries the best grasp so far;
a stage that cannot be interrupted (reading, validating, preparing a large mesh) is
answered at once "timed out during <stage>" and finishes in the background, its object
kept in the cache so that a repeat is fast; its thread stays counted as busy until then.

Cancel: a queued job is answered at once and leaves the queue; a running one stops
within one iteration (or is answered at once when it is not planning yet).

Completion: the job's rclpy Future is completed through ``executor.create_task`` (a
Future completed from another thread does not wake the awaiting coroutine).
"""

from __future__ import annotations

import hashlib
import os
import threading
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np
from rclpy.task import Future

from ..cache import BoundedCache
from ..errors import GraspApsoError, ObjectError
from ..model import builtin as builtin_objects
from ..model import mesh_files, objects
from ..search.planner import GraspResult, plan, warm_up
from . import database_answers
from ..tools.summary import grasp_summary, grasp_verdict
from .requests import PACKED, Job, packed_message

__all__ = ["Outcome", "Worker", "OBJECT_CACHE_ENTRIES", "OBJECT_CACHE_BYTES", "TIMEOUT_GRACE"]

#: Objects (inline meshes and mesh files) kept, at most this many and this many bytes.
OBJECT_CACHE_ENTRIES = 32
OBJECT_CACHE_BYTES = 256 * 1024 * 1024
#: After plan_timeout in the planning stage, the swarm stops at its next iteration and
#: the best grasp so far is verified; a reply is sent at the latest this much later.
TIMEOUT_GRACE = 1.0


@dataclass
class Outcome:
    """What the worker answers for one request (``source``: the reply's ``grasp_source``,
    "planned" or "database"; a database answer's ``result`` is a
    :class:`~.database_answers.StoredGrasps`)."""

    success: bool
    message: str
    result: GraspResult | database_answers.StoredGrasps | None = None
    cancelled: bool = False
    worker_time: float = 0.0
    source: str = "planned"


class Hooks(Protocol):
    """What the worker tells the node (publishing is thread-safe in rclpy)."""

    def log(self, level: str, text: str) -> None: ...
    def on_progress(self, job: Job, stats: Any) -> None: ...
    def on_result(self, job: Job, result: GraspResult) -> None: ...


def _complete(future: Future, outcome: Outcome, executor: Any) -> None:
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

    def __init__(self, hooks: Hooks, workers: int = 1, queue_length: int = 4, database: Any = None) -> None:
        self._hooks = hooks
        self.database = database
        self.workers = int(workers)
        self.queue_length = int(queue_length)
        self._lock = threading.Lock()
        self._pending = 0  # running + waiting (reserved places)
        self._jobs: dict[str, Job] = {}
        self._stopping = threading.Event()
        self.objects: BoundedCache[objects.GraspObject] = BoundedCache(OBJECT_CACHE_ENTRIES, OBJECT_CACHE_BYTES)
        self._pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="grasp_apso_planner")
        # The first job: load the compiled kernels, so that the first request does not pay.
        self._pool.submit(self._warm_up)

    # ------------------------------------------------------------------ admission
    def reserve(self) -> str | None:
        """Reserve a place for one request; None when admitted, else the "busy" message."""
        with self._lock:
            if self._stopping.is_set():
                return "node shutting down"
            if self._pending >= self.workers + self.queue_length:
                waiting = max(0, self._pending - self.workers)
                return (f"busy: {waiting} requests queued behind the {self.workers} running plan(s) "
                        f"(queue_length {self.queue_length}, workers {self.workers}); try again later")
            self._pending += 1
            return None

    def release(self) -> None:
        """Give a reserved place back."""
        with self._lock:
            self._pending = max(0, self._pending - 1)

    @property
    def pending(self) -> int:
        """Jobs running or waiting (reserved places)."""
        with self._lock:
            return self._pending

    def submit(self, job: Job, executor: Any) -> Future:
        """Queue a job whose place was reserved; returns the Future of its :class:`Outcome`."""
        job.future, job.executor = Future(), executor
        with self._lock:
            self._jobs[job.request_id] = job
        try:
            self._pool.submit(self._run, job)
        except RuntimeError:  # the pool is shut down
            self._answer(job, Outcome(False, "node shutting down"))
            self._finish(job)
        return job.future

    # ------------------------------------------------------------------ cancellation
    def cancel(self, job: Job, reason: str = "cancelled") -> None:
        """Cancel a job: queued -> answered now and its place freed; reading or validating
        -> answered now (it finishes in the background); planning -> stops within one
        iteration and answers with the best grasp so far."""
        with job.lock:
            job.cancelled = True
            queued = not job.started and not job.answered
            loading = job.started and job.stage in ("reading", "validation", "preparation")
        if queued:
            if self._answer(job, Outcome(False, f"{reason} while queued", cancelled=True)):
                self._finish(job)
        elif loading:
            self._answer(job, Outcome(False, f"{reason} during {job.stage}", cancelled=True))

    def cancel_where(self, predicate: Callable[[Job], bool], reason: str) -> int:
        """Cancel every queued or running job for which ``predicate`` holds; how many."""
        with self._lock:
            jobs = [j for j in self._jobs.values() if predicate(j) and not j.cancelled]
        for job in jobs:
            self.cancel(job, reason)
        return len(jobs)

    def active_kinds(self) -> set[str]:
        """The kinds ("service", "action") of the jobs queued or running."""
        with self._lock:
            return {j.kind for j in self._jobs.values()}

    # ------------------------------------------------------------------ running
    def _answer(self, job: Job, outcome: Outcome) -> bool:
        """Complete the job's Future once (the first answer wins); True when this did."""
        with job.lock:
            if job.answered:
                return False
            job.answered = True
        executor = job.executor
        if executor is not None:
            try:
                executor.create_task(_complete, job.future, outcome, executor)
                return True
            except Exception:  # noqa: BLE001 -- executor shut down: nobody awaits any more
                pass
        if not job.future.done():
            job.future.set_result(outcome)
        return True

    def _finish(self, job: Job) -> None:
        with self._lock:
            if self._jobs.pop(job.request_id, None) is not None:
                self._pending = max(0, self._pending - 1)

    def _run(self, job: Job) -> None:
        """A planning thread: run one job (never raises)."""
        with job.lock:
            if job.answered or job.cancelled:
                return  # cancelled while queued: already answered, its place freed
            job.started = True
        timer = None
        if job.timeout > 0:
            timer = threading.Timer(job.timeout, self._on_deadline, (job,))
            timer.daemon = True
            timer.start()
        t0 = time.perf_counter()
        try:
            outcome = self._plan(job, t0)
        except GraspApsoError as exc:
            detail = getattr(exc, "detail", "")
            self._hooks.log("info", f"request {job.request_id}: {exc}{f' ({detail})' if detail else ''}")
            outcome = Outcome(False, f"{exc} ({job.database_note})" if job.database_note else str(exc))
        except Exception:  # noqa: BLE001 -- request boundary: a worker thread never dies
            self._hooks.log("error", f"request {job.request_id}: internal error\n{traceback.format_exc()}")
            outcome = Outcome(False, f"internal error while {job.stage} (request {job.request_id}; "
                                     "the details are in the node's log)")
        finally:
            if timer is not None:
                timer.cancel()
        outcome.worker_time = time.perf_counter() - t0
        if job.timed_out and not outcome.success and outcome.result is None and not job.answered:
            outcome.message = self._timeout_message(job)
        self._answer(job, outcome)
        self._finish(job)

    def _timeout_message(self, job: Job, tail: str = "") -> str:
        return (f"timed out after {job.timeout:g} s (parameter plan_timeout) during {job.stage}"
                f"{tail}")

    def _on_deadline(self, job: Job) -> None:
        """Timer thread: plan_timeout ran out."""
        job.timed_out = True
        if job.stage != "planning":
            if self._answer(job, Outcome(False, self._timeout_message(
                    job, "; the node finishes loading this object in the background and keeps it, "
                         "so a repeat of the request is faster"))):
                self._hooks.log("info", f"request {job.request_id}: timed out during {job.stage}")
            return
        grace = threading.Timer(TIMEOUT_GRACE, self._on_grace, (job,))
        grace.daemon = True
        grace.start()

    def _on_grace(self, job: Job) -> None:
        if self._answer(job, Outcome(False, self._timeout_message(job, " (the final verification did not end)"))):
            self._hooks.log("info", f"request {job.request_id}: timed out, answered without the verification")

    def _object(self, job: Job) -> objects.GraspObject:
        """Build (or fetch from the cache) the job's object."""
        if job.source == "object_name":
            job.stage = "preparation"
            return builtin_objects.builtin(job.object_name)
        if job.source == "mesh_uri":
            try:
                real = mesh_files.resolve(job.mesh_uri, job.allowed_dir)
                stat = os.stat(real)
                key: tuple = ("file", real, stat.st_mtime_ns, stat.st_size, job.max_triangles, job.max_bytes)
            except (OSError, ObjectError):
                key = ()  # from_file reports the problem in the caller's terms
            cached = self.objects.get(key) if key else None
            if cached is not None:
                return cached

            def stage(name: str) -> None:
                job.stage = name

            obj = mesh_files.from_file(job.mesh_uri, allowed_dir=job.allowed_dir, max_triangles=job.max_triangles,
                                       max_bytes=job.max_bytes, shown=job.shown_uri, on_stage=stage)
            return self.objects.put(key, obj) if key else obj
        job.stage = "validation"
        digest = hashlib.sha1()
        for array in (job.vertices, job.triangles):
            digest.update(str(array.shape).encode())
            digest.update(np.ascontiguousarray(array).tobytes())
        key = ("mesh", digest.hexdigest(), job.max_triangles)
        cached = self.objects.get(key)
        if cached is not None:
            return cached
        try:
            obj = objects.from_arrays(job.vertices, job.triangles, name="mesh", max_triangles=job.max_triangles)
        except ObjectError as exc:
            if job.source != PACKED:
                raise
            raise ObjectError(packed_message(str(exc))) from None
        return self.objects.put(key, obj)

    def _should_stop(self, job: Job) -> bool:
        job.stage = "planning"
        goal = job.goal_handle
        return bool(self._stopping.is_set() or job.cancelled or job.timed_out or job.answered
                    or (goal is not None and goal.is_cancel_requested))

    def _plan(self, job: Job, t0: float) -> Outcome:
        opts = job.options
        self._hooks.log("info", f"request {job.request_id}: {job.describe}, {opts.algorithm} {opts.particles} "
                                f"particles x {opts.iterations} iterations, frame '{job.header.frame_id}'"
                                f"{', with a scene' if job.scene is not None else ''}")
        obj = self._object(job)
        if job.answered:
            return Outcome(False, "already answered")
        if job.scene is not None:
            job.stage = "validation"
            rot, trans = job.pose[:3, :3], job.pose[:3, 3]
            job.scene.check_object_placement(np.asarray(obj.mesh.vertices) @ rot.T + trans, "object_pose")
        note = ""
        if self.database is not None:
            job.stage = "database lookup"
            stored, note = database_answers.lookup(
                self.database, obj, job.hand, job.pose, job.scene, opts, preparation_time=time.perf_counter() - t0,
                obj_bvh=database_answers.object_bvh(obj) if job.scene is not None else None)
            job.database_note = note
            if stored is not None:
                self._hooks.on_result(job, stored)
                return Outcome(True, stored.message, stored, source="database")
        job.stage = "preparation"
        result = plan(obj, pose=job.pose, options=opts, rng=np.random.default_rng(job.seed), hand=job.hand,
                      progress=lambda stats: self._hooks.on_progress(job, stats),
                      should_stop=lambda: self._should_stop(job), scene=job.scene)
        self._hooks.on_result(job, result)
        elapsed = time.perf_counter() - t0
        summary = grasp_summary(result, opts.iterations, elapsed)
        goal = job.goal_handle
        if self._stopping.is_set() and result.cancelled:
            return Outcome(False, f"node shutting down: stopped after {summary}", result, True)
        if result.cancelled and (job.cancelled or (goal is not None and goal.is_cancel_requested)):
            return Outcome(False, f"cancelled: {summary}", result, cancelled=True)
        if job.timed_out and result.cancelled:
            return Outcome(False, f"{self._timeout_message(job)}: best so far {summary}", result)
        verdict = grasp_verdict(result, opts.iterations, elapsed)  # the CLI's wording too
        if not result.valid:
            return Outcome(False, verdict, result)
        n = len(result.candidates)
        if n < opts.max_grasps and not result.candidates_message:
            verdict += f"; {n} of the {opts.max_grasps} requested distinct candidates found"
        return Outcome(True, f"{verdict}{'; ' + note if note else ''}", result)

    def _warm_up(self) -> None:
        """Load the compiled kernels (never raises: a request would then report it)."""
        if self._stopping.is_set():
            return
        try:
            seconds = warm_up()
        except Exception:  # noqa: BLE001 -- a worker thread never dies
            self._hooks.log("error", f"warm-up failed\n{traceback.format_exc()}")
            return
        self._hooks.log("debug", f"planner kernels loaded in {seconds:.2f} s")

    def stop(self, wait: bool = True) -> None:
        """Stop the running plans (within one iteration), drop queued ones, join the threads."""
        self._stopping.set()
        with self._lock:
            queued = [j for j in self._jobs.values() if not j.started]
        for job in queued:
            self.cancel(job, "node shutting down")
        self._pool.shutdown(wait=wait, cancel_futures=True)
