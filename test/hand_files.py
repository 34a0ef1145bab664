"""The test hands: third-party description files from installed wheels, and an
Allegro-like hand that the project writes itself.

Installed as test dependencies (requirements-hands.txt, ``pip install --no-deps``), never
copied into the repository:

- the Shadow hand and the Adroit hand (gymnasium-robotics 1.4.2, MJCF);
- the Inspire and Fourier right hands (robosuite 1.5.2, MJCF).

:func:`write_allegro_like` writes a URDF of a four-finger hand with the dimensions of the
Allegro Hand v4 (right). Source of the dimensions: Wonik Robotics / SimLab,
``allegro_hand_ros`` (v4), ``allegro_hand_description/allegro_hand_description_right.urdf``
(BSD-licensed): the joint origins, axes and limits and the link box sizes below are its
values (metres, radians). Collision geometry: boxes and cylinders on some links and STL
meshes (rounded boxes written here by trimesh) on the others, fingertips as spheres or
meshes, so the URDF path meets primitives and meshes in one hand.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import trimesh

__all__ = ["installed_hand", "HANDS", "write_allegro_like", "urdf_actuated_joints"]

#: name -> (distribution module, path inside it)
HANDS = {
    "shadow": ("gymnasium_robotics", "envs/assets/hand/reach.xml"),
    "adroit": ("gymnasium_robotics", "envs/assets/adroit_hand/adroit_relocate.xml"),
    "inspire": ("robosuite", "models/assets/grippers/inspire_right_hand.xml"),
    "fourier": ("robosuite", "models/assets/grippers/fourier_right_hand.xml"),
    # Three-finger grippers of the same wheel: tendon-equality couplings, one finger opposing
    # two. Compiled on their own their joint ranges are read in degrees (MJCF's default;
    # robosuite compiles them inside a robot in radians), so they barely move: they test
    # structure, couplings and kinematics, not the closing motion.
    "robotiq_s": ("robosuite", "models/assets/grippers/robotiq_gripper_s.xml"),
    "jaco": ("robosuite", "models/assets/grippers/jaco_three_finger_gripper.xml"),
}


def urdf_actuated_joints(path: str | Path) -> list[str]:
    """A URDF's own non-fixed, non-mimic joints in file order, read with the standard
    library's XML parser (independent of the hand loader, to check it)."""
    import xml.etree.ElementTree as ET

    return [j.get("name") for j in ET.parse(path).getroot().iter("joint")
            if j.get("type") != "fixed" and j.find("mimic") is None]


def installed_hand(name: str) -> Path:
    """The description file of an installed test hand (its package is not imported: the
    files are all that is used)."""
    module, rel = HANDS[name]
    spec = importlib.util.find_spec(module)
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError(f"{module} is not installed: pip install --no-deps -r requirements-hands.txt")
    return Path(list(spec.submodule_search_locations)[0]) / rel


# (joint, parent, child, xyz, rpy, axis, (lower, upper)); finger links are boxes of
# (0.0196, 0.0275, length) centred at length / 2 along z.
_FINGERS = {
    "index": ((0.0, 0.0435, -0.001542), (-0.08726646, 0.0, 0.0), 0),
    "middle": ((0.0, 0.0, 0.0007), (0.0, 0.0, 0.0), 4),
    "ring": ((0.0, -0.0435, -0.001542), (0.08726646, 0.0, 0.0), 8),
}
_FINGER_LENGTHS = (0.0164, 0.054, 0.0384, 0.0267)
_FINGER_LIMITS = ((-0.47, 0.47), (-0.196, 1.61), (-0.174, 1.709), (-0.227, 1.618))
_THUMB = {
    "origin": ((-0.0182, 0.019333, -0.045987), (0.0, -1.65806278845, -1.5707963259)),
    "joints": (((-1.0, 0.0, 0.0), (0.263, 1.396)), ((0.0, 0.0, 1.0), (-0.105, 1.163)),
               ((0.0, 1.0, 0.0), (-0.189, 1.644)), ((0.0, 1.0, 0.0), (-0.162, 1.719))),
    "offsets": ((-0.027, 0.005, 0.0399), (0.0, 0.0, 0.0177), (0.0, 0.0, 0.0514)),
    "lengths": (None, 0.0177, 0.0514, 0.0423),
}
_TIP_RADIUS = 0.012
_WIDTH, _DEPTH = 0.0196, 0.0275


