#!/usr/bin/env python3
"""The MPC's weights and limits tuned at run time (dynamic_reconfigure ~tuning; rostest mpc_tuning).

The test plays one kinematic robot (a unicycle at 100 Hz driven by the node's cmd_vel, its Vicon
topic) sent by go_to_goal to a goal 0.6 m away, so it drives at v_max. Through the dynamic_reconfigure
client, as a user would:

- v_max 0.5 m/s (above hardware_v_max 0.2) and a negative weight are refused with the reason (the
  answer's 'refused'); nothing changes: the robot still drives at 0.05 m/s;
- v_max 0.02: every command from the second control step after the answer on is within 0.02 m/s;
- w_goal_terminal doubled: the solver's cost (SolverStats.cost, dominated by that weight times the
  squared distance to the goal) doubles from the next steps on;
- the parameter server mirrors the live values (/mpc/tuning/...).
"""

import statistics
import threading
import time
import unittest

import rospy
import rostest
from dynamic_reconfigure.client import Client
from geometry_msgs.msg import Point, TransformStamped, Twist

from puzzlebot_common import names
from puzzlebot_common.model import unicycle_arc
from puzzlebot_msgs.msg import SolverStats
from puzzlebot_msgs.srv import SetBehavior, SetBehaviorRequest

POSE_RATE = 100.0
DT = 0.1                 # s, the MPC's period (mpc.yaml)


class Plant:
    """One unicycle driven by cmd_vel, published as Vicon poses; the node's commands and costs, logged."""

    def __init__(self):
        self.lock = threading.Lock()
        self.pose, self.cmd = (0.0, 0.0, 0.0), (0.0, 0.0)
        self.cmds, self.costs = [], []                         # (wall time, v) / (wall time, cost)
        self.pub = rospy.Publisher(names.vicon_topic("pz1"), TransformStamped, queue_size=20)
        rospy.Subscriber(names.cmd_vel_topic("pz1"), Twist, self._on_cmd, queue_size=10)
        rospy.Subscriber(names.SOLVER_STATS_TOPIC, SolverStats, self._on_stats, queue_size=100)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _on_cmd(self, msg):
        with self.lock:
            self.cmd = (msg.linear.x, msg.angular.z)
            self.cmds.append((time.monotonic(), msg.linear.x))

    def _on_stats(self, msg):
        with self.lock:
            self.costs.append((time.monotonic(), msg.cost))

    def _run(self):
        t_next = time.monotonic()
        while not self.stop.is_set():
            with self.lock:
                self.pose = unicycle_arc(self.pose, *self.cmd, 1.0 / POSE_RATE)
                x, y, _ = self.pose
            msg = TransformStamped()
            msg.header.stamp = rospy.Time.now()
            msg.header.frame_id, msg.child_frame_id = names.WORLD_FRAME, "vicon/pz1/pz1"
            msg.transform.translation.x, msg.transform.translation.y = x, y
            msg.transform.rotation.w = 1.0
            self.pub.publish(msg)
            t_next += 1.0 / POSE_RATE
            time.sleep(max(0.0, t_next - time.monotonic()))

    def since(self, log, t0):
        with self.lock:
            return [v for t, v in log if t >= t0]


class MpcTuning(unittest.TestCase):
    def setUp(self):
        self.plant = Plant()
        rospy.wait_for_service(names.SET_BEHAVIOR_SERVICE, timeout=60.0)
        self.tuning = Client("/mpc/tuning", timeout=30.0)

    def tearDown(self):
        self.plant.stop.set()

    def wait(self, seconds):
        time.sleep(seconds)

    def test_weights_and_limits_at_run_time(self):
        call = rospy.ServiceProxy(names.SET_BEHAVIOR_SERVICE, SetBehavior)
        resp = call(SetBehaviorRequest(behavior="go_to_goal", robots=["pz1"], goals=[Point(0.6, 0.0, 0.0)]))
        self.assertTrue(resp.accepted, resp.message)
        self.wait(1.0)
        start = self.tuning.get_configuration(timeout=10.0)
        self.assertEqual((start["v_max"], start["w_goal_terminal"]), (0.05, 10000.0))   # mpc.yaml
        self.assertAlmostEqual(max(self.plant.since(self.plant.cmds, time.monotonic() - 0.5)), 0.05, places=3)

        for change, reason in (({"v_max": 0.5}, "exceed the hardware limits"),
                               ({"w_goal_terminal": -1.0}, "w_goal_terminal: must be >= 0")):
            answer = self.tuning.update_configuration(change)
            print("tuning %s: refused: %s" % (change, answer["refused"]), flush=True)
            self.assertIn(reason, answer["refused"])
            self.assertEqual((answer["v_max"], answer["w_goal_terminal"]), (0.05, 10000.0))
        t0 = time.monotonic()
        self.wait(0.5)
        self.assertAlmostEqual(max(self.plant.since(self.plant.cmds, t0)), 0.05, places=3)  # unchanged

        before = time.monotonic()
        answer = self.tuning.update_configuration({"v_max": 0.02})
        t_answer = time.monotonic()
        self.assertEqual((answer["refused"], answer["v_max"]), ("", 0.02))
        self.wait(1.0)
        after = self.plant.since(self.plant.cmds, t_answer + 2 * DT)
        print("tuning v_max 0.05 -> 0.02: answered after %.0f ms; %d commands from 2 steps on, the largest "
              "%.4f m/s" % (1e3 * (t_answer - before), len(after), max(after)), flush=True)
        self.assertTrue(after and max(after) <= 0.02 + 1e-6, "commands above the new v_max: %s" % after[:5])
        self.assertAlmostEqual(rospy.get_param("/mpc/tuning/v_max"), 0.02)

        t0 = time.monotonic()
        self.wait(0.5)
        cost_before = statistics.median(self.plant.since(self.plant.costs, t0))
        answer = self.tuning.update_configuration({"w_goal_terminal": 20000.0})
        t_answer = time.monotonic()
        self.assertEqual(answer["refused"], "")
        self.wait(0.2 + 2 * DT)
        t1 = time.monotonic()
        self.wait(0.5)
        cost_after = statistics.median(self.plant.since(self.plant.costs, t1))
        print("tuning w_goal_terminal 1e4 -> 2e4: solver cost (median of 0.5 s) %.1f -> %.1f (x%.2f)"
              % (cost_before, cost_after, cost_after / cost_before), flush=True)
        self.assertGreater(cost_after / cost_before, 1.6)
        self.assertLess(cost_after / cost_before, 2.2)


if __name__ == "__main__":
    rospy.init_node("mpc_tuning_test")
    rostest.rosrun("puzzlebot_mpc", "mpc_tuning", MpcTuning)
