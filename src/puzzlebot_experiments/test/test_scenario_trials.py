"""scenario_trials: the in-process scenario runs (Bullet + MPC core), checked in Bullet."""

import os

import pytest

from puzzlebot_common.config import shipped_config
from puzzlebot_common.errors import ConfigError
from puzzlebot_experiments.scenario_trials import (PairTrace, format_pose_ranges, format_table, held_pose_ranges,
                                                   parse_pair, plot_trials, pull_summary, request_of, run_trial,
                                                   scenario_steps, summarize)

SCENARIOS = shipped_config("puzzlebot_bringup", "scenarios")


def test_steps_become_the_requests_sim_launch_sends():
    couple, drive, decouple = scenario_steps(SCENARIOS, "couple4_line")
    assert request_of(couple).behavior == "couple" and request_of(couple).target == "line"
    req = request_of(drive)
    assert req.velocities == [(0.03, 0.0)] and req.distance == pytest.approx(0.3) and req.robots == ["pz1"]
    assert request_of(decouple).pair == ["pz1", "pz2"]
    with pytest.raises(ConfigError, match="unknown scenario"):
        scenario_steps(SCENARIOS, "nope")


def test_a_pair_cycle_run_is_checked_in_bullet_step_by_step():
    rec = run_trial(SCENARIOS, "pair_cycle", seed=1, trial=0)
    assert [s["behavior"] for s in rec["steps"]] == ["couple", "drive_assembly", "decouple"]
    assert rec["success"], rec["steps"]
    assert all(s["ok"] and not s["problems"] for s in rec["steps"])
    assert rec["failed_mpc_steps"] == 0
    couple, drive, decouple = (s["held"] for s in rec["steps"])
    for held in (couple, drive):                # the pair held coupled, seated, its faces together
        assert [(h["pair"], h["seated"]) for h in held] == [("pz1-pz2", True)]
        assert abs(held[0]["gap_mm"]) < 3.0 and abs(held[0]["lateral_mm"]) < 5.0 and abs(held[0]["dtheta"]) < 0.2
        assert abs(held[0]["anchor_turn"]) < 0.5
    assert decouple == []


def test_a_traced_trial_is_the_same_trial_and_its_pair_goes_from_open_to_seated():
    trace = PairTrace("pz1", "pz2", every=1.0)
    traced = run_trial(SCENARIOS, "pair_cycle", seed=1, trial=0, on_tick=trace)
    assert traced == run_trial(SCENARIOS, "pair_cycle", seed=1, trial=0)     # the trace only reads
    rows = trace.rows
    assert [r["step"] for r in rows] == sorted(r["step"] for r in rows) and {r["step"] for r in rows} == {0, 1, 2}
    assert all(b["t"] - a["t"] == pytest.approx(1.0, abs=0.11) for a, b in zip(rows, rows[1:]) if a["step"] == b["step"])
    first, drive = rows[0], [r for r in rows if r["step"] == 1]
    assert first["controller"] == "decoupled" and first["bullet"] == "-" and first["gap_mm"] > 10.0
    assert abs(drive[0]["gap_mm"]) < 3.0                              # seated once the couple step has ended
    assert all(r["controller"] == "coupled" and r["bullet"] == "head_inserted" for r in drive)
    assert all(r["anchor_cmd"][0] > 0.0 for r in drive[1:])          # the pair drives forward as one body
    table = trace.table().splitlines()
    assert table[0].startswith("| t | step | controller") and len(table) == len(rows) + 2


