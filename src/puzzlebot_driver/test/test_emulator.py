"""The emulator's motor + unicycle model and start poses."""

import math

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.robots import parse_robot_list
from puzzlebot_driver.emulator import EmulatedRobot, MotorModel, start_poses
from puzzlebot_driver.params import MotorParams


def run_robot(params, left, right, seconds, dt=0.005):
    robot = EmulatedRobot("r", params, (0.0, 0.0, 0.0))
    robot.command(0.0, left, right)
    for k in range(int(round(seconds / dt))):
        robot.step(k * dt, dt)
    return robot


def test_motor_deadband_gain_and_lag():
    p = MotorParams(mps_per_pwm=0.001, gain=0.9, deadband=5.0, tau=0.05, delay=0.0)
    m = MotorModel(p, 1.0)
    m.command(0.0, 4)
    assert m.advance(0.0, 1.0) == 0.0                       # within the deadband
    m.command(1.0, 105)
    first = m.advance(1.0, 0.05)
    assert first == pytest.approx(0.09 * (1 - math.exp(-1)))   # one time constant
    for k in range(100):
        m.advance(1.05 + 0.01 * k, 0.01)
    assert m.speed == pytest.approx(0.001 * 0.9 * 100, rel=1e-6)


def test_motor_delay():
    m = MotorModel(MotorParams(tau=0.0, delay=0.03), 1.0)
    m.command(1.0, 100)
    assert m.advance(1.02, 0.01) == 0.0
    assert m.advance(1.03, 0.01) > 0.0


def test_equal_pwm_drives_straight_and_imbalance_turns():
    straight = run_robot(MotorParams(imbalance=0.0, delay=0.0), 100, 100, 1.0)
    assert abs(straight.pose[1]) < 1e-12 and abs(straight.pose[2]) < 1e-12
    expected_v = 0.0007 * 0.95 * (100 - 4)
    assert straight.v == pytest.approx(expected_v, rel=1e-3)
    curved = run_robot(MotorParams(imbalance=0.04), 100, 100, 1.0)
    assert curved.w == pytest.approx(0.04 * expected_v / 0.04, rel=1e-3)   # right wheel faster: left turn
    assert curved.pose[2] > 0


def test_reverse_and_turn_in_place():
    r = run_robot(MotorParams(imbalance=0.0), -80, 80, 1.0)
    assert abs(r.v) < 1e-12 and r.w > 0


def test_mocap_noise_is_seeded():
    import numpy as np

    a = EmulatedRobot("r", MotorParams(), (0, 0, 0), np.random.default_rng(5)).measured_pose(1e-3, 1e-2)
    b = EmulatedRobot("r", MotorParams(), (0, 0, 0), np.random.default_rng(5)).measured_pose(1e-3, 1e-2)
    assert a == b and a != (0.0, 0.0, 0.0)


def test_start_poses():
    robots = parse_robot_list([{"name": "a", "ip_octet": 1}, {"name": "b", "ip_octet": 2}])
    assert start_poses(robots, None, 0.15) == {"a": (0.0, 0.0, 0.0), "b": (0.0, 0.15, 0.0)}
    assert start_poses(robots, {"b": [1, 2, 3]}, 0.15)["b"] == (1.0, 2.0, 3.0)
    with pytest.raises(ConfigError, match="not in the robot list: c"):
        start_poses(robots, {"c": [0, 0, 0]}, 0.15)
    with pytest.raises(ConfigError, match="start.a"):
        start_poses(robots, {"a": [0, "x", 0]}, 0.15)
