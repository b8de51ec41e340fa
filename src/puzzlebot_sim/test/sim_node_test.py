#!/usr/bin/env python3
"""The sim node publishes /clock, tf (robots and anchors), vicon poses and the
physical couplings at the configured rates, counted in simulated time."""

import collections
import math
import threading
import unittest

import rospy
import rostest
import tf2_ros
from geometry_msgs.msg import TransformStamped, Twist
from rosgraph_msgs.msg import Clock
from tf2_msgs.msg import TFMessage

from puzzlebot_msgs.msg import ConnectionPair, ConnectionPairArray

ROBOTS = ("pz1", "pz2", "pz3")
WINDOW = 3.0        # s of simulated time to count messages over


class SimNodeTest(unittest.TestCase):
    def setUp(self):
        self.lock = threading.Lock()
        self.stamps = collections.defaultdict(list)   # key -> header stamps (s, sim time)
        self.pairs = None
        rospy.Subscriber("/clock", Clock, lambda m: self.record("clock", m.clock))
        rospy.Subscriber("/tf", TFMessage, self.on_tf, queue_size=100)
        for r in ROBOTS:
            rospy.Subscriber("/vicon/%s/%s" % (r, r), TransformStamped,
                             lambda m, r=r: self.record("vicon/" + r, m.header.stamp), queue_size=100)
        rospy.Subscriber("/puzzlebot/sim/physical_pairs", ConnectionPairArray, self.on_pairs, queue_size=10)
        self.tf_buffer = tf2_ros.Buffer()
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)

    def record(self, key, stamp):
        with self.lock:
            self.stamps[key].append(stamp.to_sec())

    def on_tf(self, msg):
        for t in msg.transforms:
            self.record("tf/" + t.child_frame_id, t.header.stamp)

    def on_pairs(self, msg):
        self.record("pairs", msg.header.stamp)
        with self.lock:
            self.pairs = msg

    def rate(self, key, t0, t1):
        with self.lock:
            n = sum(1 for s in self.stamps[key] if t0 <= s < t1)
        return n / (t1 - t0)

    def test_topics_rates_and_coupling(self):
        for _ in range(600):                      # up to 30 s (wall) for the node to start
            if self.stamps["clock"] or rospy.is_shutdown():
                break
            rospy.rostime.wallsleep(0.05)
        self.assertTrue(self.stamps["clock"], "no /clock from the sim node")
        t0 = rospy.get_time() + 0.5
        pub = rospy.Publisher("/pz3/cmd_vel", Twist, queue_size=1)
        while rospy.get_time() < t0 + WINDOW + 0.3 and not rospy.is_shutdown():
            msg = Twist()
            msg.linear.x = 0.03
            pub.publish(msg)
            rospy.rostime.wallsleep(0.05)
        t1 = t0 + WINDOW
        self.assertAlmostEqual(self.rate("clock", t0, t1), 100.0, delta=5.0)
        for r in ROBOTS:
            self.assertAlmostEqual(self.rate("vicon/" + r, t0, t1), 100.0, delta=5.0, msg=r)
            self.assertAlmostEqual(self.rate("tf/%s/base_link" % r, t0, t1), 100.0, delta=5.0, msg=r)
            self.assertAlmostEqual(self.rate("tf/%s/anchor" % r, t0, t1), 100.0, delta=5.0, msg=r)
            for frame in ("%s/base_link" % r, "%s/anchor" % r):
                self.tf_buffer.lookup_transform("world", frame, rospy.Time(0), rospy.Duration(1.0))
        self.assertAlmostEqual(self.rate("pairs", t0, t1), 10.0, delta=1.0)
        # the anchor sits behind pz1 (pushed in: ~ -17 mm from the body centre), pz3 drove forward
        anchor = self.tf_buffer.lookup_transform("pz1/base_link", "pz1/anchor", rospy.Time(0))
        self.assertLess(anchor.transform.translation.x, -0.012)
        pz3 = self.tf_buffer.lookup_transform("world", "pz3/base_link", rospy.Time(0)).transform.translation
        self.assertGreater(math.hypot(pz3.x - 0.0, pz3.y - 0.2), 0.05)      # drove ~0.03 m/s for > 3 s
        with self.lock:
            pairs = [(p.anchor_robot, p.robot_j, p.status, p.type) for p in self.pairs.pairs]
        self.assertEqual(pairs, [("pz1", "pz2", ConnectionPair.STATUS_HEAD_INSERTED, ConnectionPair.TYPE_ANCHOR)])


if __name__ == "__main__":
    rospy.init_node("sim_node_test")
    rostest.rosrun("puzzlebot_sim", "sim_node", SimNodeTest)