def test_a_trial_runs_on_another_model_when_asked_and_records_it():
    seen = []
    rec = run_trial(SCENARIOS, "pair_cycle", seed=1, trial=0, model={"robot": {"caster_clearance": 0.0003}},
                    on_tick=lambda cl, step, tick: seen.append(cl.world.params.caster_clearance))
    assert set(seen) == {0.0003} and rec["model"] == {"robot": {"caster_clearance": 0.0003}}
    assert "model" not in run_trial(SCENARIOS, "pair_cycle", seed=1, trial=0, on_tick=lambda cl, step, tick: (
        seen.append(cl.world.params.caster_clearance)))
    assert seen[-1] != 0.0003                                        # the shipped model otherwise
    with pytest.raises(ConfigError, match="--robot"):
        run_trial(SCENARIOS, "pair_cycle", seed=1, trial=0, model={"robot": {"caster_clearence": 0.0003}})


def test_a_traced_pair_is_named_anchor_robot_first_among_the_scenarios_robots():
    assert parse_pair("pz7-pz8", ["pz7", "pz8"]) == ("pz7", "pz8")
    for bad in ["pz7", "pz7-", "pz7-pz7", "pz7-pz8-pz9"]:
        with pytest.raises(ConfigError, match="ANCHOR_ROBOT-OPENING_ROBOT"):
            parse_pair(bad)
    with pytest.raises(ConfigError, match="no robot pz9 in this scenario"):
        parse_pair("pz1-pz9", ["pz1", "pz2"])


def test_summary_counts_steps_reached_and_passed():
    steps = scenario_steps(SCENARIOS, "couple4_line")
    ok = {"behavior": "x", "ok": True, "sim_seconds": 10.0, "problems": [], "coupled_pairs": 3}
    bad = dict(ok, ok=False, problems=["pz1-pz2 not seated"])
    records = [{"trial": 0, "success": True, "steps": [ok, ok, ok], "failed_mpc_steps": 0},
               {"trial": 1, "success": False, "steps": [ok, bad], "failed_mpc_steps": 0}]
    s = summarize(records, steps)
    assert (s["trials"], s["successes"], s["failed_trials"]) == (2, 1, [1])
    assert (s["pairs_held"], s["pairs_not_seated"]) == (15, 1)
    assert [(x["reached"], x["succeeded"]) for x in s["steps"]] == [(2, 2), (2, 1), (1, 1)]
    assert "| couple all robots into line | 2 | 2 | 10.0 | 10.0 |" in format_table(s)
    assert s["not_seated_by"] == {"not told": 1}          # a record written before the reasons were kept


def test_summary_counts_why_pairs_were_not_seated():
    steps = scenario_steps(SCENARIOS, "couple4_line")
    problems = ["pz1-pz2 not seated (barb R folded into the mouth (3.7 mm off the axis, the lips at 4.2 mm))",
                "pz2-pz3 not seated (barb L on the lip; barb R folded into the mouth (3.1 mm ...))",
                "pz3-pz4 not seated (barb L folded into the mouth (2.0 mm ...))",
                "pz1's anchor out of its holder (x 3.0 mm, yaw 0.10 rad)",
                "pz1-pz5 not seated (the knob partly in the hole: the sides 2.0 mm apart)",
                "pz2-pz6 not seated (the knob not at the hole)"]
    bad = {"behavior": "x", "ok": False, "sim_seconds": 10.0, "problems": problems, "coupled_pairs": 5}
    s = summarize([{"trial": 0, "success": False, "steps": [bad], "failed_mpc_steps": 0}], steps)
    assert s["pairs_not_seated"] == 5
    assert s["not_seated_by"] == {"a barb folded into the mouth": 2, "a barb on the lip": 1,
                                  "the knob partly in the hole": 1, "the knob not at the hole": 1}


def test_a_pull_test_pulls_the_held_pair_both_ways_and_the_run_goes_on():
    rec = run_trial(SCENARIOS, "couple2", seed=1, trial=0, pull_test=True)
    couple, drive = rec["steps"]
    assert couple["ok"] and [p["pair"] for p in couple["pulls"]] == ["pz1-pz2"]
    pull = couple["pulls"][0]
    assert pull["before"] == "head_inserted" and pull["anchor"]["held"] and pull["opening"]["held"]
    assert "pulls" not in drive and drive["ok"]          # the drive runs on from the state before the pulls
    assert pull_summary([rec]) == {"seated": [2, 2]}


