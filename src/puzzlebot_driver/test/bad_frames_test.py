#!/usr/bin/env python3
"""The real driver_node as a black box, fed bad mocap frames (rostest bad_frames).

This test plays the lab around the driver: five robots' ESP8266 peers on
loopback TCP (from 127.0.0.21..25, the emulator's models, in this process),
the Vicon bridge (it publishes their poses at 100 Hz) and the MPC (cmd_vel
(0.04 m/s, 0.3 rad/s) at 10 Hz). Every fault of puzzlebot_common.mocap_faults,
as one frame and as a burst of 10, replaces the frames of one of p21..p24
(four at a time, 0.6 s apart); p25 stays clean. Asserted:

- the driver never dies (every robot still gets lines at the end) and p25
  drives throughout;
- |PWM| at a hit robot never exceeds twice its steady value;
- a line on /rosout from the driver names each rejection (robot and kind);
- a hit robot keeps driving (its wheel_pwm reason stays ``drive``): a burst
  of 0.1 s is shorter than pose_timeout;
- half a second of garbage frames (p21) and of no frames (p22) stop the
  robot within 0.6 s (rule: pose_timeout 0.2 s + a tick) and it drives
  again within 0.6 s of good frames (both measured and printed);
- the diagnostics count the rejections by kind.

Wall-time bounds are generous (the machine is shared); the exact figures of
the rules are asserted on a simulated clock in test_bad_frames.py.
"""

import math
import threading
import time
import unittest

import rosgraph
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist

from puzzlebot_common import names
from puzzlebot_common.mocap_faults import FAULTS, SILENCE
from puzzlebot_common.node_utils import robot_list_from_param
from puzzlebot_common.rostest_lab import Mocap, NodeLog
from puzzlebot_driver.emulator import EmulatedFleet, start_poses
from puzzlebot_driver.params import emulator_config
from puzzlebot_msgs.msg import WheelPwm

CMD = (0.04, 0.3)
POSE_RATE = 100.0          # Hz
SPACING = 0.6              # s between two faults on a robot (> pose_gate/log_period 0.3 s of the test launch)
VICTIMS = ("p21", "p22", "p23", "p24")
CLEAN = "p25"
LONG = 0.5                 # s of garbage / silence for the stop-and-resume cases
BOUND = 0.6                # s, generous wall-time bound of the 0.3 s rules


class Lab:
    """TCP peers + Vicon + cmd_vel around the driver node; records what the robots receive."""

    def __init__(self, robots, port):
        self.lock = threading.Lock()
        cfg = emulator_config({"port": port, "reconnect_period": 0.1}, robots)
        self.fleet = EmulatedFleet(robots, cfg, start_poses(robots, None, 0.15), clock=time.time)
        self.received = {r.name: [] for r in robots}         # (t, left, right) at the robot
        self.wheel = {r.name: [] for r in robots}            # (stamp, reason) from /<robot>/wheel_pwm
        self.log = NodeLog("driver")
        self.diag = {}
        for name, client in self.fleet.clients.items():
            client.on_pwm = self._on_pwm(name)
        self.cmd_pubs = {r.name: rospy.Publisher(names.cmd_vel_topic(r.name), Twist, queue_size=1) for r in robots}
        for r in robots:
            rospy.Subscriber(names.wheel_pwm_topic(r.name), WheelPwm, self._on_wheel, callback_args=r.name,
                             queue_size=100)
        rospy.Subscriber(names.DIAGNOSTICS_TOPIC, DiagnosticArray, self._on_diag, queue_size=10)
        self.mocap = Mocap(robots, self._step, POSE_RATE)     # its plan: the faults; .good: clean frames' stamps
        self.ticks = 0

    def _on_pwm(self, name):
        robot = self.fleet.robots[name]

        def on_pwm(t, left, right):
            with self.lock:
                robot.command(t, left, right)
                self.received[name].append((t, left, right))
        return on_pwm

    def _on_wheel(self, msg, name):
        with self.lock:
            self.wheel[name].append((msg.header.stamp.to_sec(), msg.reason))

    def _on_diag(self, msg):
        with self.lock:
            for s in msg.status:
                self.diag[s.name] = {kv.key: kv.value for kv in s.values}

    def _step(self, t, dt):
        """The Mocap's plant: the emulated robots advanced, their measured poses; cmd_vel at a tenth of the rate."""
        with self.lock:
            self.fleet.advance(t, dt)
            measured = self.fleet.mocap(t)
        if self.ticks % 10 == 0:
            for pub in self.cmd_pubs.values():
                tw = Twist()
                tw.linear.x, tw.angular.z = CMD
                pub.publish(tw)
        self.ticks += 1
        return measured

    def lines(self, name, t0, t1=math.inf):
        with self.lock:
            return [x for x in self.received[name] if t0 <= x[0] < t1]

    def reasons(self, name, t0, t1):
        with self.lock:
            return [r for t, r in self.wheel[name] if t0 <= t < t1]


