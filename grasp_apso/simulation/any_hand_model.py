"""The MuJoCo model of a grasp check for any hand, from the hand's OWN description file
(DESIGN.md Part 3, "Simulation and database for any hand"), edited through ``mujoco.MjSpec``.

- The hand: an MJCF file as it is (its includes, defaults, meshes, joint equalities and
  tendons kept; visual meshes whose files are missing dropped as the loader drops them);
  a URDF through MuJoCo's own URDF import (``fusestatic`` off so every link stays a body,
  visuals discarded, mesh paths resolved as the hand loader resolves them; ``mimic``
  becomes MuJoCo joint equalities); the project's YAML through its generated URDF.
- Only the hand stays: the world's other bodies and geoms (tables, objects, floors, mocap
  targets of the file), its actuators, sensors and keyframes are removed.
- The hand root held at ``root_pose``: the joints between the world and the root link (a
  free joint, arm and wrist joints: ``hand.held_joints``) are removed and the bodies on
  that chain fixed where the held values put them, the top body placed so that the root
  body is at ``root_pose``; the hand's moving joints start from the root, welded to the
  world without a soft constraint.
- No hand self-contacts: the hand's geoms collide with the object and the scene only
  (MuJoCo collides a mesh as its convex hull, far beyond a concave link; the planner
  checks the hand against itself on its exact geometry): :func:`_no_hand_self_contacts`.
- Compiled once per (object, hand, scene, settings) and cached (MuJoCo compiles a hand of
  many meshes in 0.5 s); each grasp moves a copy (the top body, the object's free joint).
- Position servos (gain ``settings.kp``, raised on joints the file damps more so that the
  servo's time constant stays ``joint_damping / kp``, and times ``hand.servo_weight`` on a
  coupled leader, so that it holds each joint it drives as stiffly; torque within
  ``settings.max_torque``, times ``hand.servo_force_scale`` on a leader of URDF mimic
  joints, so that the most loaded joint it drives bears that torque; an MJCF's tendon or
  equality keeps its one actuator's limit) on the actuated joints, in
  ``hand.actuated_joints`` order (``data.ctrl`` = targets, rad or m).
  Joint armature and damping are raised to at least the settings' values: a servo is
  stable at the protocol's 4 ms step only with enough inertia on the joint (a bare
  fingertip of 1e-6 kg m^2 under 2 N m/rad would need a 0.7 ms step); joint friction is
  capped at ``settings.max_joint_friction``, which the servos overcome, and damping at
  ``settings.max_joint_damping``.
- The object: a free body of convex parts (:mod:`.convex`), mass ``settings.object_mass``
  at its centre of mass with the uniform-density inertia; its geoms and the scene's
  geoms collide with every hand geom that collides at all (all contype/conaffinity bits)
  and carry the contact parameters (friction mu, condim, solref, solimp) with a higher
  ``priority`` than any hand geom, so MuJoCo uses them for every contact.
- The scene (support planes, BOX/SPHERE/CYLINDER obstacles) as static world geoms; the
  protocol switches their contacts off before the disturbances.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, SimulationError
from ..model.hands.urdf_loader import unphysical_inertia
from ..model.scene import BOX, CYLINDER, SPHERE
from .mjcf import matrix_to_quat, object_inertia, plane_frame
from .settings import SimulationSettings

__all__ = ["AnyHandScene", "build_any_hand_scene", "OBJECT_BODY", "SCENE_GEOM_PREFIX"]

#: Name of the object's body (free joint ``<OBJECT_BODY>_free``).
OBJECT_BODY = "grasp_object"
#: Names of the scene's geoms (support planes ``<prefix>plane<i>``, obstacles ``<prefix>obstacle<i>``).
SCENE_GEOM_PREFIX = "scene_"
#: Every contype / conaffinity bit MuJoCo has (int32, sign bit excluded).
_ALL_BITS = (1 << 31) - 1
#: A hand geom's contype and conaffinity: no common bit (hand geoms never collide with
#: one another), each within _ALL_BITS (they collide with the object and the scene).
_HAND_TYPE, _HAND_AFFINITY = 1, 2
#: Lower bounds of a hand body's mass (kg) and inertia (kg m^2) (MuJoCo's boundmass /
#: boundinertia).
_MIN_MASS = 0.001
_MIN_INERTIA = 1e-8


@dataclass(frozen=True, eq=False)
class AnyHandScene:
    """A compiled check: ``model`` (mujoco.MjModel) and ``data`` (mujoco.MjData, at rest).

    Attributes
    ----------
    object_body, root_body : int
        Body ids of the object and of the hand's root link.
    scene_geoms : tuple of int
        Geom ids of the support planes and obstacles.
    joint_qpos : tuple of (int, int)
        ``(qpos address, index in hand.joint_names)`` of every hand joint the model moves.
    """

    model: object
    data: object
    object_body: int
    root_body: int
    scene_geoms: tuple[int, ...]
    joint_qpos: tuple[tuple[int, int], ...]


@dataclass(frozen=True, eq=False)
class _Template:
    """A compiled check with the hand's top body and the object at the identity: moved
    per grasp on a copy (``top_to_root`` (4, 4): the root body in the top body's frame)."""

    model: object
    top_body: int
    top_to_root: np.ndarray
    object_body: int
    object_qpos: int
    root_body: int
    scene_geoms: tuple[int, ...]
    joint_qpos: tuple[tuple[int, int], ...]


def _pose(pos, quat) -> np.ndarray:
    import mujoco

    out = np.eye(4)
    m = np.empty(9)
    mujoco.mju_quat2Mat(m, np.asarray(quat, float))
    out[:3, :3] = m.reshape(3, 3)
    out[:3, 3] = pos
    return out


def _set_pose(body, pose: np.ndarray) -> None:
    import mujoco

    body.pos = pose[:3, 3]
    body.quat = matrix_to_quat(pose[:3, :3])
    body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT


def _urdf_spec(text: str, base: Path):
    """MuJoCo's URDF import of ``text``, mesh paths resolved against ``base``."""
    import mujoco

    from ..model.hands.urdf_loader import resolve_mesh_path

    root = ET.fromstring(text.encode("utf-8") if isinstance(text, str) else text)
    for old in root.findall("mujoco"):
        root.remove(old)
    _repair_inertias(root)
    ext = ET.SubElement(root, "mujoco")
    ET.SubElement(ext, "compiler", fusestatic="false", discardvisual="true", strippath="false")
    spec = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
    for mesh in spec.meshes:
        if mesh.file:
            path = resolve_mesh_path(mesh.file, base)
            mesh.file = str(path if path.suffix.lower() in _MUJOCO_MESHES else _decodable_copy(path))
    return spec


_INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


def _repair_inertias(root) -> list[str]:
    """Drop the products of inertia of every link ``<inertia>`` with a negative principal
    moment (:func:`~grasp_apso.model.hands.urdf_loader.unphysical_inertia`): off-diagonal
    terms that no inertia with that diagonal can have (a physical one has ``|ixy| <=
    sqrt(ixx iyy)``), as a CAD export's unit slip gives them (the Allegro V5's ``link_2_0``:
    ``ixy`` about 1000 times its moments). MuJoCo refuses to compile such a link ("inertia
    must have positive eigenvalues") and ``balanceinertia`` does not mend it; the moments
    (the diagonal, at least :data:`_MIN_INERTIA`) are kept, then balanced by MuJoCo as any
    other link's. Keeping the principal axes instead (the negative moment raised) keeps a
    moment 1000 times too large: the V5 then held 4 of 21 best grasps. A physical inertia
    with a principal moment below :data:`_MIN_INERTIA` (zero: MuJoCo refuses that too) gets
    that moment raised to it about its principal axes, as ``boundinertia`` raises the
    others. Any other inertia is left as written. Returns the links changed (the hand
    loader notes the unphysical ones: :mod:`grasp_apso.model.hands.urdf_loader`)."""
    changed = []
    for link in root.findall("link"):
        element = link.find("inertial/inertia")
        if element is None:
            continue
        try:
            xx, xy, xz, yy, yz, zz = (float(element.get(k, "0")) for k in _INERTIA_KEYS)
        except ValueError:
            continue  # MuJoCo names the attribute it cannot read
        matrix = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        if not np.all(np.isfinite(matrix)) or not matrix.any():
            continue  # (not finite: MuJoCo names it; all zero: MuJoCo bounds it as a massless link's)
        if unphysical_inertia(matrix):
            values = (xx, 0.0, 0.0, yy, 0.0, zz)
        else:
            moments, axes = np.linalg.eigh(matrix)
            if moments[0] >= _MIN_INERTIA:
                continue
            # A principal moment of zero (a CAD export rounding to 1e-6: DexHand's finger
            # links, "1e-06 1e-06 0.0"): MuJoCo refuses it before ``boundinertia`` raises
            # it, so raised here as that would, about the same principal axes.
            full = (axes * np.maximum(moments, _MIN_INERTIA)) @ axes.T
            values = (full[0, 0], full[0, 1], full[0, 2], full[1, 1], full[1, 2], full[2, 2])
        for key, value in zip(_INERTIA_KEYS, values):
            element.set(key, repr(float(max(value, _MIN_INERTIA) if key in ("ixx", "iyy", "izz") else value)))
        changed.append(link.get("name", ""))
    return changed


#: Mesh files MuJoCo decodes itself; others (a ROS URDF's COLLADA files) go as STL copies.
_MUJOCO_MESHES = (".stl", ".obj", ".msh")


def _decodable_copy(path: Path) -> Path:
    """An STL copy of a collision mesh MuJoCo cannot decode, read as the hand loader reads
    it (units in metres), kept under the cache root by the file's content hash."""
    from .. import tunables
    from ..cache import DISK_LIMITS, cache_root, prune_folder, touch, write_atomically
    from ..model.hands.urdf_loader import read_collision_mesh

    if not path.is_file():
        return path  # MuJoCo names the missing file
    digest = hashlib.sha256(b"stl-v1;" + path.read_bytes()).hexdigest()
    out = cache_root() / "sim_meshes" / f"{digest}.stl"
    if out.is_file():
        touch(out)
    else:
        mesh = read_collision_mesh(path, f"simulation: mesh {path.name}", int(tunables.default("max_hand_file_bytes")))
        error = write_atomically(out, lambda handle: handle.write(mesh.export(file_type="stl")))
        if error is not None:
            raise SimulationError(f"simulation: MuJoCo reads no {path.suffix} mesh, and the STL copy of {path.name} "
                                  f"cannot be written under the cache root ({error})")
        prune_folder(out.parent, DISK_LIMITS["sim_meshes"], keep=out, pattern="*.stl")
    return out


def _hand_spec(hand):
    """The hand's own description as an ``MjSpec`` (unnamed bodies named ``body<id>`` as
    the hand loader names them)."""
    path = Path(hand.source_path) if hand.source_path else None
    if path is None or not path.is_file():
        raise InputError(f"hand: the description file of hand {hand.name!r} is not available "
                         f"({hand.source_path or 'built from data'}); load it with load_hand(path)", "hand")
    suffix = path.suffix.lower()
    if suffix == ".xml":
        from ..model.hands.mjcf_loader import open_spec

        spec = open_spec(path, [])
    elif suffix == ".urdf":
        spec = _urdf_spec(path.read_text(encoding="utf-8"), path.parent)
    else:  # the project's YAML: its generated URDF, as the loader reads it
        from ..model.hand import load_hand as load_paper_hand
        from ..model.urdf import hand_to_urdf

        spec = _urdf_spec(hand_to_urdf(load_paper_hand(path)), path.parent)
    for i, body in enumerate(spec.bodies):
        if not body.name:
            body.name = f"body{i}"
    # Links without mass (a URDF's frame links) cannot move in MuJoCo: a floor of 1 g and
    # 1e-8 kg m^2 (below any real finger link: bodies that have mass keep theirs).
    spec.compiler.boundmass = max(float(spec.compiler.boundmass), _MIN_MASS)
    spec.compiler.boundinertia = max(float(spec.compiler.boundinertia), _MIN_INERTIA)
    # Real URDFs carry inertias that violate A + B >= C (dex-urdf's Allegro: link_1.0),
    # which MuJoCo refuses to compile; it balances them when asked (the diagonal raised
    # to the nearest physical one, masses and frames kept).
    spec.compiler.balanceinertia = True
    return spec


def _keep_only_the_hand(spec, top_name: str) -> None:
    """Remove what is not the hand: other world bodies and world geoms, actuators,
    sensors, keyframes, and the constraints and contact pairs that named removed bodies."""
    for body in list(spec.worldbody.bodies):
        if body.name != top_name:
            spec.delete(body)
    for geom in list(spec.worldbody.geoms):
        spec.delete(geom)
    for group in (spec.actuators, spec.sensors, spec.keys):
        for element in list(group):
            spec.delete(element)
    bodies = {b.name for b in spec.bodies}
    geoms = {g.name for g in spec.geoms}
    import mujoco

    for eq in list(spec.equalities):
        if eq.type in (mujoco.mjtEq.mjEQ_WELD, mujoco.mjtEq.mjEQ_CONNECT) and eq.objtype == mujoco.mjtObj.mjOBJ_BODY \
                and not ({eq.name1, eq.name2} - {""} <= bodies):
            spec.delete(eq)
    for ex in list(spec.excludes):
        if not {ex.bodyname1, ex.bodyname2} <= bodies:
            spec.delete(ex)
    for pair in list(spec.pairs):
        if not {pair.geomname1, pair.geomname2} <= geoms:
            spec.delete(pair)


def _set_joints(model, data, values) -> None:
    """Set the hinge and slide joints of ``values`` ((name, value) pairs, rad or m) in
    ``data.qpos``; names the model lacks are skipped. The joint types are compared as
    ints: a numpy int is never found ``in`` a tuple of MuJoCo's enums, and the values were
    once never set that way."""
    import mujoco

    settable = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    for name, value in values:
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j >= 0 and int(model.jnt_type[j]) in settable:
            data.qpos[model.jnt_qposadr[j]] = value


def _no_hand_self_contacts(spec) -> None:
    """The hand's geoms collide with the object and the scene only (contype
    :data:`_HAND_TYPE`, conaffinity :data:`_HAND_AFFINITY`; the object's and the scene's
    geoms have every bit), not with one another; the file's visual geoms (no bits) stay
    out. Why: MuJoCo collides a mesh as its convex hull, and a concave link's hull reaches
    far beyond it: DexHand's URDF (``iotdesignshop/dexhand_description``) at its planned
    grasp of the orange had its thumb base 21 mm inside a palm part's hull and its middle
    and index phalanges 7.6 mm inside each other's, which held the index finger at 1 degree
    of its 22.5 and no finger reached the object (its best grasps held 3 of 21 in this
    check, 13 with DexGraspBench's parameters; without these contacts 13 and 18). The
    planner checks the hand against itself on its exact geometry (python-fcl) at the grasp
    and the pre-grasp, and the closing moves between them; so the simulation leaves those
    contacts out, as it left out before, pair by pair, the links the file has overlapping
    in the open posture (a thumb base modelled inside the palm box) and a link against the
    palm it hinges on (LEAP's thumb base, 1.9 mm inside its palm with a contact force of
    1e15 N)."""
    for geom in spec.geoms:
        if int(geom.contype) or int(geom.conaffinity):
            geom.contype, geom.conaffinity = _HAND_TYPE, _HAND_AFFINITY


def _hold_root(spec, hand) -> np.ndarray:
    """Fix the chain from the world to the root link at the held joint values (its
    joints removed), the top body at the world origin. Returns the root body's pose in
    the top body's frame (4, 4)."""
    import mujoco

    chain = [spec.body(hand.root_link)]
    if chain[0] is None:
        raise SimulationError(f"simulation: the root link {hand.root_link!r} is not a body of the compiled hand")
    while chain[-1].parent is not None and chain[-1].parent.name != "world":
        chain.append(chain[-1].parent)
    chain.reverse()  # top body first
    try:
        model = spec.compile()
    except Exception as exc:
        raise SimulationError(f"simulation: MuJoCo cannot compile hand {hand.name!r}: {exc}") from exc
    data = mujoco.MjData(model)
    _set_joints(model, data, hand.held_joints.items())
    mujoco.mj_kinematics(model, data)
    world = [_pose(data.xpos[model.body(b.name).id], data.xquat[model.body(b.name).id]) for b in chain]
    for k in range(1, len(chain)):
        _set_pose(chain[k], np.linalg.inv(world[k - 1]) @ world[k])
    top_to_root = np.linalg.inv(world[0]) @ world[-1]
    _set_pose(chain[0], np.eye(4))
    chain[0].mocap = False
    held = {j.name for body in chain for j in body.joints}
    _drop_users_of(spec, model, held)
    for body in chain:
        for joint in list(body.joints):
            spec.delete(joint)
    return top_to_root


def _drop_users_of(spec, model, joints: set[str]) -> None:
    """Remove the tendons that wrap a removed joint (the file's wrist tendons), and the
    equalities that name a removed joint or tendon."""
    import mujoco

    tendons = list(spec.tendons)
    gone = set()
    for t in range(model.ntendon):
        adr, num = model.tendon_adr[t], model.tendon_num[t]
        wraps = [int(model.wrap_objid[w]) for w in range(adr, adr + num)
                 if model.wrap_type[w] == mujoco.mjtWrap.mjWRAP_JOINT]
        if any(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) in joints for j in wraps):
            gone.add(tendons[t].name or f"tendon{t}")
            spec.delete(tendons[t])
    for eq in list(spec.equalities):
        if eq.type == mujoco.mjtEq.mjEQ_JOINT and {eq.name1, eq.name2} & joints \
                or eq.type == mujoco.mjtEq.mjEQ_TENDON and {eq.name1, eq.name2} & gone:
            spec.delete(eq)


