"""What a loader reads from a description file, before any derivation.

:class:`RawHand` is the common form of a URDF, an MJCF and the project's YAML: links in
tree order with their fixed origin, joint motions and collision geometry, the couplings
between joints, and notes on what the loader decided on its own. :func:`kinematics`
turns it into the arrays of :class:`~.model.HandModel` (actuated joints, limits, the
linear map to every joint's value, coupling loops refused).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ...errors import HandDescriptionError
from .geometry import LinkGeometry
from .model import Coupling, Motion, readonly

__all__ = ["RawJoint", "RawLink", "RawHand", "Kinematics", "kinematics", "lagging_couplings", "rigid",
           "CONTINUOUS_RANGE"]

#: A leader whose followers' limits leave it a range narrower than this (rad or m) is held
#: (:func:`_pinned_leaders`).
PINNED_RANGE = 1e-3
#: A joint whose own limits are this close (rad or m) is locked by its file: held there.
LOCKED_RANGE = 1e-12
#: The range a continuous joint without limits is given (rad), with a note.
CONTINUOUS_RANGE = (-math.pi, math.pi)


def rigid(rotation: np.ndarray, translation) -> np.ndarray:
    """A (4, 4) pose from a (3, 3) rotation and a (3,) translation."""
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


@dataclass
class RawJoint:
    """A movable joint as the file has it (``lower``/``upper`` None: no limits)."""

    name: str
    kind: str  # "revolute" | "prismatic" | "continuous"
    axis: np.ndarray
    anchor: np.ndarray = field(default_factory=lambda: np.zeros(3))
    lower: float | None = None
    upper: float | None = None
    ref: float = 0.0
    source: str = ""


@dataclass
class RawLink:
    """A link: its parent's name, its frame in the parent's at zero motion, its joints."""

    name: str
    parent: str | None
    origin: np.ndarray
    joints: list[RawJoint] = field(default_factory=list)
    geoms: list[LinkGeometry] = field(default_factory=list)


@dataclass
class RawHand:
    """A description file's hand: links parents-first, couplings, actuator hints, notes."""

    name: str
    links: list[RawLink]
    couplings: list[Coupling] = field(default_factory=list)
    actuated_hint: set[str] | None = None
    fixed_values: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def joint(self, name: str) -> RawJoint:
        for link in self.links:
            for joint in link.joints:
                if joint.name == name:
                    return joint
        raise HandDescriptionError(f"joint {name!r}: not a movable joint of the hand", field=name)


@dataclass(frozen=True)
class Kinematics:
    """The arrays of a HandModel's kinematics (see :class:`~.model.HandModel`)."""

    links: tuple[str, ...]
    parents: tuple[int, ...]
    origins: np.ndarray
    motions: tuple[tuple[Motion, ...], ...]
    joint_names: tuple[str, ...]
    actuated: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    matrix: np.ndarray
    offset: np.ndarray
    couplings: tuple[Coupling, ...]
    held: dict[str, float]


def _resolve(couplings: list[Coupling]) -> dict[str, tuple[str, float, float]]:
    """follower -> (independent leader, multiplier, offset), chains followed; loops refused."""
    direct = {}
    for c in couplings:
        if c.follower in direct:
            raise HandDescriptionError(f"{c.source}: joint {c.follower!r} follows two joints", field=c.follower)
        if c.follower == c.leader:
            raise HandDescriptionError(f"{c.source}: coupling loop: {c.follower!r} follows itself", field=c.follower)
        direct[c.follower] = (c.leader, c.multiplier, c.offset, c.source)
    out = {}
    for follower in direct:
        leader, mult, off, source = direct[follower]
        seen = [follower]
        while leader in direct:
            if leader in seen:
                loop = " -> ".join(seen + [leader])
                raise HandDescriptionError(f"{source}: coupling loop {loop}", field=follower)
            seen.append(leader)
            nxt, m2, o2, _ = direct[leader]
            mult, off, leader = mult * m2, mult * o2 + off, nxt
        out[follower] = (leader, mult, off)
    return out


