"""Conversions between ROS 2 messages and the planner's numpy data (no node here).

Everything is SI (REP 103): metres, radians, seconds. The planning frame of a request is
``object_pose.header.frame_id``; every pose, point and marker produced here is in that
frame, stamped with the request's ``object_pose.header``.

Functions
---------
- :func:`mesh_to_arrays` -- ``shape_msgs/Mesh`` -> vertices (V, 3) float64, triangles (T, 3) int64
- :func:`arrays_to_mesh` -- the reverse (for clients and tests)
- :func:`packed_mesh_to_arrays` -- the packed request fields ``mesh_vertices`` /
  ``mesh_triangles`` -> the same arrays; :func:`arrays_to_packed` the reverse
- :func:`pose_stamped_to_matrix` -- ``PoseStamped`` -> (frame_id, 4x4), validated
- :func:`matrix_to_pose_msg` -- 4x4 rigid transform -> ``geometry_msgs/Pose``
- :func:`grasp_msg` -- one :class:`~grasp_apso.search.result.GraspCandidate` -> ``Grasp``
- :func:`fill_result` -- a :class:`~grasp_apso.search.result.GraspResult` into a ``PlanGrasp``
  response or action result (they have the same fields): ``grasps`` and the top-level
  fields (= ``grasps[0]``)
- :func:`progress_msg` -- :class:`~grasp_apso.search.swarm.IterationStats` -> ``GraspProgress``
- :func:`reply_header` -- a request's frame and stamp -> ``std_msgs/Header``

RViz markers are in :mod:`grasp_apso.ros.markers`.
"""

from __future__ import annotations

import array
import operator
from typing import Any, Iterable

import numpy as np
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Vector3, Vector3Stamped
from sensor_msgs.msg import JointState
from shape_msgs.msg import Mesh, MeshTriangle
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from grasp_apso_interfaces.msg import Grasp, GraspProgress

from ..model.hand import JOINT_NAMES
from ..model.poses import matrix_to_pose, pose_to_matrix
from ..search.hand_trajectory import hand_trajectory

__all__ = [
    "reply_header",
    "arrays_to_mesh",
    "arrays_to_packed",
    "fill_result",
    "grasp_msg",
    "joint_state",
    "joint_trajectory",
    "matrix_to_pose_msg",
    "mesh_to_arrays",
    "packed_mesh_to_arrays",
    "pose_stamped_to_matrix",
    "progress_msg",
]

# --------------------------------------------------------------------------------------
# Meshes
# --------------------------------------------------------------------------------------


_XYZ = operator.attrgetter("x", "y", "z")
_INDICES = operator.attrgetter("vertex_indices")


def mesh_to_arrays(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a ``shape_msgs/Mesh``, unvalidated.

    Validation (finite vertices, indices in range, degenerate or flat meshes, size
    limits) is :func:`grasp_apso.model.objects.from_arrays`'s job; this only copies (about
    2 ms for 10,000 triangles; rclpy's own conversion of such a message to Python
    objects takes much longer).

    Parameters
    ----------
    mesh : shape_msgs.msg.Mesh
        Vertices in metres, object frame.

    Returns
    -------
    vertices : (V, 3) float64, m
    triangles : (T, 3) int64
    """
    points = mesh.vertices
    if len(points):
        vertices = np.array(list(map(_XYZ, points)), dtype=np.float64).reshape(-1, 3)
    else:
        vertices = np.zeros((0, 3), dtype=np.float64)
    tris = mesh.triangles
    if len(tris):
        triangles = np.concatenate(list(map(_INDICES, tris))).astype(np.int64).reshape(-1, 3)
    else:
        triangles = np.zeros((0, 3), dtype=np.int64)
    return vertices, triangles


def arrays_to_mesh(vertices: Any, triangles: Any) -> Mesh:
    """A ``shape_msgs/Mesh`` from vertices (V, 3) metres and triangles (T, 3) indices."""
    verts = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    tris = np.asarray(triangles, dtype=np.uint32).reshape(-1, 3)
    mesh = Mesh()
    mesh.vertices = [Point(x=x, y=y, z=z) for x, y, z in verts.tolist()]
    mesh.triangles = [MeshTriangle(vertex_indices=t) for t in tris]
    return mesh


# --------------------------------------------------------------------------------------
# Poses
# --------------------------------------------------------------------------------------


def packed_mesh_to_arrays(vertices: Any, triangles: Any) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a packed mesh (the ``mesh_vertices`` / ``mesh_triangles``
    request fields), unvalidated beyond their lengths.

    rclpy hands primitive sequences over as ``array.array``; numpy reads their buffers
    directly (the vertices as a view, the indices in one vectorised copy to int64), under
    0.1 ms for 10,000 triangles, where rclpy needs ~25 ms to build a ``shape_msgs/Mesh``
    of that size as Python objects before the node sees it.

    Parameters
    ----------
    vertices : (3 V,) float sequence, m -- x, y, z of each vertex
    triangles : (3 T,) unsigned int sequence -- vertex indices, three per triangle

    Returns
    -------
    vertices : (V, 3) float64, m
    triangles : (T, 3) int64

    Raises
    ------
    ValueError
        A length that is not a multiple of 3 (names the field).
    """
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    if v.ndim != 1 or len(v) % 3:
        raise ValueError(f"mesh_vertices: {v.size} values, not a multiple of 3 (x, y, z per vertex)")
    if t.ndim != 1 or len(t) % 3:
        raise ValueError(f"mesh_triangles: {t.size} indices, not a multiple of 3 (3 per triangle)")
    return v.reshape(-1, 3), t.reshape(-1, 3)


