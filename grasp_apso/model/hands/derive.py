"""The grasp semantics of a hand, derived from its kinematics (DESIGN.md Part 3).

- Root (palm): walking down from the top of the tree, the first link where two or more
  child branches each reach a link with collision geometry through at least two movable
  joints. Joints above it are held (not actuated for grasping).
- Fingers: the chains from the root to each *geometric leaf* (a link with collision
  geometry and none below it) with at least two movable joints on the way.
- Per finger, at the reference posture (every joint at 0 clipped into its range): the
  flexion axis is the axis of the chain's last joint; a joint whose axis is more than
  45 degrees from it moves the tip sideways (abduction, thumb rotation): a pre-shape
  joint, closing 0. The flexion joints curl the tip about the flexion axis in one sense.
  Which sense closes: first from the joint ranges (fingers flex further than they
  extend), then, once the thumb and the palm normal are known, from the geometry (the
  tip moves toward the palm normal; the thumb's tip toward the other fingers' tips)
  wherever that is clear; a finger that extends along the palm normal (a claw's) with
  ranges that do not say, toward the other fingers' tips across the normal.
- Thumb: the finger whose closing motion opposes the others' most.
- Palm normal: from the root's collision geometry toward the centre of the fingertips of
  the closed hand, made perpendicular to the direction the straight fingers extend in when
  most of it remains, then the mean normal of the palm's surface facing that way (within
  45 degrees; fallback: the fingers' mean closing direction).
- Pads: :func:`.pads.find_pad` on the tip link, with the palmar direction (the tip's
  closing motion) and the distal direction in that link's frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import HandDescriptionError
from .description import RawHand

__all__ = ["find_root", "finger_tips", "FingerSemantics", "derive_fingers", "finger_label", "subtree", "ancestors"]

_SIDEWAYS_COS = math.cos(math.radians(45.0))
_CLEAR_COS = 0.25
#: A finger's joint ranges vote for a closing sense by how much further its flexion
#: joints turn one way than the other (rad); within this they do not say.
_WEAK_VOTE = 0.2
#: A link of a fingertip's body whose collision geometry spans less than this share of the
#: body's largest is a marker (a tip frame drawn as a small box or ball), never the tip.
_MARKER_SHARE = 0.2
#: The palm normal is taken toward the fingertips closed this share of the way to their
#: closing limits (:func:`_palm_normal`; the loader notes limits that close a finger
#: through the palm at that posture).
PALM_NORMAL_FRACTION = 0.7


def _children(raw: RawHand) -> dict[str | None, list[str]]:
    out: dict[str | None, list[str]] = {}
    for link in raw.links:
        out.setdefault(link.parent, []).append(link.name)
    return out


def _leaves_with_joints(raw: RawHand, start: str, children) -> list[tuple[str, int]]:
    """(geometric leaf, movable joints from ``start`` exclusive down to it) in the subtree
    of ``start`` (``start`` itself excluded)."""
    by_name = {link.name: link for link in raw.links}
    out = []
    stack = [(c, len(by_name[c].joints)) for c in children.get(start, [])]
    while stack:
        name, count = stack.pop()
        kids = children.get(name, [])
        below = [(c, count + len(by_name[c].joints)) for c in kids]
        if by_name[name].geoms and not _has_geometry_below(name, children, by_name):
            out.append((name, count))
        stack.extend(below)
    return out


def _has_geometry_below(name: str, children, by_name) -> bool:
    stack = list(children.get(name, []))
    while stack:
        n = stack.pop()
        if by_name[n].geoms:
            return True
        stack.extend(children.get(n, []))
    return False


def find_root(raw: RawHand) -> str:
    """The palm: the first link, from the top, where finger branches split (see module).
    A file holding several hands (a humanoid's, both palms below its torso) is refused,
    naming their palms, unless ``hand_config.root_link`` picks one."""
    children = _children(raw)
    by_name = {link.name: link for link in raw.links}
    current = raw.links[0].name
    for _ in range(len(raw.links)):
        branches = _finger_branches(current, raw, children, by_name)
        if len(branches) >= 2:
            _refuse_several_hands(current, raw, children, by_name)
            return current
        if not branches:
            break
        current = branches[0]
    raise HandDescriptionError("hand_description: fewer than two fingers (chains of two or more movable "
                               "joints ending in a link with collision geometry)", field="hand_description")


def _finger_branches(name: str, raw: RawHand, children, by_name) -> list[str]:
    """The children of link ``name`` whose subtree holds a finger: a geometric leaf with
    two or more movable joints from that child (its own included) down to it."""
    branches = []
    for child in children.get(name, []):
        leaves = [(n, c + len(by_name[child].joints)) for n, c in _leaves_with_joints(raw, child, children)]
        if by_name[child].geoms and not _has_geometry_below(child, children, by_name):
            leaves.append((child, len(by_name[child].joints)))
        if any(count >= 2 for _, count in leaves):
            branches.append(child)
    return branches


def _refuse_several_hands(root: str, raw: RawHand, children, by_name) -> None:
    """Refuse when two links below ``root`` where fingers split lie on separate branches
    (neither above the other): the file holds several hands (Unitree's G1 with hands:
    the pelvis would be the palm, its feet fingers). Nested splits (a knuckle turning two
    fingers of one hand, the Schunk SDH's) are one hand."""
    below = subtree(raw, root)
    splits = [link.name for link in raw.links
              if link.name in below and len(_finger_branches(link.name, raw, children, by_name)) >= 2]
    lowest = [name for name in splits if not any(other != name and name in ancestors(raw, other)
                                                  for other in splits)]
    if len(lowest) >= 2:
        raise HandDescriptionError(
            f"hand_description: the file holds {len(lowest)} hands (their palms, where their fingers split: "
            f"{', '.join(lowest)}); give the palm of the one to plan with as hand_config.root_link "
            "(--hand-config FILE with 'root_link: NAME')", field="hand_description")


def subtree(raw: RawHand, root: str) -> set[str]:
    """The names of link ``root`` and every link below it."""
    inside = {root}
    for link in raw.links:  # parents first
        if link.parent in inside:
            inside.add(link.name)
    return inside


def ancestors(raw: RawHand, link: str) -> set[str]:
    """The names of the links strictly above link ``link``."""
    parents = {item.name: item.parent for item in raw.links}
    out = set()
    while parents.get(link) is not None:
        link = parents[link]
        out.add(link)
    return out


def finger_tips(raw: RawHand, root: str) -> list[str]:
    """The fingertip links below ``root``, file order: per geometric leaf with at least two
    movable joints above it, the tip link of its body (:func:`_tip_link`); leaves that hang
    by fixed joints off a link that moves further links (a tactile sensor on a phalanx)
    are no fingers."""
    children = _children(raw)
    by_name = {link.name: link for link in raw.links}
    tips = {_tip_link(leaf, children, by_name) for leaf, count in _leaves_with_joints(raw, root, children)
            if count >= 2}
    return [link.name for link in raw.links if link.name in tips]


def _tip_link(leaf: str, children, by_name) -> str | None:
    """The fingertip link of a geometric leaf's body (the nearest link with a movable
    joint, the leaf included, and the links fixed below it): None when a movable joint
    lies below that link; else the body's link whose collision geometry reaches farthest
    from the moving link's origin (the leaf on a tie): a fingertip with a sensor pad fixed
    inside it (dex-urdf's Allegro with FSRs) keeps the fingertip, and so does one with a
    millimetre-sized marker fixed at its end (the Linker hands' tip frames)."""
    moving = leaf
    while not by_name[moving].joints and by_name[moving].parent is not None:
        moving = by_name[moving].parent
    body, stack = [], [(moving, np.eye(4))]
    while stack:
        name, pose = stack.pop()
        if name != moving and by_name[name].joints:
            return None
        body.append((name, pose))
        stack.extend((c, pose @ by_name[c].origin) for c in children.get(name, []))
    reach, size = {}, {}
    for name, pose in body:
        points = [g.to_trimesh().vertices @ pose[:3, :3].T + pose[:3, 3] for g in by_name[name].geoms]
        if points:
            v = np.concatenate(points)
            reach[name] = float(np.linalg.norm(v, axis=1).max())
            size[name] = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    if not reach:
        return leaf
    # a frame marker (a millimetre-sized geom a file fixes at the fingertip to name its
    # tip) reaches farthest but is no pad
    largest = max(size.values())
    best, far = leaf, -1.0
    for name, d in reach.items():
        if size[name] < _MARKER_SHARE * largest:
            continue
        if d > far + 1e-9 or (abs(d - far) <= 1e-9 and name == leaf):
            best, far = name, d
    return best


def finger_label(*candidates: list[str]) -> list[str]:
    """Finger names from link names (one list per candidate source, e.g. the tip links and
    the first links below the palm): per source, the tokens (split at ``_ : - .``) that
    more than half of the names share and single-letter side marks (``l``, ``R``) are
    dropped, then the characters all remaining names begin or end with (or only the first
    remaining token); the labels that come out shortest (and distinct) win. Shadow:
    ``robot0:ffdistal`` -> ``ff``; Inspire: ``thumb_proximal_base`` -> ``thumb``."""
    best = None
    for names in candidates:
        for first_token in (False, True):
            labels = _labels(names, first_token)
            if labels is not None and (best is None or sum(map(len, labels)) < sum(map(len, best))):
                best = labels
    return best if best is not None else list(candidates[0])


def _labels(names: list[str], first_token: bool = False) -> list[str] | None:
    """Labels of one source (None: not distinct); ``first_token``: only the first token
    each name keeps (``thumb_base`` -> ``thumb``)."""
    import re

    tokens = [[t for t in re.split(r"[_:\-. ]+", n) if t] for n in names]
    if len(names) >= 2:
        counts: dict[str, int] = {}
        for toks in tokens:
            for t in set(toks):
                counts[t] = counts.get(t, 0) + 1
        shared = [[t for t in toks if counts[t] * 2 <= len(names)] for toks in tokens]
        keep = [[t for t in toks if not (len(t) == 1 and t.isalpha())] for toks in shared]
        cores = ["_".join(k) for k in keep]
        if not all(cores):  # single letters are the names themselves (Schunk SVH: c, r, q ...)
            keep = shared
            cores = ["_".join(k) for k in shared]
        if first_token:
            cores = [k[0] if k else "" for k in keep]
        if all(cores):
            prefix, suffix = len(_common(cores)), len(_common([c[::-1] for c in cores]))
            trimmed = [c[prefix:len(c) - suffix].strip("_") for c in cores]
            cores = trimmed if all(trimmed) else cores
            if len(set(cores)) == len(cores):
                return cores
    return list(names) if len(set(names)) == len(names) else None


def _common(items: list[str]) -> str:
    """The longest prefix all ``items`` share."""
    first = items[0]
    n = 0
    while n < len(first) and all(len(s) > n and s[n] == first[n] for s in items):
        n += 1
    return first[:n]


@dataclass
class FingerSemantics:
    """What :func:`derive_fingers` finds for one finger."""

    tip_link: str
    joints: tuple[str, ...]
    closing: tuple[int, ...]
    palmar: np.ndarray   # (3,) tip link frame
    distal: np.ndarray   # (3,) tip link frame
    is_thumb: bool


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else np.zeros_like(v)


def derive_fingers(hand, tips: list[str], overrides: dict) -> tuple[list[FingerSemantics], np.ndarray, list[str]]:
    """Joints, closing senses, thumb, palmar directions and the palm normal.

    hand : a HandModel without semantics (kinematics and collision only).
    overrides : ``closing`` {joint: -1|0|1}, ``thumb`` (tip link), ``palm_normal`` (3,).
    Returns (fingers, palm_normal (3,), notes).
    """
    notes: list[str] = []
    n = hand.n_joints
    q0 = np.clip(0.0, hand.lower, hand.upper)
    poses0 = hand.link_transforms_batch(q0[None])[0]
    centroid = {}
    for tip in tips:
        pts = np.concatenate([g.to_trimesh().vertices for g in hand.collision[tip]])
        centroid[tip] = 0.5 * (pts.min(axis=0) + pts.max(axis=0))

    def tip_points(Q: np.ndarray) -> np.ndarray:  # (P, n) -> (P, F, 3)
        poses = hand.link_transforms_batch(Q)
        out = []
        for tip in tips:
            T = poses[:, hand.link_index(tip)]
            out.append(T[:, :3, :3] @ centroid[tip] + T[:, :3, 3])
        return np.stack(out, axis=1)

    eps = 1e-4
    Q = np.repeat(q0[None], n + 1, axis=0)
    Q[1:] += eps * np.eye(n)
    pts = tip_points(Q)
    velocity = (pts[1:] - pts[0]) / eps          # (n, F, 3): d tip / d q_j
    tip0 = pts[0]                                # (F, 3)

    info = [_finger_info(hand, tip, velocity[:, f], tip0[f], poses0, q0) for f, tip in enumerate(tips)]

    def closing_dirs():
        return [_unit(i["sigma"] * i["curl"]) for i in info]

    # ---- thumb: the finger whose closing direction opposes the others' most
    dirs = closing_dirs()
    thumb_tip = overrides.get("thumb")
    if thumb_tip is None:
        if len(tips) >= 3:
            scores = [sum(float(np.dot(dirs[f], dirs[g])) for g in range(len(tips)) if g != f) for f in range(len(tips))]
            thumb_f = int(np.argmin(scores))
        else:
            thumb_f = max(range(len(tips)), key=lambda f: (len(info[f]["joints"]), f))
    else:
        thumb_f = tips.index(thumb_tip)

    # ---- palm normal: from the palm toward the closed fingertips
    normal = overrides.get("palm_normal")
    claw = False  # a finger closes across the normal, toward the others (below)
    for _ in range(2):
        if overrides.get("palm_normal") is None:
            # A claw's fingers extend along the palm normal and curl back past the palm,
            # so the closed tips do not show it: the straight fingers' direction does.
            normal = (_unit(np.mean([_unit(tip0[f] - i["base"]) for f, i in enumerate(info)], axis=0)) if claw
                      else _palm_normal(hand, info, tip_points, q0, thumb_f))
        # Stage 2: geometric closing sense where it is clear.
        others = np.mean([tip0[g] for g in range(len(tips)) if g != thumb_f], axis=0)
        for f, i in enumerate(info):
            target = _unit(others - tip0[f]) if f == thumb_f else normal
            c = float(np.dot(_unit(i["curl"]), target))
            if abs(c) <= _CLEAR_COS and f != thumb_f and abs(i["vote"]) <= _WEAK_VOTE:
                # A finger that extends along the palm normal (a claw's) and whose ranges
                # do not say which way it flexes: its tip closes toward the other tips,
                # across the normal.
                claw = True
                rest = np.mean([tip0[g] for g in range(len(tips)) if g != f], axis=0) - tip0[f]
                c = float(np.dot(_unit(i["curl"]), _unit(rest - float(np.dot(rest, normal)) * normal)))
            if abs(c) > _CLEAR_COS:
                new = 1.0 if c > 0 else -1.0
                if new != i["sigma"] and abs(i["vote"]) > _WEAK_VOTE:
                    notes.append(f"finger {i['tip']}: closing sense from the geometry, against the joint ranges")
                i["sigma"] = new

    out = []
    closing_override = overrides.get("closing", {})
    for f, i in enumerate(info):
        closing = []
        for a, (kind, sense) in zip(i["joints"], i["kinds"]):
            value = 0 if kind == "pre" else int(i["sigma"] * sense)
            closing.append(int(closing_override.get(a, value)))
        T = poses0[hand.link_index(i["tip"])]
        anchor = i["anchor"]
        palmar_root = _unit(i["sigma"] * np.cross(i["axis"], tip0[f] - anchor)) if np.linalg.norm(i["curl"]) else normal
        distal_root = _unit(tip0[f] - anchor)
        out.append(FingerSemantics(i["tip"], tuple(i["joints"]), tuple(closing),
                                   T[:3, :3].T @ palmar_root, T[:3, :3].T @ distal_root, f == thumb_f))
    return out, np.asarray(normal, float), notes


def _finger_info(hand, tip: str, velocity: np.ndarray, tip0: np.ndarray, poses0: np.ndarray,
                 q0: np.ndarray) -> dict:
    """One finger at the reference posture: its actuated joints, each joint's kind
    ("flex" with its curl sense about the flexion axis, or "pre"), the tip's curl velocity,
    the closing sense the ranges vote for, the flexion axis and the finger's base point.

    velocity : (n, 3) d tip / d q per actuated joint; tip0 : (3,) the tip; poses0 :
    (L, 4, 4) link poses; all in the root frame.
    """
    chain = hand.chain(tip)
    chain_motions = [m for i, ms in enumerate(hand.motions) if hand.links[i] in set(chain) for m in ms]
    moving = {m.joint for m in chain_motions}
    joints = [a for a in hand.actuated_joints if _moves_chain(hand, a, moving)]
    last = chain_motions[-1]
    last_link = next(i for i, ms in enumerate(hand.motions) if last in ms)
    R_last = poses0[last_link][:3, :3]
    axis_f = R_last @ np.asarray(last.axis)
    anchor = R_last @ np.asarray(last.anchor) + poses0[last_link][:3, 3]
    curl, kinds, vote = np.zeros(3), [], 0.0
    for a in joints:
        k = hand.actuated_joints.index(a)
        v = velocity[k]
        motion = _own_motion(hand, a, moving)
        if np.linalg.norm(v) < 1e-6:
            kinds.append(("pre", 0.0))
            continue
        if motion is not None and motion[0].kind == "revolute":
            c = float(np.dot(poses0[motion[1]][:3, :3] @ np.asarray(motion[0].axis), axis_f))
            if abs(c) < _SIDEWAYS_COS:  # turns the tip sideways: abduction, thumb rotation
                kinds.append(("pre", 0.0))
                continue
            sense = 1.0 if c > 0 else -1.0
        else:
            if abs(float(np.dot(_unit(v), axis_f))) > _SIDEWAYS_COS:
                kinds.append(("pre", 0.0))
                continue
            sense = 1.0 if float(np.dot(np.cross(axis_f, tip0 - anchor), v)) >= 0 else -1.0
        kinds.append(("flex", sense))
        curl += sense * v
        vote += sense * ((hand.upper[k] - q0[k]) - (q0[k] - hand.lower[k]))
    below = chain[chain.index(hand.root_link) + 1:]
    first = next(hand.link_index(name) for name in below if hand.motions[hand.link_index(name)])
    m0 = hand.motions[first][0]
    base = poses0[first][:3, :3] @ np.asarray(m0.anchor) + poses0[first][:3, 3]
    return {"tip": tip, "joints": joints, "kinds": kinds, "curl": curl, "sigma": 1.0 if vote >= 0 else -1.0,
            "base": base, "axis": axis_f, "anchor": anchor, "last_link": last_link, "vote": vote}


def _moves_chain(hand, joint: str, moving: set[str]) -> bool:
    """Whether actuated ``joint`` drives a motion on the chain (itself or a follower)."""
    k = hand.actuated_joints.index(joint)
    return any(hand.full_matrix[hand.joint_names.index(j), k] != 0 for j in moving)


def _own_motion(hand, joint: str, moving: set[str]):
    """(Motion, link index) of ``joint`` on the chain, or of its first follower on it."""
    k = hand.actuated_joints.index(joint)
    for i, ms in enumerate(hand.motions):
        for m in ms:
            if m.joint in moving and hand.full_matrix[m.index, k] != 0:
                return m, i
    return None


def _palm_normal(hand, info, tip_points, q0, thumb_f) -> np.ndarray:
    """Unit (3,): from the root's geometry toward the centre of the closed fingertips."""
    q = q0.copy()
    for i in info:
        for a, (kind, sense) in zip(i["joints"], i["kinds"]):
            if kind == "pre":
                continue
            k = hand.actuated_joints.index(a)
            target = hand.upper[k] if i["sigma"] * sense > 0 else hand.lower[k]
            q[k] = q0[k] + PALM_NORMAL_FRACTION * (target - q0[k])
    centre = tip_points(q[None])[0].mean(axis=0)
    fallback = _unit(sum(_unit(i["sigma"] * i["curl"]) for f, i in enumerate(info) if f != thumb_f))
    geoms = hand.collision.get(hand.root_link, ())
    if not geoms:
        return fallback
    import trimesh

    mesh = trimesh.util.concatenate([g.to_trimesh() for g in geoms])
    closest, distance, _ = trimesh.proximity.closest_point(mesh, centre[None])
    direction = centre - closest[0]
    inside = min(float(g.signed_distance(centre[None])[0]) for g in geoms) < 0
    if inside or np.linalg.norm(direction) < 1e-6:
        return fallback
    normal = _unit(direction)
    # Fingers that extend along the palm (most hands): the closed fingertips sit beyond the
    # palm's edge, which tilts the direction toward the fingers; the palm's face is
    # perpendicular to them. (Fingers that extend along the normal, as a Barrett hand's,
    # leave little of it and keep it.)
    straight = tip_points(q0[None])[0]
    along = _unit(np.mean([_unit(straight[f] - info[f]["base"]) for f in range(len(info)) if f != thumb_f], axis=0))
    across = normal - float(np.dot(normal, along)) * along
    normal = _unit(across) if np.linalg.norm(across) > 0.5 else normal
    # The palm's face: the area-weighted mean normal of the root's surface facing within 45
    # degrees of that direction (a box palm: exactly its face's normal).
    facing = mesh.face_normals @ normal > _SIDEWAYS_COS
    face = (mesh.area_faces[facing, None] * mesh.face_normals[facing]).sum(axis=0)
    return _unit(face) if np.linalg.norm(face) > 1e-12 else normal
