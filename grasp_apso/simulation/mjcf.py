"""MJCF (MuJoCo XML) of the hand, the object and the support planes.

Generated from the same :class:`~grasp_apso.model.hand.HandModel` as the planner and the
URDF (:mod:`grasp_apso.model.urdf`), with the same names and kinematics:

- ``palm``: a body welded to the world at ``wrist_pose`` (the palm frame in the planning
  frame = the MuJoCo world frame) holding the palm box (``palm_center``,
  ``palm_half_extents``).
- per finger f: bodies ``f_knuckle`` (hinge ``f_pivot``; frame = the planner's ``base``
  frame after the pivot, see the URDF module for the DH rewrite), ``f_proximal_link``
  (hinge ``f_proximal``), ``f_middle_link`` (hinge ``f_middle``), ``f_distal_link``
  (hinge ``f_distal``), each link a capsule of its ``link_radii`` from joint to joint,
  and the pad sphere ``f_pad`` (``pad_radius``) at the fingertip with a site ``f_tip``.
- eq. 1 coupling: an equality constraint ``f_middle = coupling_ratio * f_distal``.
- 15 position servos named after the driven joints (``f_distal``, ``f_proximal``,
  ``f_pivot``); ``ctrlrange`` = the joint limits.
- ``object``: a free body at ``pose``, one mesh geom per convex part
  (:mod:`grasp_apso.simulation.convex`), mass ``settings.object_mass`` at the object's
  centre of mass, inertia of the uniform-density solid (its hull when the mesh is open).
- each support plane ``a x + b y + c z + d = 0`` as an infinite plane geom whose +z is
  ``(a, b, c)`` normalised (solid below).

Collision filtering: hand geoms (contype 1, conaffinity 0) touch the object and the
planes but not each other; the object (1, 1) touches the hand and the planes; the planes
(0, 1) touch both. Contact parameters come from the settings (friction mu, condim,
solref/solimp); see :class:`grasp_apso.simulation.protocol.SimulationSettings`.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..model.hand import FINGER_NAMES, HandModel

from .settings import SimulationSettings

__all__ = ["scene_xml", "matrix_to_quat", "object_inertia", "plane_frame", "OBJECT_BODY"]

#: Name of the object's body (free joint ``object_free``).
OBJECT_BODY = "object"
#: Nominal mass of the body between the palm and a finger's first link (kg); MuJoCo
#: needs a positive mass for a moving body, and the knuckle has no geometry.
_KNUCKLE_MASS = 0.005
#: Density of the finger links (kg/m^3, about that of a hand).
_LINK_DENSITY = 1000.0


def _num(x: float) -> str:
    v = round(float(x), 10)
    return "0" if v == 0.0 else repr(v)


def _vec(v: Sequence[float]) -> str:
    return " ".join(_num(x) for x in v)


def matrix_to_quat(rot: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` (w >= 0) of a rotation matrix (3, 3)."""
    r = np.asarray(rot, dtype=float)
    t = np.trace(r)
    if t > 0:
        s = 2.0 * math.sqrt(t + 1.0)
        q = np.array([0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s])
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + r[i, i] - r[j, j] - r[k, k], 1e-300))
        q = np.empty(4)
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def _rx(alpha: float) -> np.ndarray:
    c, s = math.cos(alpha), math.sin(alpha)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def plane_frame(plane: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """The frame of a MuJoCo plane geom for ``a x + b y + c z + d = 0``: its point (3,)
    nearest the origin and the quaternion (w, x, y, z) turning +z onto ``(a, b, c)``."""
    a, b, c, d = (float(v) for v in plane)
    n = np.array([a, b, c])
    norm = float(np.linalg.norm(n))
    n_hat = n / norm
    point = -d / norm * n_hat
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, n_hat)
    sin, cos = float(np.linalg.norm(axis)), float(np.dot(z, n_hat))
    if sin < 1e-12:
        quat = np.array([1.0, 0, 0, 0]) if cos > 0 else np.array([0.0, 1.0, 0, 0])
    else:
        half = 0.5 * math.atan2(sin, cos)
        quat = np.concatenate([[math.cos(half)], math.sin(half) * axis / sin])
    return point, quat


