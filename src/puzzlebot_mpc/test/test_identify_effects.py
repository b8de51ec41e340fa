"""The identification tool on synthetic lab data with known effects (issues 7 and 27 acceptance).

Each scenario simulates robots with some true effects (or none) at realistic
mocap noise with dropped samples, writes a CSV or a bag, and runs the tool on
the file alone. Asserted: the tool names exactly the true effects of every
robot, recovers every parameter within 20 %, brings the held-out position
RMSE within 1.5x of what the true model achieves on the same windows, and adds
nothing on clean data. Records are shorter than lab runs (2 robots x 45 s,
40 s for the short logs) to keep the suite quick; the benchmark script
(identify_benchmark.py) runs the same scenarios at lab size (3 x 150 s).
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import identify_synth as synth
from puzzlebot_common.effects import ActuatorModel
from puzzlebot_mpc.identify import core, data

ROBOTS = 2
DURATION = 45.0          # s per robot
PARAM_TOLERANCE = 0.20   # relative
RMSE_FACTOR = 1.5        # x the true model's position RMSE on the same windows

DELAYS = {"pz1": 0.05, "pz2": 0.1, "pz3": 0.2}     # robots that differ: 4x from the fastest to the slowest
LAG = {"tau_v_s": 0.12, "tau_w_s": 0.08}

#: scenario -> dict(effects (all robots), fmt, seed, and optional: robot_effects, robots, duration,
#: record options of identify_synth.lab_record, csv_times (write the t_cmd column), expect (per robot
#: {name: params} the tool must report; default: the true effects))
SCENARIOS = {
    "none": dict(effects={}, fmt="bag", seed=11),
    "none (csv)": dict(effects={}, fmt="csv", seed=25),
    "input_delay": dict(effects={"input_delay": {"delay_s": 0.12}}, fmt="csv", seed=12),
    "deadband": dict(effects={"deadband": {"v_min": 0.02, "w_min": 0.3}}, fmt="bag", seed=17),
    "friction_offset": dict(effects={"friction_offset": {"v_c": 0.012, "w_c": 0.2}}, fmt="bag", seed=30),
    "velocity_scale": dict(effects={"velocity_scale": {"k_v": 0.8, "k_w": 1.25}}, fmt="bag", seed=14),
    "velocity_lag": dict(effects={"velocity_lag": {"tau_v_s": 0.2, "tau_w_s": 0.1}}, fmt="bag", seed=13),
    "accel_limit": dict(effects={"accel_limit": {"a_v": 0.3, "a_w": 5.0}}, fmt="bag", seed=31),
    "gain_drift": dict(effects={"gain_drift": {"rate_per_s": -0.003}}, fmt="bag", seed=32),
    "yaw_rate_bias": dict(effects={"yaw_rate_bias": {"w_per_v": 1.5, "w0": 0.05}}, fmt="bag", seed=15),
    "heading_offset": dict(effects={"heading_offset": {"offset_rad": 0.08}}, fmt="bag", seed=16),
    "delay+lag": dict(effects={"input_delay": {"delay_s": 0.08}, "velocity_lag": {"tau_v_s": 0.15, "tau_w_s": 0.1}},
                      fmt="bag", seed=18),
    "scale+bias": dict(effects={"velocity_scale": {"k_v": 0.85, "k_w": 1.2},
                                "yaw_rate_bias": {"w_per_v": -1.0, "w0": 0.04}}, fmt="bag", seed=19),
    "offset+delay": dict(effects={"heading_offset": {"offset_rad": -0.06}, "input_delay": {"delay_s": 0.1}},
                         fmt="bag", seed=20),
    "deadband+scale": dict(effects={"deadband": {"v_min": 0.015, "w_min": 0.25},
                                    "velocity_scale": {"k_v": 1.2, "k_w": 0.85}}, fmt="csv", seed=21),
    "lag+bias": dict(effects={"velocity_lag": {"tau_v_s": 0.12, "tau_w_s": 0.2},
                              "yaw_rate_bias": {"w_per_v": 2.0, "w0": -0.03}}, fmt="csv", seed=22),
    "drift+offset": dict(effects={"gain_drift": {"rate_per_s": 0.003}, "heading_offset": {"offset_rad": 0.05}},
                         fmt="bag", seed=33),
    "friction+delay": dict(effects={"friction_offset": {"v_c": 0.01, "w_c": 0.15}, "input_delay": {"delay_s": 0.1}},
                           fmt="bag", seed=34),
    "limit+lag": dict(effects={"accel_limit": {"a_v": 0.25, "a_w": 4.0}, "velocity_lag": LAG}, fmt="bag", seed=35),
    "robots differ": dict(effects={}, robot_effects={r: {"input_delay": {"delay_s": d}, "velocity_lag": LAG}
                                                     for r, d in DELAYS.items()}, robots=3, fmt="bag", seed=40),
    "one robot offset": dict(effects={}, robot_effects={"pz1": {"heading_offset": {"offset_rad": 0.08}}},
                             fmt="bag", seed=41),
    "mocap artefacts": dict(effects={}, fmt="bag", seed=42,
                            record=dict(latency=0.008, outliers=6, drop=0.05, bursts_per_min=6)),
    "mocap latency": dict(effects={}, fmt="bag", seed=43, record=dict(latency=0.06),
                          expect={"input_delay": {"delay_s": 0.06}}),
    "short logs": dict(effects={"input_delay": {"delay_s": 0.1}, "yaw_rate_bias": {"w_per_v": 1.5, "w0": 0.0}},
                       fmt="bag", seed=44, duration=40.0),
    "commands on rows (csv)": dict(effects={"input_delay": {"delay_s": 0.1}, "heading_offset": {"offset_rad": 0.05}},
                                   fmt="csv", seed=45, record=dict(commands_on_rows=True)),
    "commands on rows (csv, t_cmd)": dict(effects={"heading_offset": {"offset_rad": 0.05}}, fmt="csv", seed=46,
                                          csv_times=True, record=dict(commands_on_rows=True)),
    "commands between rows (csv, t_cmd)": dict(effects={"heading_offset": {"offset_rad": 0.05}}, fmt="csv",
                                               seed=47, csv_times=True),
}


def write_record(tmp_path, name, sc):
    robots = sc.get("robots", ROBOTS)
    rec = synth.lab_record(sc["effects"], n_robots=robots, duration=sc.get("duration", DURATION), seed=sc["seed"],
                           robot_effects=sc.get("robot_effects"), **sc.get("record", {}))
    path = str(tmp_path / ("%s.%s" % ("".join(ch for ch in name if ch.isalnum()), sc["fmt"])))
    if sc["fmt"] == "bag":
        synth.write_bag(path, rec)
    else:
        synth.write_csv(path, rec, command_times=sc.get("csv_times", False))
    return path, rec


def true_effects(sc, robot):
    if "expect" in sc:
        return sc["expect"]
    return (sc.get("robot_effects") or {}).get(robot, sc["effects"])


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_identifies_the_true_effects(tmp_path, scenario):
    sc = SCENARIOS[scenario]
    path, rec = write_record(tmp_path, scenario, sc)
    result = core.identify(path)        # the tool sees the file only

    trace = [(t["name"], t["reason"]) for rnd in result.selection.rounds for t in rnd.tried]
    for robot in rec:
        truth = true_effects(sc, robot)
        assert sorted(result.robot_effects(robot)) == sorted(truth), (robot, trace, result.selection.removed)
        own = result.model.for_robot(robot)
        for name, params in truth.items():
            for key, true in params.items():
                got = own.param(key)
                assert abs(got - true) <= PARAM_TOLERANCE * abs(true) + (1e-3 if true == 0 else 0), (robot, key, got)
    glitches = [w for w in result.warnings if "glitches" in w]
    assert result.warnings == glitches            # no parameter at a search bound, no robot made worse
    truth_model = ActuatorModel()
    for robot in rec:
        for name, params in true_effects(sc, robot).items():
            truth_model.add_for_robot(robot, name, params)
    true_rmse = result.problem.metric(truth_model)[0].rmse_pos_m
    final = result.selection.final[0]
    assert final.rmse_pos_m <= RMSE_FACTOR * true_rmse, (final, true_rmse)
    if result.effect_names:
        assert final.rmse_pos_m < result.selection.nominal[0].rmse_pos_m
    else:
        assert not result.model.has_effects()
    assert "time dependence:" in result.final_analysis.notes and "saturation:" in result.final_analysis.notes


def test_robots_that_differ_keep_their_own_delay_and_share_the_lag(tmp_path):
    path, _ = write_record(tmp_path, "differ", SCENARIOS["robots differ"])
    result = core.identify(path)
    assert result.selection.shared == ["velocity_lag"], result.selection.sharing
    doc = result.model.to_dict()["model"]
    assert [e["name"] for e in doc["effects"]] == ["velocity_lag"]
    assert sorted(doc["robots"]) == ["pz1", "pz2", "pz3"]
    assert all([e["name"] for e in doc["robots"][r]["effects"]] == ["input_delay"] for r in doc["robots"])


def test_unknown_effect_is_reported_as_structured_residual(tmp_path):
    """Mocap markers 15 mm ahead of the body centre: no candidate explains it, and the
    residual analysis must say so and name what it correlates with."""
    lever = 0.015   # m

    def markers_ahead(t, x, y, th):
        return x + lever * np.cos(th), y + lever * np.sin(th), th

    rec = synth.lab_record({}, n_robots=ROBOTS, duration=DURATION, seed=23, mutate=markers_ahead)
    path = str(tmp_path / "lever.csv")
    synth.write_csv(path, rec)
    result = core.identify(path)
    analysis = result.final_analysis
    assert not analysis.white
    assert "structured" in analysis.notes and "correlates with" in analysis.notes
    strongest = analysis.correlations[0]
    assert strongest["significant"]
    assert "w_cmd" in strongest["regressor"] or "turn rate" in strongest["regressor"]


@pytest.mark.parametrize("effects, seed", [({"gain_drift": {"rate_per_s": -0.004}}, 36)], ids=["drifting gain"])
def test_time_dependence_and_saturation_are_named(tmp_path, effects, seed):
    """What the nominal model lacks is named in its residual notes (a drifting gain as time dependence);
    the identified model, which holds it, leaves neither. (The saturation test is weaker: an
    acceleration limit of 0.25 m/s^2 in 2 x 45 s gives p = 0.23 (along) for the nominal model, not
    significant, docs/model-identification.md; it is identified all the same, scenario "accel_limit".)"""
    rec = synth.lab_record(effects, n_robots=ROBOTS, duration=DURATION, seed=seed)
    path = str(tmp_path / "diag.bag")
    synth.write_bag(path, rec)
    result = core.identify(path)
    nominal, final = result.nominal_analysis, result.final_analysis
    assert result.effect_names == list(effects)
    if "gain_drift" in effects:
        td = nominal.time_dependence["v"]
        assert td["p"] < 0.01 and td["late"] < td["early"], nominal.time_dependence
        assert "changes over the record" in nominal.notes
    else:
        assert nominal.saturation["along"]["p"] < 0.01, nominal.saturation
        assert "cannot follow large command changes" in nominal.notes
    assert "time dependence: none" in final.notes and "saturation: none" in final.notes, final.notes


def test_too_little_data_adds_nothing(tmp_path):
    """8 s of one robot (a few commands): a strong delay explains most of the cost, but 5 s of windows
    cannot show it, so nothing is added, with a warning."""
    rec = synth.lab_record({"input_delay": {"delay_s": 0.1}}, n_robots=1, duration=8.0, seed=27)
    path = str(tmp_path / "short.csv")
    synth.write_csv(path, rec)
    result = core.identify(path)
    assert result.effect_names == []
    assert not result.selection.rounds[0].tried[0]["accepted"]
    assert any("too little to show" in w for w in result.warnings)


def test_mocap_glitches_are_dropped(tmp_path):
    """Marker swaps (a pose 5 cm off for one sample, the yaw flipped for two) are dropped with a
    warning; the clean record then still comes out without effects."""
    rec = synth.lab_record({}, n_robots=ROBOTS, duration=DURATION, seed=26)
    r = rec["pz1"]
    for k in range(500, r["t"].size - 500, 900):
        r["x"][k] += 0.05
        r["yaw"][k + 300:k + 302] = np.arctan2(np.sin(r["yaw"][k + 300:k + 302] + np.pi),
                                               np.cos(r["yaw"][k + 300:k + 302] + np.pi))
    path = str(tmp_path / "glitches.bag")
    synth.write_bag(path, rec)
    result = core.identify(path)
    assert result.effect_names == []
    assert len(result.warnings) == 1 and "robot pz1" in result.warnings[0] and "glitches" in result.warnings[0]
    n_glitches = 3 * len(range(500, r["t"].size - 500, 900))
    assert "%d pose sample(s)" % n_glitches in result.warnings[0]


def test_command_line_end_to_end(tmp_path):
    """rosrun entry point on a bag: report.json, model.yaml (with per-robot sections), plot, table."""
    sc = dict(SCENARIOS["robots differ"], robots=2, seed=48)
    path, _ = write_record(tmp_path, "cli", sc)
    node = os.path.join(os.path.dirname(__file__), "..", "nodes", "identify_model")
    out, model, plot = tmp_path / "report.json", tmp_path / "model.yaml", tmp_path / "residuals.png"
    proc = subprocess.run([sys.executable, node, path, "--out", str(out), "--model-out", str(model),
                           "--plot", str(plot)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "pos RMSE [mm]" in proc.stdout and "nominal unicycle" in proc.stdout
    assert "round 1" in proc.stderr            # progress lines go to stderr
    rep = json.loads(out.read_text())
    for key in ("data", "robots", "cv_folds", "horizon_s", "before", "effects", "after", "residual", "sharing"):
        assert key in rep
    assert rep["robots"] == ["pz1", "pz2"] and rep["cv_folds"] == 3 and rep["horizon_s"] == 1.0
    assert sorted(e["name"] for e in rep["effects"]) == ["input_delay", "velocity_lag"]
    for e in rep["effects"]:
        assert set(e["after"]) == {"rmse_pos_m", "rmse_yaw_rad"}
    assert rep["after"]["rmse_pos_m"] < rep["before"]["rmse_pos_m"]
    assert isinstance(rep["residual"]["white"], bool) and rep["residual"]["notes"]
    loaded = ActuatorModel.load(str(model))
    assert loaded.to_dict()["model"] == rep["model"]
    for robot, delay in (("pz1", 0.05), ("pz2", 0.1)):
        assert loaded.for_robot(robot).param("delay_s") == pytest.approx(delay, rel=PARAM_TOLERANCE)
        assert rep["per_robot"][robot]["params"]["delay_s"] == loaded.for_robot(robot).param("delay_s")
    assert plot.stat().st_size > 10000


@pytest.mark.parametrize("on_rows", [False, True], ids=["between rows", "on rows"])
def test_csv_reader_agrees_with_the_bag_of_the_same_run(tmp_path, on_rows):
    """The CSV with t_cmd gives the bag's command times exactly; without it the documented convention
    (midway between the rows) is within half a pose period of them, early by half a period on average
    when the commands were logged on the pose rows. Both identify the same delay."""
    rec = synth.lab_record({"input_delay": {"delay_s": 0.1}}, n_robots=ROBOTS, duration=DURATION, seed=24,
                           commands_on_rows=on_rows, drop=0.0, bursts_per_min=0)
    bag, timed, plain = str(tmp_path / "run.bag"), str(tmp_path / "timed.csv"), str(tmp_path / "plain.csv")
    synth.write_bag(bag, rec)
    synth.write_csv(timed, rec, t0=1.7e9, command_times=True)
    synth.write_csv(plain, rec, t0=1.7e9)
    b, t, p = data.load(bag), data.load(timed), data.load(plain)
    for rb, rt, rp in zip(b.robots, t.robots, p.robots):
        changed = np.concatenate([[True], (np.diff(rb.cmd_v) != 0) | (np.diff(rb.cmd_w) != 0)])
        np.testing.assert_allclose(rt.cmd_t + t.t0, rb.cmd_t + b.t0, atol=1e-6)
        np.testing.assert_allclose(rt.x, rb.x, atol=1e-6)
        offset = (rp.cmd_t + p.t0) - (rb.cmd_t[changed] + b.t0)[:rp.cmd_t.size]
        assert np.all(np.abs(offset[1:]) <= 0.0051)     # half a pose period
        assert np.median(offset[1:]) == pytest.approx(-0.005 if on_rows else 0.0, abs=0.002)
    delays = [core.identify(f).model.param("delay_s") for f in (bag, timed, plain)]
    assert delays[0] == pytest.approx(0.1, rel=0.05) and delays[1] == pytest.approx(delays[0], abs=1e-6)
    assert delays[2] == pytest.approx(delays[0], abs=0.008)
