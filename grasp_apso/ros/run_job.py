"""Running one job on a planning thread: build the object, check its placement, ask the
grasp database, plan; the :class:`~.replies.Outcome` of a normal end.

Errors are raised to the caller (:class:`~.worker.Worker`), which turns every one of them
into a reply. The stages (:class:`~.job.Stage`) are set as the job moves on, so that a
timeout names where it was.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Protocol

import numpy as np

from ..cache import BoundedCache
from ..geometry.collision import object_bvh
from ..model.object_source import resolve_object
from ..model.objects import GraspObject
from ..search.planner import plan
from ..search.result import GraspResult
from . import database_answers
from .job import Job, Stage
from .replies import Outcome, plan_outcome

__all__ = ["Hooks", "run_job"]


class Hooks(Protocol):
    """What the worker tells the node (publishing is thread-safe in rclpy)."""

    def log(self, level: str, text: str) -> None: ...
    def on_progress(self, job: Job, stats: Any) -> None: ...
    def on_result(self, job: Job, result: GraspResult | database_answers.StoredGrasps) -> None: ...


def run_job(job: Job, *, objects: BoundedCache[GraspObject], database: Any, hooks: Hooks,
            should_stop: Callable[[], bool], stopping: Callable[[], bool], t0: float) -> Outcome:
    """Plan (or look up) the job's grasps; ``t0`` (``time.perf_counter``) is when it started.

    ``should_stop`` is polled by the planner (GRG's start and every iteration);
    ``stopping`` tells whether the node shuts down. Raises GraspApsoError for a bad
    object or an ungraspable one, anything else for a bug.
    """
    req = job.request
    opts = req.options
    hooks.log("info", f"request {req.request_id}: {req.describe}")
    obj = resolve_object(req.source, cache=objects, on_stage=job.set_stage)
    if job.answered:
        return Outcome(False, "already answered")
    if req.scene is not None:
        job.set_stage(Stage.VALIDATION)
        rot, trans = req.pose[:3, :3], req.pose[:3, 3]
        req.scene.check_object_placement(np.asarray(obj.mesh.vertices) @ rot.T + trans, "object_pose")
    note = ""
    if database is not None:
        job.set_stage(Stage.DATABASE_LOOKUP)
        stored, note = database_answers.lookup(
            database, obj, req.hand, req.pose, req.scene, opts, preparation_time=time.perf_counter() - t0,
            obj_bvh=object_bvh(obj) if req.scene is not None else None)
        job.database_note = note
        if stored is not None:
            hooks.on_result(job, stored)
            return Outcome(True, stored.message, stored, source="database")
    job.set_stage(Stage.PREPARATION)  # until the planner first polls should_stop (then PLANNING)
    result = plan(obj, pose=req.pose, options=opts, rng=np.random.default_rng(req.seed), hand=req.hand,
                  progress=lambda stats: hooks.on_progress(job, stats), should_stop=should_stop, scene=req.scene)
    job.set_stage(Stage.PLANNING)
    hooks.on_result(job, result)
    return plan_outcome(result, opts.iterations, time.perf_counter() - t0, stopping=stopping(),
                        cancelled=job.cancel_requested(), timed_out=job.timed_out, timeout=req.timeout,
                        max_grasps=opts.max_grasps, note=note)
