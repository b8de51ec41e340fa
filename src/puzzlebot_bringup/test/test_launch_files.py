"""sim.launch, lab.launch and record.launch as roslaunch reads them (no roscore; the
launch-time configuration command runs, so the workspace must be built)."""

import os
import subprocess
import xml.etree.ElementTree as ET

import pytest

from puzzlebot_common.config import load_yaml
from puzzlebot_common.robots import parse_robot_list
from puzzlebot_driver.params import driver_config, emulator_config
from puzzlebot_sim.params import SimParams

HERE = os.path.dirname(os.path.abspath(__file__))
PKG = os.path.dirname(HERE)
LAUNCH = {name: os.path.join(PKG, "launch", name + ".launch") for name in ("sim", "lab", "record", "replay")}


def load_launch(name, **args):
    roslaunch = pytest.importorskip("roslaunch")
    import roslaunch.config
    import roslaunch.xmlloader

    config = roslaunch.config.ROSLaunchConfig()
    argv = ["%s:=%s" % kv for kv in args.items()]
    roslaunch.xmlloader.XmlLoader().load(LAUNCH[name], config, argv=argv, verbose=False)
    return config


def node_names(config):
    return sorted(n.name for n in config.nodes)


@pytest.mark.parametrize("name", sorted(LAUNCH))
def test_every_arg_is_documented(name):
    for a in ET.parse(LAUNCH[name]).getroot().findall("arg"):
        if a.get("name").startswith("_"):          # internal values, not arguments
            assert a.get("value") is not None
            continue
        assert a.get("doc"), "%s.launch: arg %s has no doc" % (name, a.get("name"))


def sim_params(config):
    """The SimParams the sim node builds from its ~sim parameters (the defaults for keys not set)."""
    prefix = "/sim/sim/"
    return SimParams.from_dict({k[len(prefix):]: p.value for k, p in config.params.items() if k.startswith(prefix)})


def test_sim_launch_defaults_and_options():
    c = load_launch("sim")
    assert node_names(c) == ["diagnostic_aggregator", "mpc", "robot_state_publisher", "scenario_runner", "sim"]
    assert c.params["/diagnostic_aggregator/analyzers/sim/startswith"].value == ["puzzlebot_sim"]
    assert "/diagnostic_aggregator/analyzers/driver/path" not in c.params
    assert [r.name for r in parse_robot_list(c.params["/puzzlebot/robots"].value)] == ["pz1", "pz2", "pz3", "pz4"]
    assert c.params["/sim/sim/world"].value == "flat" and c.params["/use_sim_time"].value is True
    assert c.params["/sim/sim/mocap_position_std"].value == 0.0003 and c.params["/sim/sim/seed"].value == 0
    c = load_launch("sim", mocap="ideal", seed="7")
    assert sim_params(c).mocap_position_std == 0.0 and c.params["/sim/sim/seed"].value == 7
    c = load_launch("sim", scenario="chain_step", robots="2", rviz="true", record="true", bag="/tmp/x.bag",
                    diagnostics="false")
    assert node_names(c) == ["markers", "mpc", "record", "robot_state_publisher", "rviz", "scenario_runner", "sim"]
    description = ET.fromstring(c.params["/robot_description"].value)       # the robots' model, the pilot's
    links = {link.get("name") for link in description.findall("link")}
    assert {"pz1/front_left_wheel", "pz2/left_wheel", "pz1/anchor", "pz2/anchor_head"} <= links
    joints = {j.get("name"): j.get("type") for j in description.findall("joint")}
    assert joints["pz1/base_joint"] == joints["pz1/anchor_joint"] == "floating"    # both poses from the sim's tf
    robots = parse_robot_list(c.params["/puzzlebot/robots"].value)
    assert [(r.name, r.pilot) for r in robots] == [("pz1", True), ("pz2", False)]
    assert sorted(c.params["/puzzlebot/scenario"].value["start"]) == ["pz1", "pz2"]
    assert c.params["/sim/sim/world"].value == "step"             # the scenario's world
    record = [n for n in c.nodes if n.name == "record"][0]
    assert record.args.startswith("-O /tmp/x.bag -e ")


@pytest.mark.parametrize("launch, args, message", [
    ("sim", ["robots:=0"], "sim.launch: robots:=0: the robot count must be at least 1"),
    ("sim", ["scenario:=nope"], "sim.launch: unknown scenario 'nope'; known scenarios: "),
    ("sim", ["world:=moon"], "sim.launch: world:=moon: unknown world 'moon'; known worlds: flat, gap, step"),
    ("sim", ["mocap:=vikon"], "sim.launch: mocap:=vikon: unknown mocap profile 'vikon'; known profiles: ideal, vicon"),
    ("lab", ["robots:=/nonexistent/robots.yaml"], "lab.launch: robot list file /nonexistent/robots.yaml does not exist"),
])
def test_wrong_arguments_stop_roslaunch_with_one_clear_line(launch, args, message):
    """What a user sees: the first line of roslaunch's output names the problem, no node starts."""
    env = dict(os.environ, ROS_MASTER_URI="http://localhost:1")    # nothing may contact a master
    proc = subprocess.run(["roslaunch", "puzzlebot_bringup", launch + ".launch"] + args, capture_output=True,
                          text=True, timeout=120, env=env)
    assert proc.returncode != 0
    lines = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.startswith(launch + ".launch:")]
    assert lines and lines[0].startswith(message), proc.stderr + proc.stdout
    assert "started roslaunch server" not in proc.stdout


