"""The data the planner works on: the hand description and kinematics, objects (validated
meshes, mesh files, built-in shapes), poses and the scene. Immutable models; no rclpy."""