def _contact(geom, settings: SimulationSettings, priority: int) -> None:
    geom.contype = _ALL_BITS
    geom.conaffinity = _ALL_BITS
    geom.priority = priority
    geom.condim = settings.condim
    geom.friction = [settings.friction, settings.torsional_friction, settings.rolling_friction]
    geom.solref = list(settings.solref)
    geom.solimp = [*settings.solimp, 0.5, 2.0]
    geom.margin = 0.0
    geom.gap = 0.0


def _add_scene(spec, scene, settings: SimulationSettings, priority: int) -> list[str]:
    import mujoco

    names = []
    if scene is None:
        return names
    for i, plane in enumerate(np.asarray(scene.planes, float).reshape(-1, 4)):
        point, quat = plane_frame(plane)
        g = spec.worldbody.add_geom(name=f"{SCENE_GEOM_PREFIX}plane{i}", type=mujoco.mjtGeom.mjGEOM_PLANE, pos=point,
                                    quat=quat, size=[0.0, 0.0, 1.0])
        _contact(g, settings, priority)
        names.append(g.name)
    for i, ob in enumerate(scene.obstacles):
        dims = [float(d) for d in ob.dimensions]
        if ob.kind == BOX:
            kind, size = mujoco.mjtGeom.mjGEOM_BOX, [d / 2.0 for d in dims]
        elif ob.kind == SPHERE:
            kind, size = mujoco.mjtGeom.mjGEOM_SPHERE, [dims[0], 0.0, 0.0]
        elif ob.kind == CYLINDER:
            kind, size = mujoco.mjtGeom.mjGEOM_CYLINDER, [dims[1], dims[0] / 2.0, 0.0]
        else:  # Scene validates kinds; a new kind must be added here
            raise InputError(f"scene.obstacles[{i}]: kind {ob.kind} is not simulated", "scene")
        pose = np.asarray(ob.pose, float)
        g = spec.worldbody.add_geom(name=f"{SCENE_GEOM_PREFIX}obstacle{i}", type=kind, size=size, pos=pose[:3, 3],
                                    quat=matrix_to_quat(pose[:3, :3]))
        _contact(g, settings, priority)
        names.append(g.name)
    return names


