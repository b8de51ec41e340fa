#!/usr/bin/env python3
"""record.launch on a running simulation: the bag holds what a run's analysis needs.

The test starts `roslaunch puzzlebot_bringup record.launch bag:=<results>/record_test.bag`
next to sim.launch (couple2 scenario), runs the scenario's steps (the robots couple and drive),
stops the recorder with SIGINT (as Ctrl-C or the end of sim.launch does) and reads the bag:
- the topics of record.launch are there with their types: /vicon/<r>/<r>, /<r>/cmd_vel,
  /puzzlebot/connection_pairs, /puzzlebot/sim/physical_pairs, /puzzlebot/mpc/solver_stats, /tf;
  /clock and the rviz markers are not;
- the vicon poses come at the sim's 100 Hz (+/- 10 %) of simulated time, with header stamps
  strictly increasing and within the bag's time span (record times are simulated times);
- every robot has non-zero commands, tf has world -> <r>/base_link and <r>/anchor, the
  connection pairs include the coupled pair;
- the model-identification tool (`rosrun puzzlebot_mpc identify_model BAG --out report.json`,
  issue 7) reads the bag and reports both robots with a finite prediction error.
"""

import json
import math
import os
import signal
import subprocess
import sys
import time
import unittest

import rosbag
import rosgraph
import rospkg
import rospy
import rostest

from puzzlebot_common import names
from puzzlebot_common.node_utils import get_param, robot_list_from_param
from puzzlebot_msgs.msg import ConnectionPair
from puzzlebot_bringup.runner import Runner
from puzzlebot_bringup.scenario import parse_scenario
from puzzlebot_sim.config import load_sim_config

POSE_RATE = float(load_sim_config().sim.pose_rate)   # Hz of simulated time, the sim node's pose rate
SUBSCRIBE_TIMEOUT = 30.0   # s (wall) for rosbag record to subscribe to the topics
STOP_TIMEOUT = 30.0        # s (wall) for rosbag record to close the bag
IDENTIFY_TIMEOUT = 120.0   # s (wall) for identify_model on the short bag (0.4 s unloaded)