def test_lab_launch_emulate_port_and_record():
    lab = load_launch("lab", port="9123")
    emu = load_launch("lab", emulate="true", port="0", record="true")
    assert node_names(lab) == ["diagnostic_aggregator", "driver", "mpc", "robot_state_publisher"]
    assert node_names(emu) == ["diagnostic_aggregator", "driver", "emulator", "mpc", "record", "robot_state_publisher"]
    joints = {j.get("name"): j.get("type") for j in ET.fromstring(lab.params["/robot_description"].value).iter("joint")}
    assert joints["p21/anchor_joint"] == "fixed"           # nothing measures a lab anchor: drawn at rest
    groups = {k.split("/")[3] for k in lab.params if k.startswith("/diagnostic_aggregator/analyzers/")}
    assert groups == {"mpc", "driver"}                     # no simulation group in the lab (it would be stale)
    assert lab.params["/driver/driver/port"].value == 9123
    assert emu.params["/emulator/emulator/port"].value == 0 and emu.params["/driver/bound_port"].value == 0
    assert emu.params["/use_sim_time"].value is False
    robots = parse_robot_list(emu.params["/puzzlebot/robots"].value)
    assert all(r.ip_octet is not None for r in robots)
    assert "/puzzlebot/scenario" not in emu.params
    assert node_names(load_launch("lab", mpc="false", diagnostics="false")) == ["driver", "robot_state_publisher"]


def test_lab_launch_scenario_and_robot_list_combine():
    c = load_launch("lab", emulate="true", scenario="goto3", robots=os.path.join(HERE, "config", "pz3_lab.yaml"))
    robots = parse_robot_list(c.params["/puzzlebot/robots"].value)
    assert [r.ip_octet for r in robots] == [41, 42, 43]      # the robot list wins over the scenario's
    assert sorted(c.params["/puzzlebot/scenario"].value["start"]) == ["pz1", "pz2", "pz3"]
    assert "scenario_runner" in node_names(c)
    c = load_launch("lab", emulate="true", scenario="goto3", run_scenario="false",
                    robots=os.path.join(HERE, "config", "pz3_lab.yaml"))
    assert "scenario_runner" not in node_names(c)


def test_replay_launch_plays_with_the_runs_robots():
    c = load_launch("replay", bag="/tmp/run.bag", scenario="couple2")
    assert node_names(c) == ["markers", "play", "robot_state_publisher", "rviz"]
    assert [r.name for r in parse_robot_list(c.params["/puzzlebot/robots"].value)] == ["pz1", "pz2"]
    assert [n for n in c.nodes if n.name == "play"][0].args == "--clock -r 1.0 /tmp/run.bag"
    lab = load_launch("replay", bag="/tmp/run.bag", rviz="false", robots=os.path.join(HERE, "config", "pz3_lab.yaml"))
    assert node_names(lab) == ["markers", "play", "robot_state_publisher"]
    assert [r.ip_octet for r in parse_robot_list(lab.params["/puzzlebot/robots"].value)] == [41, 42, 43]
    assert lab.params["/markers/world"].value == "flat"


def test_the_markers_node_draws_the_world_the_mpc_keeps_the_robots_on():
    runs = (("sim", {"scenario": "bridge_gap", "markers": "true"}),
            ("replay", {"bag": "/tmp/run.bag", "scenario": "bridge_gap"}))
    for launch, args in runs:
        c = load_launch(launch, **args)
        assert c.params["/markers/world"].value == "gap", launch
        assert c.params["/markers/world_params"].value["gap_width"] == pytest.approx(0.04), launch
        if launch == "sim":
            assert c.params["/mpc/world"].value == "gap"
            assert c.params["/mpc/world_params"].value == c.params["/markers/world_params"].value


def test_lab_robot_list_and_configs_parse():
    robots = parse_robot_list(load_yaml(os.path.join(PKG, "config", "robots", "lab.yaml")))
    for r in robots:
        assert r.name == "p%d" % r.ip_octet and r.mocap_subject == r.name
    driver = load_yaml(os.path.join(os.path.dirname(PKG), "puzzlebot_driver", "config", "driver.yaml"))
    emulator = load_yaml(os.path.join(os.path.dirname(PKG), "puzzlebot_driver", "config", "emulator.yaml"))
    cfg = driver_config(driver, robots)
    assert set(cfg.gains) == {r.name for r in robots}
    emulator_config(emulator, robots)
