#!/usr/bin/env python3
"""rviz as a person sees it: the shipped configuration under Xvfb on a running simulation.

The sim runs the couple2 scenario's couple step; rviz starts at the same time on a virtual
display. Once the pair is coupled the screen is saved as a PNG in the test results
(<results dir>/puzzlebot_bringup/rviz_screenshot.png, printed) and the test fails if
- rviz died or logged an ERROR line (the benign media_export lines are filtered:
  puzzlebot_bringup/screenshot.py),
- /puzzlebot/markers lacks one of the namespaces the configuration shows,
- the image does not show the robots (blue bodies), the coupled pair's polygon (green) and the
  seated anchor (cyan disc) in the 3D view.
"""

import os
import sys
import time
import unittest

import rospkg
import rospy
import rostest
from visualization_msgs.msg import MarkerArray

from puzzlebot_common import names
from puzzlebot_common.config import package_path
from puzzlebot_common.node_utils import get_param, robot_list_from_param
from puzzlebot_bringup.runner import Runner
from puzzlebot_bringup.scenario import parse_scenario
from puzzlebot_bringup.screenshot import Rviz, VirtualDisplay, hue_pixels, rviz_log_errors

SIZE = (1200, 800)
VIEW = (380, 70, 1180, 760)          # the 3D view of the shipped layout (left: the Displays panel)
RVIZ_SETTLE = 3.0                    # s (wall) for rviz to draw the coupled state
RVIZ_STARTUP = 60.0                  # s (wall), generous: software OpenGL on a loaded machine
NAMESPACES = {"bodies", "fronts", "labels", "anchors", "polygons", "pairs", "physical", "predicted", "slots"}
# Minimum pixel counts in the 3D view (2 robots of 70 x 70 px at the configuration's 1400 px/m;
# measured: ~9000 blue, ~1200 green, ~150 cyan): a fraction, so that only a missing or
# mis-coloured feature fails.
MIN_PIXELS = {"blue": 3000, "green": 300, "cyan": 30}


class RvizScreenshot(unittest.TestCase):
    def setUp(self):
        robots = robot_list_from_param()
        self.scenario = parse_scenario(get_param(names.SCENARIO_PARAM, required=True), [r.name for r in robots])
        self.runner = Runner(robots)
        self.namespaces = set()
        rospy.Subscriber(names.MARKERS_TOPIC, MarkerArray, self.on_markers, queue_size=5)
        out_dir = os.path.join(rospkg.get_test_results_dir(), "puzzlebot_bringup")
        os.makedirs(out_dir, exist_ok=True)
        self.png = os.path.join(out_dir, "rviz_screenshot.png")
        self.log = os.path.join(out_dir, "rviz_screenshot.log")

    def on_markers(self, msg):
        self.namespaces |= {m.ns for m in msg.markers if m.ns}

    def test_rviz_shows_robots_pairs_and_polygons(self):
        config = package_path("puzzlebot_bringup", "rviz", "puzzlebot.rviz")
        with VirtualDisplay(*SIZE) as display, Rviz(config, display, self.log) as rviz:
            t_rviz = time.monotonic()
            self.assertTrue(self.runner.connect(), "the MPC never solved a step")
            couple = self.scenario.steps[0]
            result = self.runner.run_step(couple, 0.0, time.monotonic() + 300.0)
            self.assertEqual(result.outcome, "succeeded", result.message)
            end = time.monotonic() + RVIZ_STARTUP
            while time.monotonic() < end and not NAMESPACES <= self.namespaces:   # rviz subscribed, markers flow
                time.sleep(0.1)
            time.sleep(max(RVIZ_SETTLE, 2 * RVIZ_SETTLE - (time.monotonic() - t_rviz)))
            alive = rviz.running()
            image = display.grab()
        image.save(self.png)
        counts = hue_pixels(image, VIEW)
        print("rviz screenshot: %s (rviz log %s); pixels in the 3D view: %s" % (self.png, self.log, counts),
              flush=True)
        self.assertTrue(alive, "rviz exited (log: %s)" % self.log)
        errors = rviz_log_errors(self.log)
        self.assertEqual(errors, [], "rviz logged errors: %s" % errors[:5])
        self.assertLessEqual(NAMESPACES, self.namespaces, "marker namespaces missing: %s"
                             % sorted(NAMESPACES - self.namespaces))
        for hue, least in MIN_PIXELS.items():
            self.assertGreaterEqual(counts[hue], least, "%s: %d %s pixels in the 3D view, expected >= %d"
                                    % (self.png, counts[hue], hue, least))


if __name__ == "__main__":
    rospy.init_node("rviz_screenshot_test", argv=sys.argv)
    rostest.rosrun("puzzlebot_bringup", "rviz_screenshot", RvizScreenshot)
