"""A hand from an MJCF file, compiled by MuJoCo's own compiler (includes, defaults,
mesh directories resolved; meshes as MuJoCo places them).

- Bodies become links (an unnamed body is ``body<id>``), hinge/slide joints their
  motions in order (``qpos0`` is the reference of each). The hand is the world body's
  child subtree with the most hinge and slide joints; other subtrees (tables, objects,
  mocap bodies) are ignored, with a note. A free joint at the top of the hand is
  ignored (the root pose is the planner's); a ball joint is refused. A base fused into the
  world body (as MuJoCo writes a URDF's fixed base link) is lifted into a body first.
- Collision geometry: geoms that collide (``contype`` or ``conaffinity`` non-zero);
  planes and height fields are not hand geometry. Ellipsoids become meshes.
- Couplings: joint equalities (``polycoef``: the linear part; higher terms noted) and
  fixed tendons over two joints whose length is held in a narrow range (a ``limited``
  tendon, as the Shadow hand of gymnasium-robotics couples its distal joints) or by a
  tendon equality. The follower is the joint without an actuator (else the distal one).
  A limited tendon's coupling is the middle of its range with the rest as the follower's
  ``slack``; the loaded hand follows the edge the closing drags it along
  (:func:`.description.lagging_couplings`).
- A visual mesh whose file is missing is dropped before compiling (with a note); a
  missing collision mesh is an error naming it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

from ...errors import HandDescriptionError
from .description import RawHand, RawJoint, RawLink, rigid
from .file_search import find_in_tree
from .geometry import LinkGeometry
from .model import Coupling

__all__ = ["read_mjcf", "open_spec"]

#: A limited fixed tendon couples its two joints when its range is at most this
#: fraction of the length span its joints' ranges allow.
_NARROW_TENDON = 0.25


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def open_spec(path: Path, notes: list[str], max_mesh_bytes: int | None = None):
    """The file's ``mujoco.MjSpec`` with its visual-only meshes whose files are missing
    removed and the materials it uses without defining them left off its geoms (noted in
    ``notes``); a missing collision mesh, or one over ``max_mesh_bytes`` (default: the
    tunable ``max_hand_file_bytes``), is an error naming it."""
    if max_mesh_bytes is None:
        from ... import tunables

        max_mesh_bytes = int(tunables.default("max_hand_file_bytes"))
    import mujoco

    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as exc:
        raise HandDescriptionError(f"hand_description: {path.name} is not a valid MJCF file "
                                   f"({str(exc).splitlines()[0][:200]})", field="hand_description") from None
    meshdir = Path(spec.modelfiledir or path.parent) / (spec.meshdir or "")
    for mesh in list(spec.meshes):
        if not mesh.file:
            continue
        file = Path(mesh.file) if Path(mesh.file).is_absolute() else meshdir / mesh.file
        if file.is_file():
            if file.stat().st_size > max_mesh_bytes:
                raise HandDescriptionError(f"mesh {mesh.name}: {file.name} is over the size limit "
                                           f"({file.stat().st_size} > {max_mesh_bytes} bytes)", field=mesh.name)
            continue
        users = [g for g in spec.geoms if g.meshname == mesh.name]
        colliding = [g for g in users if g.contype or g.conaffinity]
        if colliding:
            raise HandDescriptionError(f"geom {colliding[0].name or mesh.name}: collision mesh file {file} not found"
                                       f"{_meshdir_hint(path.parent, mesh.file)}",
                                       field=colliding[0].name or mesh.name)
        for g in users:
            spec.delete(g)
        spec.delete(mesh)
        notes.append(f"mesh {mesh.name}: file {file.name} missing, visual only: ignored")
    # A material the file uses but does not define (a hand file made to be included in a
    # scene that defines them: an Inspire RH56DFTP's inspire_hand_right.xml) makes MuJoCo
    # refuse the model; a material only colours a geom.
    defined = {m.name for m in spec.materials}
    undefined = sorted({g.material for g in spec.geoms if g.material and g.material not in defined})
    for g in spec.geoms:
        if g.material in undefined:
            g.material = ""
    for name in undefined:
        notes.append(f"material {name}: not defined in the file (a scene including it defines it?): "
                     "its geoms drawn without it")
    return _lift_fused_base(spec, path, notes)


def _moving_tops(spec) -> list:
    """The world's child bodies whose subtrees hold hinge or slide joints, no free joint."""
    import mujoco

    tops = []
    for body in spec.worldbody.bodies:
        kinds = [j.type for j in body.find_all(mujoco.mjtObj.mjOBJ_JOINT)]  # its own joints included
        if kinds and mujoco.mjtJoint.mjJNT_FREE not in kinds:
            tops.append(body)
    return tops