def arrays_to_packed(vertices: Any, triangles: Any) -> tuple[array.array, array.array]:
    """The packed request fields from vertices (V, 3) metres and triangles (T, 3) indices.

    Parameters
    ----------
    vertices : (V, 3) float array_like, m, object frame
    triangles : (T, 3) int array_like -- zero-based vertex indices

    Returns
    -------
    mesh_vertices : array.array('d'), 3 V values, m -- x, y, z of each vertex
    mesh_triangles : array.array('I'), 3 T indices

    Built from the arrays' bytes (no Python object per value; ~1 ms for 10,000
    triangles); rclpy takes both without conversion, for
    ``req.mesh_vertices, req.mesh_triangles = arrays_to_packed(v, t)``. Only the shapes
    and the index type are checked here: the node validates the mesh itself.

    Raises
    ------
    ValueError
        Wrong shapes, indices that are not whole numbers or do not fit in uint32.
    """
    verts = np.asarray(vertices, dtype=np.float64)
    tris = np.asarray(triangles)
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise ValueError(f"vertices: expected shape (V, 3), got {verts.shape}")
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise ValueError(f"triangles: expected shape (T, 3), got {tris.shape}")
    if tris.size and tris.dtype.kind not in "iu":
        # Floats are accepted when they hold whole numbers; astype would truncate others.
        if tris.dtype.kind != "f" or not np.all(np.isfinite(tris) & (tris == np.round(tris))):
            raise ValueError(f"triangles: indices must be whole numbers, got dtype {tris.dtype}")
    if tris.size and (tris.min() < 0 or tris.max() > np.iinfo(np.uint32).max):
        raise ValueError("triangles: indices must lie in [0, 2**32 - 1]")
    # Native byte order: array.array reads its bytes in the machine's order.
    return (array.array("d", verts.astype("=f8").tobytes()),
            array.array("I", tris.astype("=u4").tobytes()))


def pose_stamped_to_matrix(pose: PoseStamped, field: str = "object_pose") -> tuple[str, np.ndarray]:
    """Planning frame and homogeneous transform of a ``PoseStamped``.

    Parameters
    ----------
    pose : geometry_msgs.msg.PoseStamped
        Pose of the object frame in ``header.frame_id``.
    field : str
        Request field named in error messages.

    Returns
    -------
    frame_id : str
    transform : (4, 4) float
        Object frame -> planning frame.

    Raises
    ------
    ObjectError
        ``object_pose: ...`` for a non-finite position, a zero quaternion or one whose
        norm is not 1 (within 1e-3; see :func:`grasp_apso.model.poses.pose_to_matrix`).
    """
    p, q = pose.pose.position, pose.pose.orientation
    matrix = pose_to_matrix((p.x, p.y, p.z), (q.x, q.y, q.z, q.w), field=field)
    return pose.header.frame_id, matrix


