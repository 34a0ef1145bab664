"""Physics check of a grasp in MuJoCo (DESIGN.md, "Simulation check").

::

    from grasp_apso.simulation import SimulationSettings, SimResult, simulate_grasp
    res = simulate_grasp(hand, obj, pose, wrist_pose, pre_grasp_q, grasp_q, planes=None)
    res.held, res.max_shift, res.max_turn, res.per_direction, res.sim_time

Modules: :mod:`.mjcf` (the MJCF scene generated from the hand description),
:mod:`.convex` (CoACD convex decomposition, cached per mesh), :mod:`.protocol` (the
test: close, squeeze, six disturbances). Nothing here imports rclpy; ``mujoco`` and
``coacd`` are imported when a check runs.
"""

from .convex import ConvexSettings, convex_parts
from .protocol import DIRECTIONS, SimResult, SimulationSettings, build_model, simulate_grasp

__all__ = ["ConvexSettings", "convex_parts", "DIRECTIONS", "SimResult", "SimulationSettings",
           "build_model", "simulate_grasp"]
