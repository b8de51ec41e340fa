#!/usr/bin/env python3
"""Two robots through MPC + driver + emulator (wall time), as a scenario runs in the sim:
go_to_goal into a line 65 mm apart, then follow_velocity side by side.

Stand-in for the couple-and-drive scenario (needs the MPC's coupling
behaviours): the same requests the scenario runner sends, measured on the
mocap stream and the emulator's ground truth.
"""

import math
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import Point, TransformStamped, Twist, TwistStamped

from puzzlebot_common import names
from puzzlebot_msgs.msg import BehaviorStatus
from puzzlebot_msgs.srv import SetBehavior, SetBehaviorRequest

GOALS = {"pz1": (0.05, 0.0), "pz2": (0.115, 0.0)}
TOLERANCE = 0.005       # m
GOAL_TIMEOUT = 40.0     # s (wall = ROS time in the lab launch)
DRIVE = (0.03, 0.0)     # m/s, rad/s
DRIVE_TIME = 3.0        # s


class LabPair(unittest.TestCase):
    def setUp(self):
        self.pose, self.truth, self.status = {}, {n: [] for n in GOALS}, None
        self.true_pose = {}
        for n in GOALS:
            rospy.Subscriber(names.vicon_topic(n), TransformStamped, self.on_pose, callback_args=n)
            rospy.Subscriber(names.emulator_velocity_topic(n), TwistStamped, self.on_truth, callback_args=n)
            rospy.Subscriber(names.emulator_truth_topic(n), TransformStamped, self.on_true_pose, callback_args=n)
        rospy.Subscriber(names.BEHAVIOR_STATUS_TOPIC, BehaviorStatus, self.on_status)
        rospy.wait_for_service(names.SET_BEHAVIOR_SERVICE, timeout=90.0)
        self.call = rospy.ServiceProxy(names.SET_BEHAVIOR_SERVICE, SetBehavior)

    def on_pose(self, msg, name):
        self.pose[name] = (msg.transform.translation.x, msg.transform.translation.y)

    def on_true_pose(self, msg, name):
        self.true_pose[name] = (msg.transform.translation.x, msg.transform.translation.y)

    def on_truth(self, msg, name):
        self.truth[name].append((msg.header.stamp.to_sec(), msg.twist.linear.x, msg.twist.angular.z))

    def on_status(self, msg):
        self.status = msg

    def wait_done(self, request_id, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            s = self.status
            if s and s.request_id == request_id and s.state in (BehaviorStatus.SUCCEEDED, BehaviorStatus.FAILED):
                return s
            time.sleep(0.05)
        return self.status

    def test_go_to_goals_then_drive_together(self):
        end = time.monotonic() + 30.0
        while time.monotonic() < end and len(self.pose) < 2:
            time.sleep(0.1)
        self.assertEqual(set(self.pose), set(GOALS), "no mocap poses from the emulator")
        robots = sorted(GOALS)
        t0 = rospy.get_time()
        resp = self.call(SetBehaviorRequest(behavior="go_to_goal", robots=robots, tolerance=TOLERANCE,
                                            goals=[Point(GOALS[n][0], GOALS[n][1], 0) for n in robots],
                                            timeout=GOAL_TIMEOUT))
        self.assertTrue(resp.accepted, resp.message)
        s = self.wait_done(resp.request_id, GOAL_TIMEOUT + 10.0)
        elapsed = rospy.get_time() - t0
        errors = {n: math.hypot(self.true_pose[n][0] - g[0], self.true_pose[n][1] - g[1]) for n, g in GOALS.items()}
        print("go_to_goal through the driver: %s after %.1f s; true distance to goal [mm]: %s"
              % (s.message if s else "no status", elapsed, {n: round(1e3 * e, 1) for n, e in errors.items()}),
              flush=True)
        self.assertEqual(s.state, BehaviorStatus.SUCCEEDED, s.message)
        for n, e in errors.items():
            self.assertLess(e, 2 * TOLERANCE, "%s ends %.1f mm from its goal (true pose)" % (n, 1e3 * e))

        gap0 = math.dist(self.true_pose["pz1"], self.true_pose["pz2"])
        drive = Twist()
        drive.linear.x, drive.angular.z = DRIVE
        resp = self.call(SetBehaviorRequest(behavior="follow_velocity", robots=robots, velocities=[drive, drive],
                                            timeout=DRIVE_TIME))
        self.assertTrue(resp.accepted, resp.message)
        t1 = rospy.get_time()
        self.wait_done(resp.request_id, DRIVE_TIME + 10.0)
        gap1 = math.dist(self.true_pose["pz1"], self.true_pose["pz2"])
        for n in robots:
            xs = [x for x in self.truth[n] if t1 + 1.0 <= x[0] < t1 + DRIVE_TIME]
            v = sum(x[1] for x in xs) / len(xs)
            print("drive together: %s true v %.4f m/s (cmd %.3f, %.1f %%)" % (n, v, DRIVE[0],
                                                                            100 * abs(v - DRIVE[0]) / DRIVE[0]),
                  flush=True)
            self.assertLessEqual(abs(v - DRIVE[0]), 0.1 * DRIVE[0])
        print("drive together: gap %.1f mm -> %.1f mm" % (1e3 * gap0, 1e3 * gap1), flush=True)
        self.assertLess(abs(gap1 - gap0), 0.01)


if __name__ == "__main__":
    rospy.init_node("lab_pair_test")
    rostest.rosrun("puzzlebot_bringup", "lab_pair", LabPair)
