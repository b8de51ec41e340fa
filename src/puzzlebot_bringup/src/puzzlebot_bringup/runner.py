"""rospy adapter that runs scenario steps through the MPC node's behaviour action.

Used by the ``scenario_runner`` node and by the integration tests (which add
their physical checks between the steps). The scenario format and the
summary are ROS-free (``scenario.py``); this module needs a running ROS graph.

Sends each step as a goal of the action /puzzlebot/mpc/behavior
(puzzlebot_msgs/Behavior: its result says how the step ended); reads
/puzzlebot/mpc/behavior_status, /puzzlebot/mpc/solver_stats,
/puzzlebot/connection_pairs, /puzzlebot/sim/physical_pairs (when a
simulation publishes it) and the robots' vicon topics.
"""

import collections
import math
import threading
import time

import actionlib
import rospy
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Point, Pose2D, TransformStamped
from rosgraph_msgs.msg import Clock

from puzzlebot_common import names
from puzzlebot_common.geometry import yaw_from_quaternion
from puzzlebot_msgs.msg import (BehaviorAction, BehaviorGoal, BehaviorStatus, ConnectionPair, ConnectionPairArray,
                                SolverStats)
from puzzlebot_mpc.ros_conversions import twist

from puzzlebot_bringup.scenario import StepResult

STATUS_TEXT = {ConnectionPair.STATUS_DECOUPLED: "decoupled", ConnectionPair.STATUS_HEAD_ALIGNED: "head aligned",
               ConnectionPair.STATUS_HEAD_INSERTED: "coupled"}
PHYSICAL_TEXT = {ConnectionPair.STATUS_HEAD_ALIGNED: "head in", ConnectionPair.STATUS_HEAD_INSERTED: "seated"}
POLL = 0.01   # s (wall) between checks of the behaviour status
SETTLE = 2.0  # s of simulated time added to a step's timeout before the runner gives up on its status
START_DELAY = 1.0   # s of ROS time at least between submitting a script of steps and its first step ...
SCRIPT_START = 3.0  # s: ... which starts at this ROS time at the earliest: in a simulation (time from 0) a
                    # script then starts at the same control step whatever the graph's start-up timing
POSE_HISTORY = 2000  # vicon samples kept per robot (20 s at 100 Hz), for the pose at a step's end
ACCEPT_TIMEOUT = 30.0  # s (wall) for the MPC node to accept or reject a goal


def pairs_text(msg):
    """'a->b coupled, ...' for a ConnectionPairArray (None or empty: 'none coupled')."""
    if msg is None or not msg.pairs:
        return "none coupled"
    return ", ".join("%s->%s %s" % (p.robot_i, p.robot_j, STATUS_TEXT.get(p.status, "?")) for p in msg.pairs)


def step_goal(step, cls=BehaviorGoal):
    """The request of a scenario Step: a BehaviorGoal (or ``cls``: SetBehaviorRequest has the same fields)."""
    req = cls(behavior=step.behavior, robots=step.robots, tolerance=step.tolerance,
              timeout=step.timeout, target=step.target, pair=step.pair, distance=step.distance,
              groups=step.groups, cross_edges=step.cross_edges)
    req.slots = [Pose2D(x=sl[0], y=sl[1], theta=sl[2]) for sl in step.slots]
    req.goals = [Point(x=g[0], y=g[1], z=0.0) for g in step.goals]
    req.velocities = [twist(v, w) for v, w in step.velocities]
    return req


