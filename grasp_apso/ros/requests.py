"""Request parsing: a ``PlanGrasp`` request or action goal -> an immutable
:class:`~.plan_request.PlanRequest` (its object source a typed
:mod:`~grasp_apso.model.object_source` union) for the worker.

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
from typing import Any

import numpy as np

from ..errors import ObjectError, RequestError, SceneError
from ..model import builtin as builtin_objects
from ..model.object_source import PACKED, BuiltinObject, InlineMesh, MeshFile, ObjectSource
from ..model.poses import pose_to_matrix
from ..model.scene import Scene
from ..search.options import ALGORITHMS, PlanOptions
from .conversions import mesh_to_arrays, packed_mesh_to_arrays, pose_stamped_to_matrix
from .parameters import Settings
from .plan_request import PlanRequest, RequestKind

__all__ = ["parse_request", "parse_scene"]

_SOURCES = f"mesh, {PACKED}, mesh_uri, object_name"


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


def parse_request(req: Any, settings: Settings, request_id: str, kind: RequestKind = RequestKind.SERVICE) -> PlanRequest:
    """Check a request (cheap checks only) and build the worker's :class:`PlanRequest`.

    Raises
    ------
    RequestError, ObjectError, SceneError
        Naming the field at fault.
    """
    source, has_mesh, has_packed, uri, name = _object_source(req)
    frame, pose = pose_stamped_to_matrix(req.object_pose, "object_pose")
    options, seed = _options(req, settings, pose)
    scene = parse_scene(req)
    stamp = req.object_pose.header.stamp
    return PlanRequest(
        request_id=request_id, frame_id=frame, stamp=(int(stamp.sec), int(stamp.nanosec)), pose=pose,
        source=_checked_source(req, settings, has_mesh, has_packed, uri, name), options=options, seed=seed,
        hand=settings.hand, timeout=float(settings["plan_timeout"]), scene=scene, kind=kind)


def _checked_source(req: Any, settings: Settings, has_mesh: bool, has_packed: bool, uri: str,
                    name: str) -> ObjectSource:
    """The request's object source, its sizes counted before any array is built."""
    max_triangles = int(settings["max_mesh_triangles"])
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
            vertices, triangles = packed_mesh_to_arrays(req.mesh_vertices, req.mesh_triangles)
        except ValueError as exc:
            raise ObjectError(str(exc)) from None
        return InlineMesh(vertices, triangles, packed=True, max_triangles=max_triangles)
    if has_mesh:
        n_tri, n_vert = len(req.mesh.triangles), len(req.mesh.vertices)
        if n_tri > max_triangles:
            raise ObjectError(f"mesh: {n_tri} triangles exceeds the limit of {max_triangles} {limit}")
        if n_vert > 3 * max_triangles:
            raise ObjectError(f"mesh: {n_vert} vertices exceeds the limit of {3 * max_triangles} {limit}")
        vertices, triangles = mesh_to_arrays(req.mesh)
        return InlineMesh(vertices, triangles, packed=False, max_triangles=max_triangles)
    if uri:
        allowed = str(settings["allowed_mesh_dir"])
        if not allowed:
            raise ObjectError("mesh_uri: mesh files are disabled on this node (parameter allowed_mesh_dir "
                              "is empty); send the mesh inline")
        if "://" not in uri and not os.path.isabs(uri):
            uri = os.path.join(allowed, uri)
        return MeshFile(uri, allowed_dir=allowed, max_bytes=int(settings["max_mesh_bytes"]),
                        shown=req.mesh_uri.strip(), max_triangles=max_triangles)
    if name not in builtin_objects.BUILTIN_OBJECTS:
        builtin_objects.builtin(name)  # raises ObjectError "object_name: unknown ..."
    return BuiltinObject(name)
