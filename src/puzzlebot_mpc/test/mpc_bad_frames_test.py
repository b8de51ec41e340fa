#!/usr/bin/env python3
"""The MPC node as a black box, fed bad mocap frames (rostest mpc_bad_frames).

The test is the lab around the MPC node: five kinematic robots (unicycles at
100 Hz driven by the node's cmd_vel) and their Vicon topics; every robot
follows (0.03 m/s, 0.3 rad/s). Every fault of puzzlebot_common.mocap_faults,
as one frame and as a burst of 10, replaces the frames of one of pz1..pz4
(four at a time, 0.6 s apart); pz5 stays clean. Asserted:

- the node never dies: it solves every step (solver_stats) to the end;
- the hit robot gets a zero command (held by its pose gate) after each fault,
  and its command back within 0.6 s of good frames (rule: reacquire_frames
  0.15 s + a control step; measured and printed);
- pz5 is commanded throughout, never zero;
- a line on /rosout from the node names each rejection (robot and kind).
"""

import statistics
import threading
import time
import unittest

import rosgraph
import rospy
import rostest
from geometry_msgs.msg import Twist

from puzzlebot_common import names
from puzzlebot_common.mocap_faults import FAULTS
from puzzlebot_common.node_utils import robot_list_from_param
from puzzlebot_common.rostest_lab import Mocap, NodeLog, UnicyclePlant
from puzzlebot_msgs.msg import SolverStats
from puzzlebot_msgs.srv import SetBehavior, SetBehaviorRequest

CMD = (0.03, 0.3)
POSE_RATE = 100.0        # Hz
SPACING = 0.6            # s between two faults on a robot (> pose_gate/log_period 0.3 s of the test launch)
VICTIMS = ("pz1", "pz2", "pz3", "pz4")
CLEAN = "pz5"
BOUND = 0.6              # s, generous wall-time bound of the ~0.25 s rule


class Lab:
    """Unicycles driven by the node's cmd_vel (plant), published as Vicon poses with faults (mocap); the
    node's log lines and solver stats."""

    def __init__(self, robots):
        self.plant = UnicyclePlant({r.name: (0.0, 0.15 * i, 0.0) for i, r in enumerate(robots)})
        self.mocap = Mocap(robots, self.plant.step, POSE_RATE)
        self.log = NodeLog("mpc")
        self.lock = threading.Lock()
        self.stats = []                                       # (arrival, success)
        rospy.Subscriber(names.SOLVER_STATS_TOPIC, SolverStats, self._on_stats, queue_size=100)

    def _on_stats(self, msg):
        with self.lock:
            self.stats.append((time.time(), msg.success))


class MpcBadFrames(unittest.TestCase):
    def test_bad_frames_hold_the_robot_and_never_stop_the_others(self):
        robots = robot_list_from_param()
        lab = Lab(robots)
        lab.mocap.start()
        try:
            self.run_cases(lab, [r.name for r in robots])
        finally:
            lab.mocap.stop()

    def run_cases(self, lab, robot_names):
        plant = lab.plant
        rospy.wait_for_service(names.SET_BEHAVIOR_SERVICE, timeout=60.0)
        call = rospy.ServiceProxy(names.SET_BEHAVIOR_SERVICE, SetBehavior)
        tw = Twist()
        tw.linear.x, tw.angular.z = CMD
        resp = call(SetBehaviorRequest(behavior="follow_velocity", robots=robot_names,
                                       velocities=[tw] * len(robot_names), timeout=120.0))
        self.assertTrue(resp.accepted, resp.message)
        end = time.monotonic() + 30.0
        while not all(c and c[-1][1] > 0.02 for c in (plant.commands(n, 0.0) for n in robot_names)) \
                and time.monotonic() < end:
            time.sleep(0.1)
        time.sleep(1.0)
        t0 = time.time() + 0.2
        schedule = lab.mocap.plan.every_fault(VICTIMS, t0, SPACING, POSE_RATE)   # (robot, fault, burst, t)
        t_end = schedule[-1][3] + SPACING + 0.5
        while time.time() < t_end:
            time.sleep(0.1)

        resume = []
        for name, fault, burst, t in schedule:
            kind = FAULTS[fault][1]
            t_good = t + burst / POSE_RATE
            window = plant.commands(name, t, t + SPACING)                 # until the next fault on this robot
            held = [c for c in window if (c[1], c[2]) == (0.0, 0.0)]
            self.assertTrue(held, "%s: %s x %d never held at zero" % (name, fault, burst))
            back = [c[0] for c in window if c[0] > held[-1][0] and c[1] > 0.02]
            self.assertTrue(back, (name, fault, burst))
            resume.append(back[0] - t_good)
            self.assertLess(back[0] - t_good, BOUND, (name, fault, burst))
            named = lab.log.rejections(name, kind, t - 0.05, t + SPACING + 0.5)
            self.assertTrue(named, "no log line for %s on %s at %.2f" % (fault, name, t))
        clean_cmds = plant.commands(CLEAN, t0, t_end)
        self.assertGreater(len(clean_cmds), 10 * (t_end - t0) * 0.5)
        self.assertTrue(all(v > 0.02 for _, v, _ in clean_cmds))
        with lab.lock:
            stats = [s for t, s in lab.stats if t0 <= t < t_end]
        self.assertTrue(stats and all(stats), "failed or missing MPC steps: %d of %d" % (stats.count(False), len(stats)))
        self.assertIn("/mpc", [n for _, nodes in rosgraph.Master("/t").getSystemState()[0] for n in nodes])
        print("%d cases; command back %.3f s (median) / %.3f s (max) after the first good frame; %d MPC steps, "
              "all solved" % (len(schedule), statistics.median(resume), max(resume), len(stats)))


if __name__ == "__main__":
    rospy.init_node("mpc_bad_frames_test")
    rostest.rosrun("puzzlebot_mpc", "mpc_bad_frames", MpcBadFrames)
