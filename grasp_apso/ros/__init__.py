"""The ROS 2 side (the only folder that imports rclpy): the node, its parameters, request
parsing, the worker, message conversions, markers and the demo client."""
