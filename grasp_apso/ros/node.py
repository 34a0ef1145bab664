"""The ROS 2 node ``grasp_apso``: a thin adapter over :func:`grasp_apso.search.planner.plan`.

Interface (names relative to the node, so ``/grasp_apso/...`` by default)
-------------------------------------------------------------------------
- service ``~/plan_grasp`` (``grasp_apso_interfaces/srv/PlanGrasp``)
- action ``~/plan_grasp`` (``grasp_apso_interfaces/action/PlanGrasp``): the same goal and
  result, the progress as feedback, cancellable (the plan stops within one iteration)
- topic ``~/progress`` (``grasp_apso_interfaces/msg/GraspProgress``): one message per
  iteration of every plan (service or action), tagged with the request id
- topic ``~/grasp_markers`` (``visualization_msgs/MarkerArray``, transient local): the
  last planned grasp for RViz (palm, finger links, fingertips, contacts and normals)
- parameters: every tunable, see :data:`PARAMETERS` and ``config/grasp_apso.yaml``

Concurrency
-----------
Plans run one at a time in ONE worker thread (``ThreadPoolExecutor(max_workers=1)``)
with at most ``queue_length`` requests waiting behind the running one; a request that
finds the queue full is answered at once with ``success = false``, ``"busy: ..."``.
The service and action callbacks are coroutines in a ``ReentrantCallbackGroup``: they
check the request, hand it to the worker and ``await`` an rclpy Future, so the
executor keeps serving (progress, parameters, other callers) while a plan runs. The
worker completes that Future through ``executor.create_task`` (a Future completed
directly from another thread does not wake the executor). The worker publishes progress,
action feedback and markers itself (publishing is thread-safe in rclpy). The worker's
first job loads the planner's compiled kernels (:func:`grasp_apso.search.planner.warm_up`, about
0.3 s; once after an install about 5 s while they compile); requests that arrive
meanwhile wait behind it. The kernels release the GIL, so the executor's threads keep
running while a plan computes.

Requests
--------
Exactly one object source: a non-empty ``mesh``, the same mesh packed in
``mesh_vertices`` / ``mesh_triangles`` (flat arrays that rclpy converts without a Python
object per vertex: for large meshes), a ``mesh_uri`` (a path or ``file://``
URI inside the directory of the ``allowed_mesh_dir`` parameter; relative paths are taken
from that directory; mesh files are refused while it is empty) or an ``object_name``
(sphere, cube, barrel, fish). The planning frame is ``object_pose.header.frame_id``;
``wrist_position`` (when ``fix_wrist_position``) is given in that frame too.
``particles`` / ``iterations`` 0, ``algorithm`` "" and ``seed`` -1 mean "use the node
parameter". Every bad input is answered with ``success = false`` and a message that names
the field at fault; unexpected errors become ``"internal error: ..."`` (logged with the
traceback) and the node keeps serving.

Reply
-----
``success`` is true when the planner found a valid grasp (>= 2 fingertip contacts, no
illegal collision) within ``plan_timeout``; the configuration, wrist pose, contacts and
qualities are filled whenever the planner returned a grasp (also when it is not valid,
timed out or was cancelled). ``planning_time`` is the time the worker spent on the
request (loading and validating the object, the planner's preparation, the swarm and the
verification), so ``round trip - planning_time`` is the ROS overhead (transport,
(de)serialisation, queueing).
"""

from __future__ import annotations

import gc
import hashlib
import math
import os
import re
import signal
import sys
import threading
import time
import traceback
import uuid
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
import rclpy
import rclpy.parameter
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from grasp_apso_interfaces.action import PlanGrasp as PlanGraspAction
from grasp_apso_interfaces.msg import GraspProgress
from grasp_apso_interfaces.srv import PlanGrasp

from ..model import objects
from ..model import mesh_files
from ..model import builtin as builtin_objects
from .. import errors
from ..model import mesh_checks
from .conversions import (
    fill_result, grasp_markers, mesh_to_arrays, packed_mesh_to_arrays, pose_stamped_to_matrix, progress_msg,
)
from ..model.hand import HandModel, load_hand
from ..model.builtin import BUILTIN_OBJECTS
from ..errors import ObjectError
from ..search.planner import ALGORITHMS, GraspResult, PlanningError, PlanOptions, plan, warm_up

__all__ = ["GraspPlannerNode", "PARAMETERS", "main"]

NODE_NAME = "grasp_apso"
_DEFAULTS = PlanOptions()
_INT64_MAX = 2**63 - 1


