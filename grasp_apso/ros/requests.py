"""Request parsing: a ``PlanGrasp`` request or action goal -> a :class:`Job` for the worker.

Only cheap checks run here, on the executor's thread: exactly one object source, sizes
counted before any array is built (triangles AND vertices against
``max_mesh_triangles``), the pose, the per-request overrides (``0`` / ``""`` / ``-1`` =
node parameter), the scene (``support_planes``, ``obstacles`` + ``obstacle_poses``) and
the plan options. Building the object (mesh validation, file reading) is the worker's
job, bounded by ``plan_timeout``. Every problem raises a
:class:`~grasp_apso.errors.GraspApsoError` whose message starts with the field at fault.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from std_msgs.msg import Header

from ..errors import ObjectError, RequestError, SceneError
from ..model import builtin as builtin_objects
from ..model.hand import HandModel
from ..model.poses import pose_to_matrix
from ..model.scene import Scene
from ..search.options import ALGORITHMS, PlanOptions
from .conversions import mesh_to_arrays, packed_mesh_to_arrays, pose_stamped_to_matrix
from .parameters import Settings

__all__ = ["Job", "PACKED", "parse_request", "parse_scene", "packed_message"]

#: The packed mesh source, as it is named in messages.
PACKED = "mesh_vertices/mesh_triangles"
_SOURCES = f"mesh, {PACKED}, mesh_uri, object_name"


@dataclass
class Job:
    """A checked request, ready for the worker, and its progress through it.

    ``stage`` is where the worker is (``queued``, ``reading``, ``validation``,
    ``preparation``, ``planning``); a timeout names it. ``answered`` is set by whichever
    of the worker, the timeout or a cancel answers first (the others then do nothing).
    """

    request_id: str
    header: Header
    pose: np.ndarray
    source: str                      # "mesh" | PACKED | "mesh_uri" | "object_name"
    describe: str                    # for log lines
    options: PlanOptions
    seed: int | None
    hand: HandModel
    timeout: float
    scene: Scene | None = None
    vertices: np.ndarray | None = None
    triangles: np.ndarray | None = None
    mesh_uri: str = ""
    allowed_dir: str = ""
    object_name: str = ""
    max_triangles: int = 200_000
    max_bytes: int = 50_000_000
    shown_uri: str = ""              # mesh_uri as the caller wrote it (for messages)
    goal_handle: Any = None
    kind: str = "service"            # "service" | "action"
    future: Any = None               # the rclpy Future the callback awaits
    executor: Any = None             # the executor that completes it
    stage: str = "queued"
    started: bool = False
    cancelled: bool = False
    timed_out: bool = False
    answered: bool = False
    database_note: str = ""          # why the grasp database did not answer (for the message)
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)


def packed_message(text: str) -> str:
    """A validation message of the mesh checks (which say ``mesh: ...``) re-addressed to the
    packed fields the client filled: vertex problems name ``mesh_vertices``, index problems
    ``mesh_triangles``, problems of the whole mesh both."""
    if not text.startswith("mesh: "):
        return text
    rest = text[len("mesh: "):]
    if re.match(r"(vertex \d|vertices |\d+ vertices )", rest):
        name = "mesh_vertices"
    elif re.match(r"(triangle \d|triangles |\d+ triangles )", rest):
        name = "mesh_triangles"
    else:
        name = PACKED
    return f"{name} (packed mesh): {rest}"


def _finite_or_default(value: float, name: str, default: float) -> float:
    """A per-request length: 0 = the node parameter; negative or non-finite refused."""
    value = float(value)
    if not math.isfinite(value) or value < 0.0:
        raise RequestError(f"{name}: {value!r} must be a finite number >= 0 m (0 = node parameter)", name)
    return value if value > 0.0 else default


def parse_scene(req: Any) -> Scene | None:
    """The request's scene (planning frame), or None when it has none.

    Raises SceneError naming ``support_planes[i]``, ``obstacles[i]`` or
    ``obstacle_poses[i]``.
    """
    planes = [tuple(float(c) for c in plane.coef) for plane in req.support_planes]
    if len(req.obstacles) != len(req.obstacle_poses):
        raise SceneError(
            f"obstacle_poses: {len(req.obstacles)} obstacles but {len(req.obstacle_poses)} "
            "obstacle_poses (they must have the same length)", "obstacle_poses")
    poses = []
    for i, pose in enumerate(req.obstacle_poses):
        p, q = pose.position, pose.orientation
        try:
            poses.append(pose_to_matrix((p.x, p.y, p.z), (q.x, q.y, q.z, q.w), field=f"obstacle_poses[{i}]"))
        except ObjectError as exc:
            raise SceneError(str(exc), "obstacle_poses") from None
    obstacles = [(int(o.type), [float(d) for d in o.dimensions]) for o in req.obstacles]
    if not planes and not obstacles:
        return None
    return Scene.from_primitives(planes=planes, obstacles=obstacles, obstacle_poses=poses)


def _object_source(req: Any) -> tuple[str, bool, bool, str, str]:
    has_mesh = len(req.mesh.vertices) > 0 or len(req.mesh.triangles) > 0
    has_packed = len(req.mesh_vertices) > 0 or len(req.mesh_triangles) > 0
    uri = req.mesh_uri.strip()
    name = req.object_name.strip()
    given = [f for f, present in (("mesh", has_mesh), (PACKED, has_packed), ("mesh_uri", bool(uri)),
                                  ("object_name", bool(name))) if present]
    if not given:
        raise RequestError(
            "no object: mesh is empty and mesh_vertices/mesh_triangles, mesh_uri and object_name "
            f"are not set (give exactly one of {_SOURCES})", "mesh")
    if len(given) > 1:
        raise RequestError(f"give exactly one of {_SOURCES} (got {' and '.join(given)})", "mesh")
    return given[0], has_mesh, has_packed, uri, name


def _options(req: Any, settings: Settings, pose: np.ndarray) -> tuple[PlanOptions, int | None]:
    base = settings.options
    algorithm = req.algorithm.strip().lower() or base.algorithm
    if algorithm not in ALGORITHMS:
        raise RequestError(
            f"algorithm: unknown {req.algorithm!r} (expected one of: {', '.join(ALGORITHMS)}, "
            "or empty for the node parameter)", "algorithm")
    particles = int(req.particles) or base.particles
    if not 2 <= particles <= 1000:
        raise RequestError(f"particles: {particles} out of range [2, 1000] (0 = node parameter)", "particles")
    iterations = int(req.iterations) or base.iterations
    if not 1 <= iterations <= 10000:
        raise RequestError(f"iterations: {iterations} out of range [1, 10000] (0 = node parameter)", "iterations")
    max_grasps = int(req.max_grasps) or base.max_grasps
    if not 1 <= max_grasps <= 50:
        raise RequestError(f"max_grasps: {max_grasps} out of range [1, 50] (0 = node parameter)", "max_grasps")
    seed = int(req.seed)
    if seed < -1:
        raise RequestError(f"seed: {seed} is negative (use a seed >= 0, or -1 for the node parameter)", "seed")
    if seed == -1:
        seed = int(settings["seed"])
    wrist = None
    if req.fix_wrist_position:
        p = req.wrist_position
        point = np.array([p.x, p.y, p.z], dtype=float)
        if not np.all(np.isfinite(point)):
            raise RequestError(f"wrist_position: not finite: {point.tolist()}", "wrist_position")
        inverse = np.linalg.inv(pose)
        wrist = tuple(float(v) for v in inverse[:3, :3] @ point + inverse[:3, 3])
    clearance = _finite_or_default(req.clearance, "clearance", base.clearance)
    approach = _finite_or_default(req.approach_distance, "approach_distance", base.approach_distance)
    try:
        options = dataclasses.replace(
            base, algorithm=algorithm, particles=particles, iterations=iterations, wrist_position=wrist,
            neighborhood_size=max(1, min(int(settings["neighborhood_size"]), particles)),
            clearance=clearance, approach_distance=approach, max_grasps=max_grasps,
            simulate=bool(req.simulate))
    except ValueError as exc:
        raise RequestError(str(exc)) from None
    return options, (None if seed < 0 else seed)


def parse_request(req: Any, settings: Settings, request_id: str, goal_handle: Any = None) -> Job:
    """Check a request (cheap checks only) and build the worker's :class:`Job`.

    Raises
    ------
    RequestError, ObjectError, SceneError
        Naming the field at fault.
    """
    source, has_mesh, has_packed, uri, name = _object_source(req)
    frame, pose = pose_stamped_to_matrix(req.object_pose, "object_pose")
    header = Header(stamp=req.object_pose.header.stamp, frame_id=frame)
    options, seed = _options(req, settings, pose)
    scene = parse_scene(req)
    max_triangles = int(settings["max_mesh_triangles"])
    job = Job(
        request_id=request_id, header=header, pose=pose, source=source, describe="",
        options=options, seed=seed, hand=settings.hand, timeout=float(settings["plan_timeout"]),
        scene=scene, max_triangles=max_triangles, max_bytes=int(settings["max_mesh_bytes"]),
        goal_handle=goal_handle, kind="service" if goal_handle is None else "action")
    limit = f"(parameter max_mesh_triangles; at most 3 vertices per triangle, {3 * max_triangles} vertices)"
    if has_packed:
        if not len(req.mesh_vertices) or not len(req.mesh_triangles):
            missing = "mesh_triangles" if len(req.mesh_vertices) else "mesh_vertices"
            other = "vertices" if missing == "mesh_triangles" else "triangles"
            raise ObjectError(f"{missing}: empty, but the packed mesh has {other} "
                              "(give both mesh_vertices and mesh_triangles)", missing)
        n_tri, n_vert = len(req.mesh_triangles) // 3, len(req.mesh_vertices) // 3
        if n_tri > max_triangles:
            raise ObjectError(f"mesh_triangles: {n_tri} triangles exceeds the limit of {max_triangles} {limit}")
        if n_vert > 3 * max_triangles:
            raise ObjectError(f"mesh_vertices: {n_vert} vertices exceeds the limit of {3 * max_triangles} {limit}")
        try:
            job.vertices, job.triangles = packed_mesh_to_arrays(req.mesh_vertices, req.mesh_triangles)
        except ValueError as exc:
            raise ObjectError(str(exc)) from None
        job.describe = f"packed mesh ({len(job.vertices)} vertices, {len(job.triangles)} triangles)"
    elif has_mesh:
        n_tri, n_vert = len(req.mesh.triangles), len(req.mesh.vertices)
        if n_tri > max_triangles:
            raise ObjectError(f"mesh: {n_tri} triangles exceeds the limit of {max_triangles} {limit}")
        if n_vert > 3 * max_triangles:
            raise ObjectError(f"mesh: {n_vert} vertices exceeds the limit of {3 * max_triangles} {limit}")
        job.vertices, job.triangles = mesh_to_arrays(req.mesh)
        job.describe = f"mesh ({n_vert} vertices, {n_tri} triangles)"
    elif uri:
        allowed = str(settings["allowed_mesh_dir"])
        if not allowed:
            raise ObjectError("mesh_uri: mesh files are disabled on this node (parameter allowed_mesh_dir "
                              "is empty); send the mesh inline")
        if "://" not in uri and not os.path.isabs(uri):
            uri = os.path.join(allowed, uri)
        job.mesh_uri, job.allowed_dir, job.shown_uri = uri, allowed, req.mesh_uri.strip()
        job.describe = f"mesh_uri {req.mesh_uri}"
    else:
        if name not in builtin_objects.BUILTIN_OBJECTS:
            builtin_objects.builtin(name)  # raises ObjectError "object_name: unknown ..."
        job.object_name = name
        job.describe = f"object {name}"
    return job