def _meshdir_hint(folder: Path, written: str) -> str:
    """Where a mesh file the MJCF names (``written``, as in its ``file``) lies in the tree of
    the description's ``folder`` (at most :data:`.file_search.SCAN_FILES` files looked at), as a hint for
    the error: a model file copied out of the folder its ``meshdir`` is relative to (one of
    a Unitree G1 repository's Inspire hand files names ``meshes/inspire_hands/...`` beside
    it, the meshes lying under ``unitree_g1/assets``). Empty when none is found."""
    if Path(written).is_absolute():
        return ""
    tail = Path(written).parts
    found = find_in_tree(folder, tail)
    if found is None:
        return ""
    base = Path(*found.parts[:-len(tail)]) if len(found.parts) > len(tail) else Path("/")
    return (f" (a file of that name is at {found}: <compiler meshdir=\"{os.path.relpath(base, folder)}\"/> "
            "would find it; is the model file out of its folder?)")


def _lift_fused_base(spec, path: Path, notes: list[str]):
    """A hand whose base is fused into the world body -- its palm geoms directly in
    ``<worldbody>`` and its fingers world bodies of their own, as MuJoCo writes a URDF with
    a fixed base link -- gets that base back as a body (``<model>_base`` at the world's
    origin) holding those geoms and fingers, so that it can be found, held and placed as
    any hand's root. Planes, lights, cameras, free bodies and bodies without joints stay
    in the world."""
    import xml.etree.ElementTree as ET

    import mujoco

    flat = (mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_HFIELD)  # the scene's, never the hand's
    keep_geoms = [g.type in flat for g in spec.worldbody.geoms]
    tops = _moving_tops(spec)
    if not any(not keep and (g.contype or g.conaffinity) for keep, g in zip(keep_geoms, spec.worldbody.geoms)) \
            or len(tops) < 2:
        return spec
    # the XML's world children come in the spec's order: geoms and bodies matched by index
    moves_body = [any(b is t for t in tops) for b in spec.worldbody.bodies]
    names = {b.name for b in spec.bodies}
    base_name = next(n for n in (f"{spec.modelname or path.stem}_base", "hand_base", *(f"hand_base{i}" for i in range(1000)))
                     if n not in names)
    try:
        root = ET.fromstring(spec.to_xml())
    except Exception as exc:
        raise HandDescriptionError(f"hand_description: {path.name}: the hand's base is fused into the world body and "
                                   f"MuJoCo cannot write the file back to lift it ({str(exc).splitlines()[0][:200]})",
                                   field="hand_description") from None
    world = root.find("worldbody")
    children = list(world)
    if [e.tag for e in children].count("geom") != len(keep_geoms) or \
            [e.tag for e in children].count("body") != len(moves_body):
        return spec  # world geoms or bodies inside <frame>s: left as the file has them
    base = ET.Element("body", {"name": base_name})
    index = {"geom": 0, "body": 0}
    for element in children:
        if element.tag not in index:
            continue
        k = index[element.tag]
        index[element.tag] += 1
        if (keep_geoms[k] if element.tag == "geom" else not moves_body[k]):
            continue
        world.remove(element)
        base.append(element)
    world.append(base)
    # the XML is parsed without the file's folder: asset paths made absolute
    folder = Path(spec.modelfiledir or path.parent)
    compiler = root.find("compiler")
    if compiler is None:
        compiler = ET.SubElement(root, "compiler")
    for key, value in (("meshdir", spec.meshdir), ("texturedir", spec.texturedir)):
        compiler.set(key, str(folder / (value or "")))
    compiler.set("assetdir", str(folder))
    try:
        lifted = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
    except Exception as exc:
        raise HandDescriptionError(f"hand_description: {path.name}: the hand's base is fused into the world body and "
                                   f"could not be lifted into a body ({str(exc).splitlines()[0][:200]})",
                                   field="hand_description") from None
    notes.append(f"the hand's base is fused into the world body (its geoms and {len(tops)} jointed bodies directly "
                 f"under <worldbody>, as MuJoCo writes a URDF's fixed base): taken as the root body {base_name!r} "
                 "at the world's origin")
    return lifted


