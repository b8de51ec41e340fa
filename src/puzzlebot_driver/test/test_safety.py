"""Stale-pose and stale-command logic, command rejection, e-stop (driver core, no ROS)."""

import pytest

from puzzlebot_common.robots import parse_robot_list
from puzzlebot_driver import safety
from puzzlebot_driver.driver import DriverCore
from puzzlebot_driver.params import DriverParams, driver_config

P = DriverParams()    # pose_timeout 0.2 s, cmd_timeout 0.5 s


def reason(now, estop=False, pose=10.0, cmd=(0.05, 0.0), cmd_time=10.0, rejected=False):
    return safety.zero_reason(now, estop, pose, cmd, cmd_time, rejected, P)


def test_defaults_are_the_issue_figures():
    assert (P.pose_timeout, P.cmd_timeout, P.loop_rate, P.port) == (0.2, 0.5, 30.0, 8080)


def test_stale_pose_by_stamp():
    assert reason(10.19) == safety.DRIVE
    assert reason(10.2) == safety.DRIVE
    assert reason(10.21) == safety.POSE_STALE
    assert reason(10.0, pose=None) == safety.NO_POSE


def test_stale_command_by_arrival_time():
    assert reason(10.15, pose=10.1, cmd_time=9.7) == safety.DRIVE
    assert reason(10.15, pose=10.1, cmd_time=9.6) == safety.COMMAND_STALE
    assert reason(10.0, cmd=None, cmd_time=None) == safety.NO_COMMAND


def test_precedence_and_stop():
    assert reason(11.0, estop=True) == safety.ESTOP              # e-stop first, even with a stale pose
    assert reason(10.0, rejected=True) == safety.COMMAND_REJECTED
    assert reason(10.0, cmd=(0.0005, 0.005)) == safety.STOP
    assert reason(10.0, cmd=(0.0, 0.02)) == safety.DRIVE           # turning in place is a command


@pytest.mark.parametrize("v, w, text", [(float("nan"), 0.0, "non-finite"), (0.0, float("inf"), "non-finite"),
                                        (0.25, 0.0, "v_limit"), (0.0, -6.5, "w_limit"), ("x", 0.0, "non-finite")])
def test_bad_commands_are_rejected(v, w, text):
    assert text in safety.check_command(v, w, P)


def core(n=2):
    robots = parse_robot_list([{"name": "a%d" % i, "ip_octet": 21 + i} for i in range(n)])
    return DriverCore(robots, driver_config({}, robots))


def test_rejected_command_stops_the_robot_until_a_valid_one():
    c = core()
    c.on_pose("a0", 1.00, 0, 0, 0)
    c.on_pose("a0", 1.01, 0.0005, 0, 0)
    assert c.on_cmd("a0", 1.0, 0.05, 0.0) is None
    assert c.tick(1.02, 1 / 30)["a0"].reason == safety.DRIVE
    assert c.tick(1.02, 1 / 30)["a0"].left > 0
    msg = c.on_cmd("a0", 1.02, float("nan"), 0.0)
    assert "a0" in msg and "non-finite" in msg and "stopped" in msg
    d = c.tick(1.03, 1 / 30)["a0"]
    assert (d.left, d.right, d.reason) == (0, 0, safety.COMMAND_REJECTED)
    assert c.robots["a0"].rejected_commands == 1
    assert c.on_cmd("a0", 1.03, 0.05, 0.0) is None
    assert c.tick(1.04, 1 / 30)["a0"].reason == safety.DRIVE


def test_estop_latches_until_released_and_unknown_names_are_reported():
    c = core()
    for name in ("a0", "a1"):
        c.on_pose(name, 1.0, 0, 0, 0)
        c.on_cmd(name, 1.0, 0.05, 0.0)
    assert c.set_estop(True, "test")
    assert not c.set_estop(True, "again")
    for k in range(10):
        assert all((d.left, d.right) == (0, 0) for d in c.tick(1.0 + 0.01 * k, 1 / 30).values())
    c.on_cmd("a0", 1.1, 0.05, 0.0)                      # new commands do not release it
    assert c.tick(1.1, 1 / 30)["a0"].reason == safety.ESTOP
    assert c.set_estop(False)
    assert c.tick(1.1, 1 / 30)["a0"].reason == safety.DRIVE
    assert "unknown robot" in c.on_cmd("ghost", 1.0, 0.0, 0.0)
    assert "unknown robot" in c.on_pose("ghost", 1.0, 0.0, 0.0, 0.0).reason


