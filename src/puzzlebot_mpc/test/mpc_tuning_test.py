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
from geometry_msgs.msg import Point

from puzzlebot_common import names
from puzzlebot_common.node_utils import robot_list_from_param
from puzzlebot_common.rostest_lab import Mocap, UnicyclePlant
from puzzlebot_msgs.msg import SolverStats
from puzzlebot_msgs.srv import SetBehavior, SetBehaviorRequest

POSE_RATE = 100.0
DT = 0.1                 # s, the MPC's period (mpc.yaml)


class Lab:
    """One unicycle driven by cmd_vel (plant), published as Vicon poses (mocap); the node's costs, logged."""

    def __init__(self):
        self.plant = UnicyclePlant({"pz1": (0.0, 0.0, 0.0)})
        self.mocap = Mocap(robot_list_from_param(), self.plant.step, POSE_RATE).start()
        self.lock = threading.Lock()
        self.costs = []                                        # (wall time, cost)
        rospy.Subscriber(names.SOLVER_STATS_TOPIC, SolverStats, self._on_stats, queue_size=100)

    def _on_stats(self, msg):
        with self.lock:
            self.costs.append((time.time(), msg.cost))

    def speeds(self, t0):
        """v [m/s] of the commands that arrived since wall time ``t0``."""
        return [v for _, v, _ in self.plant.commands("pz1", t0)]

    def costs_since(self, t0):
        with self.lock:
            return [c for t, c in self.costs if t >= t0]


class MpcTuning(unittest.TestCase):
    def setUp(self):
        self.lab = Lab()
        rospy.wait_for_service(names.SET_BEHAVIOR_SERVICE, timeout=60.0)
        self.tuning = Client("/mpc/tuning", timeout=30.0)

    def tearDown(self):
        self.lab.mocap.stop()

    def wait(self, seconds):
        time.sleep(seconds)

    def test_weights_and_limits_at_run_time(self):
        call = rospy.ServiceProxy(names.SET_BEHAVIOR_SERVICE, SetBehavior)
        resp = call(SetBehaviorRequest(behavior="go_to_goal", robots=["pz1"], goals=[Point(0.6, 0.0, 0.0)]))
        self.assertTrue(resp.accepted, resp.message)
        self.wait(1.0)
        start = self.tuning.get_configuration(timeout=10.0)
        self.assertEqual((start["v_max"], start["w_goal_terminal"]), (0.05, 10000.0))   # mpc.yaml
        self.assertAlmostEqual(max(self.lab.speeds(time.time() - 0.5)), 0.05, places=3)

        for change, reason in (({"v_max": 0.5}, "exceed the hardware limits"),
                               ({"w_goal_terminal": -1.0}, "w_goal_terminal: must be >= 0")):
            answer = self.tuning.update_configuration(change)
            print("tuning %s: refused: %s" % (change, answer["refused"]), flush=True)
            self.assertIn(reason, answer["refused"])
            self.assertEqual((answer["v_max"], answer["w_goal_terminal"]), (0.05, 10000.0))
        t0 = time.time()
        self.wait(0.5)
        self.assertAlmostEqual(max(self.lab.speeds(t0)), 0.05, places=3)  # unchanged

        before = time.time()
        answer = self.tuning.update_configuration({"v_max": 0.02})
        t_answer = time.time()
        self.assertEqual((answer["refused"], answer["v_max"]), ("", 0.02))
        self.wait(1.0)
        after = self.lab.speeds(t_answer + 2 * DT)
        print("tuning v_max 0.05 -> 0.02: answered after %.0f ms; %d commands from 2 steps on, the largest "
              "%.4f m/s" % (1e3 * (t_answer - before), len(after), max(after)), flush=True)
        self.assertTrue(after and max(after) <= 0.02 + 1e-6, "commands above the new v_max: %s" % after[:5])
        self.assertAlmostEqual(rospy.get_param("/mpc/tuning/v_max"), 0.02)

        t0 = time.time()
        self.wait(0.5)
        cost_before = statistics.median(self.lab.costs_since(t0))
        answer = self.tuning.update_configuration({"w_goal_terminal": 20000.0})
        t_answer = time.time()
        self.assertEqual(answer["refused"], "")
        self.wait(0.2 + 2 * DT)
        t1 = time.time()
        self.wait(0.5)
        cost_after = statistics.median(self.lab.costs_since(t1))
        print("tuning w_goal_terminal 1e4 -> 2e4: solver cost (median of 0.5 s) %.1f -> %.1f (x%.2f)"
              % (cost_before, cost_after, cost_after / cost_before), flush=True)
        self.assertGreater(cost_after / cost_before, 1.6)
        self.assertLess(cost_after / cost_before, 2.2)


if __name__ == "__main__":
    rospy.init_node("mpc_tuning_test")
    rostest.rosrun("puzzlebot_mpc", "mpc_tuning", MpcTuning)