@dataclass(frozen=True)
class ParameterSpec:
    """One declared parameter: default, description and accepted range.

    ``lo``/``hi`` are inclusive bounds (the descriptor's range); ``lo_open`` makes the
    lower bound exclusive (checked by the node, descriptors cannot say so);
    ``choices`` restricts a string.
    """

    name: str
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple[str, ...] | None = None


#: Every parameter of the node. Planner defaults come from :class:`PlanOptions`.
PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec("particles", _DEFAULTS.particles,
                  "Swarm size np used when a request leaves particles at 0.", 2, 1000),
    ParameterSpec("iterations", _DEFAULTS.iterations,
                  "Iterations nit used when a request leaves iterations at 0.", 1, 10000),
    ParameterSpec("neighborhood_size", _DEFAULTS.neighborhood_size,
                  "Particles per APSO neighbourhood (clamped to the swarm size).", 1, 1000),
    ParameterSpec("c1", float(_DEFAULTS.c1),
                  "Acceleration constant toward each particle's personal best.", 0.0, 4.0),
    ParameterSpec("c2", float(_DEFAULTS.c2),
                  "Acceleration constant toward the global best.", 0.0, 4.0),
    ParameterSpec("inertia", float(_DEFAULTS.inertia),
                  "Inertia weight w applied to the velocity after each step.", 0.0, 1.0),
    ParameterSpec("stall_iterations", _DEFAULTS.stall_iterations,
                  "APSO: iterations without improvement before a neighbourhood's worst "
                  "particle is replaced by a new GRG particle.", 1, 1000),
    ParameterSpec("contact_tolerance", float(_DEFAULTS.contact_tolerance),
                  "Fingertip contact tolerance and accepted penetration, metres (> 0).",
                  0.0, 0.02, lo_open=True),
    ParameterSpec("friction", float(_DEFAULTS.friction),
                  "Coulomb friction coefficient mu for the friction cones (> 0).",
                  0.0, 5.0, lo_open=True),
    ParameterSpec("friction_edges", _DEFAULTS.friction_edges,
                  "Edges of the linearised friction cones (epsilon quality).", 3, 64),
    ParameterSpec("closure_candidates", _DEFAULTS.closure_candidates,
                  "When the global best is not force closure, how many of the best distinct "
                  "personal bests are checked for a force-closure grasp (1 = the global best only).",
                  1, 100),
    ParameterSpec("seed", -1,
                  "Random seed used when a request's seed is -1; -1 = a fresh random seed "
                  "per request.", -1, _INT64_MAX),
    ParameterSpec("algorithm", _DEFAULTS.algorithm,
                  "Algorithm used when a request's algorithm is empty: apso or pso.",
                  choices=ALGORITHMS),
    ParameterSpec("hand_description", "",
                  "Path of the hand description YAML; empty = the hand shipped in the package."),
    ParameterSpec("allowed_mesh_dir", "",
                  "Directory mesh_uri files must lie in (symlinks and '..' resolved); "
                  "empty = mesh files are refused."),
    ParameterSpec("max_mesh_triangles", mesh_checks.DEFAULT_MAX_TRIANGLES,
                  "Largest accepted mesh (inline or file), triangles.", 4, 10_000_000),
    ParameterSpec("max_mesh_bytes", mesh_files.DEFAULT_MAX_BYTES,
                  "Largest accepted mesh file, bytes.", 1, 2_000_000_000),
    ParameterSpec("queue_length", 4,
                  "Requests that may wait behind the running plan; more are answered "
                  "'busy' at once.", 0, 1000),
    ParameterSpec("plan_timeout", 60.0,
                  "Seconds a request may spend in the worker (object loading and planning); "
                  "the plan is stopped and answered 'timed out' after it. 0 = no limit.",
                  0.0, 86400.0),
)
PARAMETER_NAMES: tuple[str, ...] = tuple(spec.name for spec in PARAMETERS)
_SPECS = {spec.name: spec for spec in PARAMETERS}

#: Inline meshes whose GraspObject is kept (keyed by a hash of the raw arrays).
_OBJECT_CACHE_SIZE = 8
# The packed mesh source, as it is named in messages.
_PACKED = "mesh_vertices/mesh_triangles"
_SOURCES = f"mesh, {_PACKED}, mesh_uri, object_name"


