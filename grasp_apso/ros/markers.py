"""RViz markers of a planned grasp and its scene (``visualization_msgs/MarkerArray``).

Colours come from :mod:`grasp_apso.presentation.palette`, the palette of the PNG pictures too.
Everything is in the request's planning frame (``object_pose.header.frame_id``).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point, Vector3
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from ..model.hand import FINGER_NAMES, HandModel
from ..model.scene import BOX, CYLINDER, SPHERE, Scene
from ..presentation import palette
from ..presentation.hand_geometry import hand_triangles, link_colors
from .conversions import matrix_to_pose_msg

__all__ = ["MARKER_NAMESPACE", "delete_all_markers", "grasp_markers", "scene_markers"]

#: Namespace prefix of the markers (``<prefix>/palm``, ``<prefix>/scene`` ...).
MARKER_NAMESPACE = "grasp_apso"
#: Support planes are drawn as boxes this wide (m) and this thick (m), on their solid side.
PLANE_SIZE, PLANE_THICKNESS = 1.0, 0.01
_CONTACT_RGB = (0.95, 0.1, 0.1)
_TOUCH_RGB = (0.2, 0.85, 0.2)
_IDLE_RGB = (0.6, 0.6, 0.6)


def _color(rgb: Sequence[float] | str, alpha: float = 1.0) -> ColorRGBA:
    r, g, b = palette.rgb(rgb) if isinstance(rgb, str) else rgb
    return ColorRGBA(r=float(r), g=float(g), b=float(b), a=float(alpha))


def _point(values: Any) -> Point:
    x, y, z = (float(v) for v in values)
    return Point(x=x, y=y, z=z)


def _marker(header: Header, ns: str, marker_id: int, kind: int) -> Marker:
    marker = Marker()
    marker.header = header
    marker.ns = ns
    marker.id = marker_id
    marker.type = kind
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.lifetime = Duration(sec=0, nanosec=0)  # forever, until the next DELETEALL
    return marker


class _Builder:
    """Appends markers with consecutive ids."""

    def __init__(self, header: Header, ns: str) -> None:
        self.header, self.ns = header, ns
        self.array = MarkerArray()
        clear = Marker()
        clear.header = header
        clear.action = Marker.DELETEALL
        self.array.markers.append(clear)

    def add(self, name: str, kind: int) -> Marker:
        marker = _marker(self.header, f"{self.ns}/{name}", len(self.array.markers), kind)
        self.array.markers.append(marker)
        return marker


def _hand(b: _Builder, hand: HandModel, wrist: np.ndarray, joints: np.ndarray, prefix: str,
          alpha: float, contacts: set[str] | None) -> None:
    """Palm box, finger links and fingertip pads of one hand posture."""
    palm = b.add(f"{prefix}palm", Marker.CUBE)
    palm_tf = wrist.copy()
    palm_tf[:3, 3] = wrist[:3, :3] @ np.asarray(hand.palm_center, dtype=float) + wrist[:3, 3]
    palm.pose = matrix_to_pose_msg(palm_tf)
    half = 2.0 * np.asarray(hand.palm_half_extents, dtype=float)
    palm.scale = Vector3(x=float(half[0]), y=float(half[1]), z=float(half[2]))
    palm.color = _color(palette.PALM_COLOR, 0.6 * alpha)
    diameter = 2.0 * float(np.max(hand.link_radii))
    for f, name in enumerate(FINGER_NAMES):
        line = b.add(f"{prefix}links", Marker.LINE_LIST)
        chain = [wrist[:3, 3], *joints[f]]
        for a, c in zip(chain[:-1], chain[1:]):
            line.points += [_point(a), _point(c)]
        line.scale.x = diameter
        line.color = _color(palette.FINGER_COLORS.get(name, "#B3B3B3"), 0.9 * alpha)
    tips = b.add(f"{prefix}fingertips", Marker.SPHERE_LIST)
    pad = 2.0 * float(hand.pad_radius)
    tips.scale = Vector3(x=pad, y=pad, z=pad)
    tips.color = _color(_IDLE_RGB, 0.9 * alpha)
    for f, name in enumerate(FINGER_NAMES):
        tips.points.append(_point(joints[f, -1]))
        touching = contacts is not None and name in contacts
        tips.colors.append(_color(_TOUCH_RGB if touching else _IDLE_RGB, 0.9 * alpha))


def _is_general(hand: Any) -> bool:
    return not isinstance(hand, HandModel)


#: Triangles of a general hand's drawing at the grasp and (faint) at the pre-grasp.
HAND_TRIANGLES, PRE_GRASP_TRIANGLES = 3000, 1000


def _general_hand(b: _Builder, hand: Any, root: np.ndarray, q: np.ndarray, prefix: str, alpha: float,
                  max_triangles: int) -> None:
    """A general hand's own collision geometry at posture ``q``, root link at ``root``:
    one TRIANGLE_LIST per link (``<ns>/<prefix>hand``), in its finger's colour."""
    colors = link_colors(hand)
    for link, tris in hand_triangles(hand, q, root, max_triangles).items():
        m = b.add(f"{prefix}hand", Marker.TRIANGLE_LIST)
        m.scale = Vector3(x=1.0, y=1.0, z=1.0)
        m.color = _color(colors.get(link, palette.PALM_COLOR), 0.8 * alpha)
        # Python floats straight from tolist(): about 3x quicker than a float() per value.
        m.points = [Point(x=x, y=y, z=z) for x, y, z in tris.reshape(-1, 3).tolist()]