def peak(lines):
    return max(max(abs(l), abs(r)) for _, l, r in lines)


class DriverBadFrames(unittest.TestCase):
    def test_bad_frames_never_drive_a_robot_and_never_kill_the_driver(self):
        robots = robot_list_from_param()
        end = time.monotonic() + 30.0
        while rospy.get_param("/driver/bound_port", 0) == 0 and time.monotonic() < end:
            time.sleep(0.1)
        lab = Lab(robots, rospy.get_param("/driver/bound_port"))
        lab.fleet.start()
        lab.mocap.start()
        try:
            self.run_cases(lab)
        finally:
            lab.mocap.stop()
            lab.fleet.stop()

    def run_cases(self, lab):
        end = time.monotonic() + 20.0
        while not all(len(lab.lines(n, 0.0)) > 30 for n in lab.received) and time.monotonic() < end:
            time.sleep(0.1)
        time.sleep(1.5)
        now = time.time()
        steady = {n: peak(lab.lines(n, now - 1.0, now)) for n in lab.received}
        self.assertTrue(all(40 < s < 100 for s in steady.values()), steady)     # ~57 + 9 for (0.04, 0.3)
        plan = lab.mocap.plan
        t0 = time.time() + 0.2
        schedule = plan.every_fault(VICTIMS, t0, SPACING, POSE_RATE)            # (robot, fault, burst, t)
        t_long = schedule[-1][3] + SPACING + 0.2
        plan.add("p21", t_long, t_long + LONG, "translation.x = nan")
        plan.add("p22", t_long, t_long + LONG, SILENCE)
        while time.time() < t_long + LONG + 1.0:
            time.sleep(0.1)
        time.sleep(1.2)                                                         # a diagnostics message

        for name, fault, burst, t in schedule:
            kind = FAULTS[fault][1]
            window = lab.lines(name, t, t + SPACING)
            self.assertGreater(len(window), 10, (name, fault, burst))
            self.assertLessEqual(peak(window), 2 * steady[name], (name, fault, burst, peak(window)))
            named = lab.log.rejections(name, kind, t - 0.05, t + SPACING + 0.5)
            self.assertTrue(named, "no log line for %s on %s at %.2f" % (fault, name, t))
            reasons = lab.reasons(name, t, t + SPACING)
            self.assertTrue(reasons and all(r == "drive" for r in reasons), (name, fault, burst, set(reasons)))

        clean_lines = lab.lines(CLEAN, t0)
        self.assertTrue(all(l > 0 and r > 0 for _, l, r in clean_lines))
        self.assertEqual(set(lab.reasons(CLEAN, t0, time.time())), {"drive"})
        for name in lab.received:                                               # the driver is alive
            self.assertGreater(len(lab.lines(name, time.time() - 0.5)), 5, name)
        self.assertIn("/driver", [n for _, nodes in rosgraph.Master("/t").getSystemState()[0] for n in nodes])

        for name, what in (("p21", "garbage"), ("p22", "silence")):
            good = list(lab.mocap.good[name])
            last_good = max(t for t in good if t < t_long)
            first_good = min(t for t in good if t >= t_long + LONG)
            zero = [t for t, l, r in lab.lines(name, t_long) if (l, r) == (0, 0)]
            self.assertTrue(zero, "%s: %s never stopped it" % (name, what))
            stop = zero[0] - last_good
            back = next(t for t, l, r in lab.lines(name, first_good) if l != 0) - first_good
            print("%s of %.1f s on %s: PWM 0 at the robot %.3f s after the last good pose, PWM again %.3f s "
                  "after the first good one" % (what, LONG, name, stop, back))
            self.assertLess(stop, BOUND)
            self.assertLess(back, BOUND)
            self.assertLessEqual(peak(lab.lines(name, t_long, t_long + LONG + 1.0)), 2 * steady[name])

        with lab.lock:
            diag = {k.split(": ")[-1]: v for k, v in lab.diag.items()}
        for name in VICTIMS:
            counts = {kind: int(diag[name]["rejected poses: %s" % kind])
                      for kind in {FAULTS[f][1] for n, f, _, _ in schedule if n == name}}
            self.assertTrue(all(c > 0 for c in counts.values()), (name, counts))
        self.assertEqual(diag[CLEAN]["rejected poses"], "0")
        print("steady peak PWM %s; %d cases, rejections by kind on p21: %s" % (
            steady, len(schedule), {k: v for k, v in diag["p21"].items() if k.startswith("rejected poses: ")}))


if __name__ == "__main__":
    rospy.init_node("driver_bad_frames_test")
    rostest.rosrun("puzzlebot_driver", "driver_bad_frames", DriverBadFrames)
