"""The node's ROS parameters, declared from :mod:`grasp_apso.tunables` (one source of truth).

- :func:`descriptor`: a ``ParameterDescriptor`` per :class:`~grasp_apso.tunables.Tunable`
  (type, description, range, constraints; ``read_only`` for the security and resource
  limits: ``allowed_mesh_dir``, ``max_mesh_triangles``, ``max_mesh_bytes``,
  ``hand_description``, ``hand_config``, ``queue_length``, ``workers``, ``grasp_database``).
- :class:`NodeParameters`: declares them on a node, checks the start-up values with
  :meth:`Tunable.check <grasp_apso.tunables.Tunable.check>` (a bad value stops the node
  with a message naming the parameter), loads the hand it plans with
  (:func:`~grasp_apso.model.planning_hand.load_planning_hand`: the paper's for a ``.yaml``,
  a general hand for a ``.urdf`` / ``.xml``) and opens the grasp
  database (:mod:`.database_answers`) once, and keeps a
  :class:`Settings` snapshot that requests read. Changes at run time go through a
  pre-set callback (an integer is accepted for a double), an on-set callback (read-only
  parameters refused, every value checked, the options checked together) and a
  post-set callback that takes a new snapshot: requests never re-read parameters.
"""

from __future__ import annotations

import dataclasses
import os
import threading
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Mapping

import rclpy.parameter
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult,
)
from rclpy.node import Node

from ..errors import GraspApsoError, InputError
from ..cache import set_cache_root
from ..model.planning_hand import is_general_hand, load_planning_hand
from ..search.options import PlanOptions
from ..tunables import Tunable, ros_tunables
from .database_answers import open_database

__all__ = ["PARAMETERS", "PARAMETER_NAMES", "READ_ONLY", "NodeParameters", "Settings", "descriptor"]

#: Every parameter of the node, in declaration order.
PARAMETERS: tuple[Tunable, ...] = ros_tunables()
PARAMETER_NAMES: tuple[str, ...] = tuple(t.name for t in PARAMETERS)
#: Parameters fixed at start-up (security and resource limits).
READ_ONLY: frozenset[str] = frozenset(t.name for t in PARAMETERS if t.read_only)
_BY_NAME = {t.name: t for t in PARAMETERS}
_OPTION_FIELDS = frozenset(f.name for f in dataclasses.fields(PlanOptions)) & set(PARAMETER_NAMES)


def descriptor(t: Tunable) -> ParameterDescriptor:
    """The ROS descriptor of a tunable (type, description, range, read-only flag)."""
    desc = ParameterDescriptor(name=t.name, description=t.description, read_only=bool(t.read_only))
    if t.kind is bool:
        desc.type = ParameterType.PARAMETER_BOOL
    elif t.kind is int:
        desc.type = ParameterType.PARAMETER_INTEGER
        desc.integer_range = [IntegerRange(from_value=int(t.lo), to_value=int(t.hi), step=1)]
    elif t.kind is float:
        desc.type = ParameterType.PARAMETER_DOUBLE
        desc.floating_point_range = [FloatingPointRange(from_value=float(t.lo), to_value=float(t.hi), step=0.0)]
        if t.lo_open:
            desc.additional_constraints = f"{t.range_text()}{' ' + t.unit if t.unit else ''}"
    else:
        desc.type = ParameterType.PARAMETER_STRING
        if t.choices:
            desc.additional_constraints = t.range_text()
    if t.unit and not desc.additional_constraints:
        desc.additional_constraints = f"unit: {t.unit}"
    return desc


@dataclass(frozen=True)
class Settings:
    """An immutable snapshot of the parameters: what one request uses from start to end.

    ``values`` maps every parameter name to its value; ``options`` are the plan options
    made of them (a request overrides a few); ``hand`` is the hand loaded at start-up
    (the paper's :class:`~grasp_apso.model.hand.HandModel` or a general
    :class:`grasp_apso.model.hands.HandModel`).
    """

    values: Mapping[str, Any]
    options: PlanOptions
    hand: Any

    def __getitem__(self, name: str) -> Any:
        return self.values[name]