def test_stale_pose_zeroes_one_robot_and_resets_its_integrator():
    c = core()
    for k in range(20):
        t = 1.0 + 0.01 * k
        c.on_pose("a0", t, 0.0, 0.0, 0.0)        # a0 standing still although commanded: integrates
        c.on_pose("a1", t, 0.0, 0.0, 0.0)
    for name in ("a0", "a1"):
        c.on_cmd(name, 1.19, 0.05, 0.0)
    c.tick(1.19, 1 / 30)
    assert c.controllers["a0"].i_v > 0
    for k in range(1, 30):                          # only a1's poses keep coming
        c.on_pose("a1", 1.19 + 0.01 * k, 0.0, 0.0, 0.0)
    d = c.tick(1.45, 1 / 30)
    assert d["a0"].reason == safety.POSE_STALE and (d["a0"].left, d["a0"].right) == (0, 0)
    assert c.controllers["a0"].i_v == 0.0
    assert d["a1"].reason == safety.DRIVE and d["a1"].left > 0


def test_after_a_pose_gap_the_loop_restarts_on_feed_forward_alone():
    c = core()
    for k in range(20):                                 # a0 driving at 0.05 m/s along x
        c.on_pose("a0", 1.0 + 0.01 * k, 0.0005 * k, 0.0, 0.0)
    c.on_cmd("a0", 1.19, 0.05, 0.0)
    assert c.tick(1.19, 1 / 30)["a0"].reason == safety.DRIVE
    assert c.estimate("a0") is not None
    d = c.tick(1.5, 1 / 30)                             # no pose for 0.3 s: stale
    assert d["a0"].reason == safety.POSE_STALE and c.estimate("a0") is None
    c.on_pose("a0", 1.5, 0.0, 0.0, 0.0)                 # the robot stopped meanwhile: poses again
    c.on_cmd("a0", 1.5, 0.05, 0.0)
    d = c.tick(1.5, 1 / 30)["a0"]
    g = c.controllers["a0"].gains
    # no velocity estimated across the gap (it would read "standing still" and add kp_v times the whole
    # command): the feed-forward alone
    assert d.reason == safety.DRIVE
    assert d.left == pytest.approx(g.pwm_per_v * 0.05 + g.pwm_deadband + g.trim_left, abs=1)


def test_future_stamps_are_rejected_clock_check():
    c = core()
    assert c.on_pose("a0", 10.04, 0, 0, 0, now=10.0).accepted
    v = c.on_pose("a0", 10.5, 0, 0, 0, now=10.0)
    assert not v.accepted and v.kind == "clock" and "future" in v.reason and "synchronised" in v.reason
    assert c.robots["a0"].pose[0] == 10.04
    assert c.on_pose("a0", 10.05, 0, 0, 0, now=10.01).accepted     # the future frame did not become the track


def test_a_robot_without_link_does_not_wind_up():
    c = core()
    for k in range(30):
        c.on_pose("a0", 1.0 + 0.01 * k, 0.0, 0.0, 0.0)      # standing still
    c.on_cmd("a0", 1.29, 0.05, 0.0)
    for k in range(30):
        d = c.tick(1.29 + k / 300, 1 / 30, connected=set())["a0"]
    assert d.reason == safety.NO_LINK and (d.left, d.right) == (0, 0)
    assert c.controllers["a0"].i_v == 0.0
    d = c.tick(1.29, 1 / 30, connected={"a0"})["a0"]
    assert d.reason == safety.DRIVE
    assert d.left == pytest.approx(c.controllers["a0"].gains.pwm_per_v * 0.05 * (1 + c.controllers["a0"].gains.kp_v),
                                   abs=2)
