"""The nodes' shipped configuration agrees on every robot dimension, limit and rate (ROS-free).

Each node reads its own parameters: the sim node sim.yaml, robot.yaml and a
mocap profile (puzzlebot_sim.config, as sim.launch loads them), the MPC
mpc.yaml (lab.launch) or mpc.yaml + mpc_sim.yaml (sim.launch) and the
RobotGeometry defaults (no launch file sets ``~geometry``), the driver
driver.yaml, the emulator emulator.yaml, each for the lab's robot list. A value
has one home (RobotGeometry, puzzlebot_common.hardware) and a YAML file may
override it for one node; this test fails when such an override leaves two
nodes disagreeing, and when a launch file sets one of these values itself.
"""

import glob
import os
import xml.etree.ElementTree as ET

import pytest
import yaml

from puzzlebot_common import hardware
from puzzlebot_common.config import load_yaml, shipped_config
from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_common.robots import parse_robot_list
from puzzlebot_driver.params import driver_config, emulator_config
from puzzlebot_mpc.config_files import load_settings
from puzzlebot_sim.config import load_sim_config, mocap_profiles

HERE = os.path.dirname(os.path.abspath(__file__))
LAUNCH_FILES = sorted(glob.glob(os.path.join(HERE, "..", "launch", "*.launch")))
#: PWM per m/s and per rad/s are written to 0.1 PWM in driver.yaml
PWM_ROUNDING = 0.05
#: parameter names that only the homes above may set: no launch file passes one to a node
SHARED_KEYS = {"wheel_base", "body_side", "knob_radius", "wheel_y", "wheel_radius", "wheel_max_speed",
               "v_limit", "w_limit", "hardware_v_max", "hardware_w_max", "mps_per_pwm", "pwm_per_v", "pwm_per_w",
               "dt", "sync_period", "pose_rate", "physics_rate"}


def lab_robots():
    return parse_robot_list(load_yaml(shipped_config("puzzlebot_bringup", "robots", "lab.yaml")))


def sources(sim_configs, mpc_lab, mpc_sim, geometry, driver, emulator):
    """{quantity: [(source, value), ...]}: every value each node uses for a dimension, a limit or a rate.

    ``sim_configs``: {mocap profile: SimConfig}; ``mpc_lab`` / ``mpc_sim``: MPCSettings as lab.launch /
    sim.launch load them; ``geometry``: the MPC's RobotGeometry; ``driver`` / ``emulator``: DriverConfig /
    EmulatorConfig for the lab's robots.
    """
    out = {"wheel_base [m]": [("MPC geometry", geometry.wheel_base)],
           "body_side [m]": [("MPC geometry", geometry.body_side)],
           "knob_radius [m]": [("MPC geometry", geometry.knob_radius)],
           "top speed [m/s]": [("hardware.V_MAX", hardware.V_MAX), ("mpc.yaml hardware_v_max", mpc_lab.hardware_v_max),
                               ("mpc.yaml + mpc_sim.yaml hardware_v_max", mpc_sim.hardware_v_max),
                               ("driver.yaml v_limit", driver.params.v_limit)],
           "top turn rate [rad/s]": [("hardware.W_MAX", hardware.W_MAX),
                                     ("mpc.yaml hardware_w_max", mpc_lab.hardware_w_max),
                                     ("mpc.yaml + mpc_sim.yaml hardware_w_max", mpc_sim.hardware_w_max),
                                     ("driver.yaml w_limit", driver.params.w_limit)],
           "control period [s]": [("hardware.CONTROL_PERIOD", hardware.CONTROL_PERIOD), ("mpc.yaml dt", mpc_lab.dt),
                                  ("mpc.yaml + mpc_sim.yaml dt", mpc_sim.dt)],
           "mocap rate [Hz]": [("hardware.MOCAP_RATE", hardware.MOCAP_RATE),
                               ("emulator.yaml pose_rate", emulator.params.pose_rate)],
           "m/s per PWM": [("hardware.MPS_PER_PWM", hardware.MPS_PER_PWM)]}
    for mocap, cfg in sorted(sim_configs.items()):
        sim = "sim (mocap %s)" % mocap
        r = cfg.robot
        out["wheel_base [m]"] += [(sim + " wheel_base", r.wheel_base), (sim + " 2 x wheel_y (URDF)", 2 * r.wheel_y)]
        out["body_side [m]"].append((sim + " body_side", r.body_side))
        out["knob_radius [m]"].append((sim + " knob_radius", r.knob_radius))
        out["top speed [m/s]"].append((sim + " wheel_max_speed x wheel_radius", r.v_max))
        out["control period [s]"].append((sim + " sync_period", cfg.sim.sync_period))
        out["mocap rate [Hz]"].append((sim + " pose_rate", cfg.sim.pose_rate))
    for name, motor in sorted(emulator.motors.items()):
        out["wheel_base [m]"].append(("emulator.yaml motor %s wheel_base" % name, motor.wheel_base))
        out["m/s per PWM"].append(("emulator.yaml motor %s mps_per_pwm" % name, motor.mps_per_pwm))
    for name, g in sorted(driver.gains.items()):
        # the feed-forward, written to 0.1 PWM: pwm_per_v = 1 / (m/s per PWM), pwm_per_w = pwm_per_v x wheel_base / 2
        out["m/s per PWM"].append(("driver.yaml %s 1 / pwm_per_v" % name, 1.0 / g.pwm_per_v,
                                   PWM_ROUNDING / g.pwm_per_v ** 2))
        out["wheel_base [m]"].append(("driver.yaml %s 2 pwm_per_w / pwm_per_v" % name, 2.0 * g.pwm_per_w / g.pwm_per_v,
                                      2.0 * PWM_ROUNDING / g.pwm_per_v))
    return out


