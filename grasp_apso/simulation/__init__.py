"""Physics check of a grasp in MuJoCo (DESIGN.md, "Simulation check").

::

    from grasp_apso.simulation import SimulationSettings, SimResult, simulate_grasp
    res = simulate_grasp(hand, obj, pose, wrist_pose, pre_grasp_q, grasp_q, planes=None)
    res.held, res.max_shift, res.max_turn, res.per_direction, res.sim_time

Any hand (``grasp_apso.model.load_hand(path)``), on its own description file::

    from grasp_apso.simulation import simulate_any_hand
    res = simulate_any_hand(hand, obj, obj_pose, root_pose, q_pre, q_grasp, q_squeeze, scene, friction)

Modules: :mod:`.mjcf` (the MJCF scene generated from the paper hand's description),
:mod:`.convex` (CoACD convex decomposition, cached per mesh), :mod:`.phases` (the
protocol's phases: close, squeeze, six disturbances from the planned pose),
:mod:`.protocol` (the paper's hand), :mod:`.any_hand_model` and :mod:`.any_hand` (any
hand). Nothing here imports rclpy; ``mujoco`` and
``coacd`` are imported when a check runs.
"""

from .convex import ConvexSettings, convex_parts
from .protocol import DIRECTIONS, SimResult, SimulationSettings, build_model, simulate_grasp
from .any_hand import SimOutcome, simulate_any_hand, squeezed_positions

__all__ = ["ConvexSettings", "convex_parts", "DIRECTIONS", "SimResult", "SimulationSettings",
           "build_model", "simulate_grasp", "SimOutcome", "simulate_any_hand", "squeezed_positions"]
