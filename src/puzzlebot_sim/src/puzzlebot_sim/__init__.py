"""PuzzleBot Bullet simulation: ROS-free core (robot URDF, worlds, stepping)."""
