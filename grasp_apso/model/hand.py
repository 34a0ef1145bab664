"""Kinematic model of the five-fingered hand (paper section 3), vectorised over particles.

The hand is data: :func:`load_hand` reads a YAML description (lengths, bases, limits,
coupling ratio, radii) into an immutable :class:`HandModel`. Forward kinematics follows
the Denavit-Hartenberg convention (``T = Rz(theta) Tz(d) Tx(a) Rx(alpha)``): per finger a
fixed base transform, the pivot joint (theta_i3, twist alpha to the flexion axis), the
proximal flexion theta_i2, and the two coupled flexions of eq. 1 (the middle joint turns
by ``coupling_ratio * theta_i1``, the distal joint by theta_i1).

Configuration layout (the paper's Cg, eq. 7, row-major 6x3), radians::

    q[3*i + 0] = theta_i1  distal (coupled) flexion of finger i
    q[3*i + 1] = theta_i2  proximal flexion
    q[3*i + 2] = theta_i3  pivot (abduction)
    q[15:18]   = theta_x, theta_y, theta_z  wrist orientation

with i = 0..4 for little, ring, middle, index, thumb.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import HandDescriptionError

from .particle import LAYOUT
FINGER_NAMES: tuple[str, ...] = ("little", "ring", "middle", "index", "thumb")
JOINT_KINDS: tuple[str, ...] = ("distal", "proximal", "pivot")
WRIST_NAMES: tuple[str, ...] = ("wrist_x", "wrist_y", "wrist_z")
JOINT_NAMES: tuple[str, ...] = tuple(
    f"{finger}_{kind}" for finger in FINGER_NAMES for kind in JOINT_KINDS
) + WRIST_NAMES
N_FINGERS = 5
N_JOINTS = 18
#: Frames returned per finger by :meth:`HandModel.finger_frames`: after the pivot (MCP,
#: thumb CMC), the two intermediate joints, and the fingertip.
FRAME_NAMES: tuple[str, ...] = ("base", "pip", "dip", "tip")


def _readonly(array: Any) -> np.ndarray:
    out = np.array(array, dtype=float)
    out.flags.writeable = False
    return out


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``, angles in rad -> (3, 3)."""
    return wrist_rotation(np.array([roll, pitch, yaw]))


def wrist_rotation(angles: np.ndarray) -> np.ndarray:
    """Rotation matrices ``Rz(tz) @ Ry(ty) @ Rx(tx)`` for wrist angles.

    Parameters
    ----------
    angles : (..., 3) float, rad
        ``(theta_x, theta_y, theta_z)``.

    Returns
    -------
    (..., 3, 3) float
    """
    angles = np.asarray(angles, dtype=float)
    cx, cy, cz = np.cos(angles[..., 0]), np.cos(angles[..., 1]), np.cos(angles[..., 2])
    sx, sy, sz = np.sin(angles[..., 0]), np.sin(angles[..., 1]), np.sin(angles[..., 2])
    out = np.empty(angles.shape[:-1] + (3, 3))
    out[..., 0, 0] = cz * cy
    out[..., 0, 1] = cz * sy * sx - sz * cx
    out[..., 0, 2] = cz * sy * cx + sz * sx
    out[..., 1, 0] = sz * cy
    out[..., 1, 1] = sz * sy * sx + cz * cx
    out[..., 1, 2] = sz * sy * cx - cz * sx
    out[..., 2, 0] = -sy
    out[..., 2, 1] = cy * sx
    out[..., 2, 2] = cy * cx
    return out


def rotation_to_wrist_angles(rot: np.ndarray) -> np.ndarray:
    """Inverse of :func:`grasp_apso.model.hand.wrist_rotation`: (P, 3, 3) -> (P, 3) rad."""
    ty = -np.arcsin(np.clip(rot[:, 2, 0], -1.0, 1.0))
    tx = np.arctan2(rot[:, 2, 1], rot[:, 2, 2])
    tz = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
    return np.stack([tx, ty, tz], axis=1)


def dh_transform(theta: np.ndarray, d: float, a: float, alpha: float) -> np.ndarray:
    """Denavit-Hartenberg transform ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``.

    Parameters
    ----------
    theta : (...) float, rad
    d, a : float, m
    alpha : float, rad

    Returns
    -------
    (..., 4, 4) float
    """
    theta = np.asarray(theta, dtype=float)
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    out = np.zeros(theta.shape + (4, 4))
    out[..., 0, 0] = ct
    out[..., 0, 1] = -st * ca
    out[..., 0, 2] = st * sa
    out[..., 0, 3] = a * ct
    out[..., 1, 0] = st
    out[..., 1, 1] = ct * ca
    out[..., 1, 2] = -ct * sa
    out[..., 1, 3] = a * st
    out[..., 2, 1] = sa
    out[..., 2, 2] = ca
    out[..., 2, 3] = d
    out[..., 3, 3] = 1.0
    return out