def matrix_to_pose_msg(transform: Any) -> Pose:
    """``geometry_msgs/Pose`` of a rigid 4x4 transform (unit quaternion, w >= 0)."""
    position, quat = matrix_to_pose(transform)
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quat)
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def _point(values: Iterable[float]) -> Point:
    x, y, z = (float(v) for v in values)
    return Point(x=x, y=y, z=z)


def _vector(values: Iterable[float]) -> Vector3:
    x, y, z = (float(v) for v in values)
    return Vector3(x=x, y=y, z=z)


# --------------------------------------------------------------------------------------
# Results and progress
# --------------------------------------------------------------------------------------


def joint_state(positions: Any, header: Header, names: tuple[str, ...] = JOINT_NAMES) -> JointState:
    """A JointState of ``names`` (default the paper hand's 18
    :data:`~grasp_apso.model.hand.JOINT_NAMES`; radians, or m for a prismatic joint)."""
    values = np.asarray(positions, dtype=np.float64).reshape(-1)
    if values.shape != (len(names),):
        raise ValueError(f"joint positions: expected {len(names)} values, got {values.shape}")
    return JointState(header=header, name=list(names), position=[float(v) for v in values])


def joint_trajectory(times: Any, positions: Any, header: Header, names: tuple[str, ...]) -> JointTrajectory:
    """A ``trajectory_msgs/JointTrajectory`` over ``names``.

    times : (K,) float, s from the start, increasing; positions : (K, len(names)) float.
    """
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    q = np.asarray(positions, dtype=np.float64)
    if q.shape != (len(t), len(names)):
        raise ValueError(f"trajectory: expected positions of shape {(len(t), len(names))}, got {q.shape}")
    points = []
    for ti, qi in zip(t.tolist(), q.tolist()):
        point = JointTrajectoryPoint(positions=qi)
        sec = int(np.floor(ti))
        point.time_from_start.sec, point.time_from_start.nanosec = sec, int(round((ti - sec) * 1e9))
        points.append(point)
    return JointTrajectory(header=header, joint_names=list(names), points=points)


def grasp_msg(candidate: Any, header: Header, names: tuple[str, ...] = JOINT_NAMES, hand: Any = None) -> Grasp:
    """One ranked candidate as ``grasp_apso_interfaces/Grasp`` (field by field, SI,
    everything in the request's planning frame ``header.frame_id``).

    Parameters
    ----------
    candidate : grasp_apso.search.result.GraspCandidate
    header : std_msgs.msg.Header
        The request's ``object_pose.header``.
    names : tuple of str
        The result's ``joint_names`` (the hand's actuated joints; the paper hand's 18).
    hand : the hand planned with (paper or general ``HandModel``; None = the paper's)
        Its joint limits bound the squeeze of ``hand_trajectory``
        (:func:`grasp_apso.search.hand_trajectory.hand_trajectory`).
    """
    msg = Grasp()
    msg.id = str(candidate.id)
    msg.grasp_posture = joint_state(candidate.joint_positions, header, names)
    msg.pre_grasp_posture = joint_state(candidate.pre_grasp_positions, header, names)
    msg.hand_trajectory = joint_trajectory(*hand_trajectory(candidate, hand), header, names)
    msg.grasp_pose = PoseStamped(header=header, pose=matrix_to_pose_msg(candidate.wrist_pose))
    msg.pre_grasp_pose = PoseStamped(header=header, pose=matrix_to_pose_msg(candidate.pre_grasp_pose))
    msg.approach_direction = Vector3Stamped(header=header, vector=_vector(candidate.approach))
    msg.approach_distance = float(candidate.approach_distance)
    msg.grasp_quality = float(candidate.grasp_quality)
    _fill_quality_and_contacts(msg, candidate)
    msg.sim_result = int(candidate.sim_result)
    msg.sim_max_shift = float(candidate.sim_max_shift)
    msg.sim_max_turn = float(candidate.sim_max_turn)
    return msg


