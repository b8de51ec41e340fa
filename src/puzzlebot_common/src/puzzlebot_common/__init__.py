"""ROS-free building blocks shared by the PuzzleBot packages."""
