"""The hand as a robot description: a URDF generated from the :class:`HandModel`.

:func:`hand_to_urdf` turns the hand description (``data/hand.yaml``) into URDF text;
:func:`write_urdf` writes it to ``<directory>/<hand.name>.urdf``. The console script
``grasp_apso_urdf`` (:mod:`grasp_apso.tools.urdf_cli`) does the same from a shell, and the
package installs the shipped hand's file as ``share/grasp_apso/urdf/apso_paper_hand.urdf``.

Structure (names are a contract: clients and robot_state_publisher depend on them)::

    wrist --wrist_z--> wrist_z_link --wrist_y--> wrist_y_link --wrist_x--> palm
    palm --f_pivot--> f_knuckle --f_proximal--> f_proximal_link
         --f_middle (mimic of f_distal, multiplier coupling_ratio)--> f_middle_link
         --f_distal--> f_distal_link --f_tip_joint (fixed)--> f_tip

for f in little, ring, middle, index, thumb. The actuated (non-mimic, non-fixed) joints
are exactly the 18 names of :data:`grasp_apso.model.hand.JOINT_NAMES`, so a reply's
JointState drives the model as it is.

- ``wrist`` is the base link: it sits at the wrist (palm-frame origin) position with the
  axes of the planning frame. ``wrist_z``, ``wrist_y``, ``wrist_x`` turn about z, y, x in
  that order, so the ``palm`` link's orientation in ``wrist`` is
  ``Rz(wrist_z) Ry(wrist_y) Rx(wrist_x)`` (:func:`~grasp_apso.model.hand.wrist_rotation`),
  and the ``palm`` frame is the planner's palm frame (``grasp_pose``).
- Finger kinematics reproduce :meth:`HandModel.finger_frames` exactly. The DH step of the
  pivot, ``Rz(theta_i3) Rx(alpha)``, is written as a joint whose origin is
  ``base @ Rx(alpha)`` and whose axis is ``Rx(-alpha) z``, so the ``f_knuckle`` frame *is*
  the planner's ``base`` frame (after the pivot); every flexion joint turns about its own
  z axis. The planner's ``pip``, ``dip`` and ``tip`` frames are the origins of the joints
  ``f_middle``, ``f_distal`` and ``f_tip_joint``; the ``f_tip`` link frame is the
  fingertip frame (pad centre).
- Joint limits are the description's (radians); the mimic joint's limits are the distal
  limits times the coupling ratio. Wrist limits are the planner's wrist-angle bounds.
- Collision geometry equals the planner's: the palm box, one capsule per link (URDF has
  no capsule: a cylinder plus a sphere at each end, radius ``link_radii``) from joint to
  joint along the link's x axis, and the pad sphere (``pad_radius``) on ``f_tip``. The
  visual geometry is the same shapes.
- Inertial elements are omitted: the file is for display and kinematics
  (robot_state_publisher, RViz, MoveIt); the physics model is the MJCF of
  :mod:`grasp_apso.simulation.mjcf`, generated from the same description.

The output is deterministic (fixed number formatting), so the committed file can be
compared with a fresh generation.
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import InputError
from .hand import FINGER_NAMES, HandModel

__all__ = ["hand_to_urdf", "write_urdf", "link_names", "rotation_to_rpy"]

#: Link names per finger after the pivot: knuckle (after the pivot), the three links, tip.
_LINK_SUFFIXES: tuple[str, ...] = ("knuckle", "proximal_link", "middle_link", "distal_link", "tip")
#: Effort (N m) and velocity (rad/s) written into the joint limits (URDF requires them;
#: they are nominal values for display and planning tools, not a hardware rating).
_EFFORT = 5.0
_VELOCITY = 3.0
_COLORS = {"palm": "0.80 0.65 0.55 1", "link": "0.85 0.72 0.62 1", "pad": "0.90 0.45 0.40 1"}


def _num(x: float) -> str:
    """A number as fixed, platform-independent text (1e-12 resolution, no ``-0``)."""
    v = round(float(x), 12)
    if v == 0.0:
        v = 0.0
    text = f"{v:.12f}".rstrip("0").rstrip(".")
    return text if text not in ("", "-") else "0"


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def rotation_to_rpy(rot: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of a rotation ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

    rot : (3, 3) float -> (roll, pitch, yaw) rad. At the pitch singularity (|pitch| = 90
    deg) the roll is set to 0 and the yaw carries the whole turn about z.
    """
    r = np.asarray(rot, dtype=float)
    if r.shape != (3, 3):
        raise InputError(f"rot: expected a (3, 3) rotation, got shape {r.shape}")
    sy = -r[2, 0]
    pitch = math.asin(max(-1.0, min(1.0, sy)))
    if math.hypot(r[0, 0], r[1, 0]) > 1e-9:
        roll = math.atan2(r[2, 1], r[2, 2])
        yaw = math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock
        roll = 0.0
        yaw = math.atan2(-r[0, 1], r[1, 1])
    return roll, pitch, yaw


