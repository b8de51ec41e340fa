"""Driver core + emulated robots on a simulated clock: tracking and the mocap-stop rule.

Deterministic (no sockets, no wall time): the timing figures here are exact
for the loop's logic. The same rules over real TCP are in test_loopback.py
and, through ROS, in puzzlebot_bringup's lab_emulated rostest.
"""

import pytest

from puzzlebot_common.robots import parse_robot_list
from puzzlebot_driver.closed_loop import run
from puzzlebot_driver.params import driver_config, emulator_config

ROBOTS = parse_robot_list([{"name": "p%d" % n, "ip_octet": n, "pilot": n == 23} for n in (21, 22, 23)])
CMD = (0.04, 0.5)


def configs(motor=None):
    return driver_config({}, ROBOTS), emulator_config({"motor": motor or {}}, ROBOTS)


@pytest.mark.parametrize("motor", [{}, {"gain": 0.85, "imbalance": 0.1, "delay": 0.05, "tau": 0.08, "deadband": 8.0}])
def test_three_robots_track_within_10_percent_after_1_s(motor):
    traces = run(ROBOTS, *configs(motor), lambda t: {n.name: CMD for n in ROBOTS}, 3.0)
    for name, tr in traces.items():
        for t0 in (1.0, 1.5, 2.0, 2.5):                 # every 0.5 s window after 1 s
            v, w = tr.mean("v", t0, t0 + 0.5), tr.mean("w", t0, t0 + 0.5)
            assert abs(v - CMD[0]) <= 0.1 * CMD[0], (name, t0, v)
            assert abs(w - CMD[1]) <= 0.1 * CMD[1], (name, t0, w)


def test_open_loop_would_not_track():
    """The same imperfect robots with the loop's feedback off miss the 10 % band (the test can fail)."""
    d, e = configs({"gain": 0.85, "imbalance": 0.1, "delay": 0.05, "tau": 0.08, "deadband": 8.0})
    off = driver_config({"control": {"kp_v": 0.0, "ki_v": 0.0, "kp_w": 0.0, "ki_w": 0.0}}, ROBOTS)
    tr = run(ROBOTS, off, e, lambda t: {n.name: CMD for n in ROBOTS}, 3.0)["p21"]
    v, w = tr.mean("v", 2.0, 3.0), tr.mean("w", 2.0, 3.0)
    assert abs(v - CMD[0]) > 0.1 * CMD[0] or abs(w - CMD[1]) > 0.1 * CMD[1]


def test_mocap_stop_zeroes_that_robot_within_0_3_s_and_the_others_keep_moving():
    t_mute = 1.5
    traces = run(ROBOTS, *configs(), lambda t: {n.name: CMD for n in ROBOTS}, 3.0,
                 mocap_muted=lambda name, t: name == "p22" and t >= t_mute)
    tr = traces["p22"]
    last_pose = t_mute - 0.01                             # poses every 10 ms (100 Hz): the last one before
    zero = [t for t, l, r, why in zip(tr.t, tr.left, tr.right, tr.reason)
            if t >= t_mute and (l, r) == (0, 0) and why == "pose stale"]
    assert zero, "p22's PWM never went to zero"
    latency = zero[0] - last_pose
    assert latency <= 0.3, latency
    assert all((l, r) == (0, 0) for t, l, r in zip(tr.t, tr.left, tr.right) if t >= zero[0])
    for name in ("p21", "p23"):
        v = traces[name].mean("v", t_mute, 3.0)
        assert abs(v - CMD[0]) <= 0.1 * CMD[0], (name, v)


def test_stale_command_zeroes_within_cmd_timeout():
    traces = run(ROBOTS, *configs(), lambda t: {n.name: CMD for n in ROBOTS} if t < 1.0 else {}, 2.0)
    tr = traces["p21"]
    first_zero = min(t for t, why in zip(tr.t, tr.reason) if why == "command stale")
    last_cmd = 0.9                                        # commands at 10 Hz: the last before t = 1.0
    assert 0.5 <= first_zero - last_cmd <= 0.5 + 1 / 30 + 1e-9
