"""The naming contract of the stack: topics and frames, one definition each.

Simulation and the lab use the same names (docs/interfaces.md), so every
node and tool builds them with these helpers instead of formatting strings.
"""

#: Fixed world frame of the motion-capture system and of the simulation.
WORLD_FRAME = "world"

#: Namespace of stack-wide topics, services and parameters.
STACK_NS = "/puzzlebot"

CONNECTION_PAIRS_TOPIC = STACK_NS + "/connection_pairs"
#: Anchor-opening couplings read off the simulated bodies (sim node only).
PHYSICAL_PAIRS_TOPIC = STACK_NS + "/sim/physical_pairs"
SOLVER_STATS_TOPIC = STACK_NS + "/mpc/solver_stats"
BEHAVIOR_STATUS_TOPIC = STACK_NS + "/mpc/behavior_status"
SET_BEHAVIOR_SERVICE = STACK_NS + "/mpc/set_behavior"
ROBOTS_PARAM = STACK_NS + "/robots"
SCENARIO_PARAM = STACK_NS + "/scenario"


def cmd_vel_topic(robot):
    """Commanded body velocity of ``robot`` (geometry_msgs/Twist)."""
    return "/%s/cmd_vel" % robot


def vicon_topic(subject, segment=None):
    """Measured pose (geometry_msgs/TransformStamped), vicon_bridge convention.

    The lab's subjects have one segment named like the subject, so the topic
    is ``/vicon/<subject>/<subject>``.
    """
    return "/vicon/%s/%s" % (subject, segment or subject)


def base_frame(robot):
    """Body frame of ``robot`` (REP-105 style prefix): origin at the body
    centre, x forward, z up."""
    return "%s/base_link" % robot


def anchor_frame(robot):
    """Frame of the anchor body that rests in ``robot``'s holder."""
    return "%s/anchor" % robot
