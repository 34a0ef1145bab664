"""The data the planner works on: the hand description and kinematics, objects (validated
meshes, mesh files, built-in shapes), poses and the scene. Immutable models; no rclpy.

The general hand API (DESIGN.md Part 3) is exported lazily, so importing this package
does not import mujoco or yourdfpy: ``load_hand`` (any URDF, MJCF or the project's YAML),
``HandModel`` and ``Finger`` from :mod:`grasp_apso.model.hands`. The paper hand's DH model
stays in :mod:`grasp_apso.model.hand` (the planner's, until issue 20 part 2).
"""

from __future__ import annotations

__all__ = ["load_hand", "HandModel", "Finger"]


def __getattr__(name: str):
    if name == "load_hand":
        from .hands.load import load_hand

        return load_hand
    if name in ("HandModel", "Finger"):
        from .hands import model

        return getattr(model, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
