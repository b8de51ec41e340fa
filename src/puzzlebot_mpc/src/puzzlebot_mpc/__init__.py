"""PuzzleBot model predictive control: ROS-free core (model, MPC, behaviours)."""
