"""Command-line tools without ROS: the planner CLI, printed summaries and pictures."""