def _complete(future: Future, outcome: Any, executor: Any) -> None:
    """Executor task: complete ``future``, then wake the executor once more.

    An awaiting coroutine is only re-polled when the executor wakes up; the second task
    (whose creation triggers the executor's guard condition) makes that happen right after
    the result is set, not at the next unrelated event. During shutdown the executor may
    be gone; then nobody awaits any more.
    """
    future.set_result(outcome)
    try:
        executor.create_task(_nothing)
    except Exception:  # noqa: BLE001 -- executor shut down
        pass


def _nothing() -> None:
    """A task that does nothing (its creation wakes the executor)."""


def _packed_message(text: str) -> str:
    """A validation message of :func:`objects.from_arrays` (which says ``mesh: ...``)
    re-addressed to the packed fields the client filled.

    Vertex problems name ``mesh_vertices``, index problems ``mesh_triangles``, problems of
    the whole mesh (degenerate, flat) both; ``(packed mesh)`` tells the client which
    representation was checked.
    """
    if not text.startswith("mesh: "):
        return text
    rest = text[len("mesh: "):]
    if re.match(r"(vertex \d|vertices |\d+ vertices )", rest):
        field = "mesh_vertices"
    elif re.match(r"(triangle \d|triangles |\d+ triangles )", rest):
        field = "mesh_triangles"
    else:
        field = _PACKED
    return f"{field} (packed mesh): {rest}"


class RequestError(ValueError):
    """A malformed request; the message names the field."""


@dataclass
class _Job:
    """A checked request, ready for the worker."""

    request_id: str
    header: Header
    pose: np.ndarray
    source: str                      # "mesh" | _PACKED | "mesh_uri" | "object_name"
    describe: str                    # for log lines
    options: PlanOptions
    seed: int | None
    hand: HandModel
    timeout: float
    vertices: np.ndarray | None = None
    triangles: np.ndarray | None = None
    mesh_uri: str = ""
    allowed_dir: str = ""
    object_name: str = ""
    max_triangles: int = mesh_checks.DEFAULT_MAX_TRIANGLES
    max_bytes: int = mesh_files.DEFAULT_MAX_BYTES
    goal_handle: Any = None


@dataclass
class _Outcome:
    """What the worker returns for one request."""

    success: bool
    message: str
    result: GraspResult | None = None
    cancelled: bool = False
    worker_time: float = 0.0


def _descriptor(spec: ParameterSpec) -> ParameterDescriptor:
    desc = ParameterDescriptor(name=spec.name, description=spec.description)
    value = spec.default
    if isinstance(value, bool):
        desc.type = ParameterType.PARAMETER_BOOL
    elif isinstance(value, int):
        desc.type = ParameterType.PARAMETER_INTEGER
        desc.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi), step=1)]
    elif isinstance(value, float):
        desc.type = ParameterType.PARAMETER_DOUBLE
        desc.floating_point_range = [
            FloatingPointRange(from_value=float(spec.lo), to_value=float(spec.hi), step=0.0)
        ]
        if spec.lo_open:
            desc.additional_constraints = f"{spec.lo} < value <= {spec.hi}"
    else:
        desc.type = ParameterType.PARAMETER_STRING
        if spec.choices:
            desc.additional_constraints = "one of: " + ", ".join(spec.choices)
    return desc


