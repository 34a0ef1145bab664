"""The grasp database's tables: Arrow schemas and the conversion of planned candidates to rows.

Poses are stored in the OBJECT frame, so a stored grasp can be moved to any request pose
(``wrist_pose = pose @ wrist_in_object``). The paper hand's joint vectors (18 values) end
with wrist angles of the object frame (the plan pose taken as identity); the reader
recomputes them for the request's planning frame. A general hand's vectors are its
``actuated_joints`` (no wrist angles; ``wrist_*`` is its root link). Every row names its
hand: ``hand_name`` and ``hand_hash`` (:mod:`grasp_apso.model.planning_hand`).
Units: metres, radians, seconds; quaternions (x, y, z, w).
See :mod:`grasp_apso.database` for the column table.

Schema versions: 1 had ``joint_positions`` / ``pre_grasp_positions`` as float64[18] and no
``hand_hash``; its files are read as the shipped paper hand's rows (:data:`LEGACY_DEFAULTS`,
:func:`~grasp_apso.database.store.read_file`).
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Iterable

import numpy as np
import pyarrow as pa

from ..model.hand import JOINT_NAMES
from ..model.poses import matrix_to_pose
from ..search.candidates import planning_joint_positions
from ..search.result import GraspCandidate

__all__ = [
    "FORMAT_NAME", "SCHEMA_VERSION", "GRASP_SCHEMA", "FAILURE_SCHEMA", "LEGACY_DEFAULTS", "candidate_rows",
    "options_key", "empty_columns", "rigid_inverse",
]

#: Written into the marker file and every Parquet file's metadata.
FORMAT_NAME = "grasp_apso.grasp_database"
SCHEMA_VERSION = 2

_F64 = pa.float64()


def _vec(n: int) -> pa.DataType:
    return pa.list_(_F64, n)


#: One row per stored grasp.
GRASP_SCHEMA = pa.schema(
    [
        pa.field("object_id", pa.string(), nullable=False),
        pa.field("source_path", pa.string()),
        pa.field("source_sha256", pa.string(), nullable=False),
        pa.field("scale", _F64, nullable=False),
        pa.field("mesh_hash", pa.string(), nullable=False),
        pa.field("hand_name", pa.string(), nullable=False),
        pa.field("hand_hash", pa.string(), nullable=False),
        pa.field("options_key", pa.string(), nullable=False),
        pa.field("rank", pa.int32(), nullable=False),
        pa.field("joint_positions", pa.list_(_F64), nullable=False),
        pa.field("pre_grasp_positions", pa.list_(_F64), nullable=False),
        pa.field("wrist_position", _vec(3), nullable=False),
        pa.field("wrist_quaternion", _vec(4), nullable=False),
        pa.field("pre_grasp_position", _vec(3), nullable=False),
        pa.field("pre_grasp_quaternion", _vec(4), nullable=False),
        pa.field("approach", _vec(3), nullable=False),
        pa.field("approach_distance", _F64, nullable=False),
        pa.field("grasp_quality", _F64, nullable=False),
        pa.field("fitness", _F64, nullable=False),
        pa.field("epsilon", _F64, nullable=False),
        pa.field("force_closure", pa.bool_(), nullable=False),
        pa.field("valid", pa.bool_(), nullable=False),
        pa.field("scene_distance", _F64, nullable=False),
        pa.field("sim_result", pa.int8(), nullable=False),
        pa.field("sim_max_shift", _F64, nullable=False),
        pa.field("sim_max_turn", _F64, nullable=False),
        pa.field("contact_points", pa.list_(_vec(3)), nullable=False),
        pa.field("contact_normals", pa.list_(_vec(3)), nullable=False),
        pa.field("contact_fingers", pa.list_(pa.string()), nullable=False),
        pa.field("options", pa.string(), nullable=False),
        pa.field("seed", pa.int64(), nullable=False),
        pa.field("package_version", pa.string(), nullable=False),
        pa.field("planning_time", _F64, nullable=False),
        pa.field("created", pa.timestamp("us", tz="UTC"), nullable=False),
    ],
    metadata={
        "format": FORMAT_NAME, "schema_version": str(SCHEMA_VERSION), "table": "grasps",
        # The paper hand's; a general hand's rows follow its actuated_joints.
        "joint_names": json.dumps(list(JOINT_NAMES)),
    },
)


def _paper_hash() -> str:
    from ..model.planning_hand import paper_hand_hash

    return paper_hand_hash()


#: Columns that files of an older schema lack -> a function giving their value: such rows
#: are the shipped paper hand's.
LEGACY_DEFAULTS = {"hand_hash": _paper_hash}

#: One row per failed attempt at an object.
FAILURE_SCHEMA = pa.schema(
    [
        pa.field("object_id", pa.string(), nullable=False),
        pa.field("source_path", pa.string()),
        pa.field("source_sha256", pa.string()),
        pa.field("scale", _F64, nullable=False),
        pa.field("hand_name", pa.string(), nullable=False),
        pa.field("options_key", pa.string(), nullable=False),
        pa.field("error_type", pa.string(), nullable=False),
        pa.field("error", pa.string(), nullable=False),
        pa.field("retry", pa.bool_(), nullable=False),
        pa.field("package_version", pa.string(), nullable=False),
        pa.field("created", pa.timestamp("us", tz="UTC"), nullable=False),
    ],
    metadata={"format": FORMAT_NAME, "schema_version": str(SCHEMA_VERSION), "table": "failures"},
)


def empty_columns(schema: pa.Schema) -> dict[str, list]:
    """A column -> empty list mapping for ``schema`` (rows are appended as lists)."""
    return {name: [] for name in schema.names}


def options_key(options_json: str) -> str:
    """The resume key of a set of options: first 16 hex digits of SHA-256 of the JSON."""
    return hashlib.sha256(options_json.encode("utf-8")).hexdigest()[:16]


def rigid_inverse(t: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (4, 4)."""
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def candidate_rows(
    candidates: Iterable[GraspCandidate], pose: np.ndarray, common: dict[str, Any], wrist_angles: bool = True,
) -> dict[str, list]:
    """Rows (column -> list) of planned candidates, moved into the object frame.

    Parameters
    ----------
    candidates : iterable of GraspCandidate
        In the planning frame of ``pose`` (as :func:`~grasp_apso.search.planner.plan` returns them).
    pose : (4, 4) float
        The object pose the plan was run with (object -> planning frame).
    common : dict
        Values of the per-object columns (``object_id``, ``mesh_hash``, ``hand_name``,
        ``hand_hash``, ``options``, ``seed``, ``created`` ...), repeated on every row.
    wrist_angles : bool
        The paper hand: its last three joint values are wrist angles, stored for the object
        frame. False for a general hand (joint vectors stored as they are).

    Returns
    -------
    dict of str -> list
        Plain Python lists (cheap to pickle across processes), in :data:`GRASP_SCHEMA` order.
    """
    cols = empty_columns(GRASP_SCHEMA)
    inv = rigid_inverse(np.asarray(pose, dtype=float))
    rot = inv[:3, :3]
    joints = planning_joint_positions if wrist_angles else (lambda q, _wrist: np.asarray(q, dtype=float))
    for c in candidates:
        wrist = inv @ np.asarray(c.wrist_pose, dtype=float)
        pre = inv @ np.asarray(c.pre_grasp_pose, dtype=float)
        wp, wq = matrix_to_pose(wrist)
        pp, pq = matrix_to_pose(pre)
        row = {
            "rank": int(c.rank),
            "joint_positions": joints(c.joint_positions, wrist).tolist(),
            "pre_grasp_positions": joints(c.pre_grasp_positions, wrist).tolist(),
            "wrist_position": wp.tolist(), "wrist_quaternion": wq.tolist(),
            "pre_grasp_position": pp.tolist(), "pre_grasp_quaternion": pq.tolist(),
            "approach": (rot @ np.asarray(c.approach, dtype=float)).tolist(),
            "approach_distance": float(c.approach_distance),
            "grasp_quality": float(c.grasp_quality), "fitness": float(c.fitness),
            "epsilon": float(c.epsilon), "force_closure": bool(c.force_closure),
            "valid": bool(c.valid), "scene_distance": float(c.scene_distance),
            "sim_result": int(c.sim_result), "sim_max_shift": float(c.sim_max_shift),
            "sim_max_turn": float(c.sim_max_turn),
            "contact_points": [(inv[:3, :3] @ k.position + inv[:3, 3]).tolist() for k in c.contacts],
            "contact_normals": [(rot @ k.normal).tolist() for k in c.contacts],
            "contact_fingers": [str(k.finger) for k in c.contacts],
        }
        for name in GRASP_SCHEMA.names:
            cols[name].append(row[name] if name in row else common[name])
    return cols
