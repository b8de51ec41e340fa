#!/usr/bin/env python3
"""Bad input to the MPC node: clear errors, no crash, no uncommanded motion."""

import subprocess
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import Point, TransformStamped, Twist

from puzzlebot_common.rostest_lab import assert_config_error, pose_msg
from puzzlebot_msgs.msg import SolverStats
from puzzlebot_msgs.srv import SetBehavior, SetBehaviorRequest


class MpcBadInput(unittest.TestCase):
    def setUp(self):
        self.stats, self.cmd = [], {}
        rospy.Subscriber("/puzzlebot/mpc/solver_stats", SolverStats, self.stats.append)
        for n in ("pz1", "pz2"):
            rospy.Subscriber("/%s/cmd_vel" % n, Twist, lambda m, n=n: self.cmd.__setitem__(n, m))
        self.pubs = {n: rospy.Publisher("/vicon/%s/%s" % (n, n), TransformStamped, queue_size=10)
                     for n in ("pz1", "pz2")}
        rospy.wait_for_service("/puzzlebot/mpc/set_behavior", timeout=60.0)
        self.call = rospy.ServiceProxy("/puzzlebot/mpc/set_behavior", SetBehavior)

    def publish_for(self, seconds, poses):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for n, p in poses.items():
                self.pubs[n].publish(pose_msg(n, *p))
            time.sleep(0.02)

    def test_unknown_robot_nan_pose_and_stale_pose(self):
        resp = self.call(SetBehaviorRequest(behavior="go_to_goal", robots=["pz1", "ghost"],
                                            goals=[Point(0.1, 0, 0), Point(0, 0, 0)]))
        self.assertFalse(resp.accepted)
        self.assertIn("ghost", resp.message)
        resp = self.call(SetBehaviorRequest(behavior="go_to_goal", robots=["pz1"], goals=[Point(float("nan"), 0, 0)]))
        self.assertFalse(resp.accepted)

        resp = self.call(SetBehaviorRequest(behavior="go_to_goal", robots=["pz1", "pz2"],
                                            goals=[Point(0.3, 0, 0), Point(0.3, 0.2, 0)]))
        self.assertTrue(resp.accepted, resp.message)
        self.publish_for(1.0, {"pz1": (0.0, 0.0, 0.0), "pz2": (0.0, 0.2, 0.0)})
        self.assertGreater(self.cmd["pz1"].linear.x, 0.0)

        # NaN poses for pz1: rejected; its last good pose goes stale, so it is stopped; pz2 keeps going.
        n_before = len(self.stats)
        self.publish_for(1.5, {"pz1": (float("nan"), 0.0, 0.0), "pz2": (0.0, 0.2, 0.0)})
        self.assertGreater(len(self.stats), n_before + 5, "MPC node stopped publishing")
        self.assertEqual(self.cmd["pz1"].linear.x, 0.0)
        self.assertEqual(self.cmd["pz1"].angular.z, 0.0)
        self.assertGreater(self.cmd["pz2"].linear.x, 0.0)

        # Everything silent: every robot stops.
        time.sleep(1.0)
        self.assertEqual(self.cmd["pz2"].linear.x, 0.0)

    def test_malformed_robot_list_is_a_clear_startup_error(self):
        # The running node read the list at start-up (setUp waited for its service).
        good = rospy.get_param("/puzzlebot/robots")
        rospy.set_param("/puzzlebot/robots", [{"name": "pz1"}, {"pilot": True}])
        try:
            proc = subprocess.run(["rosrun", "puzzlebot_mpc", "mpc_node", "__name:=bad_mpc"],
                                  capture_output=True, text=True, timeout=60)
        finally:
            rospy.set_param("/puzzlebot/robots", good)
        assert_config_error(self, proc, "/puzzlebot/robots[1]: missing 'name'")


if __name__ == "__main__":
    rospy.init_node("mpc_bad_input_test")
    rostest.rosrun("puzzlebot_mpc", "mpc_bad_input", MpcBadInput)
