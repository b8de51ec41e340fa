"""Fault tests on loopback TCP: the driver runtime (core + server + 30 Hz loop) and
emulated ESP8266 clients connecting from 127.0.0.<ip_octet>, in real time, no ROS.

Timing assertions use generous bounds (the machine is shared); the exact
figures of the rules are in test_closed_loop.py.
"""

import socket
import threading
import time

from puzzlebot_common.mocap_faults import FAULTS

from puzzlebot_common.robots import parse_robot_list
from puzzlebot_driver.emulator import EmulatedFleet, start_poses
from puzzlebot_driver.params import driver_config, emulator_config
from puzzlebot_driver.runtime import DriverRuntime

ROBOTS = parse_robot_list([{"name": "p%d" % n, "ip_octet": n} for n in (21, 22, 23)])
CMD = (0.04, 0.3)


class Rig:
    """Driver runtime + emulated fleet + a mocap/command feeder, all threads."""

    def __init__(self):
        self.logs = []
        self.lock = threading.Lock()
        dcfg = driver_config({"port": 0, "bind_address": "127.0.0.1"}, ROBOTS)
        self.rt = DriverRuntime(ROBOTS, dcfg, clock=time.time, log=self.log).start()
        ecfg = emulator_config({"port": self.rt.server.port, "reconnect_period": 0.1}, ROBOTS)
        self.fleet = EmulatedFleet(ROBOTS, ecfg, start_poses(ROBOTS, None, 0.15), clock=time.time, log=self.log)
        self.received = {r.name: [] for r in ROBOTS}          # (t, left, right) at the emulated robot
        for name, client in self.fleet.clients.items():
            client.on_pwm = self.recorder(name)
        self.stop = threading.Event()
        self.last_pose = {r.name: None for r in ROBOTS}
        self.faults = {}           # robot -> (mocap_faults function, until [s]): its frames replaced meanwhile
        self.threads = [threading.Thread(target=self.rt.run, args=(self.stop.is_set,), daemon=True),
                        threading.Thread(target=self.feed, daemon=True)]

    def log(self, level, text):
        with self.lock:
            self.logs.append((level, text))

    def recorder(self, name):
        robot = self.fleet.robots[name]

        def on_pwm(t, left, right):
            robot.command(t, left, right)
            with self.lock:
                self.received[name].append((t, left, right))
        return on_pwm

    def feed(self):
        """Emulated Vicon at 100 Hz and cmd_vel at 10 Hz."""
        k = 0
        t_next = time.monotonic()
        while not self.stop.is_set():
            t = time.time()
            self.fleet.advance(t, 0.01)
            for name, pose in self.fleet.mocap(t):
                make, until = self.faults.get(name, (None, 0.0))
                if t < until:
                    f = make(t, *pose)
                    self.rt.on_pose(name, f.stamp, f.x, f.y, f.q, z=f.z)
                    continue
                self.rt.on_pose(name, t, *pose)
                self.last_pose[name] = t
            if k % 10 == 0:
                for r in ROBOTS:
                    self.rt.on_cmd(r.name, *CMD)
            k += 1
            t_next += 0.01
            time.sleep(max(0.0, t_next - time.monotonic()))

    def __enter__(self):
        self.fleet.start()
        for th in self.threads:
            th.start()
        assert wait_for(lambda: all(self.lines(n) > 10 for n in self.received), 10.0), "clients did not connect"
        return self

    def __exit__(self, *exc):
        self.stop.set()
        for th in self.threads:
            th.join(timeout=2.0)
        self.rt.shutdown()
        self.fleet.stop()

    def lines(self, name, since=0.0):
        with self.lock:
            return sum(1 for t, _, _ in self.received[name] if t >= since)

    def lines_after(self, name, since):
        with self.lock:
            return [x for x in self.received[name] if x[0] >= since]

    def logged(self, *words):
        with self.lock:
            return [text for _, text in self.logs if all(w in text for w in words)]


