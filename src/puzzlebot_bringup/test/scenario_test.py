#!/usr/bin/env python3
"""Integration test: run the loaded scenario's steps through the MPC node (as the scenario runner
does) and assert the outcome of every step, physically where the simulation can tell.

Bounds: every step must succeed within its own `timeout` in simulated time (plus the runner's
2 s of settling); no step may be refused.

Checks after each step (private parameters of the test node select them):
- couple: the step's k robots are joined by k - 1 coupled pairs in the MPC's statuses; with
  ~physical (simulation), every coupled anchor pair is *seated in Bullet*: the sim's
  /puzzlebot/sim/physical_pairs reports that anchor in that opening with both tips behind the
  lips (STATUS_HEAD_INSERTED), not just the controller's belief;
- drive_assembly: the lead robot's measured pose (vicon topic) moved at least `distance`; every
  coupled pair of the assembly stayed coupled in every MPC status message during the drive and,
  with ~physical, seated in every physical pairs message of the drive (~drive_hold "seated", the
  default) or at least with its head in the opening (~drive_hold "in_opening": STATUS_HEAD_ALIGNED
  or better, never decoupled; for a chain going down a step, where a robot hanging over the edge
  pulls its partner's anchor partway out and flares its barbs);
- decouple: the pair is decoupled in the MPC's statuses and, with ~physical, its anchor is out
  of the opening in Bullet (no physical pair) for ~release_hold s; every other coupled pair
  stays seated;
- ~final_z {robot: [min, max]}: each robot's body-centre height at the end (on the floor or on
  a stage), from its vicon topic;
- with ~physical, at the end: every anchor in its holder (tf <robot>/base_link -> <robot>/anchor);
- ~max_failed_solves (default -1 = not checked): at most this many failed MPC steps from the
  first step on.

A failed check's message ends with the lockstep waits that ran out (the sim's "running on", the
MPC's "stepping on older ones" on /rosout): after one, the run is no longer the seed's, so such a
failure says the machine stalled, not that the seed's run changed.

The steps are sent as one script (Runner.run_steps: each queued behind the one before), so in
lockstep the run is the same for a given sim seed whatever the timing of the graph; each check
reads the messages stamped at the control step that ended its step.
"""

import math
import sys
import time
import unittest

import rospy
import rostest
import tf2_ros

from puzzlebot_common import names
from puzzlebot_common.geometry import RobotGeometry, yaw_from_quaternion
from puzzlebot_common.node_utils import get_param, robot_list_from_param
from puzzlebot_common.rostest_lab import NodeLog
from puzzlebot_msgs.msg import ConnectionPair
from puzzlebot_bringup.runner import SETTLE, Runner
from puzzlebot_bringup.scenario import parse_scenario

INSERTED = ConnectionPair.STATUS_HEAD_INSERTED
ALIGNED = ConnectionPair.STATUS_HEAD_ALIGNED
WALL_LIMIT = 600.0   # s (wall), only so that a hung graph cannot hang the test
DRIVE_TOLERANCE = 0.002  # m: the MPC stops at the distance on its own noisy poses, the test measures on its copy
ANCHOR_YAW_MAX = 1.0     # rad: an anchor turned further in its holder has flipped round (holder play +/-0.5)
LOCKSTEP_LOST = (": running on", "stepping on older ones")   # the sim's and the MPC's warnings of a wait that ran out


def anchor_key(p):
    """(anchor robot, opening robot) of an anchor pair; (robot_i, robot_j) of a knob pair."""
    if p.type == ConnectionPair.TYPE_ANCHOR and p.anchor_robot:
        return (p.anchor_robot, p.robot_j if p.anchor_robot == p.robot_i else p.robot_i)
    return (p.robot_i, p.robot_j)


def coupled(msg, robots=None, least=INSERTED):
    """Pairs (keys) with status ``least`` or better (default head_inserted) in a ConnectionPairArray,
    among ``robots`` if given; ``least=ALIGNED``: the head at least in the opening."""
    return {anchor_key(p): p for p in (msg.pairs if msg else [])
            if p.status >= least and (robots is None or (p.robot_i in robots and p.robot_j in robots))}