def _compile(path: Path, notes: list[str], max_mesh_bytes: int):
    spec = open_spec(path, notes, max_mesh_bytes)
    try:
        return spec.compile()
    except Exception as exc:
        raise HandDescriptionError(f"hand_description: MuJoCo cannot compile {path.name} "
                                   f"({str(exc).splitlines()[0][:200]})", field="hand_description") from None


def _name(mujoco, model, kind, i: int, prefix: str) -> str:
    return mujoco.mj_id2name(model, kind, i) or f"{prefix}{i}"


def _geom(mujoco, model, g: int, where: str) -> LinkGeometry | None:
    t = model.geom_type[g]
    size = model.geom_size[g]
    origin = rigid(_quat_matrix(model.geom_quat[g]), model.geom_pos[g])
    G = mujoco.mjtGeom
    if t == G.mjGEOM_SPHERE:
        return LinkGeometry("sphere", (size[0],), origin, None, where)
    if t == G.mjGEOM_CAPSULE:
        return LinkGeometry("capsule", (size[0], size[1]), origin, None, where)
    if t == G.mjGEOM_CYLINDER:
        return LinkGeometry("cylinder", (size[0], size[1]), origin, None, where)
    if t == G.mjGEOM_BOX:
        return LinkGeometry("box", tuple(size), origin, None, where)
    if t == G.mjGEOM_ELLIPSOID:
        mesh = trimesh.creation.icosphere(subdivisions=3)
        mesh.apply_scale(size)
        return LinkGeometry("mesh", (), origin, mesh, where + " (ellipsoid)")
    if t == G.mjGEOM_MESH:
        m = model.geom_dataid[g]
        va, vn = model.mesh_vertadr[m], model.mesh_vertnum[m]
        fa, fn = model.mesh_faceadr[m], model.mesh_facenum[m]
        mesh = trimesh.Trimesh(model.mesh_vert[va:va + vn].copy(), model.mesh_face[fa:fa + fn].copy(), process=True)
        return LinkGeometry("mesh", (), origin, mesh, where)
    return None


def _subtree_sizes(model, top_children) -> dict[int, int]:
    counts = {}
    for b in top_children:
        members = {b}
        for i in range(b + 1, model.nbody):
            if model.body_parentid[i] in members:
                members.add(i)
        counts[b] = (members, sum(int(model.body_jntnum[i]) for i in members))
    return counts


