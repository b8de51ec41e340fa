"""Launch-time configuration of sim.launch and lab.launch (puzzlebot_bringup/launch_config.py)."""

import os

import pytest
import yaml

from puzzlebot_common.errors import ConfigError
from puzzlebot_bringup.launch_config import known_scenarios, lab_config, sim_config

HERE = os.path.dirname(os.path.abspath(__file__))
SCENARIOS = os.path.join(os.path.dirname(HERE), "config", "scenarios")


def names(config):
    return [r["name"] for r in config.robots]


def test_every_shipped_scenario_configures_the_sim():
    assert {"couple2", "couple4_line", "decouple2", "chain_step", "bridge_gap", "spread", "goto3"} <= set(
        known_scenarios(SCENARIOS))
    for name in known_scenarios(SCENARIOS):
        c = sim_config(SCENARIOS, name)
        assert set(c.scenario["start"]) == set(names(c)) and c.world in ("flat", "step", "gap")


def test_robot_count_takes_the_first_robots_and_their_start_poses():
    c = sim_config(SCENARIOS, "spread", robots="3")
    assert names(c) == ["pz1", "pz2", "pz3"] and sorted(c.scenario["start"]) == ["pz1", "pz2", "pz3"]
    assert len(names(sim_config(SCENARIOS, "spread"))) == 16


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(scenario="nope"), "unknown scenario 'nope'; known scenarios: bridge_gap, chain_step, couple2"),
    (dict(scenario=""), "scenario:= is empty"),
    (dict(scenario="couple2", robots="0"), "robots:=0: the robot count must be at least 1"),
    (dict(scenario="couple2", robots="-2"), "at least 1"),
    (dict(scenario="couple2", robots="two"), "expected a robot count"),
    (dict(scenario="couple2", robots="5"), "robots:=5 but scenario couple2 has 2 robot(s): pz1, pz2"),
    (dict(scenario="couple4_line", robots="1"), "robots:=1 keeps pz1"),     # its decouple step names pz2
    (dict(scenario="couple2", world="moon"), "world:=moon: unknown world 'moon'; known worlds: flat, gap, step"),
    (dict(scenario="couple2", robots="/nonexistent/list.yaml"), "robot list file /nonexistent/list.yaml does not exist"),
    (dict(scenario="couple2", mocap="vikon"), "mocap:=vikon: unknown mocap profile 'vikon'; known profiles: ideal, vicon"),
    (dict(scenario="couple2", mocap=""), "unknown mocap profile ''"),
])
def test_wrong_sim_arguments_name_the_problem(kwargs, fragment):
    with pytest.raises(ConfigError) as e:
        sim_config(SCENARIOS, **kwargs)
    assert fragment in str(e.value)


def test_known_mocap_profiles_pass():
    for profile in ("ideal", "vicon"):
        assert sim_config(SCENARIOS, "couple2", mocap=profile).world == "flat"


def test_world_comes_from_the_scenario_unless_given():
    assert sim_config(SCENARIOS, "chain_step").world == "step"
    assert sim_config(SCENARIOS, "bridge_gap").world == "gap"
    assert sim_config(SCENARIOS, "couple2").world == "flat"
    assert sim_config(SCENARIOS, "couple2", world="step").world == "step"


def test_the_mpc_gets_the_world_the_sim_builds():
    """The world name and dimensions the launch files give the MPC node (its stage edges) are the sim's."""
    from dataclasses import asdict

    from puzzlebot_sim.config import load_sim_config

    c = sim_config(SCENARIOS, "bridge_gap")
    assert c.world == "gap" and c.world_params == asdict(load_sim_config().world)
    lab_list = os.path.join(HERE, "config", "couple2_lab.yaml")
    assert lab_config(SCENARIOS, lab_list).world == "flat"
    assert lab_config(SCENARIOS, lab_list, world="step").world == "step"
    with pytest.raises(ConfigError) as e:
        lab_config(SCENARIOS, lab_list, world="moon")
    assert "world:=moon: unknown world" in str(e.value)


def test_a_robot_list_file_sets_pilots_and_must_fit_the_scenario(tmp_path):
    good = tmp_path / "pilots.yaml"
    good.write_text(yaml.safe_dump({"robots": [{"name": "pz1", "pilot": True}, {"name": "pz2"}]}))
    c = sim_config(SCENARIOS, "couple2", robots=str(good))
    assert c.robots == [{"name": "pz1", "pilot": True}, {"name": "pz2", "pilot": False}]
    bad = tmp_path / "other.yaml"
    bad.write_text(yaml.safe_dump({"robots": [{"name": "pz1"}, {"name": "zz9"}]}))
    with pytest.raises(ConfigError) as e:
        sim_config(SCENARIOS, "couple2", robots=str(bad))
    assert "zz9 not in scenario couple2" in str(e.value)


def test_lab_config_robot_list_wins_and_the_scenario_must_fit(tmp_path):
    lab_list = os.path.join(HERE, "config", "couple2_lab.yaml")
    c = lab_config(SCENARIOS, lab_list, "couple2")
    assert [r["ip_octet"] for r in c.robots] == [31, 32] and sorted(c.scenario["start"]) == ["pz1", "pz2"]
    assert lab_config(SCENARIOS, lab_list).scenario == {}
    no_ip = tmp_path / "no_ip.yaml"
    no_ip.write_text(yaml.safe_dump({"robots": [{"name": "pz1", "ip_octet": 3}, {"name": "pz2"}]}))
    for args, fragment in [(("",), "lab.launch needs a robot list: robots:=FILE"),
                           (("/nonexistent.yaml",), "robot list file /nonexistent.yaml does not exist"),
                           ((str(no_ip),), "pz2 without ip_octet"),
                           ((lab_list, "goto3"), "scenario goto3 uses pz3, not in the robot list"),
                           ((lab_list, "nope"), "unknown scenario 'nope'")]:
        with pytest.raises(ConfigError) as e:
            lab_config(SCENARIOS, *args)
        assert fragment in str(e.value)


def test_a_scattered_scenario_gets_its_start_poses_from_the_seed():
    a, b, c = (sim_config(SCENARIOS, "line8", seed=s).scenario["start"] for s in (5, 5, 6))
    assert a == b and a != c and len(a) == 8
    assert "scatter" not in sim_config(SCENARIOS, "line8", seed=5).scenario
    assert list(sim_config(SCENARIOS, "line8", robots="3", seed=5).scenario["start"]) == ["pz1", "pz2", "pz3"]