def _origin(xyz=(0.0, 0.0, 0.0), rot: np.ndarray | None = None, rpy=None) -> str:
    if rpy is None:
        rpy = (0.0, 0.0, 0.0) if rot is None else rotation_to_rpy(rot)
    return f'<origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>'


def _rx(alpha: float) -> np.ndarray:
    c, s = math.cos(alpha), math.sin(alpha)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def link_names(finger: str) -> dict[str, str]:
    """Link names of one finger: keys ``knuckle, proximal_link, middle_link, distal_link, tip``."""
    return {suffix: f"{finger}_{suffix}" for suffix in _LINK_SUFFIXES}


def _capsule(length: float, radius: float, material: str) -> list[str]:
    """Visual and collision elements of a capsule from (0,0,0) to (length,0,0): a
    cylinder along x plus a sphere at each end."""
    parts = [
        (_origin((length / 2.0, 0.0, 0.0), rpy=(0.0, math.pi / 2.0, 0.0)),
         f'<cylinder radius="{_num(radius)}" length="{_num(length)}"/>'),
        (_origin((0.0, 0.0, 0.0)), f'<sphere radius="{_num(radius)}"/>'),
        (_origin((length, 0.0, 0.0)), f'<sphere radius="{_num(radius)}"/>'),
    ]
    return _shapes(parts, material)


def _shapes(parts: list[tuple[str, str]], material: str) -> list[str]:
    out = []
    for origin, geometry in parts:
        out += ["    <visual>", f"      {origin}", f"      <geometry>{geometry}</geometry>",
                f'      <material name="{material}"/>', "    </visual>"]
    for origin, geometry in parts:
        out += ["    <collision>", f"      {origin}", f"      <geometry>{geometry}</geometry>",
                "    </collision>"]
    return out


def _link(name: str, body: list[str] | None = None) -> list[str]:
    if not body:
        return [f'  <link name="{name}"/>']
    return [f'  <link name="{name}">', *body, "  </link>"]


def _joint(name: str, kind: str, parent: str, child: str, origin: str,
           axis: np.ndarray | tuple | None = None, limits: tuple[float, float] | None = None,
           mimic: tuple[str, float] | None = None) -> list[str]:
    out = [f'  <joint name="{name}" type="{kind}">', f"    {origin}",
           f'    <parent link="{parent}"/>', f'    <child link="{child}"/>']
    if axis is not None:
        out.append(f'    <axis xyz="{_vec(axis)}"/>')
    if limits is not None:
        out.append(f'    <limit lower="{_num(limits[0])}" upper="{_num(limits[1])}" '
                   f'effort="{_num(_EFFORT)}" velocity="{_num(_VELOCITY)}"/>')
    if mimic is not None:
        out.append(f'    <mimic joint="{mimic[0]}" multiplier="{_num(mimic[1])}" offset="0"/>')
    out.append("  </joint>")
    return out