def wait_for(cond, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def test_kill_a_link_mid_run_others_served_and_the_robot_resumes():
    with Rig() as rig:
        time.sleep(0.5)
        rig.fleet.clients["p22"].drop(hold=1.0)
        t_drop = time.time()
        assert wait_for(lambda: not rig.rt.server.connected("p22"), 2.0)
        time.sleep(0.8)
        during = {n: rig.lines(n, t_drop + 0.1) for n in rig.received}
        assert during["p22"] == 0
        assert during["p21"] >= 10 and during["p23"] >= 10            # ~21 lines at 30 Hz in 0.7 s
        assert rig.logged("p22 disconnected")
        assert wait_for(lambda: rig.rt.server.connected("p22"), 3.0), "p22 did not reconnect"
        t_back = time.time()
        assert wait_for(lambda: len(rig.lines_after("p22", t_back)) >= 10, 2.0)
        assert any(left != 0 for _, left, _ in rig.lines_after("p22", t_back)), "p22 not driven again"
        assert rig.rt.server.link_info("p22").connects == 2


def test_mocap_stop_zeroes_that_robot_and_the_others_keep_moving():
    with Rig() as rig:
        time.sleep(1.0)
        rig.fleet.mute("p22", time.time() + 1.5)
        time.sleep(1.0)
        last = rig.last_pose["p22"]
        zeros = [t for t, l, r in rig.lines_after("p22", last) if (l, r) == (0, 0)]
        assert zeros, "p22 never got PWM 0"
        latency = zeros[0] - last
        print("mocap stop -> PWM 0 at the robot after %.3f s (loopback, real time)" % latency)
        assert latency < 0.6                                   # rule: 0.2 s + one tick; generous for load
        assert all((l, r) == (0, 0) for t, l, r in rig.lines_after("p22", zeros[0]) if t < last + 1.0)
        for name in ("p21", "p23"):
            assert all(l > 0 and r > 0 for _, l, r in rig.lines_after(name, last)), name
            assert rig.fleet.robots[name].v > 0.5 * CMD[0]


def test_garbage_lines_nan_commands_and_unknown_robots_are_logged_not_fatal():
    with Rig() as rig:
        assert rig.fleet.clients["p21"].send_raw(b"hello\n\xff\xfe\n12;34\n")
        assert wait_for(lambda: rig.logged("p21 sent"), 2.0)
        assert rig.rt.on_cmd("p23", float("nan"), 0.0).startswith("p23: non-finite")
        assert "v_limit" in rig.rt.on_cmd("p23", 5.0, 0.0)
        with socket.socket() as s:                             # a stranger from 127.0.0.99
            s.bind(("127.0.0.99", 0))
            s.connect(("127.0.0.1", rig.rt.server.port))
            s.settimeout(2.0)
            assert s.recv(100) == b""                          # closed by the driver
        assert rig.logged("127.0.0.99 refused")
        t = time.time()
        time.sleep(0.5)
        for name in rig.received:                              # everybody is still served
            assert rig.lines(name, t) >= 8
        assert rig.rt.server.connected("p21")


def test_estop_latches_and_shutdown_sends_zero():
    with Rig() as rig:
        time.sleep(0.5)
        assert rig.rt.set_estop(True, "test")
        t = time.time()
        time.sleep(0.5)
        for name in rig.received:
            lines = rig.lines_after(name, t + 0.05)
            assert lines and all((l, r) == (0, 0) for _, l, r in lines)
        rig.rt.set_estop(False)
        t = time.time()
        assert wait_for(lambda: any(l != 0 for _, l, _ in rig.lines_after("p21", t)), 2.0)
        rig.stop.set()
        time.sleep(0.2)
        zeroed = rig.rt.shutdown()
        assert sorted(zeroed) == ["p21", "p22", "p23"]
        time.sleep(0.3)
        for name in rig.received:
            assert rig.received[name][-1][1:] == (0, 0), name


def test_bad_frames_are_logged_by_kind_and_the_robot_keeps_driving():
    with Rig() as rig:
        time.sleep(0.5)
        for fault in ("x = 1.7e308", "heading flipped by pi", "zero quaternion", "translation.y = nan"):
            rig.faults["p21"] = (FAULTS[fault][0], time.time() + 0.1)      # a burst of ~10 frames
            time.sleep(0.3)
        assert rig.logged("rejected pose (out of range): p21: position x=1.7e+308 m")
        assert rig.logged("rejected pose (turn): p21: heading turned")
        assert rig.logged("rejected pose (quaternion): p21: quaternion (0, 0, 0, 0) has norm 0")
        assert rig.logged("rejected pose (non-finite): p21: non-finite y")
        t = time.time()
        time.sleep(0.3)
        lines = rig.lines_after("p21", t)
        assert len(lines) >= 5 and all(0 < l < 250 and 0 < r < 250 for _, l, r in lines)
        gate = rig.rt.core.robots["p21"].gate
        assert gate.counts["out of range"] >= 5 and gate.counts["turn"] >= 5