def lagging_couplings(couplings: list[Coupling], closing: dict[str, int]) -> tuple[list[Coupling], list[str]] | None:
    """The couplings with play (``slack``) moved to the edge of it their closing drags the
    follower along, with a note each; None when none has play and a leader with a closing
    sense (``closing``: joint -> +1 / -1, 0 or absent: none).

    A limited tendon holds its follower only at the edges of its range (the Shadow hand of
    gymnasium-robotics: ``0.00705 FFJ0 - 0.00805 FFJ1`` within +-0.001 leaves FFJ0 0.14 rad
    of play either side of ``1.14 FFJ1``). As the leader closes, the follower is pulled
    along the edge behind the motion, so in the hand's own simulation it lags the middle of
    the range by the whole play (MuJoCo: the distal joints 0.13 rad short, the fingertips
    off their planned contacts). ``offset - sign(sense * multiplier) * slack`` is where the
    closing leaves it."""
    out, notes, moved = [], [], False
    for c in couplings:
        sense = closing.get(c.leader, 0)
        if c.slack <= 0.0 or not sense or c.multiplier == 0.0:
            out.append(c)
            continue
        edge = c.offset - math.copysign(c.slack, sense * c.multiplier)
        out.append(replace(c, offset=edge))
        moved = True
        notes.append(f"joint {c.follower}: follows {c.leader} at the edge of its play ({c.source}: "
                     f"{c.slack:.4g} either side) that the closing drags it along, offset {edge:.4g} "
                     f"instead of {c.offset:.4g}")
    return (out, notes) if moved else None


def _leader_bounds(follower: RawJoint, mult: float, off: float) -> tuple[float, float] | None:
    """The leader's values (lo, hi) that keep ``follower = mult * leader + off`` within the
    follower's own limits; None when it has none or does not move."""
    if follower.lower is None or follower.upper is None or mult == 0.0:
        return None
    lo, hi = sorted(((follower.lower - off) / mult, (follower.upper - off) / mult))
    return lo, hi


def _pinned_leaders(raw: RawHand, joints: list[RawJoint], resolved: dict, held: set[str],
                    fixed: dict[str, float]) -> dict[str, float]:
    """Leaders whose URDF mimic followers' own limits leave them no range (dex-urdf's left Schunk SVH:
    ``j5`` in [-0.99, 0] mimics the thumb opposition in [0, 0.99] with multiplier 1): each
    is held at the value of its range nearest to what the followers allow (a controller
    and MuJoCo's URDF import enforce the follower's limits too), with a note."""
    by_name = {j.name: j for j in joints}
    # URDF mimics only: an MJCF's joint equalities and tendons are soft, and its files rely
    # on that (robosuite's Jaco and Robotiq S grippers couple joints past their ranges).
    mimics = {c.follower for c in raw.couplings if c.source.endswith(" mimic")}
    allowed: dict[str, list[float]] = {}
    for follower, (leader, mult, off) in resolved.items():
        if follower not in mimics:
            continue
        fj, lj = by_name.get(follower), by_name.get(leader)
        if fj is None or lj is None or lj.lower is None or lj.upper is None or leader in held or leader in fixed:
            continue
        preimage = _leader_bounds(fj, mult, off)
        if preimage is None:
            continue
        lo, hi = preimage
        bounds = allowed.setdefault(leader, [lj.lower, lj.upper])
        bounds[0], bounds[1] = max(bounds[0], lo), min(bounds[1], hi)
    out = {}
    for leader, (lo, hi) in allowed.items():
        if hi - lo > PINNED_RANGE:
            continue
        lj = by_name[leader]
        value = float(np.clip(0.5 * (lo + hi), lj.lower, lj.upper))
        out[leader] = value
        raw.notes.append(f"joint {leader}: held at {value:.4g}: the limits of the joints that mimic it leave it "
                         f"no range")
    return out


