"""The lab around a node under test, as the rostests that drive a node as a black box play it.

The driver's and the MPC's rostests stand in for what surrounds their node: the motion capture
(:class:`Mocap`: the robots' Vicon frames at a fixed rate, with the faults of a
:class:`puzzlebot_common.mocap_faults.FaultPlan` in place of the true frames), kinematic robots
driven by the node's cmd_vel (:class:`UnicyclePlant`) and the node's log lines (:class:`NodeLog`).
Frames are stamped with the wall time (the rostests run on it, /use_sim_time false).

Needs rospy and a running master (the test's main calls rospy.init_node); no node imports it.
"""

import math
import threading
import time

import rospy
from geometry_msgs.msg import TransformStamped, Twist
from rosgraph_msgs.msg import Log

from puzzlebot_common import names
from puzzlebot_common.mocap_faults import FaultPlan, clean
from puzzlebot_common.model import unicycle_arc


def frame_msg(child, frame):
    """geometry_msgs/TransformStamped of a mocap_faults.MocapFrame: WORLD_FRAME to ``child``."""
    msg = TransformStamped()
    msg.header.stamp = rospy.Time.from_sec(frame.stamp)
    msg.header.frame_id = names.WORLD_FRAME
    msg.child_frame_id = child
    t, r = msg.transform.translation, msg.transform.rotation
    t.x, t.y, t.z = frame.x, frame.y, frame.z
    r.x, r.y, r.z, r.w = frame.q
    return msg


def pose_msg(child, x, y, yaw):
    """The clean frame of the pose (x, y [m], yaw [rad]), stamped now (rospy.get_time())."""
    return frame_msg(child, clean(rospy.get_time(), x, y, yaw))


class Mocap:
    """The robots' Vicon frames at ``rate`` [Hz] from a thread, as ``plan`` makes them.

    Every period it calls ``step(t, dt)``, the test's plant: advance the robots by ``dt`` [s] and
    return their true poses ``[(robot, (x, y, yaw))]`` at wall time ``t`` [s]; each pose is published
    on the robot's vicon topic stamped ``t``: its clean frame, its fault's (``plan``), or nothing
    (SILENCE). ``good[robot]``: the stamps of the clean frames published.
    """

    def __init__(self, robots, step, rate=100.0):
        self.step, self.rate = step, rate
        self.plan = FaultPlan()
        self.good = {r.name: [] for r in robots}
        self.pubs = {r.name: rospy.Publisher(r.vicon_topic, TransformStamped, queue_size=20) for r in robots}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self):
        self._thread.start()
        return self

    def stop(self):
        self._stop.set()
        self._thread.join(timeout=2.0)

    def _run(self):
        # Frames are stamped on the grid of multiples of the period (wall time), as a Vicon stamps its
        # frames, and each grid instant gets its frame: a thread that falls behind on a loaded machine
        # publishes the frames it owes, late but with their own stamps, instead of skipping instants
        # (a one-frame fault of FaultPlan.every_fault lies between two grid instants and would be
        # lost) or stamping at irregular times (the plant moves by 1/rate per frame).
        k = math.ceil(time.time() * self.rate)
        while not self._stop.is_set():
            t = k / self.rate
            wait = t - time.time()
            if wait > 0:
                time.sleep(wait)
            for name, pose in self.step(t, 1.0 / self.rate):
                frame = self.plan.frame(name, t, *pose)
                if frame is None:
                    continue
                self.pubs[name].publish(frame_msg(name, frame))
                if self.plan.fault(name, t) is None:
                    self.good[name].append(t)
            k += 1


class UnicyclePlant:
    """Kinematic robots driven by the node's cmd_vel (geometry_msgs/Twist), ``step`` for a Mocap.

    ``starts``: robot -> (x, y, yaw) [m, m, rad]. Each robot holds its last command; ``commands``
    returns what arrived as (wall time [s], v [m/s], w [rad/s]).
    """

    def __init__(self, starts):
        self.lock = threading.Lock()
        self.poses = dict(starts)
        self.cmd = {name: (0.0, 0.0) for name in starts}
        self.cmds = {name: [] for name in starts}
        for name in starts:
            rospy.Subscriber(names.cmd_vel_topic(name), Twist, self._on_cmd, callback_args=name, queue_size=10)

    def _on_cmd(self, msg, name):
        with self.lock:
            self.cmd[name] = (msg.linear.x, msg.angular.z)
            self.cmds[name].append((time.time(), msg.linear.x, msg.angular.z))

    def step(self, t, dt):
        with self.lock:
            for name, (v, w) in self.cmd.items():
                self.poses[name] = unicycle_arc(self.poses[name], v, w, dt)
            return list(self.poses.items())

    def commands(self, name, t0, t1=math.inf):
        """The commands to ``name`` that arrived in [t0, t1) (wall time [s])."""
        with self.lock:
            return [c for c in self.cmds[name] if t0 <= c[0] < t1]


class NodeLog:
    """The /rosout lines of the node whose name ends with ``node`` ("": every node), as (stamp [s], text)."""

    def __init__(self, node):
        self.node = node
        self.lock = threading.Lock()
        self.lines = []
        rospy.Subscriber("/rosout", Log, self._on_log, queue_size=1000)

    def _on_log(self, msg):
        if msg.name.endswith(self.node):
            with self.lock:
                self.lines.append((msg.header.stamp.to_sec(), msg.msg))

    def rejections(self, robot, kind, t0, t1):
        """The lines stamped in [t0, t1) that report a rejected pose of ``robot`` of ``kind``
        (pose_gate.KINDS), as the driver and the MPC node write them."""
        with self.lock:
            return [text for stamp, text in self.lines
                    if t0 <= stamp < t1 and "rejected pose (%s): %s:" % (kind, robot) in text]


def assert_config_error(test, proc, expected):
    """``proc`` (a finished subprocess.run with text output) ended as a node does on a configuration
    error (node_utils.run_node): exit status 2, ``expected`` in its stderr, no traceback."""
    test.assertEqual(proc.returncode, 2, proc.stderr)
    test.assertIn(expected, proc.stderr)
    test.assertNotIn("Traceback", proc.stderr)