@dataclass(frozen=True)
class HandModel:
    """Immutable description of the hand (SI units; arrays are read-only).

    Attributes
    ----------
    name : str
    link_lengths : (5, 3) float, m
        Proximal, middle, distal link per finger (thumb: metacarpal, proximal, distal).
    base_transforms : (5, 4, 4) float
        Finger base frames in the palm frame (x: straight finger, z: pivot axis).
    pivot_twist : (5,) float, rad
        DH twist between the pivot axis and the flexion axis.
    coupling_ratio : float
        Eq. 1: the middle joint turns by ``coupling_ratio * theta_i1``.
    lower, upper : (18,) float, rad
        Joint limits (Table 2 of the paper) and wrist-angle bounds.
    link_radii : (3,) float, m
        Collision radii of proximal, middle and distal links.
    pad_radius : float, m
        Fingertip pad radius (a sphere centred on the tip point).
    palm_center, palm_half_extents : (3,) float, m
        The palm as a box in the palm frame.
    grasp_center : (3,) float, m
        Palm point aimed at the object's centre of mass.
    """

    name: str
    link_lengths: np.ndarray
    base_transforms: np.ndarray
    pivot_twist: np.ndarray
    coupling_ratio: float
    lower: np.ndarray
    upper: np.ndarray
    link_radii: np.ndarray
    pad_radius: float
    palm_center: np.ndarray
    palm_half_extents: np.ndarray
    grasp_center: np.ndarray

    finger_names: tuple[str, ...] = FINGER_NAMES
    joint_names: tuple[str, ...] = JOINT_NAMES

    # ------------------------------------------------------------------ limits
    def validate_configuration(self, q: np.ndarray, field: str = "configuration") -> np.ndarray:
        """Check a (P, 18) or (18,) configuration: finite and within limits (1e-9 rad slack).

        Raises ``ValueError`` naming the first offending joint.
        """
        q = np.asarray(q, dtype=float)
        if q.shape[-1:] != (N_JOINTS,) or q.ndim not in (1, 2):
            raise ValueError(f"{field}: expected shape (18,) or (P, 18), got {q.shape}")
        qq = np.atleast_2d(q)
        bad = ~np.isfinite(qq)
        if bad.any():
            j = int(np.argwhere(bad)[0, 1])
            raise ValueError(f"{field}: {JOINT_NAMES[j]} is not finite")
        over = (qq < self.lower - 1e-9) | (qq > self.upper + 1e-9)
        if over.any():
            p, j = np.argwhere(over)[0]
            raise ValueError(
                f"{field}: {JOINT_NAMES[j]} = {math.degrees(qq[p, j]):.2f} deg outside "
                f"[{math.degrees(self.lower[j]):.1f}, {math.degrees(self.upper[j]):.1f}] deg"
            )
        return q

    def clamp(self, q: np.ndarray) -> np.ndarray:
        """Clamp configurations (..., 18) to the joint limits (returns a new array)."""
        return np.clip(q, self.lower, self.upper)

    # ----------------------------------------------------------- kinematics
    def finger_frames(self, q: np.ndarray) -> np.ndarray:
        """Forward kinematics by DH products for every finger of every particle.

        Parameters
        ----------
        q : (P, 18) or (P, 15) float, rad
            Configurations; only the 15 finger values are used.

        Returns
        -------
        (P, 5, 4, 4, 4) float
            For each particle and finger, the frames ``FRAME_NAMES`` (after the pivot,
            after the proximal link, after the middle link, fingertip) in the palm frame.
        """
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] < 15:
            raise ValueError(f"q: expected (P, 15) or (P, 18), got {q.shape}")
        theta = LAYOUT.finger_values(q)
        t1, t2, t3 = theta[..., 0], theta[..., 1], theta[..., 2]
        frames = np.empty(theta.shape[:2] + (4, 4, 4))
        for f in range(N_FINGERS):
            l1, l2, l3 = self.link_lengths[f]
            pivot = self.base_transforms[f] @ dh_transform(t3[:, f], 0.0, 0.0, self.pivot_twist[f])
            pip = pivot @ dh_transform(t2[:, f], 0.0, l1, 0.0)
            dip = pip @ dh_transform(self.coupling_ratio * t1[:, f], 0.0, l2, 0.0)
            tip = dip @ dh_transform(t1[:, f], 0.0, l3, 0.0)
            frames[:, f] = np.stack([pivot, pip, dip, tip], axis=1)
        return frames

    def flexion_planes(self, pivot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Plane in which each finger flexes, for given pivot angles.

        Parameters
        ----------
        pivot : (P, 5) float, rad

        Returns
        -------
        origin, ex, ey : (P, 5, 3) float
            Finger base (m) and unit axes in the palm frame: ``ex`` the straight finger,
            ``ey`` the direction positive flexion curls toward. A planar point (u, v) of
            :meth:`planar_chain` lies at ``origin + u * ex + v * ey``.
        """
        pivot = np.asarray(pivot, dtype=float)
        c, s = np.cos(pivot), np.sin(pivot)
        base_r = self.base_transforms[:, :3, :3]  # (5, 3, 3)
        bx, by, bz = base_r[:, :, 0], base_r[:, :, 1], base_r[:, :, 2]
        ca = np.cos(self.pivot_twist)[:, None]
        sa = np.sin(self.pivot_twist)[:, None]
        ex = c[..., None] * bx + s[..., None] * by
        y_rot = -s[..., None] * bx + c[..., None] * by
        ey = ca * y_rot + sa * bz
        origin = np.broadcast_to(self.base_transforms[:, :3, 3], ex.shape)
        return origin, ex, ey

    def planar_chain(
        self, distal: np.ndarray, proximal: np.ndarray, fractions: np.ndarray | None = None
    ) -> np.ndarray:
        """Points along the links of each finger in its flexion plane.

        Parameters
        ----------
        distal, proximal : (P, 5, ...) float, rad
            theta_i1 and theta_i2 (any trailing shape, broadcast together).
        fractions : (K, 2) float, optional
            Points to return as (link index 0..2, fraction along the link 0..1); the
            default returns the three joint ends: PIP, DIP, tip.

        Returns
        -------
        (P, 5, ..., K, 2) float, m
            Planar coordinates (u along ``ex``, v along ``ey``).
        """
        distal = np.asarray(distal, dtype=float)
        proximal = np.asarray(proximal, dtype=float)
        distal, proximal = np.broadcast_arrays(distal, proximal)
        if fractions is None:
            fractions = np.array([[0, 1.0], [1, 1.0], [2, 1.0]])
        fractions = np.asarray(fractions, dtype=float)
        extra = distal.ndim - 2
        lengths = self.link_lengths.reshape((1, N_FINGERS) + (1,) * extra + (3,))
        phi = np.stack(
            [proximal, proximal + self.coupling_ratio * distal,
             proximal + (self.coupling_ratio + 1.0) * distal],
            axis=-1,
        )
        cos, sin = np.cos(phi), np.sin(phi)
        seg = np.stack([lengths * cos, lengths * sin], axis=-1)  # (..., 3 links, 2)
        joints = np.concatenate([np.zeros_like(seg[..., :1, :]), np.cumsum(seg, axis=-2)], axis=-2)
        link = fractions[:, 0].astype(int)
        frac = fractions[:, 1]
        return joints[..., link, :] + frac[:, None] * seg[..., link, :]

    def fingertip_positions(self, q: np.ndarray) -> np.ndarray:
        """Fingertip (pad centre) positions in the palm frame.

        q : (P, 18) float, rad -> (P, 5, 3) float, m
        """
        q = np.asarray(q, dtype=float)
        theta = LAYOUT.finger_values(q)
        origin, ex, ey = self.flexion_planes(theta[..., 2])
        uv = self.planar_chain(theta[..., 0], theta[..., 1], np.array([[2, 1.0]]))[..., 0, :]
        return origin + uv[..., :1] * ex + uv[..., 1:] * ey


def _require(mapping: dict, key: str, where: str) -> Any:
    if not isinstance(mapping, dict) or key not in mapping:
        raise HandDescriptionError(f"hand description: missing '{key}' in {where}")
    return mapping[key]


def _vector(value: Any, n: int, field: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise HandDescriptionError(f"hand description: {field} must be {n} numbers") from exc
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise HandDescriptionError(f"hand description: {field} must be {n} finite numbers")
    return arr


def _scalar(value: Any, field: str, low: float, high: float) -> float:
    """A finite number in (low, high], else ValueError naming the field."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise HandDescriptionError(f"hand description: {field} must be a number")
    value = float(value)
    if not math.isfinite(value) or not low < value <= high:
        raise HandDescriptionError(f"hand description: {field} must be in ({low}, {high}]")
    return value


def hand_from_dict(data: dict) -> HandModel:
    """Build a :class:`HandModel` from a parsed description (see ``data/hand.yaml``)."""
    if not isinstance(data, dict):
        raise HandDescriptionError("hand description: expected a mapping at the top level")
    fingers = _require(data, "fingers", "the top level")
    if not isinstance(fingers, list) or [f.get("name") for f in fingers if isinstance(f, dict)] != list(FINGER_NAMES):
        raise HandDescriptionError(f"hand description: fingers must be listed in order {FINGER_NAMES}")
    lengths, bases, twists, lower, upper = [], [], [], [], []
    for finger in fingers:
        where = f"finger '{finger['name']}'"
        links = _vector(_require(finger, "links", where), 3, f"{where} links")
        if np.any(links <= 0) or np.any(links > 0.5):
            raise HandDescriptionError(f"hand description: {where} links must be in (0, 0.5] m")
        lengths.append(links)
        base = np.eye(4)
        rpy = np.radians(_vector(_require(finger, "base_rpy_deg", where), 3, f"{where} base_rpy_deg"))
        base[:3, :3] = rpy_matrix(*rpy)
        base[:3, 3] = _vector(_require(finger, "base_position", where), 3, f"{where} base_position")
        bases.append(base)
        twists.append(math.radians(_scalar(_require(finger, "pivot_twist_deg", where), f"{where} pivot_twist_deg", -360.0, 360.0)))
        limits = _require(finger, "limits_deg", where)
        for kind in JOINT_KINDS:
            lo, hi = _vector(_require(limits, kind, f"{where} limits_deg"), 2, f"{where} limits_deg.{kind}")
            if not lo < hi:
                raise HandDescriptionError(f"hand description: {where} limits_deg.{kind} needs low < high")
            lower.append(math.radians(lo))
            upper.append(math.radians(hi))
    wrist = _require(data, "wrist_limits_deg", "the top level")
    for axis in "xyz":
        lo, hi = _vector(_require(wrist, axis, "wrist_limits_deg"), 2, f"wrist_limits_deg.{axis}")
        if not lo < hi:
            raise HandDescriptionError(f"hand description: wrist_limits_deg.{axis} needs low < high")
        lower.append(math.radians(lo))
        upper.append(math.radians(hi))
    palm = _require(data, "palm", "the top level")
    radii = _vector(_require(data, "link_radii", "the top level"), 3, "link_radii")
    pad = _scalar(_require(data, "pad_radius", "the top level"), "pad_radius", 0.0, 0.1)
    ratio = _scalar(_require(data, "coupling_ratio", "the top level"), "coupling_ratio", 0.0, 10.0)
    if np.any(radii <= 0):
        raise HandDescriptionError("hand description: link_radii must be positive")
    half = _vector(_require(palm, "half_extents", "palm"), 3, "palm.half_extents")
    if np.any(half <= 0):
        raise HandDescriptionError("hand description: palm.half_extents must be positive")
    return HandModel(
        name=str(data.get("name", "hand")),
        link_lengths=_readonly(lengths),
        base_transforms=_readonly(bases),
        pivot_twist=_readonly(twists),
        coupling_ratio=ratio,
        lower=_readonly(lower),
        upper=_readonly(upper),
        link_radii=_readonly(radii),
        pad_radius=pad,
        palm_center=_readonly(_vector(_require(palm, "center", "palm"), 3, "palm.center")),
        palm_half_extents=_readonly(half),
        grasp_center=_readonly(_vector(_require(data, "grasp_center", "the top level"), 3, "grasp_center")),
    )


def default_hand_path() -> Path:
    """Path of the hand description shipped in the package."""
    return Path(str(resources.files("grasp_apso").joinpath("data", "hand.yaml")))


def load_hand(path: str | Path | None = None) -> HandModel:
    """Load a hand description file (YAML); ``None`` loads the shipped paper hand.

    Models are immutable and cached per file (path, modification time and size).
    """
    path = default_hand_path() if path is None or str(path) == "" else Path(path)
    try:
        stat = path.stat()
    except OSError as exc:
        raise HandDescriptionError(f"hand description: cannot read {path}: {exc.strerror}") from exc
    return _load_hand_cached(str(path.resolve()), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=16)
def _load_hand_cached(path_str: str, _mtime_ns: int, _size: int) -> HandModel:
    path = Path(path_str)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise HandDescriptionError(f"hand description: cannot read {path}: {exc.strerror}") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        # The parser's text quotes the file: name the line only, never the content.
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        raise HandDescriptionError(f"hand description: {path} is not valid YAML{where}") from None
    return hand_from_dict(data)