def read_mjcf(path: Path, max_mesh_bytes: int) -> RawHand:
    """The RawHand of an MJCF file (compiled by MuJoCo); mesh files over
    ``max_mesh_bytes`` are refused."""
    import mujoco

    notes: list[str] = []
    model = _compile(path, notes, max_mesh_bytes)
    OBJ, JNT = mujoco.mjtObj, mujoco.mjtJoint
    tops = [b for b in range(1, model.nbody) if model.body_parentid[b] == 0]
    if not tops:
        raise HandDescriptionError(f"hand_description: {path.name} is not an MJCF hand (no bodies)", field="hand_description")
    subtrees = _subtree_sizes(model, tops)
    top = max(tops, key=lambda b: subtrees[b][1])
    members = subtrees[top][0]
    for b in tops:
        if b != top:
            notes.append(f"body {_name(mujoco, model, OBJ.mjOBJ_BODY, b, 'body')}: not part of the hand, ignored")
    model_name = model.names[:model.names.index(b"\0")].decode()
    # MuJoCo names a model without a name attribute "MuJoCo Model": the file's stem says more.
    raw = RawHand(name=path.stem if model_name in ("", "MuJoCo Model") else model_name, links=[], notes=notes)
    joint_names = {}
    for b in sorted(members):
        name = _name(mujoco, model, OBJ.mjOBJ_BODY, b, "body")
        parent = None if b == top else _name(mujoco, model, OBJ.mjOBJ_BODY, model.body_parentid[b], "body")
        origin = rigid(_quat_matrix(model.body_quat[b]), model.body_pos[b])
        joints = []
        for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            jname = _name(mujoco, model, OBJ.mjOBJ_JOINT, j, "joint")
            joint_names[j] = jname
            t = model.jnt_type[j]
            if t == JNT.mjJNT_FREE:
                if b != top:
                    raise HandDescriptionError(f"joint {jname!r}: a free joint inside the hand", field=jname)
                notes.append(f"joint {jname}: free joint of the hand's base, ignored")
                continue
            if t == JNT.mjJNT_BALL:
                raise HandDescriptionError(f"joint {jname!r}: ball joints are not supported (hinge, slide)", field=jname)
            kind = "prismatic" if t == JNT.mjJNT_SLIDE else "revolute"
            limited = bool(model.jnt_limited[j])
            lo, hi = (float(model.jnt_range[j, 0]), float(model.jnt_range[j, 1])) if limited else (None, None)
            if not limited and kind == "revolute":
                kind = "continuous"
            qadr = model.jnt_qposadr[j]
            joints.append(RawJoint(jname, kind, model.jnt_axis[j].copy(), model.jnt_pos[j].copy(), lo, hi,
                                   float(model.qpos0[qadr]), source=f"{'hinge' if kind != 'prismatic' else 'slide'} "
                                   "without range"))
        geoms = []
        for g in range(model.body_geomadr[b], model.body_geomadr[b] + model.body_geomnum[b]):
            if model.body_geomadr[b] < 0:
                break
            if not (model.geom_contype[g] or model.geom_conaffinity[g]):
                continue
            gname = _name(mujoco, model, OBJ.mjOBJ_GEOM, g, "geom")
            lg = _geom(mujoco, model, g, f"body {name} geom {gname}")
            if lg is not None:
                geoms.append(lg)
        raw.links.append(RawLink(name, parent, origin, joints, geoms))
    qpos0 = {joint_names[j]: float(model.qpos0[model.jnt_qposadr[j]]) for j in joint_names}
    actuated = {joint_names[model.actuator_trnid[a, 0]] for a in range(model.nu)
                if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and model.actuator_trnid[a, 0] in joint_names}
    raw.actuated_hint = actuated or None
    depth = {name: i for i, name in enumerate(j for link in raw.links for j in (x.name for x in link.joints))}
    _equalities(mujoco, model, raw, joint_names, qpos0, depth)
    _lead_shared_followers(raw)
    _tendons(mujoco, model, raw, joint_names, actuated, depth)
    _tendon_actuators(mujoco, model, raw, joint_names)
    others = [_name(mujoco, model, OBJ.mjOBJ_BODY, b, "body") for b in tops if b != top and subtrees[b][1] > 0]
    if others:
        _one_tree(raw, _name(mujoco, model, OBJ.mjOBJ_BODY, top, "body"), others, path)
    return raw


def _one_tree(raw: RawHand, top: str, others: list[str], path: Path) -> None:
    """A file whose fingers are world bodies side by side instead of children of one palm
    (OYMotion's ROHand: a palm body without joints, five jointed bodies beside it) leaves
    the hand (the subtree with the most joints) one finger: refused, naming them."""
    from .derive import find_root

    try:
        find_root(raw)
    except HandDescriptionError as exc:
        shown = ", ".join(others[:6]) + (f" and {len(others) - 6} more" if len(others) > 6 else "")
        raise HandDescriptionError(
            f"{exc} in {path.name}: the hand was taken to be world body {top!r} (the subtree with the most "
            f"joints), and {len(others)} other world bodies with joints ({shown}) stand beside it in <worldbody>, "
            "not under it: a hand is one body tree, its fingers children of its palm body (these hinge on the "
            "world, and the palm cannot carry them)", field="hand_description") from None