def _options(values: Mapping[str, Any]) -> PlanOptions:
    """PlanOptions from parameter values (InputError naming the field when invalid)."""
    settings = {name: values[name] for name in _OPTION_FIELDS}
    # The neighbourhood is clamped to the swarm size (a request may ask for fewer particles).
    settings["neighborhood_size"] = max(1, min(int(settings["neighborhood_size"]), int(settings["particles"])))
    return PlanOptions(**settings)


class NodeParameters:
    """Declares the parameters on ``node`` and keeps the current :class:`Settings`.

    Raises
    ------
    InputError, HandDescriptionError, DatabaseError
        A start-up value that is invalid (the message names the parameter; a hand file's
        content is never quoted).

    Attributes
    ----------
    database : GraspDatabase or None
        The grasp database opened at start-up (parameter ``grasp_database``, read-only).
    """

    def __init__(self, node: Node) -> None:
        self._node = node
        self._lock = threading.Lock()
        for t in PARAMETERS:
            node.declare_parameter(t.name, t.default, descriptor(t))
        values = {name: node.get_parameter(name).value for name in PARAMETER_NAMES}
        for name in PARAMETER_NAMES:
            values[name] = _BY_NAME[name].check(values[name])
        allowed = str(values["allowed_mesh_dir"])
        if allowed and not os.path.isdir(allowed):
            raise InputError("allowed_mesh_dir: not a directory", "allowed_mesh_dir")
        # The disk caches (convex decompositions, the hand's sphere covers) of this node: set
        # before the hand is loaded, which may write its covers there.
        set_cache_root(str(values["cache_directory"]))
        #: The hand every request plans with and its identity (:mod:`grasp_apso.model.planning_hand`).
        self.planning_hand = load_planning_hand(str(values["hand_description"]), str(values["hand_config"]))
        hand = self._hand = self.planning_hand.hand
        if is_general_hand(hand):
            node.get_logger().info(f"hand_description: {hand.name} ({len(hand.fingers)} fingers, {len(hand.actuated_joints)} "
                                   f"actuated joints: {', '.join(hand.actuated_joints)})")
        self.database = open_database(str(values["grasp_database"]), self.planning_hand)
        self._settings = Settings(MappingProxyType(dict(values)), _options(values), hand)
        node.add_pre_set_parameters_callback(self._coerce)
        node.add_on_set_parameters_callback(self._check)
        node.add_post_set_parameters_callback(self._snapshot)

    @property
    def settings(self) -> Settings:
        """The current snapshot (replaced atomically after every accepted change)."""
        return self._settings

    # ------------------------------------------------------------------ callbacks
    @staticmethod
    def _coerce(parameters: list[rclpy.parameter.Parameter]) -> list[rclpy.parameter.Parameter]:
        """Pre-set: accept an integer for a floating-point parameter (``param set c1 1``)."""
        out = []
        for param in parameters:
            t = _BY_NAME.get(param.name)
            if t is not None and t.kind is float and param.type_ == rclpy.parameter.Parameter.Type.INTEGER:
                param = rclpy.parameter.Parameter(param.name, value=float(param.value))
            out.append(param)
        return out

    def _check(self, parameters: list[rclpy.parameter.Parameter]) -> SetParametersResult:
        """On-set: refuse read-only parameters and invalid values (the reason names them)."""
        values = dict(self._settings.values)
        for param in parameters:
            t = _BY_NAME.get(param.name)
            if t is None:
                continue
            if t.read_only:
                return SetParametersResult(
                    successful=False,
                    reason=f"{param.name}: read-only (a security or resource limit, fixed at start-up)")
            try:
                values[param.name] = t.check(param.value)
            except InputError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        try:
            _options(values)
        except GraspApsoError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _snapshot(self, parameters: list[rclpy.parameter.Parameter]) -> None:
        """Post-set: take a new snapshot of every value (the values were checked)."""
        with self._lock:
            values = dict(self._settings.values)
            for param in parameters:
                if param.name in _BY_NAME:
                    values[param.name] = _BY_NAME[param.name].check(param.value)
            self._settings = Settings(MappingProxyType(values), _options(values), self._hand)
