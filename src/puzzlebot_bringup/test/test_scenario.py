import glob
import os

import pytest

from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.robots import parse_robot_list, robot_names
from puzzlebot_bringup.scenario import StepResult, format_summary, parse_scenario, scatter_starts

SCENARIOS = sorted(glob.glob(os.path.join(os.path.dirname(__file__), "..", "config", "scenarios", "*.yaml")))


@pytest.mark.parametrize("path", SCENARIOS, ids=os.path.basename)
def test_shipped_scenarios_parse(path):
    data = load_yaml(path)
    names = robot_names(parse_robot_list(data))
    sc = dict(data["scenario"])
    if "scatter" in sc:
        sc["start"] = scatter_starts(sc.pop("scatter"), names, seed=3)
    scenario = parse_scenario(sc, names)
    assert set(scenario.start) == set(names)


SCATTER = {"rows": 2, "spacing": [0.10, 0.11], "lateral": 0.04, "yaw": 0.35, "row_spacing": 0.3}


def test_a_scatter_is_drawn_from_the_seed_within_its_bounds():
    names = ["r%d" % k for k in range(8)]
    a, b, c = (scatter_starts(SCATTER, names, seed) for seed in (1, 1, 2))
    assert a == b and a != c
    for row in (names[:4], names[4:]):
        xs = [a[n][0] for n in row]
        assert all(0.10 - 1e-12 <= x0 - x1 <= 0.11 + 1e-12 for x0, x1 in zip(xs, xs[1:]))
    assert all(abs(a[n][1] - (0.3 if n in names[4:] else 0.0)) <= 0.04 and abs(a[n][2]) <= 0.35 for n in names)


def test_a_scatter_that_keeps_overlapping_is_a_clear_error():
    def never(poses):
        raise ConfigError("robots r0 and r1 are placed inside each other")
    with pytest.raises(ConfigError, match="draws all put robots into each other"):
        scatter_starts(SCATTER, ["r0", "r1"], 0, check=never)
    with pytest.raises(ConfigError, match="spacing"):
        scatter_starts(dict(SCATTER, spacing=[0.2, 0.1]), ["r0", "r1"], 0)
    with pytest.raises(ConfigError, match="unknown key"):
        scatter_starts(dict(SCATTER, spaceing=1), ["r0", "r1"], 0)
    with pytest.raises(ConfigError, match="either 'start' or 'scatter'"):
        parse_scenario({"name": "x", "start": {}, "scatter": SCATTER, "steps": []}, ["r0"])


ROBOTS = ["pz1", "pz2"]


@pytest.mark.parametrize("data, fragment", [
    ({"name": "x", "start": {}, "steps": {}}, "expected a list of steps"),
    ({"name": "x", "start": {}, "steps": [], "wrold": "step"}, "unknown key(s) wrold"),
    ({"name": "x", "start": [], "steps": []}, "start: expected a mapping"),
    ({"name": "x", "start": {}}, "missing 'steps'"),
    ({"name": "x", "start": {}, "steps": [{"behavior": "dance"}]}, "unknown behaviour"),
    ({"name": "x", "start": {}, "steps": [{"behavior": "go_to_goal", "goals": {"pz9": [0, 0]}}]}, "unknown robot"),
    ({"name": "x", "start": {}, "steps": [{"behavior": "go_to_goal", "goals": {"pz1": [0]}}]}, "2 finite"),
    ({"name": "x", "start": {}, "steps": [{"behavior": "follow_velocity", "velocities": {"pz1": [0, 0]}}]},
     "duration"),
    ({"name": "x", "start": {}, "steps": [{"behavior": "stop", "timeout": -2}]}, "timeout"),
    ({"name": "x", "start": {}, "steps": [{"behavior": "stop", "goal": {}}]}, "unknown key"),
])
def test_bad_scenarios_name_the_problem(data, fragment):
    with pytest.raises(ConfigError) as e:
        parse_scenario(data, ROBOTS)
    assert fragment in str(e.value)


def test_a_scenario_without_steps_only_places_robots():
    scenario = parse_scenario({"name": "idle", "start": {"pz1": [0, 0, 0]}, "world": "step", "steps": []}, ROBOTS)
    assert scenario.steps == [] and scenario.world == "step"


def test_summary_reports_outcome_and_errors():
    scenario = parse_scenario({"name": "demo", "start": {}, "steps": [
        {"behavior": "go_to_goal", "goals": {"pz1": [0.1, 0.0]}}, {"behavior": "stop"}]}, ROBOTS)
    text, ok = format_summary(scenario, [StepResult(scenario.steps[0], "succeeded", "done", 5.0, {"pz1": 0.0031})],
                              wall_seconds=2.0, sim_seconds=5.0)
    assert not ok and "pz1 3.1 mm" in text and "1 later step(s) not run" in text and "2.5x" in text


def test_coupling_steps_parse_and_check():
    scenario = parse_scenario({"name": "c", "start": {}, "steps": [
        {"behavior": "couple", "target": "line", "timeout": 60},
        {"behavior": "drive_assembly", "robots": ["pz1"], "velocity": [0.03, 0.0], "distance": 0.3},
        {"behavior": "decouple", "pair": ["pz1", "pz2"]}]}, ROBOTS)
    couple, drive, decouple = scenario.steps
    assert couple.target == "line" and couple.robots == [] and couple.timeout == 60.0
    assert drive.velocities == [(0.03, 0.0)] and drive.distance == 0.3 and "0.300 m" in drive.describe()
    assert decouple.pair == ["pz1", "pz2"] and decouple.describe() == "decouple pz1-pz2"


