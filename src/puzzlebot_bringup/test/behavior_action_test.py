#!/usr/bin/env python3
"""The MPC node's behaviour action (/puzzlebot/mpc/behavior) through sim.launch (couple2), as a client uses it,
and the graph's ROS plumbing: robot model, tf, diagnostics.

1. a couple goal: feedback every control step (running, the pair's status, progress), then SUCCEEDED with the
   pair coupled (and seated in Bullet);
2. a drive_assembly goal with a go_to_goal queued behind it and a goal that names an unknown robot
   (REJECTED with the reason); the drive is cancelled half-way: PREEMPTED (outcome cancelled), the queued goal
   ABORTED (dropped), and the robots stop: from 0.3 s after the cancel every command is below 3 mm/s
   (driving: 30 mm/s; 'stop' holds the coupled pair aligned), and the measured poses move less than 2 mm
   over the next 1 s;
3. a queued goal cancelled before it starts: PREEMPTED, outcome cancelled, never started;
4. /robot_description is the robots' model; /tf_static has the casters; tf has <robot>/base_link ->
   <robot>/anchor and world -> vicon/<robot>/<robot> (the vicon messages' child frame);
5. /diagnostics_agg has the Simulation and Controller groups, not stale, with their figures.
"""

import math
import sys
import threading
import time
import unittest
import xml.etree.ElementTree as ET

import actionlib
import rospy
import rostest
import tf2_ros
from actionlib_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Point, Twist
from tf2_msgs.msg import TFMessage

from puzzlebot_common import names
from puzzlebot_common.node_utils import robot_list_from_param
from puzzlebot_msgs.msg import BehaviorAction, BehaviorGoal, BehaviorStatus, ConnectionPair
from puzzlebot_bringup.runner import Runner

WALL = 120.0                # s, wall-time bound of each wait
# At rest after a cancel: 'stop' holds the coupled pair aligned, which takes commands of a millimetre per
# second or so; driving was 30 mm/s. Measured 2026-12: |v| <= 1.4 mm/s, |w| <= 0.0005 rad/s.
STOPPED_V = 0.003           # m/s
STOPPED_W = 0.05            # rad/s


