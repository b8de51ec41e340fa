#!/usr/bin/env python3
"""Bad input to the sim node: one clear line, exit status 2, no traceback."""

import subprocess
import unittest

import rospy
import rostest

GOOD_START = {"pz1": [0.0, 0.0, 0.0], "pz2": [0.0, 0.2, 0.0]}


class SimBadInput(unittest.TestCase):
    def run_node(self, name, start=GOOD_START, sim=None, robot=None, anchor=None):
        rospy.set_param("/puzzlebot/robots", [{"name": "pz1"}, {"name": "pz2"}])
        rospy.set_param("/puzzlebot/scenario/start", start)
        for key, value in (("sim", sim), ("robot", robot), ("anchor", anchor)):
            if value is not None:
                rospy.set_param("/%s/%s" % (name, key), value)
        proc = subprocess.run(["rosrun", "puzzlebot_sim", "sim_node", "__name:=%s" % name],
                              capture_output=True, text=True, timeout=60)
        self.assertEqual(proc.returncode, 2, proc.stderr)
        self.assertNotIn("Traceback", proc.stderr)
        return proc.stderr

    def test_unknown_world(self):
        err = self.run_node("bad_world", sim={"world": "moon"})
        self.assertIn("unknown world 'moon'; known worlds: flat, gap, step", err)

    def test_robot_inside_another(self):
        err = self.run_node("bad_start", start={"pz1": [0.0, 0.0, 0.0], "pz2": [0.02, 0.01, 0.3]})
        self.assertIn("robots pz1 and pz2 are placed inside each other", err)

    def test_anchor_inside_another(self):
        err = self.run_node("bad_anchor_start", start={"pz1": [0.0, 0.0, 0.0], "pz2": [-0.058, 0.0, 0.0]})
        self.assertIn("the anchor of robot pz1 would start inside robot pz2", err)

    def test_malformed_robot_yaml(self):
        err = self.run_node("bad_robot_key", robot={"wheel_radius": 0.01, "wheel_radiuss": 0.02})
        self.assertIn("/bad_robot_key/robot: unknown key(s) wheel_radiuss", err)
        err = self.run_node("bad_robot_value", robot={"wheel_radius": "ten"})
        self.assertIn("/bad_robot_value/robot.wheel_radius: expected a finite number, got 'ten'", err)
        err = self.run_node("bad_anchor_profile", anchor={"backward_profile_n": [0.0, 0.1]})
        self.assertIn("backward_profile_mm and backward_profile_n differ in length", err)
        err = self.run_node("bad_robot_thin", robot={"lip_depth": 0.001})
        self.assertIn("thinner than 2.0 mm", err)

    def test_missing_actuator_model(self):
        err = self.run_node("bad_model", sim={"actuator_model": "/nonexistent/model.yaml"})
        self.assertIn("/nonexistent/model.yaml: no such file", err)


if __name__ == "__main__":
    rospy.init_node("sim_bad_input_test")
    rostest.rosrun("puzzlebot_sim", "sim_bad_input", SimBadInput)