def disagreements(values):
    """Lines naming every quantity whose sources differ, with each source's value. A source is
    ``(name, value)`` (equal to the first within 1e-12 relative) or ``(name, value, tolerance)``."""
    lines = []
    for quantity, found in values.items():
        ref = found[0][1]
        off = [f for f in found if abs(f[1] - ref) > (f[2] if len(f) > 2 else 1e-12 * abs(ref))]
        if off:
            lines.append("%s: %s" % (quantity, "; ".join("%s = %r" % f[:2] for f in found)))
    return lines


def shipped(robot_path=None, mpc_path=None):
    """The sources of the shipped configuration (``robot_path`` / ``mpc_path``: another robot.yaml / mpc.yaml)."""
    robots = lab_robots()
    return sources({m: load_sim_config(mocap=m, robot_path=robot_path) for m in mocap_profiles()},
                   load_settings(mpc_path), load_settings(mpc_path, sim=True), RobotGeometry(),
                   driver_config(load_yaml(shipped_config("puzzlebot_driver", "driver.yaml")), robots),
                   emulator_config(load_yaml(shipped_config("puzzlebot_driver", "emulator.yaml")), robots))


def test_the_nodes_agree_on_every_dimension_limit_and_rate():
    values = shipped()
    assert len(values["wheel_base [m]"]) >= 8        # the MPC, each mocap profile's sim and URDF, driver, emulator
    bad = disagreements(values)
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("robot_yaml, mpc_key, quantity", [
    ("robot: {wheel_base: 0.045}\n", None, "wheel_base [m]"),
    ("robot: {wheel_y: 0.022}\n", None, "wheel_base [m]"),
    ("robot: {wheel_max_speed: 25.0}\n", None, "top speed [m/s]"),
    (None, "dt: 0.05", "control period [s]"),
    (None, "hardware_w_max: 5.0", "top turn rate [rad/s]"),
])
def test_an_override_in_one_file_is_a_disagreement(tmp_path, robot_yaml, mpc_key, quantity):
    """The test above can fail: one value changed in one node's file (a robot file, mpc.yaml) is reported,
    naming the quantity and the source."""
    robot_path = mpc_path = None
    if robot_yaml:
        robot_path = tmp_path / "robot.yaml"
        robot_path.write_text(robot_yaml)
    if mpc_key:
        mpc_path = tmp_path / "mpc.yaml"
        mpc_path.write_text("mpc:\n  %s\n" % mpc_key)
    bad = disagreements(shipped(str(robot_path) if robot_path else None, str(mpc_path) if mpc_path else None))
    assert [line.split(":")[0] for line in bad] == [quantity], bad


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=os.path.basename)
def test_no_launch_file_sets_a_shared_value(path):
    """A launch file's <param> or inline <rosparam> would be one more home: none sets these keys."""
    root = ET.parse(path).getroot()
    names = {p.get("name", "").split("/")[-1] for p in root.iter("param")}
    for rp in root.iter("rosparam"):
        if rp.text and rp.text.strip():
            names |= set(keys(yaml.safe_load(rp.text)))
    assert not SHARED_KEYS & names, "%s sets %s" % (os.path.basename(path), sorted(SHARED_KEYS & names))


def keys(data):
    """Every mapping key in a parsed YAML value, at any depth."""
    if isinstance(data, dict):
        for k, v in data.items():
            yield str(k)
            yield from keys(v)
    elif isinstance(data, list):
        for v in data:
            yield from keys(v)