class GraspPlannerNode(Node):
    """The ``grasp_apso`` node; see the module docstring for the interface."""

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._hands: dict[str, HandModel] = {}
        self._hands_lock = threading.Lock()
        self._objects: OrderedDict[str, objects.GraspObject] = OrderedDict()
        self._objects_lock = threading.Lock()
        self._stopping = threading.Event()
        self._queue_lock = threading.Lock()
        self._pending = 0  # running + waiting
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="grasp_apso_planner")

        for spec in PARAMETERS:
            self.declare_parameter(spec.name, spec.default, _descriptor(spec))
        # Values from parameter files / the command line: the same checks as on set.
        values = self._parameter_values()
        for name in PARAMETER_NAMES:
            reason = self._check_parameter(name, values[name], values)
            if reason:
                raise ValueError(f"invalid parameter {reason}")
        self.add_pre_set_parameters_callback(self._coerce_parameters)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        group = ReentrantCallbackGroup()
        self._progress_pub = self.create_publisher(
            GraspProgress, "~/progress",
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE))
        self._marker_pub = self.create_publisher(
            MarkerArray, "~/grasp_markers",
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._service = self.create_service(
            PlanGrasp, "~/plan_grasp", self._on_plan_service, callback_group=group)
        self._action_server = ActionServer(
            self, PlanGraspAction, "~/plan_grasp",
            execute_callback=self._on_plan_goal,
            goal_callback=lambda _goal: GoalResponse.ACCEPT,
            cancel_callback=lambda _handle: CancelResponse.ACCEPT,
            callback_group=group,
        )
        # The worker's first job: load the compiled kernels, so that the first request
        # does not pay for it (requests submitted meanwhile wait behind it).
        self._worker.submit(self._warm_up)
        self.get_logger().info(
            f"ready: service and action {self.resolve_service_name('~/plan_grasp')}, progress on "
            f"{self._progress_pub.topic_name}, markers on {self._marker_pub.topic_name}")

    # ------------------------------------------------------------------ parameters
    def _parameter_values(self) -> dict[str, Any]:
        return {name: self.get_parameter(name).value for name in PARAMETER_NAMES}

    def _check_parameter(self, name: str, value: Any, values: dict[str, Any]) -> str | None:
        """None when ``value`` is acceptable for parameter ``name``, else the reason."""
        spec = _SPECS.get(name)
        if spec is None:
            return None
        if spec.lo is not None:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                return f"{name}: expected a finite number, got {value!r}"
            if value > spec.hi or value < spec.lo or (spec.lo_open and value <= spec.lo):
                low = "(" if spec.lo_open else "["
                return f"{name}: {value!r} out of range {low}{spec.lo}, {spec.hi}]"
        if spec.choices is not None and value not in spec.choices:
            return f"{name}: unknown {value!r} (expected one of: {', '.join(spec.choices)})"
        if name == "hand_description":
            try:
                self._hand(str(value))
            except Exception as exc:  # noqa: BLE001 -- any failure to load is the reason
                return f"hand_description: {exc}"
        if name == "allowed_mesh_dir" and value:
            if not os.path.isdir(str(value)):
                return f"allowed_mesh_dir: not a directory: {value}"
        if name in ("particles", "c1", "c2", "inertia", "stall_iterations", "contact_tolerance",
                    "friction", "friction_edges", "algorithm", "neighborhood_size", "iterations"):
            try:
                self._options(values)
            except ValueError as exc:
                return str(exc)
        return None

    @staticmethod
    def _coerce_parameters(parameters: list[Any]) -> list[Any]:
        """Accept an integer for a floating-point parameter (``ros2 param set ... c1 1``)."""
        out = []
        for param in parameters:
            spec = _SPECS.get(param.name)
            if (spec is not None and isinstance(spec.default, float)
                    and param.type_ == rclpy.parameter.Parameter.Type.INTEGER):
                param = rclpy.parameter.Parameter(param.name, value=float(param.value))
            out.append(param)
        return out

    def _on_set_parameters(self, parameters: list[rclpy.parameter.Parameter]) -> SetParametersResult:
        values = self._parameter_values()
        for param in parameters:
            values[param.name] = param.value
        for param in parameters:
            reason = self._check_parameter(param.name, param.value, values)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    @staticmethod
    def _options(values: dict[str, Any], **override: Any) -> PlanOptions:
        """PlanOptions from parameter values (ValueError naming the field when invalid)."""
        settings = dict(
            algorithm=values["algorithm"], particles=int(values["particles"]),
            iterations=int(values["iterations"]),
            neighborhood_size=int(values["neighborhood_size"]),
            c1=float(values["c1"]), c2=float(values["c2"]), inertia=float(values["inertia"]),
            stall_iterations=int(values["stall_iterations"]),
            contact_tolerance=float(values["contact_tolerance"]),
            friction=float(values["friction"]), friction_edges=int(values["friction_edges"]),
            closure_candidates=int(values["closure_candidates"]),
        )
        settings.update(override)
        settings["neighborhood_size"] = max(1, min(settings["neighborhood_size"], settings["particles"]))
        return PlanOptions(**settings)

    def _hand(self, path: str) -> HandModel:
        """The hand model of a description file ('' = shipped), loaded once."""
        with self._hands_lock:
            hand = self._hands.get(path)
            if hand is None:
                hand = load_hand(path or None)
                self._hands[path] = hand
            return hand

    # ------------------------------------------------------------------ requests
    def _parse_request(self, req: Any, request_id: str, goal_handle: Any = None) -> _Job:
        """Check a request (cheap checks only) and build the worker's job.

        Raises RequestError / ObjectError (ValueError) naming the field at fault. The
        object itself (mesh validation, file loading) is built by the worker.
        """
        values = self._parameter_values()
        has_mesh = len(req.mesh.vertices) > 0 or len(req.mesh.triangles) > 0
        has_packed = len(req.mesh_vertices) > 0 or len(req.mesh_triangles) > 0
        uri = req.mesh_uri.strip()
        name = req.object_name.strip()
        given = [field for field, present in
                 (("mesh", has_mesh), (_PACKED, has_packed), ("mesh_uri", bool(uri)),
                  ("object_name", bool(name)))
                 if present]
        if not given:
            raise RequestError(
                "no object: mesh is empty and mesh_vertices/mesh_triangles, mesh_uri and object_name "
                f"are not set (give exactly one of {_SOURCES})")
        if len(given) > 1:
            raise RequestError(f"give exactly one of {_SOURCES} (got {' and '.join(given)})")

        frame, pose = pose_stamped_to_matrix(req.object_pose, "object_pose")
        header = Header(stamp=req.object_pose.header.stamp, frame_id=frame)

        algorithm = req.algorithm.strip().lower() or values["algorithm"]
        if algorithm not in ALGORITHMS:
            raise RequestError(
                f"algorithm: unknown {req.algorithm!r} (expected one of: {', '.join(ALGORITHMS)}, "
                f"or empty for the node parameter)")
        particles = int(req.particles) or int(values["particles"])
        if not 2 <= particles <= 1000:
            raise RequestError(f"particles: {particles} out of range [2, 1000] (0 = node parameter)")
        iterations = int(req.iterations) or int(values["iterations"])
        if not 1 <= iterations <= 10000:
            raise RequestError(f"iterations: {iterations} out of range [1, 10000] (0 = node parameter)")
        seed = int(req.seed)
        if seed < -1:
            raise RequestError(f"seed: {seed} is negative (use a seed >= 0, or -1 for the node parameter)")
        if seed == -1:
            seed = int(values["seed"])
        wrist = None
        if req.fix_wrist_position:
            p = req.wrist_position
            point = np.array([p.x, p.y, p.z], dtype=float)
            if not np.all(np.isfinite(point)):
                raise RequestError(f"wrist_position: not finite: {point.tolist()}")
            inverse = np.linalg.inv(pose)
            wrist = tuple(float(v) for v in inverse[:3, :3] @ point + inverse[:3, 3])
        try:
            options = self._options(values, algorithm=algorithm, particles=particles,
                                    iterations=iterations, wrist_position=wrist)
        except ValueError as exc:
            raise RequestError(str(exc)) from None

        job = _Job(
            request_id=request_id, header=header, pose=pose, source=given[0], describe="",
            options=options, seed=None if seed < 0 else seed,
            hand=self._hand(str(values["hand_description"])),
            timeout=float(values["plan_timeout"]),
            max_triangles=int(values["max_mesh_triangles"]),
            max_bytes=int(values["max_mesh_bytes"]),
            goal_handle=goal_handle,
        )
        if has_packed:
            if not len(req.mesh_vertices) or not len(req.mesh_triangles):
                missing = "mesh_triangles" if len(req.mesh_vertices) else "mesh_vertices"
                raise ObjectError(f"{missing}: empty, but the packed mesh has "
                                  f"{'vertices' if missing == 'mesh_triangles' else 'triangles'} "
                                  "(give both mesh_vertices and mesh_triangles)")
            try:
                job.vertices, job.triangles = packed_mesh_to_arrays(req.mesh_vertices, req.mesh_triangles)
            except ValueError as exc:
                raise ObjectError(str(exc)) from None
            n_tri = len(job.triangles)
            if n_tri > job.max_triangles:
                raise ObjectError(
                    f"mesh_triangles: {n_tri} triangles exceeds the limit of {job.max_triangles} "
                    f"(parameter max_mesh_triangles)")
            job.describe = f"packed mesh ({len(job.vertices)} vertices, {n_tri} triangles)"
        elif has_mesh:
            n_tri = len(req.mesh.triangles)
            if n_tri > job.max_triangles:
                raise ObjectError(
                    f"mesh: {n_tri} triangles exceeds the limit of {job.max_triangles} "
                    f"(parameter max_mesh_triangles)")
            job.vertices, job.triangles = mesh_to_arrays(req.mesh)
            job.describe = f"mesh ({len(req.mesh.vertices)} vertices, {n_tri} triangles)"
        elif uri:
            allowed = str(values["allowed_mesh_dir"])
            if not allowed:
                raise ObjectError(
                    "mesh_uri: mesh files are disabled on this node (parameter "
                    "allowed_mesh_dir is empty); send the mesh inline or set allowed_mesh_dir")
            if "://" not in uri and not os.path.isabs(uri):
                uri = os.path.join(allowed, uri)
            job.mesh_uri, job.allowed_dir = uri, allowed
            job.describe = f"mesh_uri {req.mesh_uri}"
        else:
            if name not in BUILTIN_OBJECTS:
                builtin_objects.builtin(name)  # raises ObjectError "object_name: unknown ..."
            job.object_name = name
            job.describe = f"object {name}"
        return job

    def _admit(self) -> str | None:
        """Reserve a place for one request; None when admitted, else the busy message."""
        queue_length = int(self.get_parameter("queue_length").value)
        with self._queue_lock:
            if self._stopping.is_set():
                return "node shutting down"
            if self._pending >= 1 + queue_length:
                waiting = max(0, self._pending - 1)
                return (f"busy: {waiting} requests queued behind the running plan "
                        f"(queue_length {queue_length}); try again later")
            self._pending += 1
            return None

    def _release(self) -> None:
        with self._queue_lock:
            self._pending -= 1

    async def _run(self, req: Any, goal_handle: Any = None) -> tuple[str, _Outcome, Header]:
        """Check ``req``, queue it and await the worker's outcome (never raises)."""
        request_id = str(uuid.uuid4())
        t_enter = time.perf_counter()
        header = Header(stamp=req.object_pose.header.stamp, frame_id=req.object_pose.header.frame_id)
        try:
            job = self._parse_request(req, request_id, goal_handle)
        except (ValueError, ObjectError) as exc:
            self.get_logger().info(f"request {request_id}: rejected: {exc}")
            return request_id, _Outcome(False, str(exc)), header
        except Exception as exc:  # noqa: BLE001 -- request boundary
            self.get_logger().error(f"request {request_id}: internal error\n{traceback.format_exc()}")
            return request_id, _Outcome(False, f"internal error: {type(exc).__name__}: {exc}"), header
        busy = self._admit()
        if busy:
            self.get_logger().info(f"request {request_id}: {busy}")
            return request_id, _Outcome(False, busy), job.header
        executor = self.executor
        # Completed by the worker through executor.create_task(_complete, ...): completing
        # an rclpy Future from another thread does not wake the awaiting coroutine.
        future = Future()
        try:
            self._worker.submit(self._work, job, future, executor)
        except RuntimeError:  # the pool is shut down
            self._release()
            return request_id, _Outcome(False, "node shutting down"), job.header
        t_queued = time.perf_counter()
        outcome = await future
        t_resumed = time.perf_counter()
        self.get_logger().debug(
            f"request {request_id}: timing: checks {1e3 * (t_queued - t_enter):.2f} ms, "
            f"worker {1e3 * outcome.worker_time:.2f} ms, wait incl. queue and hand-back "
            f"{1e3 * (t_resumed - t_queued - outcome.worker_time):.2f} ms")
        return request_id, outcome, job.header

    async def _on_plan_service(self, request: PlanGrasp.Request, response: PlanGrasp.Response):
        request_id, outcome, header = await self._run(request)
        return self._fill(response, request_id, outcome, header)

    async def _on_plan_goal(self, goal_handle: Any) -> PlanGraspAction.Result:
        request_id, outcome, header = await self._run(goal_handle.request, goal_handle)
        result = self._fill(PlanGraspAction.Result(), request_id, outcome, header)
        try:
            if outcome.cancelled and goal_handle.is_cancel_requested:
                goal_handle.canceled()
            elif outcome.success:
                goal_handle.succeed()
            else:
                goal_handle.abort()
        except Exception:  # noqa: BLE001 -- e.g. the goal was already finished
            self.get_logger().warn(f"request {request_id}: cannot set the goal state\n{traceback.format_exc()}")
        return result

    def _fill(self, msg: Any, request_id: str, outcome: _Outcome, header: Header) -> Any:
        msg.success = bool(outcome.success)
        msg.message = outcome.message
        msg.request_id = request_id
        msg.configuration.header = header
        msg.wrist_pose.header = header
        if outcome.result is not None:
            try:
                fill_result(msg, outcome.result, header, planning_time=outcome.worker_time)
            except Exception as exc:  # noqa: BLE001 -- request boundary
                self.get_logger().error(f"request {request_id}: cannot convert the result\n{traceback.format_exc()}")
                msg.success = False
                msg.message = f"internal error: {type(exc).__name__}: {exc}"
        else:
            msg.planning_time = float(outcome.worker_time)
        return msg

    # ------------------------------------------------------------------ worker
    def _work(self, job: _Job, future: Future, executor: Any) -> None:
        """Worker thread: plan one job and complete ``future`` through the executor."""
        try:
            outcome = self._plan_job(job)
        except Exception as exc:  # noqa: BLE001 -- request boundary: the worker never dies
            self.get_logger().error(f"request {job.request_id}: internal error\n{traceback.format_exc()}")
            outcome = _Outcome(False, f"internal error: {type(exc).__name__}: {exc}")
        finally:
            self._release()
        if executor is not None:
            try:
                executor.create_task(_complete, future, outcome, executor)
                return
            except Exception:  # noqa: BLE001 -- executor shut down: nobody awaits any more
                pass
        future.set_result(outcome)

    def _warm_up(self) -> None:
        """Worker thread: load the compiled kernels (never raises: a request would then
        pay for the load, or report the same error itself)."""
        if self._stopping.is_set():
            return
        try:
            seconds = warm_up()
        except Exception:  # noqa: BLE001 -- the worker never dies
            self.get_logger().error(f"warm-up failed\n{traceback.format_exc()}")
            return
        self.get_logger().debug(f"planner kernels loaded in {seconds:.2f} s")

    def _build_object(self, job: _Job) -> objects.GraspObject:
        if job.source == "object_name":
            return builtin_objects.builtin(job.object_name)
        if job.source == "mesh_uri":
            return mesh_files.from_file(job.mesh_uri, allowed_dir=job.allowed_dir,
                                     max_triangles=job.max_triangles, max_bytes=job.max_bytes)
        digest = hashlib.sha1()
        for array in (job.vertices, job.triangles):
            digest.update(str(array.shape).encode())
            digest.update(np.ascontiguousarray(array).tobytes())
        key = f"{digest.hexdigest()}:{job.max_triangles}"
        with self._objects_lock:
            obj = self._objects.get(key)
            if obj is not None:
                self._objects.move_to_end(key)
                return obj
        try:
            obj = objects.from_arrays(job.vertices, job.triangles, name="mesh", max_triangles=job.max_triangles)
        except errors.ObjectError as exc:
            if job.source != _PACKED:
                raise
            raise errors.ObjectError(_packed_message(str(exc))) from None
        with self._objects_lock:
            self._objects[key] = obj
            while len(self._objects) > _OBJECT_CACHE_SIZE:
                self._objects.popitem(last=False)
        return obj

    def _plan_job(self, job: _Job) -> _Outcome:
        t0 = time.perf_counter()
        deadline = time.monotonic() + job.timeout if job.timeout > 0 else math.inf
        goal = job.goal_handle
        state = {"timed_out": False, "published": 0}

        def should_stop() -> bool:
            if self._stopping.is_set():
                return True
            if goal is not None and goal.is_cancel_requested:
                return True
            if time.monotonic() > deadline:
                state["timed_out"] = True
                return True
            return False

        def progress(stats: Any) -> None:
            header = Header(stamp=self.get_clock().now().to_msg(), frame_id=job.header.frame_id)
            msg = progress_msg(stats, job.request_id, job.options.algorithm, header)
            try:
                self._progress_pub.publish(msg)
                state["published"] += 1
                if goal is not None:
                    goal.publish_feedback(PlanGraspAction.Feedback(progress=msg))
            except Exception:  # noqa: BLE001 -- progress must never stop a plan
                if not self._stopping.is_set():
                    self.get_logger().warn(f"request {job.request_id}: progress not published\n{traceback.format_exc()}")

        def elapsed() -> float:
            return time.perf_counter() - t0

        if should_stop():
            what = "cancelled" if goal is not None and goal.is_cancel_requested else "stopped"
            return _Outcome(False, f"{what} before planning started", cancelled=True)
        self.get_logger().info(
            f"request {job.request_id}: {job.describe}, {job.options.algorithm} "
            f"{job.options.particles} particles x {job.options.iterations} iterations, "
            f"frame '{job.header.frame_id}'")
        try:
            obj = self._build_object(job)
            rng = np.random.default_rng(job.seed)
            result = plan(obj, pose=job.pose, options=job.options, rng=rng, hand=job.hand,
                          progress=progress, should_stop=should_stop)
        except (ObjectError, PlanningError) as exc:
            self.get_logger().info(f"request {job.request_id}: {exc}")
            return _Outcome(False, str(exc), worker_time=elapsed())
        self._publish_markers(job, result)
        worker_time = elapsed()

        summary = (f"{result.n_contacts} contacts, fitness {result.fitness:.3f}, epsilon "
                   f"{result.epsilon:.4f}, force closure {'yes' if result.force_closure else 'no'}, "
                   f"{result.iterations_run} of {job.options.iterations} iterations in {worker_time:.2f} s")
        if self._stopping.is_set() and result.cancelled:
            outcome = _Outcome(False, f"node shutting down: stopped after {summary}", result, True)
        elif goal is not None and result.cancelled and goal.is_cancel_requested:
            outcome = _Outcome(False, f"cancelled: {summary}", result, cancelled=True)
        elif state["timed_out"] and result.cancelled:
            outcome = _Outcome(False, f"timed out after {job.timeout:g} s (parameter plan_timeout): "
                                      f"best so far {summary}", result)
        elif not result.valid:
            why = []
            if result.n_contacts < 2:
                why.append(f"only {result.n_contacts} fingertip contacts")
            if not result.fcl.legal:
                why.append("the collision check failed")
            reason = ", ".join(why) or "illegal configuration"
            outcome = _Outcome(False, f"no valid grasp found ({reason}): {summary}", result)
        else:
            outcome = _Outcome(True, f"grasp found: {summary}", result)
        outcome.worker_time = worker_time
        self.get_logger().info(f"request {job.request_id}: {outcome.message} "
                               f"({state['published']} progress messages)")
        return outcome

    def _publish_markers(self, job: _Job, result: GraspResult) -> None:
        try:
            self._marker_pub.publish(grasp_markers(result, job.header, job.hand))
        except Exception:  # noqa: BLE001 -- markers are best effort
            if not self._stopping.is_set():
                self.get_logger().warn(f"request {job.request_id}: markers not published\n{traceback.format_exc()}")

    # ------------------------------------------------------------------ shutdown
    def stop_worker(self, wait: bool = True) -> None:
        """Stop the running plan (within one iteration), drop queued ones, join the worker."""
        self._stopping.set()
        self._worker.shutdown(wait=wait, cancel_futures=True)

    def destroy_node(self) -> None:
        self.stop_worker(wait=True)
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Console script ``planner_node``: run the node until SIGINT / SIGTERM.

    Owns ``rclpy.init``, a MultiThreadedExecutor spin and the clean shutdown: on SIGINT
    or SIGTERM the running plan is stopped (its caller is answered), queued requests are
    dropped, the executor is shut down, the node destroyed and rclpy shut down; the exit
    status is then 0. A second signal during the shutdown exits at once (status 130).
    Returns 1 when the node cannot start (for example an invalid parameter).

    The executor spins in a thread and the main thread waits for a signal with Python
    handlers installed instead of rclpy's (``SignalHandlerOptions.NO``): with rclpy's
    handlers a SIGINT that arrives while the main thread is blocked in the executor's
    wait can be lost (rclpy wakes the wait set before Python's own handler has run, and
    the main thread blocks again), which left the node running after one SIGINT.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    signals: list[int] = []

    def on_signal(signum: int, _frame: Any) -> None:
        if stop.is_set() and signals:
            os.write(2, b"[grasp_apso] second signal: exiting now\n")
            os._exit(130)
        signals.append(signum)
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    node = None
    executor = None
    spinner = None
    errors: list[BaseException] = []
    status = 0
    try:
        node = GraspPlannerNode()
        executor = MultiThreadedExecutor(num_threads=max(4, os.cpu_count() or 2))
        executor.add_node(node)
        # The ~100k objects of the imported libraries never die: keep them out of the
        # cyclic garbage collector, whose full collections otherwise cost 50+ ms pauses
        # while a large request (thousands of message objects) is deserialised.
        gc.freeze()

        def spin() -> None:
            try:
                executor.spin()
            except ExternalShutdownException:
                pass
            except BaseException as exc:  # noqa: BLE001 -- reported by the main thread
                if not stop.is_set():  # errors of a spin being shut down do not matter
                    errors.append(exc)
                    traceback.print_exc()
            finally:
                stop.set()

        spinner = threading.Thread(target=spin, name="grasp_apso_executor", daemon=True)
        spinner.start()
        while not stop.wait(0.5):
            pass
        if errors:
            status = 1
        elif signals:
            node.get_logger().info(f"{signal.Signals(signals[0]).name}: shutting down")
    except Exception as exc:  # noqa: BLE001 -- report start-up failures readably
        print(f"[grasp_apso] error: {exc}", file=sys.stderr)
        status = 1
    finally:
        if node is not None:
            node.stop_worker(wait=True)
        if executor is not None:
            executor.shutdown(timeout_sec=5.0)
        if spinner is not None:
            spinner.join(timeout=5.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return status


if __name__ == "__main__":
    sys.exit(main())
