"""Reduced versions of the paper's coupling and decoupling experiments (docs/results.md).

The full sweeps (`make experiments`) run 100 trials per offset; these run a
few trials of the same code so that a regression of the physics, the MPC or
the behaviours breaks CI. Success is judged physically (the anchor seated in
Bullet), never from the controller's belief.
"""

import json
import os
import subprocess
import sys

import pytest

from puzzlebot_experiments import experiments as ex
from puzzlebot_experiments import version

#: Seeds the sweeps of docs/results.md do not use. In-process trials are deterministic, so these
#: tests are regression tests of fixed trials; the success rates are measured by the sweeps.
SEED = 913
DECOUPLE_SEED = 914      # seed 913's trial 1 is one of the ~1 in 20 decouplings that fail (docs/results.md)


@pytest.fixture(scope="module")
def ctx():
    return ex._Context()


@pytest.mark.parametrize("offset_mm", [0.0, 6.0, 30.0])
def test_couple_trials_seat_the_anchor_physically(ctx, offset_mm):
    for trial in range(2):
        rec = ex.couple_trial(offset_mm, SEED, trial, ctx)
        assert rec["success"], rec
        assert rec["anchor_in_holder"]
        assert rec["pairs"] == ["a>o"]        # a's anchor in o's opening, seen by Bullet's contacts
        assert 0.0 < rec["time_s"] <= ctx.params.couple_timeout
        assert rec["failed_steps"] == 0


def test_decouple_trials_release_the_anchor_by_wiggling(ctx):
    times = []
    for trial in range(10):
        rec = ex.decouple_trial(DECOUPLE_SEED, trial, ctx)
        assert rec["success"], rec
        assert rec["final_status"] == ex.DECOUPLED and rec["anchor_in_holder"]
        assert rec["controller"] == "succeeded"     # the controller saw the release from the poses
        times.append(rec["time_s"])
    # the goal of docs/results.md, simulated time; these 10 trials: 1.3 s mean with the partner's
    # counter-turn (wiggle_partner_turn 0.3), 6.9 s without it
    assert sum(times) / len(times) <= 4.0, times


def test_a_trial_is_the_same_trial_in_any_order(ctx):
    first = ex.couple_trial(12.0, SEED, 5, ctx)
    ex.couple_trial(12.0, SEED, 6, ctx)
    again = ex.couple_trial(12.0, SEED, 5, ctx)
    for key in ("success", "time_s", "start", "gap_mm", "lateral_mm"):
        assert first[key] == again[key], key


def test_sweep_is_resumable_and_keeps_torn_lines(tmp_path, ctx):
    path = str(tmp_path / "results.jsonl")
    tasks = ex.tasks_for(ex.COUPLE, 2, SEED, (4.0,))
    ex.run_sweep(tasks[:1], path, jobs=1, stream=open(os.devnull, "w"))
    with open(path, "a") as f:          # another experiment's record (the chain trials share the file)
        f.write('{"experiment": "chain", "seed": 1, "success": false}\n')
    with open(path, "a") as f:          # a run killed while writing leaves half a line
        f.write('{"experiment": "couple", "offs')
    recs = ex.run_sweep(tasks, path, jobs=1, stream=open(os.devnull, "w"))
    assert [r["trial"] for r in recs] == [0, 1]
    lines = [json.loads(s) for s in open(path) if s.strip().startswith("{") and s.strip().endswith("}")]
    assert len(lines) == 3               # trial 0 was not run again (and the chain record kept)
    version = ex.config_hash()
    assert all(r["config"] == version for r in lines if r["experiment"] == ex.COUPLE)


def test_the_version_covers_the_sources_a_trial_runs():
    names = {os.path.relpath(f, os.path.dirname(os.path.dirname(f))) for f in version.source_files()}
    assert {"puzzlebot_sim/world.py", "puzzlebot_experiments/experiments.py", "puzzlebot_mpc/controller.py",
            "behaviors/decouple.py", "puzzlebot_mpc/pairs.py", "puzzlebot_common/effects.py",
            "puzzlebot_sim/config.py"} <= names          # behaviors/: puzzlebot_mpc's subpackage
    assert not {"puzzlebot_experiments/results_page.py", "puzzlebot_experiments/experiment_suite.py",
                "puzzlebot_mpc/ros_conversions.py"} & names
    assert not any("identify" in n for n in names)


def test_the_version_follows_what_code_computes_not_its_layout():
    a = "import os\n\ndef f(x):\n    \"\"\"Doc.\"\"\"\n    return x + 1  # one more\n\nK = 2\n"
    moved = "K = 2\n\n\ndef f(x):\n    return x + 1\n"            # reordered, no docstring, comment or import
    changed = "def f(x):\n    return x + 2\n\nK = 2\n"
    assert sorted(version.definitions(a)) == sorted(version.definitions(moved))
    assert sorted(version.definitions(a)) != sorted(version.definitions(changed))


def test_summary_counts_only_physical_successes():
    recs = [{"success": True, "time_s": 4.0, "controller": "succeeded"},
            {"success": True, "time_s": 6.0, "controller": "succeeded"},
            {"success": False, "time_s": None, "controller": "succeeded"}]
    s = ex.summarize(recs)
    assert (s["trials"], s["successes"], s["mean_time_s"], s["median_time_s"]) == (3, 2, 5.0, 5.0)
    assert s["controller_succeeded"] == 3


def test_command_line_prints_one_json_line_and_rejects_bad_arguments(tmp_path):
    script = os.path.join(os.path.dirname(__file__), "..", "scripts", "couple_trials")
    out = subprocess.run([sys.executable, script, "--offset-mm", "2", "--trials", "1", "--seed", str(SEED),
                          "--jobs", "1", "--results", str(tmp_path / "r.jsonl"), "--json"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    line = json.loads(out.stdout.strip().splitlines()[-1])
    assert line["trials"] == 1 and line["offset_mm"] == 2.0
    assert set(line) >= {"successes", "mean_time_s", "median_time_s"}
    assert "1/1" in out.stderr           # the progress line
    for bad, msg in ((["--trials", "0"], "--trials"), (["--offset-mm", "-3"], "--offset-mm"),
                     (["--seed", "x"], "--seed")):
        out = subprocess.run([sys.executable, script] + bad, capture_output=True, text=True, timeout=120)
        assert out.returncode == 2 and msg in out.stderr
