"""Behaviour requests: validation, per-step objectives, progress status.

One behaviour runs at a time; it names the robots it drives and every other
robot is brought to rest. Requests are validated completely before they
replace the running behaviour, so a bad request changes nothing (robots at
rest stay at rest). Coupled pairs are kept by the MPC's polygon constraints
whatever the behaviour.

Each behaviour is one class behind one interface (:class:`base.Behavior`),
in its own module, which describes it:

- ``go_to_goal`` (go_to_goal.py), ``follow_velocity`` (follow_velocity.py),
  ``stop`` (stop.py);
- ``couple`` (couple.py): the robots form a target configuration;
- ``decouple`` (decouple.py): a coupled anchor pair separates (the wiggle);
- ``drive_assembly`` (drive_assembly.py): an assembly drives as one body.

registry.py lists them (request name -> class); manager.py holds the
running one (:class:`BehaviorManager`). A new behaviour is a new module with
one Behavior subclass, listed in the registry.
"""

from puzzlebot_mpc.behaviors.base import (FAILED, IDLE, RUNNING, STATE_NAMES, SUCCEEDED, Behavior, BehaviorError,
                                          BehaviorRequest, BehaviorStatus, Context, DisplayObjectives, Progress)
from puzzlebot_mpc.behaviors.couple import COUPLE, Couple
from puzzlebot_mpc.behaviors.decouple import DECOUPLE, Decouple, partner_turn, wiggle
from puzzlebot_mpc.behaviors.drive_assembly import DRIVE_ASSEMBLY, DriveAssembly
from puzzlebot_mpc.behaviors.follow_velocity import FOLLOW_VELOCITY, FollowVelocity
from puzzlebot_mpc.behaviors.go_to_goal import GO_TO_GOAL, GoToGoal
from puzzlebot_mpc.behaviors.manager import BehaviorManager
from puzzlebot_mpc.behaviors.registry import BEHAVIORS, REGISTRY
from puzzlebot_mpc.behaviors.stop import STOP, Stop

__all__ = ["BEHAVIORS", "COUPLE", "DECOUPLE", "DRIVE_ASSEMBLY", "FAILED", "FOLLOW_VELOCITY", "GO_TO_GOAL", "IDLE",
           "REGISTRY", "RUNNING", "STATE_NAMES", "STOP", "SUCCEEDED", "Behavior", "BehaviorError", "BehaviorManager",
           "BehaviorRequest", "BehaviorStatus", "Context", "Couple", "Decouple", "DisplayObjectives", "DriveAssembly",
           "FollowVelocity", "GoToGoal", "Progress", "Stop", "partner_turn", "wiggle"]
