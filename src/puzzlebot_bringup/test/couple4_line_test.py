#!/usr/bin/env python3
"""sim + MPC: four scattered robots couple into a line, the chain drives 0.3 m with every pair
coupled, then pz2-pz3 decouples by wiggling. Coupling is checked three ways:

- the MPC's pair statuses (/puzzlebot/connection_pairs, Algorithm 2 on the measured poses);
- geometrically from the measured poses (vicon topics), independently of the MPC: each coupled
  pair's anchor head inside the opening robot's front triangle (+ eps), relative heading within
  the anchor's freedom;
- physically, when the simulation publishes /puzzlebot/sim/physical_pairs (Bullet anchors):
  status HEAD_INSERTED for the coupled pairs. Without a publisher (box-only bodies) this check
  is reported as not available, and the two checks above stand.
"""

import math
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import TransformStamped
from puzzlebot_common.geometry import RobotGeometry, yaw_from_quaternion
from puzzlebot_msgs.msg import BehaviorStatus, ConnectionPair, ConnectionPairArray, SolverStats
from puzzlebot_msgs.srv import SetBehavior, SetBehaviorRequest
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.ros_conversions import twist

NAMES = ["pz1", "pz2", "pz3", "pz4"]
CHAIN = [("pz1", "pz2"), ("pz2", "pz3"), ("pz3", "pz4")]
PHYSICAL_TOPIC = "/puzzlebot/sim/physical_pairs"
COUPLE_BOUND = 60.0    # s of simulated time
DRIVE_DISTANCE = 0.3   # m
WALL_LIMIT = 240.0     # s, only so a hung simulation cannot hang the test
EPS = 0.003            # m, sim.launch's pair_epsilon