@pytest.mark.parametrize("step, fragment", [
    ({"behavior": "couple"}, "either 'target' or 'slots'"),
    ({"behavior": "couple", "target": "line", "slots": [[0, 0, 0]]}, "either"),
    ({"behavior": "couple", "slots": [[0, 0]]}, "3 finite"),
    ({"behavior": "decouple", "pair": ["pz1"]}, "two robot names"),
    ({"behavior": "decouple", "pair": ["pz1", "pz7"]}, "unknown robot"),
    ({"behavior": "drive_assembly", "robots": ["pz1"], "velocity": [0.03, 0.0]}, "distance or a timeout"),
    ({"behavior": "drive_assembly", "robots": ["pz1"], "velocity": [0.03], "distance": 1}, "2 finite"),
    ({"behavior": "go_to_goal", "goals": {"pz1": [0, 0]}, "pair": ["pz1", "pz2"]}, "do not apply"),
    ({"behavior": "couple", "target": "bridge2x2"}, "4 slots for the step's 2"),
    ({"behavior": "couple", "target": "no_such_shape"}, "unknown target 'no_such_shape'"),
    ({"behavior": "couple", "slots": [[0, 0, 0], [0.01, 0, 0]], "robots": ["pz1", "pz2"]}, "overlap"),
    ({"behavior": "couple", "slots": [[0, 0, 0], [0.5, 0, 0]], "robots": ["pz1", "pz2"]}, "connected"),
])
def test_bad_coupling_steps_name_the_problem(step, fragment):
    with pytest.raises(ConfigError) as e:
        parse_scenario({"name": "x", "start": {}, "steps": [step]}, ROBOTS)
    assert fragment in str(e.value)


def test_a_target_the_robots_cannot_form_is_an_error_at_load():
    three = ["pz1", "pz2", "pz3"]
    with pytest.raises(ConfigError, match="even number of robots"):
        parse_scenario({"name": "x", "start": {}, "steps": [{"behavior": "couple", "target": "grid"}]}, three)
    with pytest.raises(ConfigError, match="3 slots for the step's 2"):
        parse_scenario({"name": "x", "start": {}, "steps": [
            {"behavior": "couple", "target": "line3", "robots": ["pz1", "pz2"]}]}, three)
    ok = parse_scenario({"name": "x", "start": {}, "steps": [{"behavior": "couple", "target": "line3"}]}, three)
    assert ok.steps[0].target == "line3"


FOUR = ["pz1", "pz2", "pz3", "pz4"]


def test_couple_groups_and_assembly_to_goal_parse():
    scenario = parse_scenario({"name": "g", "start": {}, "steps": [
        {"behavior": "couple", "groups": [["pz1", "pz2"], ["pz3", "pz4"]], "target": "line", "timeout": 60},
        {"behavior": "assembly_to_goal", "goals": {"pz1": [0.3, 0.0], "pz3": [0.3, 0.2]}, "tolerance": 0.02}]},
        FOUR)
    couple, drive = scenario.steps
    assert couple.robots == FOUR and couple.groups == [2, 2] and "2 groups of 2" in couple.describe()
    assert drive.robots == ["pz1", "pz3"] and drive.goals == [(0.3, 0.0), (0.3, 0.2)] and drive.tolerance == 0.02
    assert drive.describe().startswith("assembly_to_goal pz1->(0.300, 0.000)")


@pytest.mark.parametrize("step, fragment", [
    ({"behavior": "couple", "groups": [["pz1", "pz2"]], "robots": ["pz1", "pz2"], "target": "line"},
     "either 'robots' or 'groups'"),
    ({"behavior": "couple", "groups": [["pz1"], ["pz2", "pz3"]], "target": "line"}, "at least two robots"),
    ({"behavior": "couple", "groups": [["pz1", "pz2"], ["pz2", "pz3"]], "target": "line"}, "more than one group"),
    ({"behavior": "couple", "groups": [["pz1", "pz9"]], "target": "line"}, "unknown robot 'pz9'"),
    ({"behavior": "couple", "groups": [], "target": "line"}, "list of robot lists"),
    ({"behavior": "couple", "groups": [["pz1", "pz2"], ["pz3", "pz4"]], "slots": [[0, 0, 0], [-0.05, 0, 0]]},
     "not slots"),
    ({"behavior": "couple", "groups": [["pz1", "pz2", "pz3"]], "target": "grid"}, "even number"),
    ({"behavior": "assembly_to_goal", "goals": {"pz1": [0.3]}}, "2 finite"),
    ({"behavior": "assembly_to_goal", "goals": {"pz1": [0.3, 0]}, "velocity": [0.03, 0]}, "do not apply"),
])
def test_bad_group_and_goal_steps_name_the_problem(step, fragment):
    with pytest.raises(ConfigError) as e:
        parse_scenario({"name": "x", "start": {}, "steps": [step]}, FOUR)
    assert fragment in str(e.value)


def test_cross_edges_parses_on_moving_steps_only():
    drive = {"behavior": "drive_assembly", "robots": ["pz1"], "velocity": [0.03, 0.0], "distance": 0.3}
    steps = parse_scenario({"name": "x", "start": {}, "steps": [dict(drive, cross_edges=True), drive]},
                           ROBOTS).steps
    assert steps[0].cross_edges is True and steps[1].cross_edges is False
    for step, fragment in [(dict(drive, cross_edges="yes"), "cross_edges: expected true or false"),
                           ({"behavior": "couple", "target": "line", "cross_edges": True}, "do not apply")]:
        with pytest.raises(ConfigError) as e:
            parse_scenario({"name": "x", "start": {}, "steps": [step]}, ROBOTS)
        assert fragment in str(e.value)
