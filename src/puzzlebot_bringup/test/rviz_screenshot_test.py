#!/usr/bin/env python3
"""rviz as a person sees it: the shipped configuration under Xvfb on the default scenario.

sim.launch runs couple4_line (the default scenario; its sim node starts a few seconds late, so
rviz is up before the robots move); rviz starts with the test on a virtual display, with the
shipped configuration and nothing panned or zoomed by hand. This test runs the scenario's steps
(as the scenario runner does) and saves three screenshots in the test results
(<results dir>/puzzlebot_bringup/rviz_{start,middle,end}.png, printed; docs/img has copies):

- start: the robots placed, before they move; middle: the chain coupled, driving; end: after
  the front robot decoupled.

It fails if rviz died or logged an ERROR line (the benign media_export lines are filtered:
puzzlebot_bringup/screenshot.py), if /puzzlebot/markers lacks a namespace the configuration
shows, if a step fails, if the start or the end picture does not show every robot whole (from the
pixels: one knob per robot seen, no robot body touching the view's edge; screenshot.robots_in_view),
or if the middle one lacks the coupled pairs' green polygons and the cyan seated-anchor discs
(pixels of those hues added since the start).
"""

import os
import sys
import time
import unittest

import rosgraph
import rospkg
import rospy
import rostest
from visualization_msgs.msg import MarkerArray

from puzzlebot_common import names
from puzzlebot_common.config import package_path
from puzzlebot_common.node_utils import get_param, robot_list_from_param
from puzzlebot_bringup.runner import Runner
from puzzlebot_bringup.scenario import parse_scenario
from puzzlebot_bringup.screenshot import Rviz, VirtualDisplay, hue_pixels, robots_in_view, rviz_log_errors

SIZE = (1200, 800)
VIEW = (366, 64, 1182, 768)          # the 3D view of the shipped layout (left: the Displays panel)
RVIZ_SETTLE = 1.5                    # s (wall) for rviz to draw a new state
RVIZ_STARTUP = 90.0                  # s (wall), generous: software OpenGL on a loaded machine
NAMESPACES = {"bodies", "fronts", "labels", "anchors", "polygons", "pairs", "physical", "predicted", "slots",
              "legend"}
# Pixels of these hues that the middle picture's 3D view has more than the start's (the legend's
# text, in every picture, has some of each; at the start nothing is coupled): the chain's three
# coupled pairs (green polygons) and seated anchors (cyan discs). Measured 2026-12: ~900 green,
# ~170 cyan more. A fraction, so that only a missing or mis-coloured feature fails.
MIN_ADDED_PIXELS = {"green": 300, "cyan": 60}


class RvizScreenshot(unittest.TestCase):
    def setUp(self):
        self.robots = robot_list_from_param()
        self.scenario = parse_scenario(get_param(names.SCENARIO_PARAM, required=True),
                                       [r.name for r in self.robots])
        self.runner = Runner(self.robots)
        self.namespaces = set()
        rospy.Subscriber(names.MARKERS_TOPIC, MarkerArray, self.on_markers, queue_size=5)
        self.out_dir = os.path.join(rospkg.get_test_results_dir(), "puzzlebot_bringup")
        os.makedirs(self.out_dir, exist_ok=True)
        self.log = os.path.join(self.out_dir, "rviz_screenshot.log")

    def on_markers(self, msg):
        self.namespaces |= {m.ns for m in msg.markers if m.ns}

    def shot(self, display, name):
        time.sleep(RVIZ_SETTLE)
        image = display.grab()
        path = os.path.join(self.out_dir, "rviz_%s.png" % name)
        image.save(path)
        seen = robots_in_view(image, VIEW)
        counts = hue_pixels(image, VIEW)
        print("rviz screenshot %s at t = %.1f s: %s; %s; pixels in the 3D view: %s"
              % (name, rospy.get_time(), path, seen, counts), flush=True)
        return path, seen, counts

    def assert_all_robots_in_view(self, path, seen):
        self.assertEqual(seen.knobs, len(self.robots), "%s: %d robot(s) seen (knobs), expected %d"
                         % (path, seen.knobs, len(self.robots)))
        self.assertEqual(seen.cut, 0, "%s: %d robot(s) cut by the view's edge" % (path, seen.cut))

    def test_default_scenario_in_view_from_start_to_end(self):
        config = package_path("puzzlebot_bringup", "rviz", "puzzlebot.rviz")
        wall_deadline = time.monotonic() + 600.0
        with VirtualDisplay(*SIZE) as display, Rviz(config, display, self.log) as rviz:
            end = time.monotonic() + RVIZ_STARTUP
            while time.monotonic() < end and not rospy.is_shutdown() and rviz.running() and \
                    not self.rviz_subscribed():
                time.sleep(0.1)
            self.assertEqual(self.runner.wait_for_start(RVIZ_STARTUP), [], "no clock or poses from the sim")
            self.assertTrue(self.runner.connect(), "the MPC never solved a step")
            ids = self.runner.submit(self.scenario.steps)
            self.assertTrue(all(isinstance(i, int) for i in ids), "a step was refused: %s" % ids)
            while time.monotonic() < end and not NAMESPACES - {"pairs", "polygons", "physical", "slots",
                                                               "predicted"} <= self.namespaces:
                time.sleep(0.1)
            start = self.shot(display, "start")
            middle = None
            for k, (step, request_id) in enumerate(zip(self.scenario.steps, ids)):
                result = self.runner.wait_step(step, request_id, 300.0, wall_deadline)
                self.assertEqual(result.outcome, "succeeded", "step %d (%s): %s" % (k + 1, step.behavior,
                                                                                 result.message))
                if step.behavior == "couple":
                    middle = self.shot(display, "middle")
            last = self.shot(display, "end")
            alive = rviz.running()
        self.assertTrue(alive, "rviz exited (log: %s)" % self.log)
        errors = rviz_log_errors(self.log)
        self.assertEqual(errors, [], "rviz logged errors: %s" % errors[:5])
        self.assertLessEqual(NAMESPACES, self.namespaces, "marker namespaces missing: %s"
                             % sorted(NAMESPACES - self.namespaces))
        self.assert_all_robots_in_view(start[0], start[1])
        self.assert_all_robots_in_view(last[0], last[1])
        self.assertIsNotNone(middle, "the scenario has no couple step")
        for hue, least in MIN_ADDED_PIXELS.items():
            added = middle[2][hue] - start[2][hue]
            self.assertGreaterEqual(added, least, "%s: %d %s pixels more than at the start in the 3D view, "
                                    "expected >= %d" % (middle[0], added, hue, least))

    @staticmethod
    def rviz_subscribed():
        """rviz is up: a node named rviz_xvfb* (screenshot.Rviz) subscribes to the markers."""
        try:
            subscribers = rosgraph.Master(rospy.get_name()).getSystemState()[1]
        except (OSError, rosgraph.MasterException):
            return False
        return any(topic == names.MARKERS_TOPIC and any("rviz_xvfb" in n for n in nodes)
                   for topic, nodes in subscribers)

if __name__ == "__main__":
    rospy.init_node("rviz_screenshot_test", argv=sys.argv)
    rostest.rosrun("puzzlebot_bringup", "rviz_screenshot", RvizScreenshot)
