import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_sim.params import AnchorParams, RobotParams
from puzzlebot_experiments.sensitivity import load_variants, run_job, table
from puzzlebot_sim.config import load_model, robot_file


def write(tmp_path, text):
    path = tmp_path / "variants.yaml"
    path.write_text(text)
    return str(path)


def test_variants_override_the_given_parameters_and_keep_the_rest(tmp_path):
    path = write(tmp_path, "variants:\n  default: {}\n  clr5: {robot: {ground_clearance: 0.005}}\n"
                           "  soft: {anchor: {neck_max_torque: 0.003}, robot: {body_friction: 0.2}}\n")
    base = RobotParams(pilot_wheel_x=0.015)
    models = load_variants(path, robot=base)
    assert [m[0] for m in models] == ["default", "clr5", "soft"]
    assert models[0][1] == base and models[0][2] == AnchorParams()
    assert models[1][1].ground_clearance == 0.005 and models[1][1].pilot_wheel_x == 0.015
    assert models[2][1].body_friction == 0.2 and models[2][2].neck_max_torque == 0.003


@pytest.mark.parametrize("text, message", [
    ("other: 1\n", "expected a non-empty mapping 'variants"),
    ("variants: {}\n", "expected a non-empty mapping 'variants"),
    ("variants:\n  a: {robots: {}}\n", "variants.a: expected a mapping with the keys robot and/or anchor"),
    ("variants:\n  a: {robot: {clearance: 0.005}}\n", r"variants.a.robot: unknown key\(s\) clearance"),
    ("variants:\n  a: {robot: {ground_clearance: fast}}\n", "variants.a.robot.ground_clearance: expected a finite"),
    ("variants:\n  a: {robot: {bottom_chamfer: 0.02}}\n", "variants.a.robot.bottom_chamfer: 20.0 mm would cut"),
    ("variants:\n  a: {robot: [1, 2]}\n", "variants.a.robot: expected a mapping of field: value"),
])
def test_bad_variants_files_are_clear_errors(tmp_path, text, message):
    with pytest.raises(ConfigError, match=message):
        load_variants(write(tmp_path, text))


def test_missing_variants_file_is_a_clear_error(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_variants(str(tmp_path / "none.yaml"))


def test_a_robot_file_sets_the_model_and_overrides_go_on_top(tmp_path):
    path = write(tmp_path, "robot: {ground_clearance: 0.005, body_friction: 0.2}\nanchor: {keel_height: 0.0075}\n")
    robot, anchor = load_model(path, robot={"body_friction": 0.4})
    assert robot.ground_clearance == 0.005 and robot.body_friction == 0.4 and anchor.keel_height == 0.0075
    assert robot.wheel_radius == RobotParams().wheel_radius                  # left out: the default
    # the package's file is the model the sim node and the experiments load; today it is the defaults
    assert load_model() == (RobotParams(), AnchorParams()) and robot_file().endswith("robot.yaml")
    for text, message in (("robot: {clearance: 1}\n", r"robot: unknown key\(s\) clearance"),
                          ("robots: {}\n", "expected a mapping with the keys robot and/or anchor"),
                          ("anchor: {base_radius: 0.02}\n", "base_radius")):
        with pytest.raises(ConfigError, match=message):
            load_model(write(tmp_path, text))
    with pytest.raises(ConfigError, match=r"--anchor: unknown key\(s\) nope"):
        load_model(path, anchor={"nope": 1})
    with pytest.raises(ConfigError, match="no such file"):
        load_model(str(tmp_path / "none.yaml"))


def test_the_package_variants_file_loads():
    import os
    here = os.path.dirname(os.path.abspath(__file__))
    models = load_variants(os.path.join(here, "..", "config", "variants.yaml"))
    assert models[0][0] == "default" and models[0][1] == RobotParams() and len(models) >= 2


def test_table_counts_successes_separations_and_other_failures():
    ok = {"success": True, "time_s": 4.0, "pairs_ever_decoupled": 0}
    apart = {"success": False, "time_s": None, "pairs_ever_decoupled": 1}
    stall = {"success": False, "time_s": None, "pairs_ever_decoupled": 0}
    text = table([("default", [ok, dict(ok, time_s=6.0), apart]), ("clr5", [stall, apart])])
    rows = [line.split() for line in text.splitlines()]
    assert rows[1] == ["default", "2/3", "1", "0", "5.00"]
    assert rows[2] == ["clr5", "0/2", "1", "1", "-"]
    assert rows[3] == ["all", "2/5"]


def test_run_job_passes_the_seed_and_keeps_the_variant_name():
    assert run_job(("clr5", lambda seed: {"seed": seed}, 7)) == ("clr5", {"seed": 7})