class BehaviorActionTest(unittest.TestCase):
    def setUp(self):
        self.robots = [r.name for r in robot_list_from_param()]
        self.runner = Runner(robot_list_from_param())       # poses, physical pairs
        self.lock = threading.Lock()
        self.cmd = {r: [] for r in self.robots}             # (ROS time, v, w) received
        for r in self.robots:
            rospy.Subscriber(names.cmd_vel_topic(r), Twist, self.on_cmd, callback_args=r, queue_size=50)
        self.static = set()
        rospy.Subscriber("/tf_static", TFMessage, self.on_static, queue_size=10)
        self.agg = None
        rospy.Subscriber("/diagnostics_agg", DiagnosticArray, self.on_agg, queue_size=5)
        self.tf = tf2_ros.Buffer()
        self.tf_listener = tf2_ros.TransformListener(self.tf)
        self.client = actionlib.ActionClient(names.BEHAVIOR_ACTION, BehaviorAction)
        self.assertTrue(self.client.wait_for_server(rospy.Duration(WALL)), "no action server")
        self.assertEqual(self.runner.wait_for_start(WALL), [])
        self.assertTrue(self.runner.connect(), "the MPC never solved a step")

    def on_cmd(self, msg, robot):
        with self.lock:
            self.cmd[robot].append((rospy.get_time(), msg.linear.x, msg.angular.z))

    def on_static(self, msg):
        self.static |= {t.child_frame_id for t in msg.transforms}

    def on_agg(self, msg):
        self.agg = msg

    # -------------------------------------------------------------- helpers
    def send(self, goal):
        """Send ``goal``; (handle, feedback list)."""
        feedback = []
        handle = self.client.send_goal(goal, feedback_cb=lambda gh, fb: feedback.append((rospy.get_time(), fb)))
        return handle, feedback

    def wait_done(self, handle, wall=WALL):
        end = time.monotonic() + wall
        while handle.get_comm_state() != actionlib.CommState.DONE and time.monotonic() < end:
            time.sleep(0.01)
        self.assertEqual(handle.get_comm_state(), actionlib.CommState.DONE, "no result within %.0f s" % wall)
        return handle.get_goal_status(), handle.get_result()

    def wait_for(self, predicate, wall=WALL):
        end = time.monotonic() + wall
        while not predicate() and time.monotonic() < end and not rospy.is_shutdown():
            time.sleep(0.01)
        return predicate()

    def couple_goal(self):
        return BehaviorGoal(behavior="couple", robots=["pz1", "pz2"], target="line", timeout=60.0)

    def drive_goal(self, distance=0.1):
        return BehaviorGoal(behavior="drive_assembly", robots=["pz1"], velocities=[Twist()], distance=distance,
                            timeout=20.0)

    # ---------------------------------------------------------------- tests
    def test_action(self):
        self.check_couple_with_feedback()
        self.check_cancel_mid_way_stops_the_robots()
        self.check_cancel_a_queued_goal()
        self.check_model_and_tf()
        self.check_diagnostics()

    def check_couple_with_feedback(self):
        handle, feedback = self.send(self.couple_goal())
        status, result = self.wait_done(handle)
        self.assertEqual(status, GoalStatus.SUCCEEDED, result.message)
        self.assertEqual(result.outcome, "succeeded")
        # the first feedback answers the goal ("started", progress not measured yet); then one per control step
        running = [fb for _, fb in feedback if fb.state == BehaviorStatus.RUNNING][1:]
        print("couple: %d feedback messages over %.1f s, progress %s -> %s; result: %s"
              % (len(feedback), result.ended.to_sec() - result.started.to_sec(), running[0].progress,
                 running[-1].progress, result.message), flush=True)
        self.assertGreater(len(running), 10, "a feedback every control step while it runs")
        self.assertTrue(all(fb.request_id == result.request_id for _, fb in feedback))
        self.assertEqual(running[0].progress, 0.0)                      # no pair coupled yet
        statuses = {p.status for fb in running for p in fb.pairs if {p.robot_i, p.robot_j} == {"pz1", "pz2"}}
        self.assertIn(ConnectionPair.STATUS_DECOUPLED, statuses, "the pair's status in the feedback")
        self.assertGreater(running[-1].elapsed, running[0].elapsed)
        final = [p for p in result.pairs if {p.robot_i, p.robot_j} == {"pz1", "pz2"}]
        self.assertEqual([p.status for p in final], [ConnectionPair.STATUS_HEAD_INSERTED])
        self.runner.wait_until(result.ended.to_sec() + 0.2)
        physical = self.runner.physical_at(result.ended.to_sec())
        self.assertTrue(physical is not None and any(p.status == ConnectionPair.STATUS_HEAD_INSERTED
                                                     for p in physical.pairs), "seated in Bullet")

    def check_cancel_mid_way_stops_the_robots(self):
        drive = self.drive_goal()
        drive.velocities[0].linear.x = 0.03
        handle, feedback = self.send(drive)
        queued = BehaviorGoal(behavior="go_to_goal", robots=["pz2"], goals=[Point(-0.5, 0.0, 0.0)], queue=True)
        queued_handle, _ = self.send(queued)
        bad_handle, _ = self.send(BehaviorGoal(behavior="go_to_goal", robots=["pz9"], goals=[Point(0, 0, 0)],
                                               queue=True))
        status, result = self.wait_done(bad_handle)
        self.assertEqual(status, GoalStatus.REJECTED)
        self.assertIn("unknown robot", result.message)
        self.assertEqual(result.outcome, "refused")
        self.assertTrue(self.wait_for(lambda: any(fb.progress >= 0.4 for _, fb in feedback)), "the drive never "
                        "got half-way")
        t_cancel = rospy.get_time()
        handle.cancel()
        status, result = self.wait_done(handle)
        print("drive: cancel sent at t = %.2f s (progress %.2f); result at t = %.2f s: %s (%s)"
              % (t_cancel, feedback[-1][1].progress, result.ended.to_sec(), result.outcome, result.message), flush=True)
        self.assertEqual(status, GoalStatus.PREEMPTED)
        self.assertEqual(result.outcome, "cancelled", result.message)
        self.assertAlmostEqual(result.errors[0], 0.05, delta=0.02)      # moved about half the distance
        q_status, q_result = self.wait_done(queued_handle)
        self.assertEqual((q_status, q_result.outcome), (GoalStatus.ABORTED, "dropped"), q_result.message)
        # the robots stop: the commands from 0.3 s on are (about) zero, the poses stand still
        t_end = max(rospy.get_time(), t_cancel) + 1.5
        self.runner.wait_until(t_end)
        with self.lock:
            late = [(r, t, v, w) for r in self.robots for t, v, w in self.cmd[r] if t > t_cancel + 0.3]
        self.assertTrue(late, "no commands after the cancel")
        v_top, w_top = max(abs(c[2]) for c in late), max(abs(c[3]) for c in late)
        for r in self.robots:
            a, b = self.runner.pose_at(r, t_end - 1.0), self.runner.pose_at(r, t_end)
            moved = math.hypot(b[0] - a[0], b[1] - a[1])
            print("after the cancel: %s moved %.2f mm in the last 1 s" % (r, 1e3 * moved), flush=True)
            self.assertLess(moved, 0.002, "%s still moves after the cancel" % r)
        print("after the cancel: %d commands from 0.3 s on, |v| <= %.2f mm/s, |w| <= %.3f rad/s (the coupled pair "
              "held at rest)" % (len(late), 1e3 * v_top, w_top), flush=True)
        self.assertLess(v_top, STOPPED_V, "commanded speed after the cancel")
        self.assertLess(w_top, STOPPED_W, "commanded turn rate after the cancel")

    def check_cancel_a_queued_goal(self):
        first = BehaviorGoal(behavior="stop", start_time=rospy.get_time() + 5.0)
        handle, feedback = self.send(first)
        self.assertTrue(self.wait_for(lambda: feedback), "no feedback for the queued goal")
        self.assertEqual(feedback[0][1].state, BehaviorStatus.IDLE)
        handle.cancel()
        status, result = self.wait_done(handle)
        # accepted (ACTIVE) while it waits, so a cancel preempts it; the outcome says it never ran
        self.assertEqual((status, result.outcome), (GoalStatus.PREEMPTED, "cancelled"), result.message)
        self.assertTrue(result.started.is_zero())

    def check_model_and_tf(self):
        description = ET.fromstring(rospy.get_param("/robot_description"))
        links = {link.get("name") for link in description.findall("link")}
        self.assertLessEqual({"pz1/base_link", "pz2/base_link", "pz1/anchor", "pz2/left_wheel"}, links)
        self.assertTrue(self.wait_for(lambda: {"pz1/front_caster", "pz2/rear_caster"} <= self.static, 10.0),
                        "tf_static: %s" % sorted(self.static))
        for parent, child in (("pz1/base_link", "pz1/anchor"), ("world", "vicon/pz1/pz1"),
                              ("pz2/base_link", "pz2/anchor_left_barb"), ("pz1/base_link", "pz1/left_wheel")):
            self.tf.lookup_transform(parent, child, rospy.Time(0), rospy.Duration(5.0))
        vicon = self.tf.lookup_transform("pz1/base_link", "vicon/pz1/pz1", rospy.Time(0))
        offset = math.hypot(vicon.transform.translation.x, vicon.transform.translation.y)
        self.assertLess(offset, 0.003, "the measured frame is the body frame with the mocap noise")

    def check_diagnostics(self):
        def groups():
            msg = self.agg
            return {s.name: s for s in msg.status} if msg is not None else {}
        self.assertTrue(self.wait_for(lambda: {"/Simulation", "/Controller"} <= set(groups()), 20.0),
                        "aggregated: %s" % sorted(groups()))
        g = groups()
        for name in ("/Simulation", "/Controller"):
            self.assertNotEqual(g[name].level, DiagnosticStatus.STALE, name)
        leaves = {s.name: dict((kv.key, kv.value) for kv in s.values) for s in self.agg.status}
        sim = next(v for k, v in leaves.items() if k.startswith("/Simulation/"))
        mpc = next(v for k, v in leaves.items() if k.startswith("/Controller/"))
        print("diagnostics: real-time factor %s, solve time median %s ms, failed solves %s"
              % (sim["real-time factor"], mpc["solve time median [ms]"], mpc["failed solves (total)"]), flush=True)
        self.assertGreater(float(sim["real-time factor"]), 0.0)
        self.assertGreater(float(mpc["solve time median [ms]"]), 0.0)


if __name__ == "__main__":
    rospy.init_node("behavior_action_test", argv=sys.argv)
    rostest.rosrun("puzzlebot_bringup", "behavior_action", BehaviorActionTest)