class CoupleFourIntoLine(unittest.TestCase):
    def setUp(self):
        self.geo = RobotGeometry()
        self.poses, self.status, self.pairs, self.physical, self.stats = {}, None, None, None, []
        self.pair_log = []
        for n in NAMES:
            rospy.Subscriber("/vicon/%s/%s" % (n, n), TransformStamped, self.on_pose, callback_args=n)
        rospy.Subscriber("/puzzlebot/mpc/behavior_status", BehaviorStatus, self.on_status)
        rospy.Subscriber("/puzzlebot/connection_pairs", ConnectionPairArray, self.on_pairs)
        rospy.Subscriber(PHYSICAL_TOPIC, ConnectionPairArray, self.on_physical)
        rospy.Subscriber("/puzzlebot/mpc/solver_stats", SolverStats, self.stats.append)
        rospy.wait_for_service("/puzzlebot/mpc/set_behavior", timeout=60.0)
        self.call = rospy.ServiceProxy("/puzzlebot/mpc/set_behavior", SetBehavior)
        wall0 = time.monotonic()        # the MPC has poses once it solved a step (couple needs them)
        while not any(s.success for s in self.stats) and time.monotonic() - wall0 < 60.0:
            time.sleep(0.02)

    def on_pose(self, msg, name):
        t, q = msg.transform.translation, msg.transform.rotation
        self.poses[name] = (t.x, t.y, yaw_from_quaternion(q.x, q.y, q.z, q.w))

    def on_status(self, msg):
        self.status = msg

    def on_pairs(self, msg):
        self.pairs = msg
        self.pair_log.append(msg)

    def on_physical(self, msg):
        self.physical = msg

    # ---------------------------------------------------------------- helpers
    def run_behavior(self, req, bound):
        resp = self.call(req)
        self.assertTrue(resp.accepted, resp.message)
        t0, wall0 = rospy.get_time(), time.monotonic()
        while time.monotonic() - wall0 < WALL_LIMIT and rospy.get_time() - t0 < bound:
            s = self.status
            if s and s.request_id == resp.request_id and s.state in (BehaviorStatus.SUCCEEDED,
                                                                     BehaviorStatus.FAILED):
                break
            time.sleep(0.02)
        time.sleep(0.3)     # a few more steps: statuses and poses of the final state
        s = self.status
        self.assertEqual(s.request_id, resp.request_id)
        self.assertEqual(s.state, BehaviorStatus.SUCCEEDED, s.message)
        return rospy.get_time() - t0, s.message

    def coupled(self, msg=None):
        msg = msg or self.pairs
        return sorted((p.robot_i, p.robot_j) for p in msg.pairs if p.status == ConnectionPair.STATUS_HEAD_INSERTED)

    def geometric(self, a, o):
        """(head margin in o's front triangle [m], relative heading [rad]) from the measured poses."""
        pair = pr.make_pair(a, o, pr.ANCHOR, self.geo)
        pa, po = self.poses[a], self.poses[o]
        return (pr.head_margin(pair, pa, po, self.geo.front_triangle()),
                pr.alignment_error(pair, pa, po)[1])

    def assert_geometrically_coupled(self, keys, when):
        for a, o in keys:
            margin, dth = self.geometric(a, o)
            self.assertGreaterEqual(margin, -EPS, "%s: %s-%s head %.1f mm outside the triangle"
                                    % (when, a, o, -1e3 * margin))
            self.assertLessEqual(abs(dth), self.geo.anchor_yaw_free, "%s: %s-%s turned %.2f rad" % (when, a, o, dth))

    def assert_physically_coupled(self, keys, when):
        if self.physical is None:
            rospy.logwarn("%s: no %s publisher: physical coupling not checked (box-only simulation)"
                          % (when, PHYSICAL_TOPIC))
            return
        seated = self.coupled(self.physical)
        for key in keys:
            self.assertIn(key, seated, "%s: %s-%s not physically seated; seated: %s" % ((when,) + key + (seated,)))

    # ------------------------------------------------------------------ test
    def test_couple_drive_decouple(self):
        bad = self.call(SetBehaviorRequest(behavior="couple", robots=["pz1", "pz2"], target="line3"))
        self.assertFalse(bad.accepted)
        self.assertIn("3 slots", bad.message)

        # 1. four scattered robots couple into a line
        t_start = rospy.get_time()     # MPC steps from here on must all succeed (before: waiting for poses)
        elapsed, message = self.run_behavior(SetBehaviorRequest(behavior="couple", target="line",
                                                                timeout=COUPLE_BOUND), COUPLE_BOUND + 2)
        rospy.loginfo("coupled after %.1f s sim: %s" % (elapsed, message))
        self.assertEqual(self.coupled(), CHAIN)
        self.assert_geometrically_coupled(CHAIN, "after couple")
        self.assert_physically_coupled(CHAIN, "after couple")
        margins = {"%s-%s" % k: round(1e3 * self.geometric(*k)[0], 1) for k in CHAIN}
        rospy.loginfo("head margins in the triangles after coupling [mm]: %s" % margins)

        # 2. the chain drives 0.3 m forward with every pair coupled at every step
        start = self.poses["pz1"]
        self.pair_log.clear()
        req = SetBehaviorRequest(behavior="drive_assembly", robots=["pz1"], distance=DRIVE_DISTANCE, timeout=30.0)
        req.velocities = [twist(0.03, 0.0)]
        elapsed, message = self.run_behavior(req, 32.0)
        moved = math.hypot(self.poses["pz1"][0] - start[0], self.poses["pz1"][1] - start[1])
        rospy.loginfo("drove %.3f m in %.1f s sim: %s" % (moved, elapsed, message))
        self.assertGreaterEqual(moved, DRIVE_DISTANCE)
        self.assertTrue(self.pair_log)
        for msg in self.pair_log:
            self.assertEqual(self.coupled(msg), CHAIN, "a pair decoupled while driving")
        self.assert_geometrically_coupled(CHAIN, "after the drive")
        self.assert_physically_coupled(CHAIN, "after the drive")

        # 3. the named pair pz2-pz3 decouples by wiggling; the others stay coupled
        elapsed, message = self.run_behavior(SetBehaviorRequest(behavior="decouple", pair=["pz2", "pz3"],
                                                                timeout=60.0), 62.0)
        rospy.loginfo("decoupled after %.1f s sim: %s" % (elapsed, message))
        self.assertEqual(self.coupled(), [("pz1", "pz2"), ("pz3", "pz4")])
        pair = pr.make_pair("pz2", "pz3", pr.ANCHOR, self.geo)
        outside = pr.head_margin(pair, self.poses["pz2"], self.poses["pz3"], self.geo.footprint())
        self.assertLess(outside, -EPS, "pz2's anchor head is still in pz3")
        self.assert_geometrically_coupled([("pz1", "pz2"), ("pz3", "pz4")], "after decouple")
        if self.physical is not None:
            self.assertNotIn(("pz2", "pz3"), self.coupled(self.physical))

        steps = [s for s in self.stats if s.header.stamp.to_sec() >= t_start]
        self.assertGreater(len(steps), 100)
        failed = [s for s in steps if not s.success]
        self.assertEqual(failed, [], "%d failed MPC steps, e.g. %s" % (len(failed), failed[:1]))


if __name__ == "__main__":
    rospy.init_node("couple4_line_test")
    rostest.rosrun("puzzlebot_bringup", "couple4_line", CoupleFourIntoLine)
