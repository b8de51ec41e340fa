"""Diagnostics content (no ROS): what an operator sees per robot and for the loop."""

from puzzlebot_driver import diagnostics, safety
from puzzlebot_driver.driver import Decision, LoopStats, RobotState
from puzzlebot_driver.link import LinkInfo
from puzzlebot_driver.params import DriverParams


def test_robot_status_values_and_levels():
    st = RobotState("p21", 21, False, pose=(9.95, 0.0, 0.0, 0.0), cmd=(0.03, 0.1), cmd_time=9.9)
    for k in range(101):
        st.pose_stamps.append(9.0 + 0.01 * k)
    st.decision = Decision(40, 45, safety.DRIVE)
    s = diagnostics.robot_status(st, LinkInfo(connected=True, address="10.0.0.21", connects=1), (0.029, 0.1), 10.0,
                                 DriverParams(), loop_rate=29.9)
    v = dict(s.values)
    assert s.level == diagnostics.OK and s.name.endswith("p21")
    assert (v["link"], v["pwm left"], v["pwm right"], v["reason"]) == ("connected", "40", "45", "drive")
    assert float(v["mocap rate [Hz]"]) == 100.0 and float(v["mocap age [s]"]) == 0.05
    assert v["loop rate [Hz]"] == "29.90"
    st.decision = Decision(0, 0, safety.POSE_STALE)
    assert diagnostics.robot_status(st, LinkInfo(connected=True), None, 10.0, DriverParams()).level == diagnostics.WARN
    lost = diagnostics.robot_status(st, LinkInfo(connected=False, connects=1), None, 10.0, DriverParams())
    assert lost.level == diagnostics.WARN and "link lost" in lost.message
    never = diagnostics.robot_status(st, None, None, 10.0, DriverParams())
    assert never.message == "not connected" and dict(never.values)["est v [m/s]"] == "n/a"


def test_loop_status_reports_rate_jitter_and_estop():
    stats = LoopStats(1 / 30)
    for k in range(31):
        stats.record(k / 30 + (0.002 if k % 2 else 0.0), 0.001)
    summary = stats.summary()
    assert abs(summary["rate_hz"] - 30.0) < 0.1 and summary["period_std_ms"] > 1.0
    s = diagnostics.loop_status(summary, DriverParams(), False, "", 0)
    assert s.level == diagnostics.OK and "30.0 Hz" in s.message
    s = diagnostics.loop_status(summary, DriverParams(), True, "service: test", 2)
    assert s.level == diagnostics.WARN and "E-STOP" in s.message and dict(s.values)["refused connections"] == "2"
    slow = LoopStats(1 / 30)
    for k in range(10):
        slow.record(k * 0.05, 0.001)
    assert diagnostics.loop_status(slow.summary(), DriverParams(), False, "", 0).level == diagnostics.WARN
