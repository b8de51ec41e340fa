"""The loop closed (puzzlebot_experiments/loop_demo.py), reduced: record, identify, rerun, in Bullet."""

import os

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_experiments import loop_demo as ld

pytest.importorskip("pybullet")
pytest.importorskip("rosbag")


def test_reduced_demo_identified_model_tracks_better_on_the_same_seed(tmp_path):
    # The shipped recording (3 robots x 16 goals x 8 s: with half of it, the last 30 % held for
    # validation is too short to accept more than the delay), then 3 robots x 2 goals x 8 s per
    # controller on seed 1 and one coupling trial each.
    cfg = ld.load_config(overrides={"legs": 2, "couple_trials": 1, "couple_timeout": 20.0})
    out = ld.run(cfg, [1], 0, str(tmp_path), say=lambda msg: None)
    from puzzlebot_common.effects import ActuatorModel

    ident = ActuatorModel.from_dict(out["identified_model"])
    for robot in ("pz1", "pz2", "pz3"):     # the robots differ: each its own delay (0.075, 0.15, 0.3 s)
        mine = ident.for_robot(robot)
        assert mine.param("delay_s") == pytest.approx(cfg.true_model.for_robot(robot).param("delay_s"), rel=0.2), \
            (robot, out["identified_model"])
        assert mine.param("offset_rad") == pytest.approx(0.05, rel=0.2), (robot, out["identified_model"])
    assert set(out["per_robot"]["identified"]) == {"pz1", "pz2", "pz3"}
    plain, after = out["summary"]["plain"], out["summary"]["identified"]
    assert after["steady_mean_mm"] < 0.6 * plain["steady_mean_mm"], (plain, after)
    assert after["steady_max_mm"] <= 1e3 * cfg.demo.reach_tolerance < plain["steady_max_mm"], (plain, after)
    assert after["held"] == after["legs"]
    assert out["coupling"]["identified"]["seated"] == 1
    assert after["failed_steps"] == 0
    for name in ("loop_demo_record.bag", "model.yaml", "identify_report.json", "loop_demo.png", "loop_demo.json"):
        assert os.path.getsize(str(tmp_path / name)) > 0


def test_true_model_expresses_the_sim_effects_in_model_terms():
    cfg = ld.load_config()
    m = cfg.true_model
    assert m.param("delay_s") == cfg.injected.param("delay_s")
    assert m.param("w_per_v") == pytest.approx(2 * cfg.demo.wheel_imbalance / 0.04)
    assert m.param("offset_rad") == cfg.demo.mocap_heading_offset


def test_tracking_metrics_of_a_known_path():
    demo = ld.DemoSettings(leg_s=4.0, settle_s=1.0, reach_tolerance=0.005)
    # straight from (0, 0) towards (0.1, 0) at 4 cm/s, 19.6 mm past the goal at 2.99 s, then at the goal
    truth = [(0.01 * k, min(0.04 * 0.01 * k, 0.12), 0.0, 0.0) for k in range(300)]
    truth += [(0.01 * k, 0.1, 0.0, 0.0) for k in range(300, 400)]
    m = ld.leg_metrics(truth, 0.0, (0.1, 0.0), demo)
    assert m["reached"] and m["t_reach_s"] == pytest.approx(2.38, abs=0.011)
    assert m["overshoot_mm"] == pytest.approx(19.6)
    assert m["steady_mm"] == pytest.approx(0.0)
    assert m["cross_rms_mm"] == pytest.approx(0.0)
    assert m["outside_after_reach"] == pytest.approx(37 / 162)     # x > 0.105 m from 2.63 s to 2.99 s


def test_bad_config_and_arguments(tmp_path, capsys):
    bad = tmp_path / "demo.yaml"
    bad.write_text("demo: {robots: 0}\ninjected: {effects: []}\n")
    with pytest.raises(ConfigError, match="robots"):
        ld.load_config(str(bad))
    bad.write_text("demo: {}\ninjected: {effects: [{name: input_delay, params: {delay: 0.1}}]}\n")
    with pytest.raises(ConfigError, match=r"injected\.effects\[0\]: effect input_delay needs exactly"):
        ld.load_config(str(bad))
    assert ld.main(["--seeds", "1-x"]) == 2
    assert ld.main(["--config", str(tmp_path / "missing.yaml")]) == 2
    err = capsys.readouterr().err
    assert "no such file" in err and "Traceback" not in err