def scene_markers(b: _Builder, scene: Scene | None) -> None:
    """Support planes as thin large boxes (on their solid side) and the obstacles."""
    if scene is None:
        return
    for plane in np.asarray(scene.planes, dtype=float).reshape(-1, 4):
        n, d = plane[:3], plane[3]
        # The box's top face lies on the plane, centred at the point of the plane nearest
        # the origin of the frame; its z axis is the plane's normal.
        z = n / np.linalg.norm(n)
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
        x /= np.linalg.norm(x)
        tf = np.eye(4)
        tf[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        tf[:3, 3] = -d * z - 0.5 * PLANE_THICKNESS * z
        box = b.add("scene", Marker.CUBE)
        box.pose = matrix_to_pose_msg(tf)
        box.scale = Vector3(x=PLANE_SIZE, y=PLANE_SIZE, z=PLANE_THICKNESS)
        box.color = _color(palette.SCENE_COLOR, 0.5)
    for obstacle in scene.obstacles:
        dims = obstacle.dimensions
        if obstacle.kind == BOX:
            m = b.add("obstacles", Marker.CUBE)
            m.scale = Vector3(x=dims[0], y=dims[1], z=dims[2])
        elif obstacle.kind == SPHERE:
            m = b.add("obstacles", Marker.SPHERE)
            m.scale = Vector3(x=2 * dims[0], y=2 * dims[0], z=2 * dims[0])
        elif obstacle.kind == CYLINDER:
            m = b.add("obstacles", Marker.CYLINDER)
            m.scale = Vector3(x=2 * dims[1], y=2 * dims[1], z=dims[0])
        else:  # pragma: no cover -- the scene refuses other types
            continue
        m.pose = matrix_to_pose_msg(obstacle.pose)
        m.color = _color(palette.OBSTACLE_COLOR, 0.6)


def grasp_markers(
    result: Any,
    header: Header,
    hand: Any,
    scene: Scene | None = None,
    ns: str = MARKER_NAMESPACE,
    normal_length: float = 0.03,
) -> MarkerArray:
    """RViz markers of a planned grasp and its scene, in the request's frame.

    The array starts with a ``DELETEALL`` marker, so the previous grasp disappears; then
    ``<ns>/palm`` (CUBE), ``<ns>/links`` (a LINE_LIST per finger, finger colours),
    ``<ns>/fingertips`` (SPHERE_LIST, green in contact), ``<ns>/contacts`` (red spheres),
    ``<ns>/normals`` (ARROWs), the pre-grasp hand of the best candidate drawn faintly
    (``<ns>/pre_grasp_palm``, ``pre_grasp_links``, ``pre_grasp_fingertips``), one
    ``<ns>/approach`` ARROW per candidate (pre-grasp wrist -> grasp wrist, the best
    opaque), and the scene: ``<ns>/scene`` (support planes as thin boxes) and
    ``<ns>/obstacles``. A general hand (:class:`grasp_apso.model.hands.HandModel`) is
    drawn from its own collision geometry instead of the palm, links and fingertips:
    ``<ns>/hand`` and ``<ns>/pre_grasp_hand`` (a TRIANGLE_LIST per link, about
    :data:`HAND_TRIANGLES` and :data:`PRE_GRASP_TRIANGLES` triangles for the whole hand).
    """
    b = _Builder(header, ns)
    candidates = tuple(getattr(result, "candidates", ()) or ())
    wrist = np.asarray(result.wrist_pose, dtype=np.float64)
    general = _is_general(hand)
    if general:
        _general_hand(b, hand, wrist, np.asarray(result.joint_positions, float), "", 1.0, HAND_TRIANGLES)
    else:
        joints = np.asarray(result.joints, dtype=np.float64)  # (5, 4, 3) base, pip, dip, tip
        _hand(b, hand, wrist, joints, "", 1.0, {c.finger for c in result.contacts})
    if result.contacts:
        spheres = b.add("contacts", Marker.SPHERE_LIST)
        spheres.scale = Vector3(x=0.006, y=0.006, z=0.006)
        spheres.color = _color(_CONTACT_RGB)
        spheres.points = [_point(c.position) for c in result.contacts]
        for contact in result.contacts:
            arrow = b.add("normals", Marker.ARROW)
            start = np.asarray(contact.position, dtype=float)
            arrow.points = [_point(start), _point(start + normal_length * np.asarray(contact.normal, float))]
            arrow.scale = Vector3(x=0.002, y=0.004, z=0.006)  # shaft, head diameter, head length
            arrow.color = _color(_CONTACT_RGB)
    if candidates:
        best = candidates[0]
        pre_joints = np.asarray(best.pre_grasp_joints, dtype=float)
        if general:
            _general_hand(b, hand, np.asarray(best.pre_grasp_pose, float), np.asarray(best.pre_grasp_positions, float),
                          "pre_grasp_", palette.PRE_GRASP_ALPHA, PRE_GRASP_TRIANGLES)
        elif np.any(pre_joints):
            _hand(b, hand, np.asarray(best.pre_grasp_pose, float), pre_joints, "pre_grasp_",
                  palette.PRE_GRASP_ALPHA, None)
        for rank, c in enumerate(candidates):
            arrow = b.add("approach", Marker.ARROW)
            arrow.points = [_point(np.asarray(c.pre_grasp_pose)[:3, 3]), _point(np.asarray(c.wrist_pose)[:3, 3])]
            arrow.scale = Vector3(x=0.003, y=0.008, z=0.012)
            arrow.color = _color(palette.APPROACH_COLOR, 1.0 if rank == 0 else 0.4)
    scene_markers(b, scene)
    return b.array


def delete_all_markers(header: Header) -> MarkerArray:
    """A MarkerArray holding only a DELETEALL marker (clears the last grasp)."""
    clear = Marker()
    clear.header = header
    clear.action = Marker.DELETEALL
    return MarkerArray(markers=[clear])
