"""Answers from a grasp database (parameter ``grasp_database``); no ROS entities here.

- :func:`open_database`: opens the database at start-up (:meth:`GraspDatabase.open
  <grasp_apso.database.lookup.GraspDatabase.open>`); every problem is a
  :class:`~grasp_apso.errors.DatabaseError` whose message starts with ``grasp_database:``,
  so the node refuses to start with the parameter named.
- :func:`lookup`: the stored grasps of a request's object and hand, moved to the request's
  pose and re-checked against its scene (clearance and approach), as a
  :class:`StoredGrasps` that the reply and the markers are built from like a planner
  result; or None and a note for the message of the plan that runs instead.

A request with a fixed wrist position is never answered from the database (the stored
grasps do not honour it); one that asks for the simulation check is answered only with
stored grasps that were simulated.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DatabaseError
from ..model.hand import JOINT_NAMES
from ..search.result import SIM_NOT_RUN, Contact, GraspCandidate

__all__ = ["FIELD", "StoredGrasps", "lookup", "open_database"]

#: The node parameter (named in every error).
FIELD = "grasp_database"


@dataclass(frozen=True)
class StoredGrasps:
    """Grasps answered from the database, shaped like the parts of a
    :class:`~grasp_apso.search.result.GraspResult` that the reply
    (:func:`~grasp_apso.ros.conversions.fill_result`) and the markers read.

    Nothing is planned: ``iterations_run`` is 0, ``planning_time`` is the lookup (move and
    scene check), ``preparation_time`` the loading of the object before it. The top-level
    grasp is ``candidates[0]``.
    """

    candidates: tuple[GraspCandidate, ...]
    stored: int                      # valid grasps stored for the object and hand
    planning_time: float             # s, the lookup
    preparation_time: float          # s, loading the object before the lookup
    iterations_run: int = 0
    joint_names: tuple[str, ...] = JOINT_NAMES

    @property
    def best(self) -> GraspCandidate:
        return self.candidates[0]

    @property
    def wrist_pose(self) -> np.ndarray:
        return self.best.wrist_pose

    @property
    def joints(self) -> np.ndarray:
        return self.best.joints

    @property
    def contacts(self) -> tuple[Contact, ...]:
        return self.best.contacts

    @property
    def joint_positions(self) -> np.ndarray:
        return self.best.joint_positions

    @property
    def fitness(self) -> float:
        return self.best.fitness

    @property
    def epsilon(self) -> float:
        return self.best.epsilon

    @property
    def force_closure(self) -> bool:
        return self.best.force_closure

    @property
    def message(self) -> str:
        """The reply's message."""
        best = self.best
        return (f"grasp found from the grasp database ({self.stored} stored, {len(self.candidates)} kept "
                f"after the scene check): fitness {best.fitness:.3f}, epsilon {best.epsilon:.4f}, force "
                f"closure {'yes' if best.force_closure else 'no'}, looked up in "
                f"{1000.0 * self.planning_time:.1f} ms; nothing planned")


def open_database(path: str, hand: Any) -> Any:
    """The grasp database at ``path`` for ``hand`` (a
    :class:`~grasp_apso.model.planning_hand.PlanningHand`: the hand and its identity), or
    None when ``path`` is empty.

    Raises
    ------
    DatabaseError
        ``grasp_database: ...``: missing, unreadable or corrupt, or pyarrow missing.
    """
    if not path:
        return None
    try:
        from ..database.lookup import GraspDatabase
    except ImportError as exc:
        raise DatabaseError(f"{FIELD}: cannot read grasp databases on this node ({exc}; install pyarrow)",
                            FIELD) from None
    try:
        return GraspDatabase.open(path, hand=hand)
    except DatabaseError:
        raise
    except Exception as exc:  # noqa: BLE001 -- any reader failure is a bad parameter value
        shown = os.path.basename(os.path.normpath(path)) or path
        raise DatabaseError(f"{FIELD}: cannot read the grasp database {shown}: {type(exc).__name__}: {exc}",
                            FIELD) from None


def lookup(database: Any, obj: Any, hand: Any, pose: np.ndarray, scene: Any, options: Any,
           obj_bvh: Any = None, preparation_time: float = 0.0) -> tuple[StoredGrasps | None, str]:
    """Answer a request from ``database`` when a stored grasp survives its scene.

    Parameters
    ----------
    database : GraspDatabase
    obj : GraspObject
        The request's object (its ``mesh_hash`` is the key).
    hand : HandModel
        The node's hand (its ``name`` is the key; the database holds only rows of its
        ``hand_hash``, see :meth:`GraspDatabase.open <grasp_apso.database.lookup.GraspDatabase.open>`).
    pose : (4, 4) float
        Object frame -> planning frame.
    scene : Scene or None
    options : PlanOptions
        The request's options: ``clearance``, ``approach_distance``, ``max_grasps``,
        ``simulate`` and ``wrist_position`` are used.
    obj_bvh : fcl.BVHModel, optional
        The object, to re-check the approach against it too.
    preparation_time : float, s
        Time spent loading the object (reported, not measured here).

    Returns
    -------
    (StoredGrasps, "") when answered; (None, note) otherwise, where ``note`` is "" for an
    object the database does not hold, else why the stored grasps were not used.
    """
    stored = database.count(obj.mesh_hash, hand.name)
    if stored == 0:
        return None, ""
    if options.wrist_position is not None:
        return None, f"the grasp database holds {stored} grasp(s) of this object, not used with a fixed wrist position"
    t0 = time.perf_counter()
    wanted = 50 if options.simulate else int(options.max_grasps)
    found = database.lookup(obj.mesh_hash, hand.name, pose, scene, clearance=options.clearance,
                            approach_distance=options.approach_distance, max_grasps=wanted, obj_bvh=obj_bvh,
                            obj=obj if obj_bvh is not None else None)
    if options.simulate:
        found = [c for c in found if c.sim_result != SIM_NOT_RUN][: int(options.max_grasps)]
        found = [dataclasses.replace(c, rank=i, id=f"g{i}") for i, c in enumerate(found)]
    seconds = time.perf_counter() - t0
    if not found:
        why = ("none of them simulated (the request asks for the simulation check) or kept after the scene check"
               if options.simulate else "none kept after the scene check (clearance and approach)")
        return None, f"the grasp database holds {stored} grasp(s) of this object, {why}; planned instead"
    names = tuple(database.planning_hand.joint_names)
    return StoredGrasps(tuple(found), stored, seconds, preparation_time, joint_names=names), ""
