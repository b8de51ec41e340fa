"""Driver and emulator configuration: shipped files, gain resolution, clear errors."""

import os

import pytest

from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.robots import parse_robot_list
from puzzlebot_driver.params import ControlGains, driver_config, emulator_config

CONFIG = os.path.join(os.path.dirname(__file__), "..", "config")
ROBOTS = parse_robot_list([{"name": "p21", "ip_octet": 21}, {"name": "p22", "ip_octet": 22, "pilot": True},
                           {"name": "p23", "ip_octet": 23, "pilot": True}])


def test_shipped_files_parse_with_the_documented_defaults():
    d = driver_config(load_yaml(os.path.join(CONFIG, "driver.yaml")), ROBOTS)
    p = d.params
    assert (p.port, p.loop_rate, p.pose_timeout, p.cmd_timeout) == (8080, 30.0, 0.2, 0.5)
    assert d.gains["p21"].pwm_per_v == pytest.approx(1 / 0.0007, rel=1e-3)
    assert d.gains["p21"] == ControlGains()            # the YAML states the code defaults
    assert d.gains["p22"].pwm_max < d.gains["p21"].pwm_max   # pilots capped lower
    e = emulator_config(load_yaml(os.path.join(CONFIG, "emulator.yaml")), ROBOTS)
    assert e.params.pose_rate == 100.0 and e.motors["p21"].mps_per_pwm == pytest.approx(0.0007)


def test_gains_resolve_control_then_pilot_then_robot():
    cfg = {"control": {"kp_v": 0.7, "pwm_max": 240}, "pilot": {"pwm_max": 150, "ki_v": 0.1},
           "robots": {"p23": {"pwm_max": 120, "trim_left": 3.0}, "p99": {"kp_v": 2.0}}}
    d = driver_config({"driver": cfg}, ROBOTS)
    g21, g22, g23 = d.gains["p21"], d.gains["p22"], d.gains["p23"]
    assert (g21.kp_v, g21.pwm_max, g21.ki_v) == (0.7, 240, ControlGains().ki_v)
    assert (g22.kp_v, g22.pwm_max, g22.ki_v) == (0.7, 150, 0.1)
    assert (g23.pwm_max, g23.trim_left, g23.ki_v) == (120, 3.0, 0.1)
    assert d.unused_overrides == ("p99",)              # tuning for a robot not on stage today: reported


@pytest.mark.parametrize("cfg, text", [
    ({"loop_rat": 30.0}, "unknown key(s) loop_rat"),
    ({"pose_timeout": -1.0}, "driver.pose_timeout: must be > 0"),
    ({"control": {"kp_v": "high"}}, "driver.control.kp_v: expected a finite number"),
    ({"pilot": {"pwm_max": 300}}, "driver.pilot.pwm_max"),
    ({"robots": {"p21": {"trim_left": 260.0}}}, "driver.robots.p21.trim_left"),
    ({"robots": {"p21": {"kp": 1.0}}}, "driver.robots.p21: unknown key(s) kp"),
    ({"control": []}, "driver.control: expected a mapping"),
])
def test_bad_driver_config_names_the_key(cfg, text):
    with pytest.raises(ConfigError) as e:
        driver_config(cfg, ROBOTS)
    assert text in str(e.value)


def test_robot_without_ip_octet_is_a_clear_error():
    with pytest.raises(ConfigError, match="robot pz1 has no ip_octet"):
        driver_config({}, parse_robot_list([{"name": "pz1"}]))
    with pytest.raises(ConfigError, match="robot pz1 has no ip_octet"):
        emulator_config({}, parse_robot_list([{"name": "pz1"}]))


def test_emulator_overrides_and_errors():
    e = emulator_config({"motor": {"gain": 0.9}, "robots": {"p22": {"imbalance": -0.1}}}, ROBOTS)
    assert e.motors["p21"].gain == 0.9 and e.motors["p22"].imbalance == -0.1 and e.motors["p22"].gain == 0.9
    with pytest.raises(ConfigError, match="not in the robot list: p99"):
        emulator_config({"robots": {"p99": {}}}, ROBOTS)
    with pytest.raises(ConfigError, match="pose_rate"):
        emulator_config({"pose_rate": 500.0}, ROBOTS)
    with pytest.raises(ConfigError, match="emulator.motor.imbalance"):
        emulator_config({"motor": {"imbalance": 1.5}}, ROBOTS)