def _fill_quality_and_contacts(msg: Any, grasp: Any) -> None:
    """The fields a ``Grasp`` and the reply's top level share: ``fitness``,
    ``epsilon_quality``, ``force_closure`` and the contacts (planning frame)."""
    msg.fitness = float(grasp.fitness)
    msg.epsilon_quality = float(grasp.epsilon)
    msg.force_closure = bool(grasp.force_closure)
    msg.contact_points = [_point(c.position) for c in grasp.contacts]
    msg.contact_normals = [_vector(c.normal) for c in grasp.contacts]
    msg.contact_fingers = [str(c.finger) for c in grasp.contacts]


def fill_result(msg: Any, result: Any, header: Header, planning_time: float | None = None,
                source: str = "planned", hand: Any = None) -> Any:
    """Copy a planner result into a ``PlanGrasp`` response or action result.

    ``grasps`` gets every ranked candidate (:func:`grasp_msg`), best first; the top-level
    fields are ``grasps[0]``: ``configuration`` (JointState of ``result.joint_names``: the
    hand's actuated joints, the paper hand's 18 names; ``header`` =
    the request's), ``wrist_pose``, ``fitness``, ``epsilon_quality``, ``force_closure`` and
    the contacts (points, outward normals, fingers; planning frame). Also sets
    ``iterations_run``, ``planning_time`` and ``grasp_source``. ``success``, ``message``
    and ``request_id`` are the caller's. A result without candidates fills the top-level
    fields from the result itself.

    Parameters
    ----------
    msg : PlanGrasp.Response or PlanGrasp.Result
    result : grasp_apso.search.result.GraspResult or grasp_apso.ros.database_answers.StoredGrasps
        A plan, or grasps answered from the grasp database (``source`` "database").
    header : std_msgs.msg.Header
        The request's ``object_pose.header`` (frame and stamp).
    planning_time : float, optional, s
        Time to report; default the planner's preparation plus planning time.
    source : str
        ``grasp_source``: "planned" or "database".
    hand : HandModel, optional
        The hand planned with (see :func:`grasp_msg`); None = the paper's hand.
    """
    names = tuple(str(n) for n in result.joint_names)
    if not names or len(set(names)) != len(names):
        raise ValueError(f"result: joint names must be distinct and not empty, got {names}")
    candidates = tuple(getattr(result, "candidates", ()) or ())
    best = candidates[0] if candidates else result
    msg.configuration = joint_state(best.joint_positions, header, names)
    msg.wrist_pose = PoseStamped(header=header, pose=matrix_to_pose_msg(best.wrist_pose))
    _fill_quality_and_contacts(msg, best)
    msg.grasps = [grasp_msg(c, header, names, hand) for c in candidates]
    msg.grasp_source = source
    msg.iterations_run = int(result.iterations_run)
    if planning_time is None:
        planning_time = result.planning_time + result.preparation_time
    msg.planning_time = float(planning_time)
    return msg


def progress_msg(stats: Any, request_id: str, algorithm: str, header: Header) -> GraspProgress:
    """A ``GraspProgress`` from one :class:`~grasp_apso.search.swarm.IterationStats`.

    Non-finite fitness values (no active particle yet) are sent as they are (``-inf``);
    ``ros2 topic echo`` shows them as ``-.inf``. ``distinct_candidates`` is the size of the
    search's archive of distinct valid candidates (0 when the planner does not keep one).
    """
    msg = GraspProgress()
    msg.header = header
    msg.request_id = request_id
    msg.algorithm = algorithm
    msg.iteration = int(stats.iteration)
    msg.iterations = int(stats.iterations)
    msg.best_fitness = float(stats.best_fitness)
    msg.mean_fitness = float(stats.mean_fitness)
    msg.active_particles = int(stats.active_particles)
    msg.best_contacts = int(stats.best_contacts)
    msg.elapsed = float(stats.elapsed)
    msg.distinct_candidates = int(stats.distinct_candidates)
    return msg


def reply_header(request: Any) -> Header:
    """The header of a reply: the :class:`~grasp_apso.ros.plan_request.PlanRequest`'s
    ``frame_id`` and ``stamp`` (sec, nanosec)."""
    header = Header(frame_id=request.frame_id)
    header.stamp.sec, header.stamp.nanosec = (int(v) for v in request.stamp)
    return header
