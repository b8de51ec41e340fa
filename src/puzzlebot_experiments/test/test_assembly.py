"""The assembly-size sweep (puzzlebot_experiments.assembly): scenarios, one real trial, the summary and page."""

import os

import pytest

from puzzlebot_bringup.launch_config import sim_config
from puzzlebot_experiments import assembly, results_page


@pytest.mark.parametrize("n", [2, 5, 16])
def test_a_line_scenario_of_n_robots_configures_the_sim(n):
    directory, name = assembly._scenario_file(n)
    launch = sim_config(directory, name, seed=3)
    assert len(launch.robots) == n and len(launch.scenario["start"]) == n
    couple = launch.scenario["steps"][0]
    assert couple["target"] == "line" and couple["timeout"] == assembly.COUPLE_S_PER_ROBOT * n + assembly.COUPLE_S_BASE


def test_one_trial_of_two_robots_couples_and_drives_checked_in_bullet():
    rec = assembly.assembly_trial((2, 1, 0))
    assert rec["n"] == 2 and rec["couple_ok"] and rec["success"], rec
    assert not rec["not_seated"]


def test_summary_counts_what_bullet_confirmed_and_the_mismatches(tmp_path):
    recs = [{"n": 4, "success": True, "couple_ok": True, "couple_s": 20.0, "controller_coupled": True},
            {"n": 4, "success": False, "couple_ok": False, "couple_s": 30.0, "controller_coupled": True},
            {"n": 4, "success": False, "couple_ok": False, "couple_s": 90.0, "controller_coupled": False}]
    s = assembly.summarize(recs)[4]
    assert (s["trials"], s["successes"], s["couple_successes"], s["median_couple_s"], s["mismatches"]) == \
        (3, 1, 1, 20.0, 1)
    assert "| 4 | 3 | 1 | 1 | 20.0 | 1 |" in results_page.assembly_table({4: s})
    path = str(tmp_path / "a.png")
    results_page.assembly_figure({4: s, 8: dict(s, median_couple_s=None)}, path)
    assert os.path.getsize(path) > 5000