def _tendon_actuators(mujoco, model, raw, joint_names) -> None:
    """A note for each actuator that drives a fixed tendon over joints no coupling ties (the
    Shadow hand of MuJoCo Menagerie: ``rh_A_FFJ0`` drives ``rh_FFJ2 + rh_FFJ1``): how the
    hand shares the tendon's motion among them is its dynamics', not kinematics, so the
    planner (and its simulation, a servo per joint) moves each of them on its own, and the
    hand's own controller can command only their weighted sum."""
    following = {c.follower for c in raw.couplings}
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_TENDON:
            continue
        t = int(model.actuator_trnid[a, 0])
        wraps = _joint_wraps(mujoco, model, t)
        if not wraps or len(wraps) < 2 or any(j not in joint_names for j, _ in wraps):
            continue
        free = [(joint_names[j], c) for j, c in wraps if joint_names[j] not in following]
        if len(free) < 2:
            continue
        total = " + ".join(f"{c:.4g} {n}" if c != 1.0 else n for n, c in free)
        raw.notes.append(f"actuator {_name(mujoco, model, mujoco.mjtObj.mjOBJ_ACTUATOR, a, 'actuator')} drives tendon "
                         f"{_name(mujoco, model, mujoco.mjtObj.mjOBJ_TENDON, t, 'tendon')} ({total}): the planner moves "
                         "those joints each on its own (its simulation too, a servo per joint); the hand's own "
                         "controller commands only this sum of theirs, so send it the sum of the grasp's values")


def _lead_shared_followers(raw) -> None:
    """A joint that is ``joint1`` of several joint equalities (each ``joint1 = a0 + a1
    joint2``) is held to each of their ``joint2``: MuJoCo reads an equality as a constraint
    between the two, so the joint leads them, each following it by the inverted relation
    (``joint2 = (joint1 - a0) / a1``), with a note. One of a Unitree G1 repository's Inspire
    hand files couples the thumb so (``joint_r_thumb_proximal_2`` is ``joint1`` of the
    equalities with the thumb's middle and distal joints), which read as one joint following
    two was refused. Left as they are (and refused) when a relation cannot be inverted or
    one of the other joints follows another joint too."""
    equal = [c for c in raw.couplings if c.source.startswith("equality ") and not c.slack]
    count: dict[str, int] = {}
    for c in raw.couplings:
        count[c.follower] = count.get(c.follower, 0) + 1
    for joint in sorted({c.follower for c in equal if count[c.follower] > 1}):
        mine = [c for c in raw.couplings if c.follower == joint]
        if any(c not in equal or abs(c.multiplier) < 1e-9 or count.get(c.leader, 0) for c in mine):
            continue
        for c in mine:
            raw.couplings[raw.couplings.index(c)] = Coupling(c.leader, joint, 1.0 / c.multiplier,
                                                             -c.offset / c.multiplier, c.source)
            count[c.leader] = 1
        count[joint] = 0
        raw.notes.append(f"joint {joint}: joint1 of {len(mine)} joint equalities "
                         f"({', '.join(c.source.removeprefix('equality ') for c in mine)}): it leads "
                         f"{', '.join(c.leader for c in mine)}, each by its equality inverted")