def hand_to_urdf(hand: HandModel) -> str:
    """URDF text of a hand (see the module docstring for names and conventions).

    Parameters
    ----------
    hand : HandModel
        E.g. :func:`grasp_apso.model.hand.load_hand`.

    Returns
    -------
    str
        The URDF document (UTF-8 text, ends with a newline); lengths in metres, angles in
        radians.
    """
    if not isinstance(hand, HandModel):
        raise TypeError(f"hand: expected a HandModel, got {type(hand).__name__}")
    lo, hi = np.asarray(hand.lower, float), np.asarray(hand.upper, float)
    radii = np.asarray(hand.link_radii, float)
    lines = [
        '<?xml version="1.0"?>',
        "<!-- Generated by grasp_apso (grasp_apso.model.urdf.hand_to_urdf) from the hand "
        "description; do not edit: regenerate with grasp_apso_urdf. -->",
        f"<robot name={quoteattr(hand.name)}>",
    ]
    for name, rgba in _COLORS.items():
        lines.append(f'  <material name="{name}"><color rgba="{rgba}"/></material>')

    # ---- wrist: base link at the wrist position, planning-frame axes; Rz Ry Rx to the palm.
    lines += _link("wrist")
    wrist_chain = (("wrist_z", "wrist", "wrist_z_link", (0, 0, 1), 17),
                   ("wrist_y", "wrist_z_link", "wrist_y_link", (0, 1, 0), 16),
                   ("wrist_x", "wrist_y_link", "palm", (1, 0, 0), 15))
    for joint, parent, child, axis, index in wrist_chain:
        if child != "palm":
            lines += _link(child)
        lines += _joint(joint, "revolute", parent, child, _origin(), axis, (lo[index], hi[index]))
    palm_box = (_origin(hand.palm_center), f'<box size="{_vec(2.0 * np.asarray(hand.palm_half_extents))}"/>')
    lines += _link("palm", _shapes([palm_box], "palm"))

    # ---- fingers
    for f, finger in enumerate(FINGER_NAMES):
        names = link_names(finger)
        l1, l2, l3 = (float(x) for x in hand.link_lengths[f])
        base = np.asarray(hand.base_transforms[f], float)
        twist = float(hand.pivot_twist[f])
        # Rz(t3) Rx(alpha) == Rx(alpha) Rot(Rx(-alpha) z, t3): origin base @ Rx(alpha).
        pivot_rot = base[:3, :3] @ _rx(twist)
        pivot_axis = _rx(-twist)[:, 2]
        k = 3 * f  # q layout: distal, proximal, pivot
        lines += _joint(f"{finger}_pivot", "revolute", "palm", names["knuckle"],
                        _origin(base[:3, 3], pivot_rot), pivot_axis, (lo[k + 2], hi[k + 2]))
        lines += _link(names["knuckle"])
        lines += _joint(f"{finger}_proximal", "revolute", names["knuckle"], names["proximal_link"],
                        _origin(), (0, 0, 1), (lo[k + 1], hi[k + 1]))
        lines += _link(names["proximal_link"], _capsule(l1, radii[0], "link"))
        ratio = float(hand.coupling_ratio)
        mimic_limits = sorted((ratio * lo[k], ratio * hi[k]))
        lines += _joint(f"{finger}_middle", "revolute", names["proximal_link"], names["middle_link"],
                        _origin((l1, 0.0, 0.0)), (0, 0, 1), (mimic_limits[0], mimic_limits[1]),
                        mimic=(f"{finger}_distal", ratio))
        lines += _link(names["middle_link"], _capsule(l2, radii[1], "link"))
        lines += _joint(f"{finger}_distal", "revolute", names["middle_link"], names["distal_link"],
                        _origin((l2, 0.0, 0.0)), (0, 0, 1), (lo[k], hi[k]))
        lines += _link(names["distal_link"], _capsule(l3, radii[2], "link"))
        lines += _joint(f"{finger}_tip_joint", "fixed", names["distal_link"], names["tip"],
                        _origin((l3, 0.0, 0.0)))
        pad = (_origin(), f'<sphere radius="{_num(hand.pad_radius)}"/>')
        lines += _link(names["tip"], _shapes([pad], "pad"))
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def write_urdf(hand: HandModel, directory: str | Path) -> Path:
    """Write :func:`hand_to_urdf` of ``hand`` to ``<directory>/<hand.name>.urdf``.

    The directory is created when missing. Returns the path written. Raises
    :class:`~grasp_apso.errors.InputError` (a ``ValueError``) naming ``directory`` when it cannot be written, or ``hand.name`` when
    the name is not a plain file name.
    """
    name = str(hand.name)
    if not name or "/" in name or "\\" in name or name in (".", ".."):
        raise InputError(f"hand.name: {name!r} is not usable as a file name")
    out_dir = Path(directory)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{name}.urdf"
        path.write_text(hand_to_urdf(hand), encoding="utf-8")
    except OSError as exc:
        raise InputError(f"directory: cannot write {out_dir}: {exc.strerror or exc}") from exc
    return path