class RecordBag(unittest.TestCase):
    def setUp(self):
        self.robots = robot_list_from_param()
        self.names = [r.name for r in self.robots]
        self.scenario = parse_scenario(get_param(names.SCENARIO_PARAM, required=True), self.names)
        self.runner = Runner(self.robots)
        out_dir = os.path.join(rospkg.get_test_results_dir(), "puzzlebot_bringup")
        os.makedirs(out_dir, exist_ok=True)
        self.bag_path = os.path.join(out_dir, "record_test.bag")
        for path in (self.bag_path, self.bag_path + ".active"):
            if os.path.exists(path):
                os.remove(path)

    def wait_subscribed(self, topics):
        master = rosgraph.Master("/record_test")
        end = time.monotonic() + SUBSCRIBE_TIMEOUT
        while time.monotonic() < end:
            subs = {t for t, nodes in master.getSystemState()[1] if "/record" in nodes}
            if set(topics) <= subs:
                return
            time.sleep(0.2)
        self.fail("rosbag record did not subscribe to %s" % sorted(set(topics) - subs))

    def test_bag_has_what_an_analysis_needs(self):
        self.assertTrue(self.runner.connect(), "the MPC never solved a step")
        vicon = [r.vicon_topic for r in self.robots]
        cmd = [names.cmd_vel_topic(n) for n in self.names]
        recorder = subprocess.Popen(["roslaunch", "puzzlebot_bringup", "record.launch", "bag:=" + self.bag_path],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
        try:
            self.wait_subscribed(vicon + cmd + [names.SOLVER_STATS_TOPIC, names.CONNECTION_PAIRS_TOPIC,
                                                 names.PHYSICAL_PAIRS_TOPIC, names.PREDICTED_TRAJECTORIES_TOPIC, "/tf"])
            for step in self.scenario.steps:
                result = self.runner.run_step(step, 0.0, time.monotonic() + 300.0)
                self.assertEqual(result.outcome, "succeeded", "%s: %s" % (step.describe(), result.message))
        finally:
            recorder.send_signal(signal.SIGINT)
            recorder.wait(STOP_TIMEOUT)
        self.assertTrue(os.path.isfile(self.bag_path), "no bag at %s (still .active?)" % self.bag_path)
        print("bag: %s (%.0f kB)" % (self.bag_path, os.path.getsize(self.bag_path) / 1e3), flush=True)

        with rosbag.Bag(self.bag_path) as bag:
            info = bag.get_type_and_topic_info().topics
            t_start, t_end = bag.get_start_time(), bag.get_end_time()
            expected = {t: "geometry_msgs/TransformStamped" for t in vicon}
            expected.update({t: "geometry_msgs/Twist" for t in cmd})
            expected.update({names.CONNECTION_PAIRS_TOPIC: "puzzlebot_msgs/ConnectionPairArray",
                             names.PHYSICAL_PAIRS_TOPIC: "puzzlebot_msgs/ConnectionPairArray",
                             names.SOLVER_STATS_TOPIC: "puzzlebot_msgs/SolverStats", "/tf": "tf2_msgs/TFMessage"})
            for topic, msg_type in sorted(expected.items()):
                self.assertIn(topic, info, "%s not recorded; recorded: %s" % (topic, sorted(info)))
                self.assertEqual(info[topic].msg_type, msg_type, topic)
            self.assertNotIn("/clock", info)
            self.assertNotIn(names.MARKERS_TOPIC, info)
            span = t_end - t_start
            print("recorded %.1f s (simulated): %s" % (span, ", ".join(
                "%s %d" % (t, info[t].message_count) for t in sorted(info))), flush=True)

            for topic in vicon:
                stamps = [m.header.stamp.to_sec() for _, m, _ in bag.read_messages(topics=[topic])]
                self.assertTrue(all(b > a for a, b in zip(stamps, stamps[1:])), "%s: stamps not increasing" % topic)
                self.assertGreaterEqual(stamps[0], t_start - 0.1)
                self.assertLessEqual(stamps[-1], t_end + 0.1)
                rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
                self.assertAlmostEqual(rate, POSE_RATE, delta=0.1 * POSE_RATE, msg="%s at %.1f Hz" % (topic, rate))
            for topic in cmd:
                moving = [m for _, m, _ in bag.read_messages(topics=[topic]) if m.linear.x or m.angular.z]
                self.assertTrue(moving, "%s: only zero commands" % topic)
            frames = {tr.child_frame_id for _, m, _ in bag.read_messages(topics=["/tf"]) for tr in m.transforms}
            for n in self.names:
                self.assertIn(names.base_frame(n), frames)
                self.assertIn(names.anchor_frame(n), frames)
            inserted = [p for _, m, _ in bag.read_messages(topics=[names.CONNECTION_PAIRS_TOPIC]) for p in m.pairs
                        if p.status == ConnectionPair.STATUS_HEAD_INSERTED]
            self.assertTrue(inserted, "no coupled pair in the recorded connection pairs")

        # the model-identification tool (issue 7) on the bag, as a user runs it
        report_path = os.path.splitext(self.bag_path)[0] + "_identify.json"
        proc = subprocess.run(["rosrun", "puzzlebot_mpc", "identify_model", self.bag_path, "--out", report_path,
                               "--quiet"], capture_output=True, text=True, timeout=IDENTIFY_TIMEOUT)
        self.assertEqual(proc.returncode, 0, "identify_model failed: %s" % (proc.stderr or proc.stdout)[-2000:])
        with open(report_path) as f:
            report = json.load(f)
        self.assertEqual(sorted(report["robots"]), sorted(self.names))
        before = report["before"]["rmse_pos_m"]
        self.assertTrue(math.isfinite(before), report["before"])
        print("identify_model on the bag: %s; nominal unicycle position RMSE %.2f mm, effects: %s"
              % (report_path, 1e3 * before, [e.get("name", e) for e in report["effects"]] or "none"), flush=True)

if __name__ == "__main__":
    rospy.init_node("record_test", argv=sys.argv)
    rostest.rosrun("puzzlebot_bringup", "record_bag", RecordBag)
