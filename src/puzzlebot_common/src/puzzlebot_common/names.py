"""The naming contract of the stack: topics and frames, one definition each.

Simulation and the lab use the same names (docs/interfaces.md), so every
node and tool builds them with these helpers instead of formatting strings.
"""

#: Fixed world frame of the motion-capture system and of the simulation.
WORLD_FRAME = "world"

#: Frame at the centre of the robots (no rotation from WORLD_FRAME): the shipped rviz view follows it
#: (puzzlebot_bringup markers node).
VIEW_FRAME = "puzzlebot/view"

#: Namespace of stack-wide topics, services and parameters.
STACK_NS = "/puzzlebot"

CONNECTION_PAIRS_TOPIC = STACK_NS + "/connection_pairs"
#: Anchor-opening couplings read off the simulated bodies (sim node only).
PHYSICAL_PAIRS_TOPIC = STACK_NS + "/sim/physical_pairs"
SOLVER_STATS_TOPIC = STACK_NS + "/mpc/solver_stats"
BEHAVIOR_STATUS_TOPIC = STACK_NS + "/mpc/behavior_status"
SET_BEHAVIOR_SERVICE = STACK_NS + "/mpc/set_behavior"
#: puzzlebot_msgs/Behavior action of the MPC node: SET_BEHAVIOR_SERVICE with feedback, result and cancel.
BEHAVIOR_ACTION = STACK_NS + "/mpc/behavior"
PREDICTED_TRAJECTORIES_TOPIC = STACK_NS + "/mpc/predicted_trajectories"
MPC_MARKERS_TOPIC = STACK_NS + "/mpc/markers"
#: puzzlebot_msgs/BehaviorObjectives: goals and target slots of the running behaviour (MPC node).
MPC_OBJECTIVES_TOPIC = STACK_NS + "/mpc/objectives"
#: visualization_msgs/MarkerArray: the rviz markers of the stack (puzzlebot_bringup markers node).
MARKERS_TOPIC = STACK_NS + "/markers"
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


# --- Lab driver and robot emulator (puzzlebot_driver; docs/driver.md) ---

#: puzzlebot_msgs/EStop service of the lab driver: zero every robot's PWM, latched until released.
DRIVER_ESTOP_SERVICE = STACK_NS + "/driver/estop"
#: std_msgs/Bool topic: true engages the driver's e-stop (latched), false releases it.
ESTOP_TOPIC = STACK_NS + "/estop"
#: diagnostic_msgs/DiagnosticArray, the ROS-wide diagnostics topic.
DIAGNOSTICS_TOPIC = "/diagnostics"
#: puzzlebot_msgs/EmulatorFault service of the robot emulator.
EMULATOR_FAULT_SERVICE = STACK_NS + "/emulator/fault"


def wheel_pwm_topic(robot):
    """PWM the lab driver decides for ``robot`` every loop tick (puzzlebot_msgs/WheelPwm)."""
    return "/%s/wheel_pwm" % robot


def emulator_pwm_topic(robot):
    """PWM lines the emulated ``robot`` received (puzzlebot_msgs/WheelPwm, stamped on arrival)."""
    return STACK_NS + "/emulator/%s/pwm" % robot


def emulator_truth_topic(robot):
    """True pose of the emulated ``robot`` (geometry_msgs/TransformStamped, world frame, no noise)."""
    return STACK_NS + "/emulator/%s/true_pose" % robot


def emulator_velocity_topic(robot):
    """True body velocity of the emulated ``robot`` (geometry_msgs/TwistStamped: linear.x, angular.z)."""
    return STACK_NS + "/emulator/%s/true_velocity" % robot
