"""The holder's stop on the anchor's roll (puzzlebot_sim.roll_stop): the law, and in Bullet."""

import math
from dataclasses import replace

import numpy as np
import pybullet as pb
import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_sim.params import AnchorParams, AnchorRestParams, RobotParams
from puzzlebot_sim.roll_stop import RETURN_TIME, relative_roll, stopped_velocity
from puzzlebot_sim.world import RobotStart, SimWorld


def quat(roll=0.0, pitch=0.0, yaw=0.0):
    return pb.getQuaternionFromEuler([roll, pitch, yaw])


@pytest.mark.parametrize("yaw", [0.0, 0.4, -2.5])
def test_relative_roll_is_the_anchor_turned_about_its_own_x_axis_whatever_the_robots_heading(yaw):
    robot = quat(yaw=yaw)
    for roll in (0.0, 0.3, -1.2, 1.55):
        anchor = pb.multiplyTransforms([0, 0, 0], robot, [0, 0, 0], quat(roll=roll, yaw=0.3))[1]   # yawed in the holder
        assert relative_roll(robot, anchor) == pytest.approx(roll, abs=1e-6)


def test_the_stop_acts_only_beyond_the_limit_and_only_against_rolling_further():
    x = np.array([1.0, 0.0, 0.0])
    assert stopped_velocity(0.3, 0.5, [2.0, 0, 0], [0, 0, 0], x) is None          # within the limit
    assert stopped_velocity(0.9, 0.0, [2.0, 0, 0], [0, 0, 0], x) is None          # no stop
    assert stopped_velocity(0.6, 0.5, [-5.0, 0, 0], [0, 0, 0], x) is None         # already returning fast
    w = stopped_velocity(0.6, 0.5, [2.0, 0.1, 0.3], [0.5, 0, 0.3], x)            # rolling further
    assert w[0] - 0.5 == pytest.approx(-0.1 / RETURN_TIME) and w[1:] == pytest.approx([0.1, 0.3])
    w = stopped_velocity(-0.7, 0.5, [-1.0, 0, 0], [0, 0, 0], x)                  # the other way
    assert w[0] == pytest.approx(0.2 / RETURN_TIME)


def test_a_roll_limit_at_or_past_the_side_is_a_clear_error():
    with pytest.raises(ConfigError, match="roll_limit"):
        replace(AnchorParams(), roll_limit=1.6).check()
    with pytest.raises(ConfigError, match="roll_limit"):
        replace(AnchorParams(), roll_limit=-0.1).check()


def _spun_roll(limit):
    """An anchor in its holder given a 40 rad/s roll: its largest roll [rad] over 0.5 s."""
    a = replace(AnchorParams(), roll_limit=limit)
    with SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0)], anchor_params=a,
                  anchor_rest=AnchorRestParams(enabled=False)) as w:
        w.run(0.2)
        robot = w.robots["pz1"]
        lin, _ = pb.getBaseVelocity(robot.anchor, physicsClientId=w.client)
        _, orn = pb.getBasePositionAndOrientation(robot.anchor, physicsClientId=w.client)
        x_axis = pb.getMatrixFromQuaternion(orn)[0::3]
        pb.resetBaseVelocity(robot.anchor, lin, [40.0 * v for v in x_axis], physicsClientId=w.client)
        peak = 0.0
        for _ in range(100):
            w.step(1)
            _, a_orn = pb.getBasePositionAndOrientation(robot.anchor, physicsClientId=w.client)
            peak = max(peak, abs(relative_roll(w.pose("pz1")[1], a_orn)))
        return peak


def test_in_bullet_the_stop_keeps_a_spun_anchor_near_its_limit_and_without_it_the_anchor_rolls_over():
    assert _spun_roll(0.0) > 1.2
    assert _spun_roll(0.5) < 0.5 + 0.15
