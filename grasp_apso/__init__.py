"""grasp_apso: precision grasp planning with Adaptive Particle Swarm Optimization.

The algorithm modules (hand, objects, sdf, contacts, collision, quality, fitness, grg,
swarm, planner) import numpy / scipy / trimesh / python-fcl only, never rclpy; the ROS
node (``grasp_apso.node``) is a thin adapter over :func:`grasp_apso.planner.plan`.
"""

__version__ = "0.1.0"
