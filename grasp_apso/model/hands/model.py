"""The general hand model (DESIGN.md Part 3): :class:`HandModel` and :class:`Finger`.

A hand is a kinematic tree of links. Each link has a fixed ``origin`` (its frame in the
parent link's frame at zero motion) followed by zero or more joint motions (URDF: one per
joint; MJCF: a body may carry several hinges/slides, applied in order). Every movable
joint of the file has a value in the *full* vector; the actuated positions ``q`` (n,)
map to it linearly: ``full = A @ q + b`` (followers of a coupling are ``multiplier *
leader + offset``; joints above the root are held at a constant). Poses are returned in
the root link's frame.

Immutable: every array is read-only; built once per hand by :func:`.load.load_hand`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Mapping

import numpy as np

from ...errors import InputError
from .fk_kernel import FlatTree, flat_tree, link_poses
from .geometry import LinkGeometry

__all__ = ["Finger", "Coupling", "Motion", "HandModel", "readonly"]


def readonly(array, dtype=float) -> np.ndarray:
    """A read-only copy of ``array``."""
    out = np.array(array, dtype=dtype)
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class Finger:
    """One finger: the chain from the root (palm) to ``tip_link``.

    Attributes
    ----------
    name : str
    tip_link : str
        The last link of the chain with collision geometry.
    joints : tuple of str
        The actuated joints that move the chain (root to tip order).
    closing : tuple of int
        Per joint of ``joints``: +1 / -1 the sense that closes the finger, 0 for a
        pre-shape joint (abduction, thumb rotation) that does not close.
    pad_link : str
    pad_center : (3,) float, m
        The pad point in the pad link's frame.
    pad_radius : float, m
        Radius of curvature of the surface at the pad.
    is_thumb : bool
    """

    name: str
    tip_link: str
    joints: tuple[str, ...]
    closing: tuple[int, ...]
    pad_link: str
    pad_center: np.ndarray
    pad_radius: float
    is_thumb: bool = False


@dataclass(frozen=True)
class Coupling:
    """``follower = multiplier * leader + offset`` (rad or m), from ``source``.

    ``slack`` (rad or m): the play the file leaves the follower either side of that value
    (a limited tendon's range; 0 for an equality or a URDF mimic). A follower with play
    lags its leader: the closing drags it along the edge of its play behind the motion,
    and the loaded hand's ``offset`` is that edge's
    (:func:`~.description.lagging_couplings`).

    ``own_effort``: the follower bears an effort limit of its own (a URDF gives every
    joint, a mimic one too, its ``<limit effort>``), so a servo on the leader may load each
    joint it drives to a servo's limit (:attr:`HandModel.servo_force_scale`); False when one
    actuator on the leader drives the chain through an equality or a tendon (an MJCF: its
    ``forcerange`` bounds the whole chain)."""

    follower: str
    leader: str
    multiplier: float
    offset: float
    source: str
    slack: float = 0.0
    own_effort: bool = False


@dataclass(frozen=True)
class Motion:
    """One joint motion of a link: ``kind`` "revolute" (about ``axis`` through ``anchor``)
    or "prismatic" (along ``axis``), by ``full[index] - ref``; ``axis`` unit, link frame."""

    joint: str
    kind: str
    axis: tuple[float, float, float]
    anchor: tuple[float, float, float]
    index: int
    ref: float = 0.0


@dataclass(frozen=True, eq=False)
class HandModel:
    """A robot hand loaded from its description, with its derived grasp semantics.

    Attributes
    ----------
    name : str
    root_link : str
        The palm: the link where the finger chains branch; poses are in its frame.
    actuated_joints : tuple of str
        The joints a JointState carries (file order; followers and held joints excluded).
    lower, upper : (n,) float, rad or m
    fingers : tuple of Finger
    palm_normal : (3,) float
        Root frame: the side the fingers close toward.
    links : tuple of str
        Every link, parents before children.
    link_parents : tuple of int
        Index of each link's parent in ``links`` (-1 for the top link).
    collision : mapping link -> tuple of LinkGeometry (link frame)
    spheres : mapping link -> SphereCover
    couplings : tuple of Coupling
    held_joints : mapping joint -> value
        Joints above the root: fixed, not actuated for grasping.
    notes : tuple of str
        What the loader decided on its own (defaults, ignored elements).
    source_hash : str
        sha256 of the description file's content and the config.
    source_path : str
        The description file it was loaded from (absolute; "" when built from data):
        the simulation compiles the hand from it.
    """

    name: str
    root_link: str
    actuated_joints: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    fingers: tuple[Finger, ...]
    palm_normal: np.ndarray
    links: tuple[str, ...]
    link_parents: tuple[int, ...]
    collision: Mapping[str, tuple[LinkGeometry, ...]]
    spheres: Mapping[str, object]
    couplings: tuple[Coupling, ...]
    held_joints: Mapping[str, float]
    notes: tuple[str, ...]
    source_hash: str
    joint_names: tuple[str, ...] = field(repr=False, default=())
    origins: np.ndarray = field(repr=False, default=None)
    motions: tuple[tuple[Motion, ...], ...] = field(repr=False, default=())
    full_matrix: np.ndarray = field(repr=False, default=None)
    full_offset: np.ndarray = field(repr=False, default=None)
    root_inverse: np.ndarray = field(repr=False, default=None)
    source_path: str = ""

    # ------------------------------------------------------------------ kinematics
    @property
    def n_joints(self) -> int:
        """Number of actuated joints n."""
        return len(self.actuated_joints)

    def full_positions(self, q: np.ndarray) -> np.ndarray:
        """Every movable joint's value (followers and held joints included).

        q : (n,) or (P, n) float -> (m,) or (P, m) float, ordered as ``joint_names``.
        """
        q = np.asarray(q, dtype=float)
        return q @ self.full_matrix.T + self.full_offset

    def link_transforms_batch(self, q: np.ndarray) -> np.ndarray:
        """Poses of every link in the root frame.

        q : (P, n) float, rad or m -> (P, L, 4, 4) float (``links`` order).
        """
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.n_joints:
            raise InputError(f"q: expected shape (P, {self.n_joints}), got {q.shape}", "q")
        return link_poses(self._tree, self.full_positions(q))

    @cached_property
    def servo_weight(self) -> np.ndarray:
        """(n,) float: how much stiffer a position servo on each actuated joint is made so
        that it holds every joint it drives as stiffly as a servo holds a joint of its own:
        the sum of squares of the joint's column of ``full_matrix`` (1 for a joint that moves
        only itself; 1 + sum r^2 for a leader whose followers move r times as far: held in its
        own angle, such a leader's chain is 1 + sum r^2 times as soft)."""
        weight = (np.asarray(self.full_matrix, dtype=float) ** 2).sum(axis=0)
        weight.flags.writeable = False
        return weight

    @cached_property
    def servo_force_scale(self) -> np.ndarray:
        """(n,) float: how much more torque a position servo on each actuated joint may exert
        than a servo's limit. A leader whose followers each bear an effort limit of their
        own (:attr:`Coupling.own_effort`: a URDF's mimic joints) may load the most loaded
        joint it drives to that limit: the servo's torque ``t`` loads joint i with
        ``t r_i / sum r^2`` (the stiffness of :attr:`servo_weight` shared by virtual work),
        so ``sum r^2 / max |r|``. 1 for a joint that moves only itself, and for a leader
        that drives a follower through the file's one actuator (an MJCF's equality or
        tendon: that actuator's limit bounds the chain)."""
        scale = self.servo_weight / np.abs(np.asarray(self.full_matrix, dtype=float)).max(axis=0)
        for c in self.couplings:
            if not c.own_effort and c.leader in self.actuated_joints:
                scale[self.actuated_joints.index(c.leader)] = 1.0
        scale.flags.writeable = False
        return scale

    @cached_property
    def _tree(self) -> FlatTree:
        """The kinematic tree flattened for the compiled walk (once per model; a model
        made by ``replace`` flattens its own)."""
        return flat_tree(self.link_parents, self.origins, self.motions, self.root_inverse)

    def link_transforms(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Every link's pose in the root frame: q (n,) -> {link: (4, 4)}, couplings applied."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n_joints,):
            raise InputError(f"q: expected shape ({self.n_joints},), got {q.shape}", "q")
        poses = self.link_transforms_batch(q[None])[0]
        return {name: poses[i] for i, name in enumerate(self.links)}

    # ------------------------------------------------------------------ structure
    def link_index(self, link: str) -> int:
        """Index of ``link`` in ``links`` (KeyError naming it when unknown)."""
        try:
            return self.links.index(link)
        except ValueError:
            raise KeyError(f"link {link!r} is not a link of hand {self.name!r}") from None

    def chain(self, link: str) -> tuple[str, ...]:
        """The links from the top of the tree down to ``link`` (inclusive)."""
        out = []
        i = self.link_index(link)
        while i >= 0:
            out.append(self.links[i])
            i = self.link_parents[i]
        return tuple(reversed(out))

    def finger_links(self, finger: Finger | str) -> tuple[str, ...]:
        """The links a finger moves: its chain below the root down to the tip, then, in
        ``links`` order (parents first), the tip's descendants and the links fixed to a
        chain link the finger's joints move (no joint between them: a phalanx's shells, a
        fingertip's nail or sensor plate fixed beside the tip link). DexRobot's DexHand021
        fixes two shells to each phalanx and its tactile pad beside the fingertip; read as
        the palm's, they stayed where the open finger holds them."""
        tip = finger.tip_link if isinstance(finger, Finger) else self.finger(finger).tip_link
        path = self.chain(tip)
        below = path[path.index(self.root_link) + 1:]
        tip_i = self.link_index(tip)
        moved = self._moved_chain(below)
        extra = [name for i, name in enumerate(self.links) if name not in below and (
            self._descends(i, tip_i) or self.rigid_base(i) in moved)]
        return tuple(below) + tuple(extra)

    def _moved_chain(self, below: tuple[str, ...]) -> set[int]:
        """Indices of the chain links ``below`` the root from the first one a joint moves on."""
        first = next((k for k, name in enumerate(below) if self.motions[self.link_index(name)]), len(below))
        return {self.link_index(name) for name in below[first:]}

    def rigid_base(self, i: int) -> int:
        """The index of the nearest link at or above link ``i`` (an index of ``links``) that
        a joint moves: the link whose motion ``i`` shares (-1: none, the top)."""
        while i >= 0 and not self.motions[i]:
            i = self.link_parents[i]
        return i

    def _descends(self, i: int, ancestor: int) -> bool:
        while i >= 0:
            if i == ancestor:
                return True
            i = self.link_parents[i]
        return False

    def finger(self, name: str) -> Finger:
        """The finger called ``name``."""
        for f in self.fingers:
            if f.name == name:
                return f
        raise KeyError(f"finger {name!r} is not a finger of hand {self.name!r}")

    @property
    def thumb(self) -> Finger | None:
        """The finger that opposes the others."""
        return next((f for f in self.fingers if f.is_thumb), None)

    def open_configuration(self) -> np.ndarray:
        """Every finger straight: each joint at the limit opposite its closing sense, 0
        clipped into range for pre-shape joints. (n,) float."""
        return self._posture(0.0)

    def closed_configuration(self, fraction: float = 0.8) -> np.ndarray:
        """Every closing joint ``fraction`` of the way to its closing limit (n,)."""
        return self._posture(fraction)

    def _posture(self, fraction: float) -> np.ndarray:
        q = np.clip(0.0, self.lower, self.upper)
        for finger in self.fingers:
            for joint, sense in zip(finger.joints, finger.closing):
                j = self.actuated_joints.index(joint)
                if sense == 0:
                    continue
                start = q[j]
                target = self.upper[j] if sense > 0 else self.lower[j]
                q[j] = start + fraction * (target - start)
        return q
