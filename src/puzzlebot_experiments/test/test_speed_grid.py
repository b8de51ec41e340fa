"""speed_test --grid (puzzlebot_experiments.speed_grid): medians per robot count, a table, a page's block."""

import os
import subprocess
import sys

from puzzlebot_experiments import speed_grid

SCRIPT = os.path.join(os.path.dirname(__file__), "..", "scripts", "speed_test")


def test_grid_reports_the_median_of_interleaved_runs_per_robot_count():
    seen = []
    grid = speed_grid.run_grid(robots=(2, 4), sim_seconds=0.2, repeat=3, progress=seen.append)
    assert [r["robots"] for r in grid["rows"]] == [2, 4]
    assert [s.split(",")[1].strip().split()[0] for s in seen] == ["2", "4"] * 3     # interleaved
    for r in grid["rows"]:
        assert r["min"] <= r["real_time_factor"] <= r["max"] and r["real_time_factor"] > 0
        assert r["coupled_pairs_at_end"] == 1           # 2 and 4 robots: one coupled pair (trials.speed_test)
    text = speed_grid.table(grid)
    assert text.splitlines()[0] == "| robots | 2 | 4 |"
    assert "3 runs per count interleaved" in text and "load average" in text


def test_grid_rewrites_the_pages_block_and_refuses_a_page_without_one(tmp_path):
    page = tmp_path / "sim.md"
    page.write_text("# Sim\n\n<!-- BEGIN speed_table -->\nold\n<!-- END speed_table -->\n\nafter\n")
    cmd = [sys.executable, SCRIPT, "--grid", "--grid-robots", "2", "--repeat", "1", "--sim-seconds", "0.2"]
    out = subprocess.run(cmd + ["--page", str(page)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    text = page.read_text()
    assert "old" not in text and "| robots | 2 |" in text and text.endswith("after\n")
    assert "| robots | 2 |" in out.stdout
    page.write_text("# no block\n")
    bad = subprocess.run(cmd + ["--page", str(page)], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "speed_table" in bad.stderr and "Traceback" not in bad.stderr
    bad = subprocess.run(cmd[:2] + ["--grid-robots", "2,x"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--grid-robots" in bad.stderr