def _add_servos(spec, hand, settings: SimulationSettings) -> None:
    import mujoco

    for joint in spec.joints:
        joint.armature = max(float(np.max(joint.armature)), settings.joint_armature)
        joint.damping = np.clip(np.asarray(joint.damping, float), settings.joint_damping,
                                max(settings.max_joint_damping, settings.joint_damping))
        # (settings.max_joint_friction: a friction the servo cannot overcome freezes the joint)
        joint.frictionloss = min(float(joint.frictionloss), settings.max_joint_friction)
    # The servo's time constant damping / kp is the settings' (0.05 s) on a joint whose
    # file damps it more (robosuite's Inspire and Fourier hands: 1 N m s/rad), else the
    # fingers would lag their targets by 0.2 rad after the closing.
    tau = settings.joint_damping / settings.kp
    for i, name in enumerate(hand.actuated_joints):
        joint = spec.joint(name)
        if joint is None:
            raise SimulationError(f"simulation: actuated joint {name!r} is not a joint of the compiled hand")
        # (no damping set: no time constant to keep, the gain as set)
        kp = max(settings.kp, float(np.max(joint.damping)) / tau) if tau > 0.0 else settings.kp
        # A coupled leader's servo as stiff on each joint it drives as an uncoupled joint's
        # (hand.servo_weight; the squeeze weights its gains alike): held in its own angle, the
        # LinkerHand L10's thumb (one servo, gears 2.24 and 2.38) gave way in the squeeze.
        kp *= float(hand.servo_weight[i])
        a = spec.add_actuator(name=f"servo:{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.dyntype = mujoco.mjtDyn.mjDYN_NONE
        a.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        a.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        gain = np.zeros(len(a.gainprm))
        gain[0] = kp
        bias = np.zeros(len(a.biasprm))
        bias[1] = -kp
        a.gainprm, a.biasprm = gain, bias
        a.gear = [1.0, 0, 0, 0, 0, 0]
        a.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        # Its torque limit alike: held to max_torque in its own angle, the L10's thumb servo
        # saturated under DexGraspBench's gain (5) while the other fingers pushed on.
        limit = settings.max_torque * float(hand.servo_force_scale[i])
        a.forcerange = [-limit, limit]


def _add_object(spec, parts, settings: SimulationSettings, priority: int) -> None:
    import mujoco

    body = spec.worldbody.add_body(name=OBJECT_BODY)
    body.add_freejoint(name=f"{OBJECT_BODY}_free")
    body.simple = 0  # its inertia is replaced after compiling (MuJoCo's body/simple="false")
    for i, part in enumerate(parts):
        mesh = spec.add_mesh(name=f"{OBJECT_BODY}_part{i}")
        mesh.scale = [1.0, 1.0, 1.0]  # not the file's default (the ORCA hand's: 0.001, its STL files in mm)
        mesh.uservert = np.asarray(part, float).ravel()
        g = body.add_geom(name=f"{OBJECT_BODY}_part{i}", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mesh.name)
        g.density = 1000.0  # replaced by the object's own inertia after compiling
        _contact(g, settings, priority)


def _set_object_inertia(model, data, body: int, obj, mass: float) -> None:
    """The object's mass at its centre of mass with its inertia (whatever the file's
    ``inertiafromgeom`` says), then MuJoCo's derived constants recomputed."""
    import mujoco

    com, inertia = object_inertia(obj, mass)
    values, vectors = np.linalg.eigh(inertia)
    if np.linalg.det(vectors) < 0:
        vectors[:, 0] *= -1.0
    model.body_mass[body] = mass
    model.body_ipos[body] = com
    model.body_iquat[body] = matrix_to_quat(vectors)
    model.body_inertia[body] = np.maximum(values, 1e-12)
    mujoco.mj_setConst(model, data)


def _scene_key(scene) -> tuple:
    if scene is None:
        return ()
    planes = np.asarray(scene.planes, float).reshape(-1, 4)
    return (planes.tobytes(), tuple((o.kind, tuple(o.dimensions), np.asarray(o.pose, float).tobytes())
                                    for o in scene.obstacles))


def _compile_template(hand, obj, parts, scene, settings: SimulationSettings) -> _Template:
    import mujoco

    spec = _hand_spec(hand)
    root = spec.body(hand.root_link)
    if root is None:
        raise SimulationError(f"simulation: the root link {hand.root_link!r} is not a body of {hand.source_path}")
    top = root
    while top.parent is not None and top.parent.name != "world":
        top = top.parent
    top_name = top.name
    _keep_only_the_hand(spec, top_name)
    top_to_root = _hold_root(spec, hand)
    _no_hand_self_contacts(spec)
    _add_servos(spec, hand, settings)
    priority = 1 + max([int(g.priority) for g in spec.geoms] + [0])
    _add_object(spec, parts, settings, priority)
    scene_names = _add_scene(spec, scene, settings, priority)
    opt = spec.option
    opt.timestep = settings.timestep
    opt.gravity = [0.0, 0.0, 0.0]
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    opt.impratio = settings.impratio
    try:
        model = spec.compile()
    except Exception as exc:
        raise SimulationError(f"simulation: MuJoCo could not build the scene of hand {hand.name!r}: "
                              f"{str(exc).splitlines()[0][:300]}") from exc
    body = model.body(OBJECT_BODY).id
    _set_object_inertia(model, mujoco.MjData(model), body, obj, settings.object_mass)
    joint_qpos = []
    for index, name in enumerate(hand.joint_names):
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j >= 0:
            joint_qpos.append((int(model.jnt_qposadr[j]), index))
    top_to_root.flags.writeable = False
    return _Template(model=model, top_body=model.body(top_name).id, top_to_root=top_to_root, object_body=body,
                     object_qpos=int(model.jnt_qposadr[model.body_jntadr[body]]),
                     root_body=model.body(hand.root_link).id,
                     scene_geoms=tuple(model.geom(n).id for n in scene_names), joint_qpos=tuple(joint_qpos))


def build_any_hand_scene(hand, obj, parts, obj_pose: np.ndarray, root_pose: np.ndarray, scene,
                         settings: SimulationSettings) -> AnyHandScene:
    """The check of one grasp (see the module docstring), from a compiled template cached
    per (object, hand, scene, settings) (:func:`grasp_apso.cache.cached`, "sim_model"):
    a copy of it with the hand's top body placed so that the root is at ``root_pose`` and
    the object's free joint at ``obj_pose``.

    Parameters
    ----------
    hand : grasp_apso.model.hands.HandModel (loaded from a file: ``source_path``)
    obj : GraspObject
    parts : sequence of (N_i, 3) float, m: the object's convex parts, object frame
    obj_pose, root_pose : (4, 4) float: the object and the hand's root link in the world
        (planning) frame
    scene : grasp_apso.model.scene.Scene or None, world frame
    settings : SimulationSettings
    """
    import copy

    import mujoco

    from ..cache import cached

    key = (obj.mesh_hash, len(parts), hand.source_hash, hand.source_path, _scene_key(scene), settings)
    template = cached("sim_model", key, lambda: _compile_template(hand, obj, parts, scene, settings),
                      nbytes=lambda v: int(mujoco.mj_sizeModel(v.model)))
    model = copy.copy(template.model)
    top = np.asarray(root_pose, float) @ np.linalg.inv(template.top_to_root)
    model.body_pos[template.top_body] = top[:3, 3]
    model.body_quat[template.top_body] = matrix_to_quat(top[:3, :3])
    data = mujoco.MjData(model)
    adr = template.object_qpos
    data.qpos[adr:adr + 3] = obj_pose[:3, 3]
    data.qpos[adr + 3:adr + 7] = matrix_to_quat(obj_pose[:3, :3])
    return AnyHandScene(model=model, data=data, object_body=template.object_body, root_body=template.root_body,
                        scene_geoms=template.scene_geoms, joint_qpos=template.joint_qpos)