class ScenarioTest(unittest.TestCase):
    def setUp(self):
        self.robots = robot_list_from_param()
        self.names = [r.name for r in self.robots]
        self.scenario = parse_scenario(get_param(names.SCENARIO_PARAM, required=True), self.names,
                                       where=names.SCENARIO_PARAM)
        self.physical = get_param("~physical", True)
        self.final_z = get_param("~final_z", {})
        self.release_hold = get_param("~release_hold", 1.0)
        self.max_failed_solves = get_param("~max_failed_solves", -1)
        self.drive_hold = get_param("~drive_hold", "seated")
        self.assertIn(self.drive_hold, ("seated", "in_opening"), "~drive_hold: 'seated' or 'in_opening'")
        self.geometry = RobotGeometry()
        self.tf = tf2_ros.Buffer()
        self.tf_listener = tf2_ros.TransformListener(self.tf)
        self.rosout = NodeLog("")                      # every node's lines: the lockstep warnings
        self.runner = Runner(self.robots)
        self.assertTrue(self.runner.connect(), "the MPC never solved a step (no poses?)")
        self.wall_deadline = time.monotonic() + WALL_LIMIT

    def log(self, text):
        print("[%s] %s" % (self.scenario.name, text), flush=True)

    def lockstep_lost(self):
        """The lockstep warnings logged so far: the text of every wait that ran out."""
        with self.rosout.lock:
            return [text for _, text in self.rosout.lines if any(k in text for k in LOCKSTEP_LOST)]

    def physical_coupled(self):
        return coupled(self.runner.physical)

    # --------------------------------------------------------------- checks
    # Every check reads the messages of the control step that ended the step (``result.end``): the
    # steps run as one script, the next one starting at the following control step.
    def check_couple(self, step, result):
        robots = step.robots or self.names
        mpc = coupled(self.runner.pairs_at(result.end), robots)
        self.assertEqual(len(mpc), len(robots) - 1, "MPC: %d coupled pair(s) among %s, expected %d: %s"
                         % (len(mpc), robots, len(robots) - 1, sorted(mpc)))
        if self.physical:
            physical = self.runner.physical_at(result.end)
            self.assertIsNotNone(physical, "no physical pairs message after t = %.2f s" % result.end)
            seated = coupled(physical)
            anchors = [k for k, p in mpc.items() if p.type == ConnectionPair.TYPE_ANCHOR]
            missing = [k for k in anchors if k not in seated]
            self.log("physically seated: %s" % sorted(seated))
            self.assertFalse(missing, "coupled for the MPC but not seated in Bullet: %s (physical: %s)"
                             % (missing, sorted((anchor_key(p), p.status) for p in physical.pairs)))
        return mpc

    def check_drive(self, step, before, result):
        lead = step.robots[0]
        start, end = self.runner.pose_at(lead, result.start), self.runner.pose_at(lead, result.end)
        moved = math.hypot(end[0] - start[0], end[1] - start[1])
        self.log("drive: %s moved %.3f m (measured), asked %.3f m" % (lead, moved, step.distance))
        if step.distance > 0:
            self.assertGreaterEqual(moved, step.distance - DRIVE_TOLERANCE)
        t0, t1 = result.start, result.end
        with self.runner.lock:
            mpc_log = [m for t, m in self.runner.pairs_log if t0 <= t <= t1]
            phys_log = [m for t, m in self.runner.physical_log if t0 <= t <= t1]
        self.assertTrue(mpc_log, "no connection pairs published during the drive")
        for m in mpc_log:
            lost = set(before) - set(coupled(m))
            self.assertFalse(lost, "MPC: pair(s) %s not coupled at t = %.2f s during the drive"
                             % (sorted(lost), m.header.stamp.to_sec()))
        anchors = [k for k, p in before.items() if p.type == ConnectionPair.TYPE_ANCHOR]
        if self.physical and anchors:
            self.assertGreater(len(phys_log), 5 * (t1 - t0), "too few physical pairs messages during the drive")
            unseated = [(m.header.stamp.to_sec(), sorted(set(anchors) - set(coupled(m)))) for m in phys_log
                        if set(anchors) - set(coupled(m))]
            apart = [(m.header.stamp.to_sec(), sorted(set(anchors) - set(coupled(m, least=ALIGNED))))
                     for m in phys_log if set(anchors) - set(coupled(m, least=ALIGNED))]
            self.log("drive: %d physical pair message(s), %d with a pair not seated, %d with a pair apart"
                     % (len(phys_log), len(unseated), len(apart)))
            self.assertFalse(apart, "anchor out of its opening in Bullet during the drive (t, pairs): %s"
                             % apart[:5])
            if self.drive_hold == "seated":
                self.assertFalse(unseated, "not seated in Bullet during the drive (t, pairs): %s" % unseated[:5])

    def check_decouple(self, step, before, result):
        pair = [k for k in before if set(k) == set(step.pair)]
        self.assertTrue(pair, "%s was not coupled before the decouple step" % step.pair)
        key = pair[0]
        self.assertNotIn(key, coupled(self.runner.pairs_at(result.end)), "MPC still reports %s coupled" % (key,))
        if self.physical:
            t0, t1 = result.end, result.end + self.release_hold
            self.runner.wait_until(t1 + 0.2)
            with self.runner.lock:
                msgs = [m for t, m in self.runner.physical_log if t0 <= t <= t1]
            self.assertTrue(msgs, "no physical pairs published after the decouple")
            inside = [m.header.stamp.to_sec() for m in msgs if key in {anchor_key(p) for p in m.pairs}]
            self.assertFalse(inside, "%s's anchor is still in %s's opening in Bullet at t = %s"
                             % (key[0], key[1], inside[:5]))
            others = [k for k, p in before.items() if k != key and p.type == ConnectionPair.TYPE_ANCHOR]
            unseated = [k for k in others if k not in coupled(self.runner.physical_at(t1))]
            self.assertFalse(unseated, "other pairs came apart in Bullet: %s" % unseated)

    def check_anchors_in_holders(self):
        """tf <robot>/base_link -> <robot>/anchor: no anchor pulled out of its holder or flipped round."""
        for name in self.names:
            tr = self.tf.lookup_transform(names.base_frame(name), names.anchor_frame(name), rospy.Time(0),
                                          rospy.Duration(5.0)).transform
            yaw = yaw_from_quaternion(tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w)
            self.assertGreaterEqual(tr.translation.x, -self.geometry.body_side / 2,
                                    "%s's anchor is out of its holder (x = %.1f mm)" % (name, 1e3 * tr.translation.x))
            self.assertLessEqual(abs(yaw), ANCHOR_YAW_MAX, "%s's anchor turned %.2f rad in its holder" % (name, yaw))

    # ----------------------------------------------------------------- test
    def test_scenario(self):
        try:
            self.run_scenario()
        except AssertionError as e:
            lost = self.lockstep_lost()
            if not lost:
                raise
            raise AssertionError("%s\n(a lockstep wait ran out before this (%d warning(s), throttled), so the "
                                 "run was not the seed's; first: %s)" % (e, len(lost), lost[0])) from None

    def run_scenario(self):
        self.log("%d step(s), robots %s, physical checks %s" % (len(self.scenario.steps), self.names,
                                                                "on" if self.physical else "off (no Bullet)"))
        sim0 = rospy.get_time()
        before = coupled(self.runner.pairs)
        results = self.runner.run_steps(self.scenario.steps, 0.0, self.wall_deadline)
        t_first = None
        for i, (step, result) in enumerate(zip(self.scenario.steps, results)):
            t_first = result.start if t_first is None else t_first
            self.log("step %d %s: %s after %.2f s simulated (t = %.1f..%.1f s): %s"
                     % (i + 1, step.describe(), result.outcome, result.sim_seconds, result.start, result.end,
                        result.message))
            self.assertEqual(result.outcome, "succeeded", "step %d (%s): %s: %s"
                             % (i + 1, step.describe(), result.outcome, result.message))
            if step.timeout > 0:
                self.assertLessEqual(result.sim_seconds, step.timeout + SETTLE)
            if step.behavior == "couple":
                self.check_couple(step, result)
            elif step.behavior == "drive_assembly":
                self.check_drive(step, before, result)
            elif step.behavior == "decouple":
                self.check_decouple(step, before, result)
            before = coupled(self.runner.pairs_at(result.end))
        self.runner.wait_until(rospy.get_time() + 0.3)      # resting: the latest poses are the final ones
        for name, (lo, hi) in sorted(self.final_z.items()):
            z = self.runner.poses[name][2]
            self.log("final height of %s: %.3f m (expected %.3f..%.3f)" % (name, z, lo, hi))
            self.assertTrue(lo <= z <= hi, "%s ends at z = %.3f m, not in [%.3f, %.3f]" % (name, z, lo, hi))
        if self.physical:
            self.check_anchors_in_holders()
        failed = [t for t in self.runner.failed_stamps if t_first is not None and t >= t_first - 1e-6]
        self.log("passed in %.1f s simulated; %d failed MPC step(s) from the first step on (%d in all, "
                 "e.g. before the first poses); %d lockstep warning(s) of a wait that ran out"
                 % (rospy.get_time() - sim0, len(failed), self.runner.failed_solves, len(self.lockstep_lost())))
        if self.max_failed_solves >= 0:
            self.assertLessEqual(len(failed), self.max_failed_solves, "failed MPC steps at t = %s" % failed[:5])


if __name__ == "__main__":
    rospy.init_node("scenario_test", argv=sys.argv)
    rostest.rosrun("puzzlebot_bringup", rospy.get_name().strip("/"), ScenarioTest)