def _vec(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


def _rounded_box(extents, radius: float) -> trimesh.Trimesh:
    """A box with rounded edges (Minkowski sum of a smaller box and a sphere), as a hull."""
    inner = np.asarray(extents, float) / 2.0 - radius
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * inner
    ball = trimesh.creation.icosphere(subdivisions=2, radius=radius).vertices
    return trimesh.convex.convex_hull((corners[:, None, :] + ball[None]).reshape(-1, 3))


class _Writer:
    def __init__(self, folder: Path, meshes: set[str]):
        self.folder, self.meshes, self.lines = folder, meshes, []

    def link(self, name: str, shapes: list[tuple[str, tuple, tuple, tuple]]) -> None:
        """shapes: (kind, size, xyz, rpy); kind box | cylinder | sphere | rounded."""
        self.lines.append(f'  <link name="{name}">')
        for k, (kind, size, xyz, rpy) in enumerate(shapes):
            if kind == "rounded" or (kind == "box" and name in self.meshes):
                file = f"meshes/{name}_{k}.stl"
                (self.folder / "meshes").mkdir(exist_ok=True)
                _rounded_box(size, 0.004).export(self.folder / file)
                geometry = f'<mesh filename="package://allegro_like/{file}"/>'
            elif kind == "sphere" and name in self.meshes:
                file = f"meshes/{name}_{k}.stl"
                (self.folder / "meshes").mkdir(exist_ok=True)
                trimesh.creation.icosphere(subdivisions=3, radius=size[0]).export(self.folder / file)
                geometry = f'<mesh filename="{file}"/>'  # a plain relative path too
            elif kind == "box":
                geometry = f'<box size="{_vec(size)}"/>'
            elif kind == "cylinder":
                geometry = f'<cylinder radius="{size[0]:.9g}" length="{size[1]:.9g}"/>'
            else:
                geometry = f'<sphere radius="{size[0]:.9g}"/>'
            origin = f'<origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>'
            self.lines.append(f"    <collision>{origin}<geometry>{geometry}</geometry></collision>")
            # Visual meshes that do not exist: a loader must not need them.
            self.lines.append(f'    <visual>{origin}<geometry><mesh filename="package://allegro_like/'
                              f'visual/{name}.dae"/></geometry></visual>')
        self.lines.append("  </link>")

    def joint(self, name, kind, parent, child, xyz, rpy=(0, 0, 0), axis=None, limits=None, mimic=None):
        self.lines.append(f'  <joint name="{name}" type="{kind}">')
        self.lines.append(f'    <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>')
        self.lines.append(f'    <parent link="{parent}"/><child link="{child}"/>')
        if axis is not None:
            self.lines.append(f'    <axis xyz="{_vec(axis)}"/>')
        if limits is not None:
            self.lines.append(f'    <limit lower="{limits[0]}" upper="{limits[1]}" effort="0.7" velocity="7"/>')
        if mimic is not None:
            self.lines.append(f'    <mimic joint="{mimic[0]}" multiplier="{mimic[1]}" offset="0"/>')
        self.lines.append("  </joint>")


def write_allegro_like(folder: str | Path, mesh_links: str = "mixed", coupled: bool = False) -> Path:
    """Write ``allegro_like/allegro_like.urdf`` (+ STL meshes) under ``folder``.

    mesh_links : "mixed" (ring finger, thumb and the index tip as meshes; the rest boxes,
        cylinders and spheres), "none" (primitives only) or "all" (every link a mesh).
    coupled : the distal joint of each finger mimics the middle one (multiplier 1), as
        in hands with a linked distal joint.
    Returns the URDF path. Links: ``palm``; per finger ``<f>_base``, ``<f>_proximal``,
    ``<f>_middle``, ``<f>_distal``, ``<f>_tip``; joints ``<f>_joint_0..3``.
    """
    root = Path(folder) / "allegro_like"
    root.mkdir(parents=True, exist_ok=True)
    names = [f"{f}_{part}" for f in (*_FINGERS, "thumb") for part in ("base", "proximal", "middle", "distal", "tip")]
    if mesh_links == "all":
        meshes = set(names) | {"palm"}
    elif mesh_links == "mixed":
        meshes = {n for n in names if n.startswith(("ring", "thumb"))} | {"index_tip"}
    else:
        meshes = set()
    w = _Writer(root, meshes)
    # An encoding declaration, as many real URDFs have (lxml refuses it on a str).
    w.lines += ['<?xml version="1.0" encoding="utf-8"?>', '<robot name="allegro_like">']
    w.link("palm", [("box", (0.0408, 0.1130, 0.095), (-0.0093, 0.0, -0.0475), (0, 0, 0))])
    for finger, (xyz, rpy, first) in _FINGERS.items():
        parts = ("base", "proximal", "middle", "distal")
        parent = "palm"
        for k, (part, length, limits) in enumerate(zip(parts, _FINGER_LENGTHS, _FINGER_LIMITS)):
            child = f"{finger}_{part}"
            origin = (xyz, rpy) if k == 0 else ((0.0, 0.0, _FINGER_LENGTHS[k - 1]), (0, 0, 0))
            axis = (0.0, 0.0, 1.0) if k == 0 else (0.0, 1.0, 0.0)
            mimic = (f"{finger}_joint_2", 1.0) if coupled and k == 3 else None
            w.joint(f"{finger}_joint_{k}", "revolute", parent, child, *origin, axis, limits, mimic)
            shape = ("cylinder", (_DEPTH / 2.0, length), (0, 0, length / 2.0), (0, 0, 0)) if part == "middle" \
                else ("box", (_WIDTH, _DEPTH, length), (0, 0, length / 2.0), (0, 0, 0))
            w.link(child, [shape])
            parent = child
        w.joint(f"{finger}_tip_joint", "fixed", parent, f"{finger}_tip", (0.0, 0.0, _FINGER_LENGTHS[-1]))
        w.link(f"{finger}_tip", [("sphere", (_TIP_RADIUS,), (0, 0, 0), (0, 0, 0))])
    parent = "palm"
    for k, (part, (axis, limits)) in enumerate(zip(("base", "proximal", "middle", "distal"), _THUMB["joints"])):
        child = f"thumb_{part}"
        origin = _THUMB["origin"] if k == 0 else (_THUMB["offsets"][k - 1], (0, 0, 0))
        mimic = ("thumb_joint_2", 1.0) if coupled and k == 3 else None
        w.joint(f"thumb_joint_{k}", "revolute", parent, child, *origin, axis, limits, mimic)
        length = _THUMB["lengths"][k]
        if length is None:
            w.link(child, [("box", (0.0358, 0.034, 0.0455), (-0.0179, 0.009, 0.0145), (0, 0, 0))])
        else:
            w.link(child, [("box", (_WIDTH, _DEPTH, length), (0, 0, length / 2.0), (0, 0, 0))])
        parent = child
    w.joint("thumb_tip_joint", "fixed", parent, "thumb_tip", (0.0, 0.0, _THUMB["lengths"][-1]))
    w.link("thumb_tip", [("sphere", (_TIP_RADIUS,), (0, 0, 0), (0, 0, 0))])
    w.lines.append("</robot>")
    path = root / "allegro_like.urdf"
    path.write_text("\n".join(w.lines) + "\n", encoding="utf-8")
    return path