def kinematics(raw: RawHand, held: set[str], hold_values: dict[str, float]) -> Kinematics:
    """The kinematic arrays of ``raw``; ``held`` joints (above the root) are fixed at
    ``hold_values`` (default 0 clipped into range) and not actuated.

    Raises HandDescriptionError naming the joint: a joint without limits that moves a
    finger (continuous joints get [-pi, pi], with a note), a coupling loop, a follower
    whose leader is unknown.
    """
    names, parents, origins, motions, joints = [], [], [], [], []
    index = {}
    for link in raw.links:
        if link.name in index:
            raise HandDescriptionError(f"link {link.name!r}: defined twice", field=link.name)
        parents.append(-1 if link.parent is None else index[link.parent])
        index[link.name] = len(names)
        names.append(link.name)
        origins.append(link.origin)
        ms = []
        for joint in link.joints:
            axis = np.asarray(joint.axis, float)
            norm = float(np.linalg.norm(axis))
            if not math.isfinite(norm) or norm < 1e-12:
                raise HandDescriptionError(f"joint {joint.name!r}: axis {axis.tolist()} is not a direction", field=joint.name)
            kind = "prismatic" if joint.kind == "prismatic" else "revolute"
            ms.append(Motion(joint.name, kind, tuple(axis / norm), tuple(np.asarray(joint.anchor, float)),
                             len(joints), float(joint.ref)))
            joints.append(joint)
        motions.append(tuple(ms))
    joint_names = [j.name for j in joints]
    if len(set(joint_names)) != len(joint_names):
        dup = next(n for n in joint_names if joint_names.count(n) > 1)
        raise HandDescriptionError(f"joint {dup!r}: defined twice", field=dup)
    resolved = _resolve(raw.couplings)
    for follower, (leader, _, _) in resolved.items():
        for name in (follower, leader):
            if name not in joint_names:
                raise HandDescriptionError(f"joint {name!r}: named by a coupling but not a movable joint", field=name)
    fixed = dict(raw.fixed_values)
    for j in joints:  # a joint the file locks (equal limits) moves nothing: held there
        if (j.name not in resolved and j.name not in held and j.name not in fixed and j.lower is not None
                and j.upper is not None and math.isfinite(j.lower) and abs(j.upper - j.lower) <= LOCKED_RANGE):
            fixed[j.name] = float(j.lower)
            raw.notes.append(f"joint {j.name}: its limits are equal, held at {j.lower:.4g}")
    fixed.update(_pinned_leaders(raw, joints, resolved, held, fixed))
    actuated = [j for j in joints if j.name not in resolved and j.name not in held and j.name not in fixed]
    lower, upper = [], []
    for j in actuated:
        lo, hi = j.lower, j.upper
        if j.kind == "continuous" and (lo is None or hi is None):
            lo, hi = CONTINUOUS_RANGE
            raw.notes.append(f"joint {j.name}: continuous, range set to [-pi, pi]")
        if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
            raise HandDescriptionError(f"joint {j.name!r}: no limits ({j.source or j.kind})", field=j.name)
        if not lo < hi:
            raise HandDescriptionError(f"joint {j.name!r}: lower limit {lo} is not below upper {hi}", field=j.name)
        lower.append(lo)
        upper.append(hi)
    act_index = {j.name: i for i, j in enumerate(actuated)}
    m, n = len(joints), len(actuated)
    matrix, offset = np.zeros((m, n)), np.zeros(m)
    hold_out = {}
    for r, j in enumerate(joints):
        if j.name in act_index:
            matrix[r, act_index[j.name]] = 1.0
        elif j.name in resolved:
            leader, mult, off = resolved[j.name]
            if leader in act_index:
                matrix[r, act_index[leader]] = mult
                offset[r] = off
            else:  # the leader is held or fixed: the follower is constant
                offset[r] = mult * hold_values.get(leader, fixed.get(leader, 0.0)) + off
        else:
            value = fixed.get(j.name, hold_values.get(j.name))
            if value is None:
                lo = j.lower if j.lower is not None else -math.inf
                hi = j.upper if j.upper is not None else math.inf
                value = float(np.clip(0.0, lo, hi))
            offset[r] = value
            hold_out[j.name] = value
    # A leader's range is narrowed so that its followers stay within their own limits.
    lower_a, upper_a = np.array(lower, float), np.array(upper, float)
    for follower, (leader, mult, off) in resolved.items():
        bounds = _leader_bounds(joints[joint_names.index(follower)], mult, off)
        if leader not in act_index or bounds is None:
            continue
        k = act_index[leader]
        lo, hi = max(lower_a[k], bounds[0]), min(upper_a[k], bounds[1])
        if lo >= hi:  # a coupling that holds the follower outside its limits: said, not fixed
            raw.notes.append(f"joint {follower}: outside its limits for every value of {leader}")
            continue
        if lo > lower_a[k] + 1e-9 or hi < upper_a[k] - 1e-9:
            raw.notes.append(f"joint {leader}: range narrowed to [{lo:.4g}, {hi:.4g}] so that "
                             f"{follower} stays within its limits")
        lower_a[k], upper_a[k] = lo, hi
    direct = {c.follower: c for c in raw.couplings}
    couplings = tuple(Coupling(f, l, mu, o, direct[f].source, direct[f].slack, direct[f].own_effort)
                      for f, (l, mu, o) in resolved.items())
    return Kinematics(tuple(names), tuple(parents), readonly(origins), tuple(motions), tuple(joint_names),
                      tuple(j.name for j in actuated), readonly(lower_a), readonly(upper_a),
                      readonly(matrix), readonly(offset), couplings, hold_out)