def test_the_pull_summary_counts_by_verdict_and_a_folded_tips_offset():
    def pulled(reason, held):
        return {"pair": "a-b", "before": "head_aligned" if reason else "head_inserted", "reason": reason,
                "anchor": {"held": held, "stretch_mm": 1.0}, "opening": {"held": False, "stretch_mm": 200.0}}
    pulls = [pulled("", True), pulled("barb R folded into the mouth (2.3 mm off the axis, the lips at 4.2 mm); "
                                      "barb R folded into the mouth (2.4 mm off the axis, the lips at 4.2 mm)", False),
             pulled("barb L on the lip", True)]
    rec = {"trial": 0, "success": False, "steps": [{"pulls": pulls}]}
    assert pull_summary([rec]) == {"seated": [2, 1], "not seated: a barb on the lip": [2, 1],
                                   "not seated: a barb folded into the mouth, tip 2-3 mm off the axis": [2, 0]}


def test_the_held_pairs_poses_are_summed_up_by_bullets_verdict():
    def held(pair, seated, lateral, gap=0.1, turn=0.05):
        return {"pair": pair, "seated": seated, "gap_mm": gap, "lateral_mm": lateral, "dtheta": 0.0,
                "anchor_turn": turn}
    step = {"behavior": "couple", "ok": False, "sim_seconds": 5.0, "problems": [], "coupled_pairs": 3,
            "held": [held("pz1-pz2", True, -3.9, turn=-0.13), held("pz2-pz3", False, 1.2, gap=-0.3),
                     held("pz3-pz4", True, 0.5, gap=0.9)]}
    old = {"behavior": "couple", "ok": True, "sim_seconds": 5.0, "problems": [], "coupled_pairs": 3}
    ranges = held_pose_ranges([{"steps": [step]}, {"steps": [old]}])
    assert list(ranges) == ["seated", "not seated"]
    assert ranges["seated"] == {"pairs": 2, "lateral_mm": (0.5, 2.2, 3.9), "gap_mm": (0.1, 0.5, 0.9),
                                "anchor_turn": (0.05, pytest.approx(0.09), 0.13)}
    assert ranges["not seated"]["pairs"] == 1 and ranges["not seated"]["gap_mm"] == (-0.3, -0.3, -0.3)
    table = format_pose_ranges(ranges).splitlines()
    assert len(table) == 4 and table[2] == "| seated | 2 | 0.5 / 2.2 / 3.9 | 0.1 / 0.5 / 0.9 | 0.05 / 0.09 / 0.13 |"
    assert held_pose_ranges([{"steps": [old]}]) == {}


def test_timeline_plot_is_written(tmp_path):
    steps = scenario_steps(SCENARIOS, "couple4_line")
    ok = {"behavior": "x", "state": "succeeded", "ok": True, "sim_seconds": 10.0, "problems": []}
    bad = dict(ok, ok=False, problems=["pz1-pz2 not seated"])
    timeout = dict(ok, ok=False, state="failed")
    records = [{"trial": k, "success": k == 0, "steps": s}
               for k, s in enumerate([[ok, ok, ok], [ok, bad], [timeout]])]
    path = str(tmp_path / "t.png")
    plot_trials(records, steps, path, "couple4_line, seed 1")
    assert os.path.getsize(path) > 5000


def test_failure_text_whole_words_and_short_timeouts():
    from puzzlebot_experiments.scenario_trials import failure_text

    long = "timeout after 90.00 s; not coupled: anchor pz1->pz2 (decoupled), knob pz2->pz4 (head_aligned), " \
           "anchor pz3->pz4 (decoupled)"
    text = failure_text(long)
    assert text.startswith("timeout (90 s): not coupled: anchor pz1->pz2 (decoupled)")
    assert len(text) <= 99 and text.endswith(" ...") and "(head_al" not in text.replace("(head_aligned)", "")
    assert failure_text("pz1-pz3 not seated") == "pz1-pz3 not seated"


