#!/usr/bin/env python3
"""mpc_node with ~actuator_model: a good model file runs and plans with it; a bad one is a clear
start-up error (one line, exit status 2, no traceback)."""

import os
import subprocess
import tempfile
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import Point, TransformStamped, Twist

from puzzlebot_common.rostest_lab import assert_config_error, pose_msg
from puzzlebot_msgs.srv import SetBehavior, SetBehaviorRequest


def start_node(model_path):
    """A second MPC node (its own name) with the given model; returns the finished process."""
    return subprocess.run(["rosrun", "puzzlebot_mpc", "mpc_node", "__name:=model_check",
                           "_actuator_model:=%s" % model_path], capture_output=True, text=True, timeout=60)


class MpcActuatorModel(unittest.TestCase):
    def test_good_model_is_loaded_and_the_node_plans_with_it(self):
        cmd = {}
        rospy.Subscriber("/pz1/cmd_vel", Twist, lambda m: cmd.__setitem__("pz1", m))
        pub = rospy.Publisher("/vicon/pz1/pz1", TransformStamped, queue_size=10)
        rospy.wait_for_service("/puzzlebot/mpc/set_behavior", timeout=60.0)
        call = rospy.ServiceProxy("/puzzlebot/mpc/set_behavior", SetBehavior)
        resp = call(SetBehaviorRequest(behavior="go_to_goal", robots=["pz1"], goals=[Point(0.3, 0, 0)]))
        self.assertTrue(resp.accepted, resp.message)
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            # Measured yaw 0.3 rad = the model's heading offset: the body faces the goal. The plain
            # unicycle would turn right at full rate to face it (measured yaw 0.3 rad off).
            pub.publish(pose_msg("pz1", 0.0, 0.0, 0.3))
            time.sleep(0.02)
        self.assertGreater(cmd["pz1"].linear.x, 0.0)
        self.assertLess(abs(cmd["pz1"].angular.z), 0.05)

    def test_missing_model_file_is_a_clear_startup_error(self):
        proc = start_node("/nonexistent/model.yaml")
        assert_config_error(self, proc, "/model_check/actuator_model: /nonexistent/model.yaml: no such file")

    def test_malformed_model_file_is_a_clear_startup_error(self):
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
            f.write("model:\n  effects:\n    - name: velocity_lag\n      params: {tau_v_s: 0.1}\n")
        try:
            proc = start_node(f.name)
        finally:
            os.unlink(f.name)
        assert_config_error(self, proc, "effects[0]: effect velocity_lag needs exactly the parameters tau_v_s, "
                                        "tau_w_s")


if __name__ == "__main__":
    rospy.init_node("mpc_actuator_model_test")
    rostest.rosrun("puzzlebot_mpc", "mpc_actuator_model", MpcActuatorModel)
