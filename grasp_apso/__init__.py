"""grasp_apso: precision grasp planning with Adaptive Particle Swarm Optimization.

The algorithm modules (hand, objects, mesh_files, shapes, poses, sdf, contacts, collision,
quality, fitness, grg, swarm, planner) import numpy / scipy / trimesh / python-fcl only,
never rclpy; the ROS node (``grasp_apso.ros.node``) is a thin adapter over
:func:`grasp_apso.search.planner.plan`. See ``docs/architecture.md`` and ``docs/algorithm.md``.
"""

__version__ = "0.1.0"
