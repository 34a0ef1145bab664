"""Any robot hand (DESIGN.md Part 3): a hand loaded from its URDF, MJCF or the project's
YAML, its collision geometry per link, the spheres that cover it for the compiled search,
the fingertip pads, and the grasp semantics derived from the kinematics. No mujoco import
at package import time."""
