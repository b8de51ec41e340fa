"""PuzzleBot bringup: scenarios (ROS-free parsing and reporting)."""