def test_set_overrides_are_checked_and_reach_the_controller(monkeypatch):
    from puzzlebot_experiments import scenario_trials as st

    assert st.parse_overrides(["dock_pull_test=true", "insert_timeout=2.5"]) == \
        {"dock_pull_test": True, "insert_timeout": 2.5}
    for bad, match in (("no_such_setting=1", "no_such_setting"), ("insert_timeout", "KEY=VALUE"),
                       ("insert_timeout=-1", "insert_timeout")):
        with pytest.raises(ConfigError, match=match):
            st.parse_overrides([bad])

    seen = []

    class Stop(Exception):
        pass

    def closed_loop(world, names=None, settings=None):
        seen.append(settings)
        raise Stop

    monkeypatch.setattr(st, "ClosedLoop", closed_loop)
    with pytest.raises(Stop):
        st.run_task((SCENARIOS, "pair_cycle", 1, 0, {"dock_pull_test": True, "insert_timeout": 2.5}))
    assert seen[0].dock_pull_test is True and seen[0].insert_timeout == 2.5
    assert seen[0].docking_settings().pull_test is True


def test_a_failed_step_says_both_what_timed_out_and_what_bullet_contradicts():
    from puzzlebot_experiments.scenario_trials import step_failure

    timeout = {"state": "failed", "problems": ["pz3-pz4 not seated"],
               "message": "timeout after 180.00 s; not coupled: anchor pz7->pz8 (head_aligned)"}
    assert step_failure(timeout) == "pz3-pz4 not seated; timeout after 180.00 s; not coupled: anchor pz7->pz8 " \
                                    "(head_aligned)"
    assert step_failure(dict(timeout, problems=[])).startswith("timeout after 180.00 s")
    assert step_failure({"state": "succeeded", "problems": ["a-b not seated", "c-d not seated"]}) == \
        "a-b not seated, c-d not seated"


def test_an_error_in_the_stack_fails_its_trial_and_says_so(monkeypatch):
    from puzzlebot_experiments import scenario_trials as st

    def broken(self, req, limit, on_tick=None):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(st.ClosedLoop, "run_behavior", broken)
    rec = run_trial(SCENARIOS, "couple2", seed=1, trial=0)          # the sweep goes on: a record, no raise
    assert not rec["success"] and len(rec["steps"]) == 1
    assert rec["steps"][0]["state"] == "error" and "ZeroDivisionError" in rec["steps"][0]["message"]


EDGE_SCENARIO = """
robots:
  - {name: pz1}
scenario:
  name: to_the_edge
  world: step
  start: {pz1: [-0.15, 0.0, 0.0]}
  steps:
    - behavior: follow_velocity
      velocities: {pz1: [0.05, 0.0]}
      timeout: 6.0
"""


@pytest.mark.parametrize("cross, edges", [(False, True), (False, False), (True, True)])
def test_in_bullet_the_stage_edges_keep_a_robot_on_its_stage(tmp_path, cross, edges):
    """A robot sent towards the step's edge at 0.05 m/s for 6 s (0.3 m, the edge 0.15 m away): on the stage
    at the end with the MPC's stage edges; over the edge without them (the trial says it left its stage) and
    with cross_edges (it may: no complaint; a lone robot driven off nose first tips over, its pose is
    rejected)."""
    text = EDGE_SCENARIO + ("      cross_edges: true\n" if cross else "")
    (tmp_path / "to_the_edge.yaml").write_text(text)
    rec = run_trial(str(tmp_path), "to_the_edge", seed=1, trial=0, overrides={"edges": edges})
    step = rec["steps"][0]
    left = any("left its stage" in p for p in step["problems"])
    if edges and not cross:
        assert rec["success"] and not step["problems"], step
    else:
        assert not rec["success"] and "pose rejected" in step["message"], step    # it went over the edge
        assert left == (not cross), step
