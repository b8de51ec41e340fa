"""rospy adapter that runs scenario steps through the MPC node.

Used by the ``scenario_runner`` node and by the integration tests (which add
their physical checks between the steps). The scenario format and the
summary are ROS-free (``scenario.py``); this module needs a running ROS graph.

Reads /puzzlebot/mpc/behavior_status, /puzzlebot/mpc/solver_stats,
/puzzlebot/connection_pairs, /puzzlebot/sim/physical_pairs (when a
simulation publishes it) and the robots' vicon topics; calls
/puzzlebot/mpc/set_behavior.
"""

import math
import threading
import time

import rospy
from geometry_msgs.msg import Point, Pose2D, TransformStamped

from puzzlebot_common import names
from puzzlebot_common.geometry import yaw_from_quaternion
from puzzlebot_msgs.msg import BehaviorStatus, ConnectionPair, ConnectionPairArray, SolverStats
from puzzlebot_msgs.srv import SetBehavior, SetBehaviorRequest
from puzzlebot_mpc.ros_conversions import twist

from puzzlebot_bringup.scenario import StepResult

STATUS_TEXT = {ConnectionPair.STATUS_DECOUPLED: "decoupled", ConnectionPair.STATUS_HEAD_ALIGNED: "head aligned",
               ConnectionPair.STATUS_HEAD_INSERTED: "coupled"}
PHYSICAL_TEXT = {ConnectionPair.STATUS_HEAD_ALIGNED: "head in", ConnectionPair.STATUS_HEAD_INSERTED: "seated"}
POLL = 0.01   # s (wall) between checks of the behaviour status
SETTLE = 2.0  # s of simulated time added to a step's timeout before the runner gives up on its status


def pairs_text(msg):
    """'a->b coupled, ...' for a ConnectionPairArray (None or empty: 'none coupled')."""
    if msg is None or not msg.pairs:
        return "none coupled"
    return ", ".join("%s->%s %s" % (p.robot_i, p.robot_j, STATUS_TEXT.get(p.status, "?")) for p in msg.pairs)


def step_request(step):
    """SetBehaviorRequest of a scenario Step."""
    req = SetBehaviorRequest(behavior=step.behavior, robots=step.robots, tolerance=step.tolerance,
                             timeout=step.timeout, target=step.target, pair=step.pair, distance=step.distance)
    req.slots = [Pose2D(x=sl[0], y=sl[1], theta=sl[2]) for sl in step.slots]
    req.goals = [Point(x=g[0], y=g[1], z=0.0) for g in step.goals]
    req.velocities = [twist(v, w) for v, w in step.velocities]
    return req


class Runner:
    """Subscriptions and the step loop. ``robots``: parsed robot list (RobotSpec)."""

    def __init__(self, robots):
        self.lock = threading.Lock()
        self.status = None
        self.poses = {}         # robot -> (x, y, z, yaw) from its vicon topic
        self.pairs = None       # latest /puzzlebot/connection_pairs
        self.physical = None    # latest /puzzlebot/sim/physical_pairs
        self.physical_log = []  # (stamp, msg) of every physical pairs message (tests)
        self.pairs_log = []     # (stamp, msg) of every connection pairs message (tests)
        self.solved = False
        self.failed_solves = 0
        rospy.Subscriber(names.BEHAVIOR_STATUS_TOPIC, BehaviorStatus, self._on_status, queue_size=10)
        rospy.Subscriber(names.SOLVER_STATS_TOPIC, SolverStats, self._on_stats, queue_size=10)
        rospy.Subscriber(names.CONNECTION_PAIRS_TOPIC, ConnectionPairArray, self._on_pairs, queue_size=10)
        rospy.Subscriber(names.PHYSICAL_PAIRS_TOPIC, ConnectionPairArray, self._on_physical, queue_size=10)
        for r in robots:
            rospy.Subscriber(r.vicon_topic, TransformStamped, self._on_pose, callback_args=r.name, queue_size=1)
        self.call = None

    # ------------------------------------------------------------ callbacks
    def _on_status(self, msg):
        self.status = msg

    def _on_stats(self, msg):
        self.solved = self.solved or msg.success
        if not msg.success:
            self.failed_solves += 1

    def _on_pairs(self, msg):
        with self.lock:
            self.pairs = msg
            self.pairs_log.append((msg.header.stamp.to_sec(), msg))

    def _on_physical(self, msg):
        with self.lock:
            self.physical = msg
            self.physical_log.append((msg.header.stamp.to_sec(), msg))

    def _on_pose(self, msg, name):
        t, q = msg.transform.translation, msg.transform.rotation
        self.poses[name] = (t.x, t.y, t.z, yaw_from_quaternion(q.x, q.y, q.z, q.w))

    # ---------------------------------------------------------------- setup
    def connect(self, service_timeout=120.0, control_timeout=60.0):
        """Wait for the MPC's service and its first solved step (it then has poses: couple needs them).
        Returns False if no step was solved within ``control_timeout`` s (wall)."""
        rospy.wait_for_service(names.SET_BEHAVIOR_SERVICE, timeout=service_timeout)
        self.call = rospy.ServiceProxy(names.SET_BEHAVIOR_SERVICE, SetBehavior)
        end = time.monotonic() + control_timeout
        while not self.solved and not rospy.is_shutdown() and time.monotonic() < end:
            time.sleep(POLL)
        return self.solved

    def wait_sim(self, seconds, wall_timeout=60.0):
        """Let ``seconds`` of ROS time pass (bounded in wall time)."""
        t0, end = rospy.get_time(), time.monotonic() + wall_timeout
        while rospy.get_time() - t0 < seconds and not rospy.is_shutdown() and time.monotonic() < end:
            time.sleep(POLL)

    # ---------------------------------------------------------------- steps
    def run_step(self, step, default_timeout, wall_deadline):
        """Request one step and wait for its final status; a StepResult (sim_seconds in ROS time)."""
        t0 = rospy.get_time()
        resp = self.call(step_request(step))
        if not resp.accepted:
            return StepResult(step, "refused", resp.message, 0.0)
        limit = (step.timeout or default_timeout) + SETTLE
        outcome, message = "timeout", "no final status from the MPC node"
        while not rospy.is_shutdown() and time.monotonic() < wall_deadline:
            s = self.status
            if s is not None and s.request_id == resp.request_id and s.state in (
                    BehaviorStatus.SUCCEEDED, BehaviorStatus.FAILED):
                outcome = "succeeded" if s.state == BehaviorStatus.SUCCEEDED else "failed"
                message = s.message
                break
            if rospy.get_time() - t0 > limit:
                message = "no result within %.1f s of simulated time" % limit
                break
            time.sleep(POLL)
        errors = {}
        for name, goal in zip(step.robots, step.goals):
            if name in self.poses:
                errors[name] = math.hypot(self.poses[name][0] - goal[0], self.poses[name][1] - goal[1])
        pairs = pairs_text(self.pairs) if step.behavior in ("couple", "decouple", "drive_assembly") else ""
        if pairs and self.physical is not None:      # simulation: the anchors themselves
            pairs += "; physically: " + (", ".join(
                "%s->%s %s" % (p.robot_i, p.robot_j, PHYSICAL_TEXT.get(p.status, "?")) for p in self.physical.pairs)
                or "no anchor in an opening")
        return StepResult(step, outcome, message, rospy.get_time() - t0, errors, pairs)
