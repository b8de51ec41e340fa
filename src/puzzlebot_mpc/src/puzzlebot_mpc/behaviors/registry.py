"""The behaviours the manager knows: request name -> class. A new behaviour is a new module with
one Behavior subclass, listed here."""

from puzzlebot_mpc.behaviors.assembly_to_goal import AssemblyToGoal
from puzzlebot_mpc.behaviors.couple import Couple
from puzzlebot_mpc.behaviors.decouple import Decouple
from puzzlebot_mpc.behaviors.drive_assembly import DriveAssembly
from puzzlebot_mpc.behaviors.follow_velocity import FollowVelocity
from puzzlebot_mpc.behaviors.go_to_goal import GoToGoal
from puzzlebot_mpc.behaviors.stop import Stop

#: name -> Behavior subclass, in the order the refusal of an unknown behaviour lists them
REGISTRY = {cls.name: cls for cls in (GoToGoal, FollowVelocity, Stop, Couple, Decouple, DriveAssembly,
                                          AssemblyToGoal)}
BEHAVIORS = tuple(REGISTRY)
