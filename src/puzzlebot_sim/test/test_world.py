import math
import xml.etree.ElementTree as ET

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import wrap_angle
from puzzlebot_sim.params import RobotParams, SimParams
from puzzlebot_sim.scenario_starts import starts_from_config
from puzzlebot_sim.urdf import robot_urdf
from puzzlebot_sim.world import RobotStart, SimWorld
from puzzlebot_common.robots import parse_robot_list


def test_urdf_is_well_formed_with_wheels_and_casters():
    root = ET.fromstring(robot_urdf(RobotParams(), name="pz1"))
    links = {l.get("name") for l in root.findall("link")}
    assert {"base_link", "left_wheel", "right_wheel", "front_caster", "rear_caster"} <= links
    joints = {j.get("name"): j.get("type") for j in root.findall("joint")}
    assert joints["left_wheel_joint"] == "continuous"


def drive(world, seconds):
    for _ in range(int(round(seconds / world.dt))):
        world.step()


def test_robot_drives_straight_and_turns():
    with SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0), RobotStart("pz2", 0, 0.2, math.pi / 2)]) as w:
        drive(w, 0.5)
        w.set_command("pz1", 0.05, 0.0)
        w.set_command("pz2", 0.03, 1.0)
        drive(w, 2.0)
        x, y, yaw = w.pose2d("pz1")
        assert 0.08 < x < 0.12 and abs(y) < 0.003 and abs(yaw) < 0.02
        assert wrap_angle(w.pose2d("pz2")[2] - math.pi / 2) > 1.0  # turned left by more than 1 rad
        assert w.time == pytest.approx(2.5)


def test_deterministic_for_same_commands():
    def run():
        with SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0.3)]) as w:
            w.set_command("pz1", 0.04, 0.7)
            drive(w, 1.0)
            return w.pose2d("pz1")
    assert run() == run()


def test_bad_setup_gives_clear_errors():
    with pytest.raises(ConfigError, match="unknown world 'moon'"):
        SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0)], world="moon")
    with pytest.raises(ConfigError, match="inside each other"):
        SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0), RobotStart("pz2", 0.03, 0.01, 0.5)])
    with pytest.raises(ConfigError, match="robot.wheel_radius"):
        RobotParams.from_dict({"wheel_radius": 0})
    with pytest.raises(ConfigError, match="integer multiple"):
        SimParams.from_dict({"physics_rate": 250, "pose_rate": 100})
    robots = parse_robot_list(["pz1", "pz2"])
    with pytest.raises(ConfigError, match="no start pose for robot pz2"):
        starts_from_config(robots, {"pz1": [0, 0, 0]})
    with pytest.raises(ConfigError, match="not in the robot list"):
        starts_from_config(robots, {"pz1": [0, 0, 0], "pz2": [1, 0, 0], "pz7": [2, 0, 0]})
    with pytest.raises(ConfigError, match="three finite numbers"):
        starts_from_config(robots, {"pz1": [0, 0, 0], "pz2": [1, "a", 0]})
