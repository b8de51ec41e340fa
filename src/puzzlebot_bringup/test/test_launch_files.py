"""lab.launch and the lab robot list, checked without a roscore."""

import os

import pytest

from puzzlebot_common.config import load_yaml
from puzzlebot_common.robots import parse_robot_list
from puzzlebot_driver.params import driver_config, emulator_config

HERE = os.path.dirname(os.path.abspath(__file__))
PKG = os.path.dirname(HERE)
LAUNCH = os.path.join(PKG, "launch", "lab.launch")


def load_launch(**args):
    roslaunch = pytest.importorskip("roslaunch")
    import roslaunch.config
    import roslaunch.xmlloader

    config = roslaunch.config.ROSLaunchConfig()
    argv = ["%s:=%s" % kv for kv in args.items()]
    roslaunch.xmlloader.XmlLoader().load(LAUNCH, config, argv=argv, verbose=False)
    return config


def test_every_arg_is_documented():
    import xml.etree.ElementTree as ET

    args = ET.parse(LAUNCH).getroot().findall("arg")
    assert {a.get("name") for a in args} >= {"robots", "emulate", "port", "record", "scenario"}
    for a in args:
        assert a.get("doc"), "arg %s has no doc" % a.get("name")


def test_emulate_adds_the_emulator_and_the_port_reaches_both_nodes():
    lab = load_launch(port="9123")
    emu = load_launch(emulate="true", port="9123")
    names = lambda c: sorted(n.name for n in c.nodes)
    assert names(lab) == ["driver", "mpc"]
    assert names(emu) == ["driver", "emulator", "mpc"]
    assert emu.params["/driver/driver/port"].value == 9123
    assert emu.params["/emulator/emulator/port"].value == 9123
    assert emu.params["/use_sim_time"].value is False
    robots = parse_robot_list(emu.params["/puzzlebot/robots"].value)
    assert all(r.ip_octet is not None for r in robots)
    assert sorted(n.name for n in load_launch(record="true").nodes) == ["driver", "mpc", "record"]
    assert sorted(n.name for n in load_launch(mpc="false").nodes) == ["driver"]


def test_scenario_and_robot_list_combine():
    c = load_launch(emulate="true", scenario="goto3", robots=os.path.join(HERE, "config", "pz3_lab.yaml"))
    robots = parse_robot_list(c.params["/puzzlebot/robots"].value)
    assert [r.ip_octet for r in robots] == [41, 42, 43]      # the robot list wins over the scenario's
    assert any(k.startswith("/puzzlebot/scenario/start/") for k in c.params)
    assert "scenario_runner" in [n.name for n in c.nodes]


def test_missing_robot_list_file_fails_at_launch_time():
    roslaunch = pytest.importorskip("roslaunch")
    with pytest.raises(roslaunch.RLException) as e:
        load_launch(robots="/nonexistent/robots.yaml")
    assert "/nonexistent/robots.yaml" in str(e.value)


def test_lab_robot_list_and_configs_parse():
    robots = parse_robot_list(load_yaml(os.path.join(PKG, "config", "robots", "lab.yaml")))
    for r in robots:
        assert r.name == "p%d" % r.ip_octet and r.mocap_subject == r.name
    driver = load_yaml(os.path.join(os.path.dirname(PKG), "puzzlebot_driver", "config", "driver.yaml"))
    emulator = load_yaml(os.path.join(os.path.dirname(PKG), "puzzlebot_driver", "config", "emulator.yaml"))
    cfg = driver_config(driver, robots)
    assert set(cfg.gains) == {r.name for r in robots}
    emulator_config(emulator, robots)
