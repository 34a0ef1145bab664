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
- :func:`fill_result` -- a :class:`~grasp_apso.search.planner.GraspResult` into a ``PlanGrasp``
  response or action result (they have the same fields)
- :func:`progress_msg` -- :class:`~grasp_apso.search.planner.IterationStats` -> ``GraspProgress``
- :func:`grasp_markers` -- a grasp as a ``visualization_msgs/MarkerArray`` for RViz
"""

from __future__ import annotations

import array
import operator
from typing import Any, Iterable

import numpy as np
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Vector3
from sensor_msgs.msg import JointState
from shape_msgs.msg import Mesh, MeshTriangle
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from grasp_apso_interfaces.msg import GraspProgress

from ..model.hand import FINGER_NAMES, JOINT_NAMES, HandModel
from ..model.poses import matrix_to_pose, pose_to_matrix

__all__ = [
    "MARKER_NAMESPACE",
    "arrays_to_mesh",
    "arrays_to_packed",
    "delete_all_markers",
    "fill_result",
    "grasp_markers",
    "matrix_to_pose_msg",
    "mesh_to_arrays",
    "packed_mesh_to_arrays",
    "pose_stamped_to_matrix",
    "progress_msg",
]

#: Namespace prefix of the grasp markers (``<prefix>/hand``, ``<prefix>/contacts`` ...).
MARKER_NAMESPACE = "grasp_apso"


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


def fill_result(msg: Any, result: Any, header: Header, planning_time: float | None = None) -> Any:
    """Copy a planner result into a ``PlanGrasp`` response or action result.

    Sets ``configuration`` (JointState: the 18 :data:`~grasp_apso.model.hand.JOINT_NAMES`,
    positions in radians, ``header`` = the request's), ``wrist_pose`` (PoseStamped in the
    request's frame), ``fitness``, ``epsilon_quality``, ``force_closure``, the contacts
    (points, outward normals, finger names; planning frame), ``iterations_run`` and
    ``planning_time``. ``success``, ``message`` and ``request_id`` are the caller's.

    Parameters
    ----------
    msg : PlanGrasp.Response or PlanGrasp.Result
    result : grasp_apso.search.planner.GraspResult
    header : std_msgs.msg.Header
        The request's ``object_pose.header`` (frame and stamp).
    planning_time : float, optional, s
        Time to report; default the planner's preparation plus planning time.

    Returns
    -------
    msg, filled in place.
    """
    names = tuple(result.joint_names)
    if names != JOINT_NAMES:
        raise ValueError(f"result: unexpected joint names {names}")
    positions = np.asarray(result.joint_positions, dtype=np.float64)
    state = JointState()
    state.header = header
    state.name = list(JOINT_NAMES)
    state.position = [float(v) for v in positions]
    msg.configuration = state
    msg.wrist_pose = PoseStamped(header=header, pose=matrix_to_pose_msg(result.wrist_pose))
    msg.fitness = float(result.fitness)
    msg.epsilon_quality = float(result.epsilon)
    msg.force_closure = bool(result.force_closure)
    msg.contact_points = [_point(c.position) for c in result.contacts]
    msg.contact_normals = [_vector(c.normal) for c in result.contacts]
    msg.contact_fingers = [str(c.finger) for c in result.contacts]
    msg.iterations_run = int(result.iterations_run)
    if planning_time is None:
        planning_time = result.planning_time + result.preparation_time
    msg.planning_time = float(planning_time)
    return msg


def progress_msg(stats: Any, request_id: str, algorithm: str, header: Header) -> GraspProgress:
    """A ``GraspProgress`` from one :class:`~grasp_apso.search.planner.IterationStats`.

    Non-finite fitness values (no active particle yet) are sent as they are (``-inf``);
    ``ros2 topic echo`` shows them as ``-.inf``.
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
    return msg


# --------------------------------------------------------------------------------------
# RViz markers
# --------------------------------------------------------------------------------------

_FINGER_COLORS = {
    "little": (0.90, 0.60, 0.20),
    "ring": (0.85, 0.75, 0.25),
    "middle": (0.40, 0.80, 0.30),
    "index": (0.25, 0.60, 0.90),
    "thumb": (0.75, 0.35, 0.85),
}


def _color(rgb: tuple[float, float, float], alpha: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(alpha))


def _marker(header: Header, ns: str, marker_id: int, kind: int) -> Marker:
    marker = Marker()
    marker.header = header
    marker.ns = ns
    marker.id = marker_id
    marker.type = kind
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.lifetime = Duration(sec=0, nanosec=0)  # forever, until the next DELETEALL
    marker.frame_locked = False
    return marker


def grasp_markers(
    result: Any,
    header: Header,
    hand: HandModel,
    ns: str = MARKER_NAMESPACE,
    normal_length: float = 0.03,
) -> MarkerArray:
    """RViz markers of a planned grasp, in the request's frame.

    The array starts with a ``DELETEALL`` marker, so the previous grasp disappears; then:

    - ``<ns>/palm``: the palm box (CUBE) at the wrist pose;
    - ``<ns>/links``: one LINE_LIST per finger (wrist -> finger base -> joints -> tip),
      line width the link diameter, coloured per finger;
    - ``<ns>/fingertips``: the fingertip pads (SPHERE_LIST, pad diameter), green for a
      finger in contact, grey otherwise;
    - ``<ns>/contacts``: contact points (SPHERE_LIST, 6 mm, red);
    - ``<ns>/normals``: the outward surface normal at each contact (ARROW, 3 cm).

    Parameters
    ----------
    result : grasp_apso.search.planner.GraspResult
        Its ``joints`` (5, 4, 3) and ``contacts`` are in the planning frame.
    header : std_msgs.msg.Header
        The request's ``object_pose.header``.
    hand : HandModel
        For the link and pad radii and the palm box.
    """
    markers = MarkerArray()
    clear = Marker()
    clear.header = header
    clear.action = Marker.DELETEALL
    markers.markers.append(clear)

    wrist = np.asarray(result.wrist_pose, dtype=np.float64)
    joints = np.asarray(result.joints, dtype=np.float64)  # (5, 4, 3) base, pip, dip, tip
    next_id = 0

    # Palm box.
    palm = _marker(header, f"{ns}/palm", next_id, Marker.CUBE)
    next_id += 1
    palm_tf = wrist.copy()
    palm_tf[:3, 3] = wrist[:3, :3] @ np.asarray(hand.palm_center, dtype=float) + wrist[:3, 3]
    palm.pose = matrix_to_pose_msg(palm_tf)
    half = np.asarray(hand.palm_half_extents, dtype=float)
    palm.scale = _vector(2.0 * half)
    palm.color = _color((0.80, 0.70, 0.60), 0.6)
    markers.markers.append(palm)

    # Finger links.
    origin = wrist[:3, 3]
    diameter = 2.0 * float(np.max(hand.link_radii))
    for f, name in enumerate(FINGER_NAMES):
        line = _marker(header, f"{ns}/links", next_id, Marker.LINE_LIST)
        next_id += 1
        chain = [origin, *joints[f]]
        for a, b in zip(chain[:-1], chain[1:]):
            line.points.append(_point(a))
            line.points.append(_point(b))
        line.scale.x = diameter
        line.color = _color(_FINGER_COLORS.get(name, (0.7, 0.7, 0.7)), 0.9)
        markers.markers.append(line)

    # Fingertip pads.
    in_contact = {c.finger for c in result.contacts}
    tips = _marker(header, f"{ns}/fingertips", next_id, Marker.SPHERE_LIST)
    next_id += 1
    pad = 2.0 * float(hand.pad_radius)
    tips.scale = Vector3(x=pad, y=pad, z=pad)
    tips.color = _color((0.6, 0.6, 0.6), 0.9)
    for f, name in enumerate(FINGER_NAMES):
        tips.points.append(_point(joints[f, -1]))
        tips.colors.append(_color((0.2, 0.85, 0.2) if name in in_contact else (0.6, 0.6, 0.6), 0.9))
    markers.markers.append(tips)

    # Contacts and their normals.
    if result.contacts:
        spheres = _marker(header, f"{ns}/contacts", next_id, Marker.SPHERE_LIST)
        next_id += 1
        spheres.scale = Vector3(x=0.006, y=0.006, z=0.006)
        spheres.color = _color((0.95, 0.1, 0.1), 1.0)
        spheres.points = [_point(c.position) for c in result.contacts]
        markers.markers.append(spheres)
        for contact in result.contacts:
            arrow = _marker(header, f"{ns}/normals", next_id, Marker.ARROW)
            next_id += 1
            start = np.asarray(contact.position, dtype=float)
            end = start + normal_length * np.asarray(contact.normal, dtype=float)
            arrow.points = [_point(start), _point(end)]
            arrow.scale = Vector3(x=0.002, y=0.004, z=0.006)  # shaft, head diameter, head length
            arrow.color = _color((0.95, 0.2, 0.2), 1.0)
            markers.markers.append(arrow)
    return markers


def delete_all_markers(header: Header) -> MarkerArray:
    """A MarkerArray holding only a DELETEALL marker (clears the last grasp)."""
    clear = Marker()
    clear.header = header
    clear.action = Marker.DELETEALL
    return MarkerArray(markers=[clear])