def object_inertia(obj, mass: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass (3,) m and inertia tensor about it (3, 3) kg m^2 in the object frame.

    Uniform density scaled to ``mass``; the mesh's hull when the mesh is not watertight
    (as :class:`~grasp_apso.model.objects.GraspObject` computes the centre of mass).
    """
    mesh = obj.mesh if getattr(obj, "watertight", obj.mesh.is_watertight) else obj.mesh.convex_hull
    volume = float(mesh.volume)
    if not volume > 0:
        mesh = obj.mesh.convex_hull
        volume = float(mesh.volume)
    inertia = np.asarray(mesh.moment_inertia, dtype=float) * (mass / volume)
    inertia = 0.5 * (inertia + inertia.T)
    return np.asarray(obj.center_of_mass, dtype=float), inertia


def _hand_xml(hand: HandModel, wrist_pose: np.ndarray) -> list[str]:
    out = [f'    <body name="palm" pos="{_vec(wrist_pose[:3, 3])}" quat="{_vec(matrix_to_quat(wrist_pose[:3, :3]))}">',
           f'      <geom name="palm" class="hand" type="box" pos="{_vec(hand.palm_center)}" '
           f'size="{_vec(hand.palm_half_extents)}"/>']
    lo, hi, radii = np.asarray(hand.lower), np.asarray(hand.upper), np.asarray(hand.link_radii)
    ratio = float(hand.coupling_ratio)
    for f, finger in enumerate(FINGER_NAMES):
        k = 3 * f
        l1, l2, l3 = (float(x) for x in hand.link_lengths[f])
        base = np.asarray(hand.base_transforms[f], float)
        twist = float(hand.pivot_twist[f])
        mid_lo, mid_hi = sorted((ratio * lo[k], ratio * hi[k]))
        ind = "      "
        out += [
            f'{ind}<body name="{finger}_knuckle" pos="{_vec(base[:3, 3])}" '
            f'quat="{_vec(matrix_to_quat(base[:3, :3] @ _rx(twist)))}">',
            f'{ind}  <inertial pos="0 0 0" mass="{_num(_KNUCKLE_MASS)}" diaginertia="1e-7 1e-7 1e-7"/>',
            f'{ind}  <joint name="{finger}_pivot" axis="{_vec(_rx(-twist)[:, 2])}" range="{_num(lo[k + 2])} {_num(hi[k + 2])}"/>',
            f'{ind}  <body name="{finger}_proximal_link">',
            f'{ind}    <joint name="{finger}_proximal" axis="0 0 1" range="{_num(lo[k + 1])} {_num(hi[k + 1])}"/>',
            f'{ind}    <geom name="{finger}_proximal" class="hand" type="capsule" fromto="0 0 0 {_num(l1)} 0 0" size="{_num(radii[0])}"/>',
            f'{ind}    <body name="{finger}_middle_link" pos="{_num(l1)} 0 0">',
            f'{ind}      <joint name="{finger}_middle" axis="0 0 1" range="{_num(mid_lo)} {_num(mid_hi)}"/>',
            f'{ind}      <geom name="{finger}_middle" class="hand" type="capsule" fromto="0 0 0 {_num(l2)} 0 0" size="{_num(radii[1])}"/>',
            f'{ind}      <body name="{finger}_distal_link" pos="{_num(l2)} 0 0">',
            f'{ind}        <joint name="{finger}_distal" axis="0 0 1" range="{_num(lo[k])} {_num(hi[k])}"/>',
            f'{ind}        <geom name="{finger}_distal" class="hand" type="capsule" fromto="0 0 0 {_num(l3)} 0 0" size="{_num(radii[2])}"/>',
            f'{ind}        <geom name="{finger}_pad" class="hand" type="sphere" pos="{_num(l3)} 0 0" size="{_num(hand.pad_radius)}"/>',
            f'{ind}        <site name="{finger}_tip" pos="{_num(l3)} 0 0"/>',
            f"{ind}      </body>",
            f"{ind}    </body>",
            f"{ind}  </body>",
            f"{ind}</body>",
        ]
    out.append("    </body>")
    return out


def scene_xml(
    hand: HandModel,
    parts: Sequence[np.ndarray],
    center_of_mass: np.ndarray,
    inertia: np.ndarray,
    pose: np.ndarray,
    wrist_pose: np.ndarray,
    planes: np.ndarray | None,
    settings: "SimulationSettings",
) -> str:
    """The MJCF document of one grasp check.

    Parameters
    ----------
    hand : HandModel
    parts : sequence of (N_i, 3) float, m
        Convex parts of the object (vertices in the object frame).
    center_of_mass : (3,) float, m, object frame
    inertia : (3, 3) float, kg m^2, about the centre of mass, object axes
    pose : (4, 4) float
        Object -> planning (world) frame.
    wrist_pose : (4, 4) float
        Palm frame in the planning frame.
    planes : (K, 4) float or None
        Support planes ``a, b, c, d`` (solid side ``a x + b y + c z + d < 0``).
    settings : SimulationSettings

    Returns
    -------
    str
    """
    s = settings
    contact = (f'condim="{s.condim}" friction="{_num(s.friction)} {_num(s.torsional_friction)} '
               f'{_num(s.rolling_friction)}" solref="{_vec(s.solref)}" solimp="{_vec(s.solimp)}"')
    lines = [
        f'<mujoco model="{hand.name}_grasp_check">',
        '  <compiler angle="radian" autolimits="true" inertiafromgeom="auto"/>',
        f'  <option timestep="{_num(s.timestep)}" gravity="0 0 0" integrator="implicitfast" '
        f'cone="elliptic" impratio="{_num(s.impratio)}"/>',
        "  <default>",
        f'    <joint damping="{_num(s.joint_damping)}" armature="{_num(s.joint_armature)}"/>',
        f'    <geom {contact} density="{_num(_LINK_DENSITY)}"/>',
        f'    <position kp="{_num(s.kp)}" forcerange="{_num(-s.max_torque)} {_num(s.max_torque)}"/>',
        '    <default class="hand"><geom contype="1" conaffinity="0" rgba="0.85 0.72 0.62 1"/></default>',
        '    <default class="object"><geom contype="1" conaffinity="1" rgba="0.3 0.5 0.8 1"/></default>',
        '    <default class="support"><geom contype="0" conaffinity="1" rgba="0.6 0.6 0.6 1"/></default>',
        "  </default>",
        "  <asset>",
    ]
    for i, part in enumerate(parts):
        lines.append(f'    <mesh name="object_part{i}" vertex="{_vec(np.asarray(part, float).ravel())}"/>')
    lines += ["  </asset>", "  <worldbody>"]
    if planes is not None:
        for i, (a, b, c, d) in enumerate(np.asarray(planes, float).reshape(-1, 4)):
            point, quat = plane_frame((a, b, c, d))
            lines.append(f'    <geom name="support{i}" class="support" type="plane" pos="{_vec(point)}" '
                         f'quat="{_vec(quat)}" size="0 0 1"/>')
    lines += _hand_xml(hand, np.asarray(wrist_pose, float))
    pose = np.asarray(pose, float)
    inertia = np.asarray(inertia, float)
    full = (inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2])
    lines += [
        f'    <body name="{OBJECT_BODY}" pos="{_vec(pose[:3, 3])}" quat="{_vec(matrix_to_quat(pose[:3, :3]))}">',
        f'      <freejoint name="{OBJECT_BODY}_free"/>',
        f'      <inertial pos="{_vec(center_of_mass)}" mass="{_num(s.object_mass)}" fullinertia="{_vec(full)}"/>',
    ]
    for i in range(len(parts)):
        lines.append(f'      <geom name="object_part{i}" class="object" type="mesh" mesh="object_part{i}" '
                     f'density="0"/>')
    lines += ["    </body>", "  </worldbody>", "  <equality>"]
    for finger in FINGER_NAMES:
        lines.append(f'    <joint name="{finger}_coupling" joint1="{finger}_middle" joint2="{finger}_distal" '
                     f'polycoef="0 {_num(hand.coupling_ratio)} 0 0 0"/>')
    lines += ["  </equality>", "  <actuator>"]
    lo, hi = np.asarray(hand.lower), np.asarray(hand.upper)
    for f, finger in enumerate(FINGER_NAMES):
        for j, kind in enumerate(("distal", "proximal", "pivot")):
            idx = 3 * f + j
            lines.append(f'    <position name="{finger}_{kind}" joint="{finger}_{kind}" '
                         f'ctrlrange="{_num(lo[idx])} {_num(hi[idx])}"/>')
    lines += ["  </actuator>", "</mujoco>"]
    return "\n".join(lines) + "\n"