def _equalities(mujoco, model, raw, joint_names, qpos0, depth) -> None:
    EQ = mujoco.mjtEq
    for e in range(model.neq):
        if not model.eq_active0[e]:
            continue
        ename = _name(mujoco, model, mujoco.mjtObj.mjOBJ_EQUALITY, e, "equality")
        poly = model.eq_data[e, :5]
        if model.eq_type[e] == EQ.mjEQ_JOINT:
            a, b = model.eq_obj1id[e], model.eq_obj2id[e]
            if a not in joint_names or (b >= 0 and b not in joint_names):
                continue
            if np.any(np.abs(poly[2:]) > 1e-12):
                raw.notes.append(f"equality {ename}: polycoef beyond the linear term ignored")
            follower = joint_names[a]
            if b < 0:
                raw.fixed_values[follower] = qpos0[follower] + float(poly[0])
                continue
            leader = joint_names[b]
            # y - y0 = a0 + a1 (x - x0)
            mult = float(poly[1])
            raw.couplings.append(Coupling(follower, leader, mult,
                                          qpos0[follower] + float(poly[0]) - mult * qpos0[leader],
                                          f"equality {ename}"))
        elif model.eq_type[e] == EQ.mjEQ_CONNECT or model.eq_type[e] == EQ.mjEQ_WELD:  # (not `in`: numpy vs enum)
            # A closed linkage (a parallel gripper's four-bar: the Robotiq 2F-85): the
            # kinematics here are the open tree, so its links do not move as the file's.
            kind = "connect" if model.eq_type[e] == EQ.mjEQ_CONNECT else "weld"
            bodies = [_name(mujoco, model, mujoco.mjtObj.mjOBJ_BODY, int(b), "body")
                      for b in (model.eq_obj1id[e], model.eq_obj2id[e])]
            raw.notes.append(f"equality {ename}: {kind} of bodies {bodies[0]} and {bodies[1]} closes a kinematic "
                             "loop, which is not modelled (the open chains are): the closing motion may not be "
                             "the file's")
        elif model.eq_type[e] == EQ.mjEQ_TENDON and model.eq_obj2id[e] < 0:
            # L - L0 = a0: the tendon keeps its length at qpos0 (plus a0).
            t = model.eq_obj1id[e]
            _tendon_coupling(mujoco, model, raw, t, float(model.tendon_length0[t] + poly[0]), f"equality {ename}",
                             joint_names, None, depth)


def _tendons(mujoco, model, raw, joint_names, actuated, depth) -> None:
    for t in range(model.ntendon):
        if not model.tendon_limited[t]:
            continue
        lo, hi = model.tendon_range[t]
        wraps = _joint_wraps(mujoco, model, t)
        if wraps is None or len(wraps) != 2 or any(j not in joint_names for j, _ in wraps):
            continue
        span = sum(abs(c) * (model.jnt_range[j, 1] - model.jnt_range[j, 0]) for j, c in wraps)
        if span <= 0 or hi - lo > _NARROW_TENDON * span:
            continue
        tname = _name(mujoco, model, mujoco.mjtObj.mjOBJ_TENDON, t, "tendon")
        _tendon_coupling(mujoco, model, raw, t, 0.5 * (lo + hi), f"tendon {tname}", joint_names, actuated, depth,
                         0.5 * (hi - lo))


def _joint_wraps(mujoco, model, t: int):
    adr, num = model.tendon_adr[t], model.tendon_num[t]
    out = []
    for w in range(adr, adr + num):
        if model.wrap_type[w] != mujoco.mjtWrap.mjWRAP_JOINT:
            return None
        out.append((int(model.wrap_objid[w]), float(model.wrap_prm[w])))
    return out


def _tendon_coupling(mujoco, model, raw, t, length, source, joint_names, actuated, depth, play=0.0) -> None:
    """The coupling of tendon t's two joints at ``length``; ``play``: how far the tendon's
    length may stray from it (half a limited tendon's range), the follower's slack."""
    wraps = _joint_wraps(mujoco, model, t)
    if wraps is None or len(wraps) != 2:
        raw.notes.append(f"{source}: not a coupling of two joints, ignored")
        return
    (j1, c1), (j2, c2) = wraps
    n1, n2 = joint_names.get(j1), joint_names.get(j2)
    if n1 is None or n2 is None or c1 == 0 or c2 == 0:
        return
    following = {c.follower for c in raw.couplings}
    if n1 in following and n2 in following:
        return
    # The follower: not already a follower; else the joint no actuator drives; else the
    # one farther down the tree.
    if (n1 in following) != (n2 in following):
        follower_first = n2 in following
    elif actuated and (n1 in actuated) != (n2 in actuated):
        follower_first = n1 not in actuated
    else:
        follower_first = depth.get(n1, 0) > depth.get(n2, 0)
    (fj, fc), (lj, lc) = ((n1, c1), (n2, c2)) if follower_first else ((n2, c2), (n1, c1))
    # fc * qf + lc * ql = length  ->  qf = -lc/fc * ql + length/fc
    raw.couplings.append(Coupling(fj, lj, -lc / fc, length / fc, source, play / abs(fc)))