class Runner:
    """Subscriptions and the step loop. ``robots``: parsed robot list (RobotSpec)."""

    def __init__(self, robots):
        self.lock = threading.Lock()
        self.poses = {}         # robot -> (x, y, z, yaw) from its vicon topic
        self.pairs = None       # latest /puzzlebot/connection_pairs
        self.physical = None    # latest /puzzlebot/sim/physical_pairs
        self.physical_log = []  # (stamp, msg) of every physical pairs message (tests)
        self.pairs_log = []     # (stamp, msg) of every connection pairs message (tests)
        self.pose_log = {r.name: collections.deque(maxlen=POSE_HISTORY) for r in robots}  # (stamp, pose)
        self.started = {}       # request id -> stamp of its first status that was not IDLE
        self.ended = {}         # request id -> its final BehaviorStatus (SUCCEEDED or FAILED)
        self.solved = False
        self.failed_solves = 0
        self.failed_stamps = []     # stamps of the failed MPC steps
        rospy.Subscriber(names.BEHAVIOR_STATUS_TOPIC, BehaviorStatus, self._on_status, queue_size=10)
        rospy.Subscriber(names.SOLVER_STATS_TOPIC, SolverStats, self._on_stats, queue_size=10)
        rospy.Subscriber(names.CONNECTION_PAIRS_TOPIC, ConnectionPairArray, self._on_pairs, queue_size=10)
        rospy.Subscriber(names.PHYSICAL_PAIRS_TOPIC, ConnectionPairArray, self._on_physical, queue_size=10)
        for r in robots:
            rospy.Subscriber(r.vicon_topic, TransformStamped, self._on_pose, callback_args=r.name, queue_size=20)
        self.client = None
        self.goals = {}         # request id -> actionlib ClientGoalHandle of its goal

    # ------------------------------------------------------------ callbacks
    def _on_status(self, msg):
        stamp = msg.header.stamp.to_sec()
        with self.lock:
            if msg.state != BehaviorStatus.IDLE:
                self.started.setdefault(msg.request_id, stamp)
            if msg.state in (BehaviorStatus.SUCCEEDED, BehaviorStatus.FAILED):
                self.ended.setdefault(msg.request_id, msg)

    def _on_stats(self, msg):
        self.solved = self.solved or msg.success
        if not msg.success:
            self.failed_solves += 1
            self.failed_stamps.append(msg.header.stamp.to_sec())

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
        pose = (t.x, t.y, t.z, yaw_from_quaternion(q.x, q.y, q.z, q.w))
        self.poses[name] = pose
        with self.lock:
            self.pose_log[name].append((msg.header.stamp.to_sec(), pose))

    # ---------------------------------------------------------------- setup
    def wait_for_start(self, timeout=60.0):
        """Wait (wall, up to ``timeout`` s) for the first /clock (under /use_sim_time) and a pose of
        every robot: the scenario's script is timed from the simulation's clock, never from before it
        runs. Returns the robots still without a pose (empty: all seen)."""
        end = time.monotonic() + timeout
        if rospy.get_param("/use_sim_time", False):
            try:
                rospy.wait_for_message("/clock", Clock, timeout=max(0.0, end - time.monotonic()))
            except rospy.ROSException:
                return sorted(self.pose_log)
        while not rospy.is_shutdown() and time.monotonic() < end:
            with self.lock:
                missing = sorted(n for n, log in self.pose_log.items() if not log)
            if not missing:
                return []
            time.sleep(POLL)
        with self.lock:
            return sorted(n for n, log in self.pose_log.items() if not log)

    def connect(self, service_timeout=120.0, control_timeout=60.0):
        """Wait for the MPC's behaviour action and its first solved step (it then has poses: couple needs
        them). Returns False if no step was solved within ``control_timeout`` s (wall)."""
        self.client = actionlib.ActionClient(names.BEHAVIOR_ACTION, BehaviorAction)
        if not self.client.wait_for_server(rospy.Duration(service_timeout)):
            raise rospy.ROSException("no action server %s within %.0f s" % (names.BEHAVIOR_ACTION, service_timeout))
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
    def submit(self, steps, start_delay=START_DELAY):
        """Request every step at once: the first starts ``start_delay`` s of ROS time from now, each
        next one is queued behind the one before (the MPC starts it at the control step after that
        one ends; SetBehavior.srv). In lockstep with the simulation the run is then the same
        whatever the timing of these calls (in simulated time the first step starts at
        SCRIPT_START unless later). Returns one entry per step: its request id, or a
        StepResult for a step the MPC refused (the steps after it are not sent)."""
        out = []
        start = max(rospy.get_time() + start_delay, SCRIPT_START if start_delay > 0 else 0.0)
        if start_delay > 0 and start > SCRIPT_START + 1e-6 and rospy.get_param("/use_sim_time", False):
            rospy.logwarn("the script starts at t = %.2f s, not %.1f s: this runner came up after the simulation "
                          "had run %.2f s, so runs of the same seed that started in time differ from this one"
                          % (start, SCRIPT_START, start - start_delay))
        for k, step in enumerate(steps):
            goal = step_goal(step)
            goal.queue, goal.start_time = k > 0, start if k == 0 and start_delay > 0 else 0.0
            accepted, detail = self.send(goal)
            if not accepted:
                out.append(StepResult(step, "refused", detail, 0.0))
                break
            out.append(detail)
        return out

    def send(self, goal, timeout=ACCEPT_TIMEOUT):
        """Send ``goal`` and wait (wall) until the MPC node accepts it (its first feedback names the request
        id) or rejects it: (True, request id) or (False, the reason)."""
        box = {}

        def on_feedback(handle, feedback):
            box.setdefault("id", feedback.request_id)
        handle = self.client.send_goal(goal, feedback_cb=on_feedback)
        end = time.monotonic() + timeout
        while "id" not in box and not rospy.is_shutdown() and time.monotonic() < end:
            if handle.get_comm_state() == actionlib.CommState.DONE:
                result = handle.get_result()
                if "id" not in box:
                    return False, (result.message if result is not None else handle.get_goal_status_text())
            time.sleep(POLL)
        if "id" not in box:
            return False, "the MPC node did not answer the goal within %.0f s" % timeout
        self.goals[box["id"]] = handle
        return True, box["id"]

    def run_steps(self, steps, default_timeout, wall_deadline, start_delay=START_DELAY):
        """Submit ``steps`` (submit) and yield each one's StepResult in order as it ends; stops after
        the first step that does not succeed (the MPC drops the ones queued behind it)."""
        for step, entry in zip(steps, self.submit(steps, start_delay)):
            result = entry if isinstance(entry, StepResult) else self.wait_step(step, entry, default_timeout,
                                                                                wall_deadline)
            yield result
            if result.outcome != "succeeded":
                return

    def run_step(self, step, default_timeout, wall_deadline):
        """Request one step now and wait for its final status; a StepResult."""
        return next(self.run_steps([step], default_timeout, wall_deadline, start_delay=0.0))

    def wait_step(self, step, request_id, default_timeout, wall_deadline):
        """Wait for the result of request ``request_id`` (``step``'s goal): a StepResult whose
        sim_seconds, final errors and pairs are those of the control step that ended it."""
        limit = (step.timeout or default_timeout) + SETTLE
        t_wait = rospy.get_time()
        outcome, message, result = "timeout", "no result from the MPC node", None
        handle = self.goals.get(request_id)
        while handle is not None and not rospy.is_shutdown() and time.monotonic() < wall_deadline:
            if handle.get_comm_state() == actionlib.CommState.DONE:
                result = handle.get_result()
                ok = handle.get_goal_status() == GoalStatus.SUCCEEDED and result is not None
                outcome = "succeeded" if ok else "failed"
                message = result.message if result is not None else handle.get_goal_status_text()
                if result is not None and result.outcome not in ("succeeded", "failed"):
                    message = "%s: %s" % (result.outcome, message)
                break
            with self.lock:
                started = self.started.get(request_id)
            if rospy.get_time() - max(t_wait, started if started is not None else -math.inf) > limit:
                message = "no result within %.1f s of simulated time" % limit
                break
            time.sleep(POLL)
        ended = result is not None and not result.ended.is_zero()
        final = self.ended.get(request_id)
        end = result.ended.to_sec() if ended else (final.header.stamp.to_sec() if final is not None
                                                   else rospy.get_time())
        with self.lock:
            start = self.started.get(request_id, t_wait)
        if result is not None and not result.started.is_zero():
            start = result.started.to_sec()
        self.wait_until(end + 0.2)       # the pair and pose messages of that step have arrived
        errors = {}
        for name, goal in zip(step.robots, step.goals):
            pose = self.pose_at(name, end)
            if pose is not None:
                errors[name] = math.hypot(pose[0] - goal[0], pose[1] - goal[1])
        pairs = ""
        if step.behavior in ("couple", "decouple", "drive_assembly", "assembly_to_goal"):
            pairs = pairs_text(self.pairs_at(end))
            physical = self.physical_at(end)
            if physical is not None:      # simulation: the anchors themselves
                pairs += "; physically: " + (", ".join(
                    "%s->%s %s" % (p.robot_i, p.robot_j, PHYSICAL_TEXT.get(p.status, "?")) for p in physical.pairs)
                    or "no anchor in an opening")
        return StepResult(step, outcome, message, end - start, errors, pairs, start, end)

    # ------------------------------------------------- state at a given time
    def wait_until(self, stamp, wall_timeout=60.0):
        """Wait until ROS time reaches ``stamp`` [s] (bounded in wall time)."""
        end = time.monotonic() + wall_timeout
        while rospy.get_time() < stamp and not rospy.is_shutdown() and time.monotonic() < end:
            time.sleep(POLL)

    def pairs_at(self, stamp):
        """The MPC's connection pairs message of the control step at ``stamp`` (the first at or after it)."""
        return _first_at(self.pairs_log, stamp, self.lock)

    def physical_at(self, stamp):
        """The simulation's physical pairs message at ``stamp`` (the first at or after it); None without one."""
        return _first_at(self.physical_log, stamp, self.lock)

    def pose_at(self, name, stamp):
        """(x, y, z, yaw) of ``name`` from its vicon topic at ``stamp`` (the first at or after it, else
        the latest); None without any."""
        pose = _first_at(self.pose_log.get(name, ()), stamp, self.lock)
        return pose if pose is not None else self.poses.get(name)


def _first_at(log, stamp, lock):
    """The first message of ``log`` [(stamp, msg)] stamped at or after ``stamp``; None if none."""
    with lock:
        return next((msg for t, msg in log if t >= stamp - 1e-6), None)
