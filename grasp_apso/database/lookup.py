"""The reader for the node: :class:`GraspDatabase` answers "grasps for this mesh and hand, at
this pose, in this scene" from a grasp database in milliseconds.

::

    db = GraspDatabase.open("grasps.db")          # validates; DatabaseError names grasp_database
    cands = db.lookup(obj.mesh_hash, hand.name, pose, scene, clearance=0.005,
                      approach_distance=0.08, max_grasps=5)

:meth:`GraspDatabase.open` reads every grasp part file once into an in-memory index keyed
by ``(mesh_hash, hand_name)`` (numpy arrays per key, best first). :meth:`GraspDatabase.lookup`
moves the stored grasps to the request pose (``wrist_pose = pose @ wrist_in_object``; the
planning-frame wrist angles, the pre-grasp pose for the request's approach distance, the
approach, contacts and finger points recomputed), re-checks each against the request's
scene with python-fcl (:mod:`grasp_apso.geometry.hand_fcl`: the whole hand at the grasp keeps
``clearance`` from the scene, and the straight approach from the pre-grasp is clear) and
returns the first ``max_grasps`` that pass, as :class:`~grasp_apso.search.result.GraspCandidate`
s ranked: force closure first, then held in simulation, not simulated, dropped, then
``grasp_quality`` and ``fitness`` (descending). Only ``valid`` stored grasps are returned.

The object's own part of the approach was checked when the grasp was planned (it does not
depend on the pose); pass ``obj_bvh`` to check it again, e.g. for a longer approach distance.
The database is read once: grasps written after :meth:`open` are not seen (open it again).

A database is opened for one hand and sees only that hand's rows: those whose ``hand_hash``
is the hand's (:class:`~grasp_apso.model.planning_hand.PlanningHand`; rows of schema 1 are
the shipped paper hand's). A general hand's grasps are re-checked against the scene with its
exact collision geometry (:mod:`grasp_apso.geometry.any_hand_fcl`).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from scipy.spatial.transform import Rotation

from ..errors import DatabaseError, InputError
from ..model.hand import HandModel
from ..model.planning_hand import PlanningHand, is_general_hand, load_planning_hand, paper_hand_hash
from ..search.candidates import planning_joint_positions, pre_grasp_pose
from ..search.result import SIM_DROPPED, SIM_HELD, Contact, GraspCandidate
from .schema import GRASP_SCHEMA
from .store import MARKER, GraspStore, read_file

__all__ = ["GraspDatabase", "FIELD"]

#: The node parameter named by every error of the reader.
FIELD = "grasp_database"

_COLUMNS = [
    "object_id", "mesh_hash", "hand_name", "hand_hash", "options_key", "rank", "joint_positions",
    "pre_grasp_positions", "wrist_position", "wrist_quaternion", "approach_distance",
    "grasp_quality", "fitness", "epsilon", "force_closure", "valid", "scene_distance", "sim_result",
    "sim_max_shift", "sim_max_turn", "contact_points", "contact_normals", "contact_fingers",
]


@dataclass(frozen=True)
class _Entry:
    """The stored grasps of one (mesh_hash, hand_name), best first (n rows)."""

    object_id: str
    wrist: np.ndarray          # (n, 4, 4) palm frame in the object frame
    closed: np.ndarray         # (n, J) grasp posture (the paper hand: object-frame wrist angles)
    opened: np.ndarray         # (n, J) pre-shape
    grasp_quality: np.ndarray
    fitness: np.ndarray
    epsilon: np.ndarray
    force_closure: np.ndarray
    sim_result: np.ndarray
    sim_max_shift: np.ndarray
    sim_max_turn: np.ndarray
    contact_range: np.ndarray  # (n, 2) start, stop into the shared contact arrays
    contact_points: np.ndarray  # (M, 3) all contacts of the database, object frame (shared)
    contact_normals: np.ndarray  # (M, 3)
    contact_fingers: np.ndarray  # (M,) str

    def __len__(self) -> int:
        return len(self.wrist)


class GraspDatabase:
    """An opened grasp database (read-only, in memory). Build it with :meth:`open`."""

    def __init__(self, path: Path, entries: dict[tuple[str, str], _Entry], rows: int, seconds: float,
                 hand: PlanningHand, other_rows: int = 0):
        self.path = path
        self._entries = entries
        self.rows = rows
        self.load_seconds = seconds
        self.planning_hand = hand
        self.hand = hand.hand
        #: Rows of other hands (another ``hand_hash``), never answered.
        self.other_rows = other_rows
        self._general = is_general_hand(self.hand)
        self._frames: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, path: str | os.PathLike, hand: Any = None) -> "GraspDatabase":
        """Read and index a grasp database: a directory written by ``grasp_apso_batch``, or a
        single Parquet file with the grasps table's columns.

        Parameters
        ----------
        path : path
        hand : PlanningHand or HandModel, optional
            The hand whose grasps are looked up (only rows of its ``hand_hash``; finger
            points, scene checks); default the shipped paper hand. A paper ``HandModel`` is
            taken as the shipped one's hash (pass a PlanningHand for another YAML).

        Raises
        ------
        DatabaseError
            ``grasp_database: ...``: missing path, not a grasp database, a corrupt or
            unreadable part file, a column missing or of the wrong type, bad values.
        """
        t0 = time.perf_counter()
        p = Path(os.fspath(path)) if str(path).strip() else None
        if p is None:
            raise DatabaseError(f"{FIELD}: empty path", FIELD)
        want = pa.schema([GRASP_SCHEMA.field(c) for c in _COLUMNS])
        if p.is_dir():
            store = GraspStore(p, field=FIELD)
            store.check_marker()
            table = store.read("grasps", _COLUMNS)
        elif p.is_file():
            table = read_file(p, want, FIELD)
        else:
            raise DatabaseError(f"{FIELD}: {p} does not exist (expected a grasp database directory "
                                f"with {MARKER}, or a Parquet file)", FIELD)
        planning = _planning_hand(hand)
        n_joints = len(planning.joint_names)
        mine = np.asarray(table.column("hand_hash").to_numpy(zero_copy_only=False), dtype=object) == planning.hash
        entries = _index(table.filter(pa.array(mine, pa.bool_())), p, n_joints)
        return cls(p, entries, int(mine.sum()), time.perf_counter() - t0, planning,
                   other_rows=int(table.num_rows - mine.sum()))

    # ------------------------------------------------------------------ queries
    def __len__(self) -> int:
        return len(self._entries)

    def __contains__(self, key: tuple[str, str]) -> bool:
        return tuple(key) in self._entries

    def keys(self) -> list[tuple[str, str]]:
        """The stored (mesh_hash, hand_name) pairs."""
        return list(self._entries)

    def count(self, mesh_hash: str, hand_name: str) -> int:
        """Number of valid stored grasps of an object (0 when unknown)."""
        entry = self._entries.get((mesh_hash, hand_name))
        return 0 if entry is None else len(entry)

    def lookup(
        self,
        mesh_hash: str,
        hand_name: str,
        pose: np.ndarray,
        scene: Any = None,
        clearance: float = 0.005,
        approach_distance: float = 0.08,
        max_grasps: int = 5,
        *,
        obj_bvh: Any = None,
        obj: Any = None,
    ) -> list[GraspCandidate]:
        """Stored grasps of an object moved to ``pose`` and filtered by ``scene``, best first.

        Parameters
        ----------
        mesh_hash : str
            :attr:`GraspObject.mesh_hash` of the request's object.
        hand_name : str
            Must be the name of this database's hand to find anything.
        pose : (4, 4) float
            Object frame -> planning frame.
        scene : Scene or None
            Support planes and obstacles in the planning frame; None or empty: no checks.
        clearance : float, m
            Least distance between the hand and the scene, at the grasp and along the approach.
        approach_distance : float, m
            Pre-grasp retreat of the returned candidates (and the approach checked).
        max_grasps : int
            At most this many candidates.
        obj_bvh : fcl.BVHModel, optional
            The object's mesh in the object frame, to check the approach against it too.
        obj : GraspObject, optional
            The same for a general hand (:func:`grasp_apso.geometry.any_hand_fcl.approach_report`
            takes the object itself).

        Returns
        -------
        list of GraspCandidate
            Empty when the object is unknown or no stored grasp survives the scene.

        Raises
        ------
        InputError
            A bad ``pose``, ``clearance``, ``approach_distance`` or ``max_grasps`` (named).
        """
        pose = _check_pose(pose)
        clearance = _nonnegative(clearance, "clearance")
        approach_distance = _nonnegative(approach_distance, "approach_distance")
        if isinstance(max_grasps, bool) or not isinstance(max_grasps, (int, np.integer)) or max_grasps < 1:
            raise InputError(f"max_grasps: expected a positive integer, got {max_grasps!r}", "max_grasps")
        key = (str(mesh_hash), str(hand_name))
        entry = self._entries.get(key)
        if entry is None or hand_name != self.hand.name:
            return []
        check_scene = scene is not None and not scene.is_empty
        if check_scene and not self._general:
            from ..geometry.hand_fcl import approach_report, hand_scene_distance
        closed_pts, open_pts = self._finger_points(key, entry)
        rot, trans = pose[:3, :3], pose[:3, 3]
        out: list[GraspCandidate] = []
        for i in range(len(entry)):
            wrist = pose @ entry.wrist[i]
            scene_distance = math.inf
            if check_scene and self._general:
                scene_distance = self._general_scene_distance(entry, i, wrist, scene, pose, obj, clearance,
                                                              approach_distance)
                if not scene_distance >= clearance:
                    continue
            elif check_scene:
                d = hand_scene_distance(self.hand, entry.closed[i], wrist, scene)
                if not d >= clearance:
                    continue
                report = approach_report(self.hand, entry.opened[i], wrist, approach_distance, scene,
                                         obj_bvh, pose if obj_bvh is not None else None, clearance)
                if not report.clear:
                    continue
                scene_distance = min(d, report.min_scene_distance)
            pre = self._pre_grasp_pose(wrist, approach_distance)
            a, b = entry.contact_range[i]
            points = entry.contact_points[a:b] @ rot.T + trans
            normals = entry.contact_normals[a:b] @ rot.T
            contacts = tuple(Contact(finger=str(f), position=p, normal=n)
                             for f, p, n in zip(entry.contact_fingers[a:b], points, normals))
            rank = len(out)
            out.append(GraspCandidate(
                id=f"g{rank}", rank=rank,
                joint_positions=self._joints(entry.closed[i], wrist),
                pre_grasp_positions=self._joints(entry.opened[i], wrist),
                wrist_pose=wrist, pre_grasp_pose=pre,
                approach_distance=float(approach_distance),
                grasp_quality=float(entry.grasp_quality[i]), fitness=float(entry.fitness[i]),
                epsilon=float(entry.epsilon[i]), force_closure=bool(entry.force_closure[i]), valid=True,
                contacts=contacts, scene_distance=float(scene_distance),
                sim_result=int(entry.sim_result[i]), sim_max_shift=float(entry.sim_max_shift[i]),
                sim_max_turn=float(entry.sim_max_turn[i]), wrist_in_object=entry.wrist[i].copy(),
                joints=closed_pts[i] @ wrist[:3, :3].T + wrist[:3, 3],
                pre_grasp_joints=open_pts[i] @ pre[:3, :3].T + pre[:3, 3],
                approach=self._approach(wrist),
            ))
            if len(out) == max_grasps:
                break
        return out

    def _joints(self, q: np.ndarray, wrist: np.ndarray) -> np.ndarray:
        """Stored joints -> the reply's: the paper hand's wrist angles for the planning frame."""
        return np.array(q, dtype=float) if self._general else planning_joint_positions(q, wrist)

    def _approach(self, wrist: np.ndarray) -> np.ndarray:
        """Unit approach: the palm normal in the planning frame (the paper palm's +z)."""
        if not self._general:
            return wrist[:3, 2].copy()
        n = wrist[:3, :3] @ np.asarray(self.hand.palm_normal, float)
        return n / np.linalg.norm(n)

    def _pre_grasp_pose(self, wrist: np.ndarray, distance: float) -> np.ndarray:
        if not self._general:
            return pre_grasp_pose(wrist, distance)
        pre = wrist.copy()
        pre[:3, 3] -= distance * self._approach(wrist)
        return pre

    def _general_scene_distance(self, entry: _Entry, i: int, wrist: np.ndarray, scene: Any, pose: np.ndarray,
                                obj: Any, clearance: float, approach_distance: float) -> float:
        """A general hand's least distance to the scene at the grasp and along the approach
        (python-fcl on its exact geometry); -inf when the approach hits the object early."""
        from ..geometry.any_hand_fcl import HandCollision, approach_report, scene_distance

        hc = HandCollision(self.hand)  # built once per hand (cached by its source_hash)
        d = scene_distance(hc, entry.closed[i], wrist, scene)
        if not d >= clearance:
            return d
        report = approach_report(hc, entry.opened[i], wrist, self._approach(wrist), approach_distance, scene,
                                 obj, pose if obj is not None else None, clearance=clearance)
        if report.hits_object:
            return -math.inf
        return min(d, float(report.min_scene_distance))

    def _finger_points(self, key: tuple[str, str], entry: _Entry) -> tuple[np.ndarray, np.ndarray]:
        """Finger points (n, 5, 4, 3) in the palm frame, closed and open (computed once);
        (n, 0, 4, 3) for a general hand (drawn from its own geometry)."""
        if self._general:
            empty = np.zeros((len(entry), 0, 4, 3))
            return empty, empty
        cached = self._frames.get(key)
        if cached is None:
            closed = self.hand.finger_frames(entry.closed)[..., :3, 3]
            opened = self.hand.finger_frames(entry.opened)[..., :3, 3]
            cached = self._frames[key] = (closed, opened)
        return cached


# ---------------------------------------------------------------------- building the index
def _planning_hand(hand: Any) -> PlanningHand:
    """The hand a database is opened for, with its identity (see :meth:`GraspDatabase.open`)."""
    if isinstance(hand, PlanningHand):
        return hand
    if hand is None:
        return load_planning_hand(None)
    if is_general_hand(hand):
        return PlanningHand(hand, hand.name, hand.source_hash)
    if isinstance(hand, HandModel):
        return PlanningHand(hand, hand.name, paper_hand_hash())
    raise InputError(f"hand: expected a PlanningHand or HandModel, got {type(hand).__name__}", "hand")


def _index(table: pa.Table, path: Path, n_joints: int = 18) -> dict[tuple[str, str], _Entry]:
    """Group the valid rows of one hand by (mesh_hash, hand_name), best first, as numpy
    arrays; every joint vector must hold ``n_joints`` values."""
    if table.num_rows == 0:
        return {}
    cols = {name: table.column(name).combine_chunks() for name in _COLUMNS}

    def fixed(name: str, n: int) -> np.ndarray:
        column = cols[name]
        if pa.types.is_list(column.type):
            lengths = np.diff(column.offsets.to_numpy())
            if np.any(lengths != n):
                raise ValueError(f"{name}: rows of {sorted(set(lengths.tolist()) - {n})} values, the hand has {n}")
        flat = column.flatten().to_numpy(zero_copy_only=False)
        return np.asarray(flat, dtype=float).reshape(-1, n)

    def plain(name: str, dtype) -> np.ndarray:
        return np.asarray(cols[name].to_numpy(zero_copy_only=False), dtype=dtype)

    try:
        closed, opened = fixed("joint_positions", n_joints), fixed("pre_grasp_positions", n_joints)
        position, quat = fixed("wrist_position", 3), fixed("wrist_quaternion", 4)
        if not (np.all(np.isfinite(closed)) and np.all(np.isfinite(opened)) and np.all(np.isfinite(position))):
            raise ValueError("non-finite joint or wrist values")
        norms = np.linalg.norm(quat, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-3):
            raise ValueError("wrist_quaternion is not unit")
        wrist = np.tile(np.eye(4), (len(quat), 1, 1))
        wrist[:, :3, :3] = Rotation.from_quat(quat / norms[:, None]).as_matrix()
        wrist[:, :3, 3] = position
        offsets = cols["contact_points"].offsets.to_numpy()
        if not (np.array_equal(offsets, cols["contact_normals"].offsets.to_numpy())
                and np.array_equal(offsets, cols["contact_fingers"].offsets.to_numpy())):
            raise ValueError("contact_points, contact_normals and contact_fingers differ in length")
        base = offsets[0]
        points = np.asarray(cols["contact_points"].flatten().flatten().to_numpy(zero_copy_only=False),
                            float).reshape(-1, 3)
        normals = np.asarray(cols["contact_normals"].flatten().flatten().to_numpy(zero_copy_only=False),
                             float).reshape(-1, 3)
        fingers = np.asarray(cols["contact_fingers"].flatten().to_numpy(zero_copy_only=False), dtype=object)
        ranges = np.stack([offsets[:-1] - base, offsets[1:] - base], axis=1)
    except (ValueError, pa.ArrowException) as exc:
        raise DatabaseError(f"{FIELD}: {path}: bad grasp rows: {exc}", FIELD) from None
    valid = plain("valid", bool)
    quality, fitness = plain("grasp_quality", float), plain("fitness", float)
    closure, sim = plain("force_closure", bool), plain("sim_result", int)
    epsilon, shift, turn = plain("epsilon", float), plain("sim_max_shift", float), plain("sim_max_turn", float)
    object_ids = plain("object_id", object)
    keys = np.char.add(np.char.add(plain("mesh_hash", str), "\n"), plain("hand_name", str))
    sim_order = np.where(sim == SIM_HELD, 0, np.where(sim == SIM_DROPPED, 2, 1))
    rows = np.flatnonzero(valid)
    # One sort: by key, then the planner's own rank (its order is the ranking, with the
    # swarm's best first in free space), then simulation, force closure and quality for
    # grasps of different batches with the same rank.
    rank = plain("rank", int)
    order = rows[np.lexsort((-fitness[rows], -quality[rows], ~closure[rows], sim_order[rows], rank[rows],
                             keys[rows]))]
    sorted_keys = keys[order]
    cuts = np.flatnonzero(sorted_keys[1:] != sorted_keys[:-1]) + 1
    entries = {}
    for group in np.split(order, cuts):
        if not len(group):
            continue
        mesh_hash, hand_name = str(keys[group[0]]).split("\n", 1)
        entries[(mesh_hash, hand_name)] = _Entry(
            object_id=str(object_ids[group[0]]), wrist=wrist[group], closed=closed[group],
            opened=opened[group], grasp_quality=quality[group], fitness=fitness[group],
            epsilon=epsilon[group], force_closure=closure[group], sim_result=sim[group],
            sim_max_shift=shift[group], sim_max_turn=turn[group], contact_range=ranges[group],
            contact_points=points, contact_normals=normals, contact_fingers=fingers,
        )
    return entries


def _check_pose(pose: Any) -> np.ndarray:
    try:
        m = np.asarray(pose, dtype=float)
    except (TypeError, ValueError):
        raise InputError("pose: expected a (4, 4) transform", "pose") from None
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InputError(f"pose: expected a finite (4, 4) transform, got shape {m.shape}", "pose")
    if not np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-6) or np.linalg.det(m[:3, :3]) <= 0:
        raise InputError("pose: the rotation block is not a rotation", "pose")
    return m


def _nonnegative(value: Any, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r}", name) from None
    if not (v >= 0 and math.isfinite(v)):
        raise InputError(f"{name}: expected a finite number >= 0, got {value!r}", name)
    return v
