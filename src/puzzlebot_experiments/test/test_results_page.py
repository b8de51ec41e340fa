"""docs/results.md generation: tables, intervals, marker blocks, figures (no Bullet)."""

import os

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_experiments import results_page as page


def _rec(off, ok, t, controller="succeeded"):
    return {"offset_mm": off, "success": ok, "time_s": t if ok else None, "controller": controller}


def test_wilson_interval_brackets_the_rate():
    lo, hi = page.wilson_interval(100, 100)
    assert 0.96 < lo < 0.97 and hi == pytest.approx(1.0)     # 100 of 100 does not prove 100 %
    lo, hi = page.wilson_interval(50, 100)
    assert lo < 0.5 < hi and abs((lo + hi) / 2 - 0.5) < 1e-9


def test_couple_table_per_offset_with_goal_and_agreement():
    recs = [_rec(0, True, 4.0), _rec(0, True, 6.0), _rec(2, True, 5.0), _rec(2, False, None)]
    rows = page.couple_table(recs).splitlines()
    assert rows[2].startswith("| 0 | 2 | 100.0 % |") and rows[2].endswith("| 2/2 | met |")
    assert "| 5.00 | 5.00 |" in rows[2]
    assert rows[3].startswith("| 2 | 2 | 50.0 % |") and "**not met**" in rows[3]
    assert "| 1/2 |" in rows[3]                      # the controller claimed the failed one


def test_decouple_table_states_whether_the_goal_is_met():
    fast = [{"success": True, "time_s": 3.0, "controller": "succeeded"}] * 4
    assert "**met**" in page.decouple_table(fast)
    slow = fast + [{"success": True, "time_s": 20.0, "controller": "succeeded"}]
    assert "**not met**" in page.decouple_table(slow)


def test_blocks_are_replaced_and_missing_blocks_are_an_error():
    text = "a\n<!-- BEGIN t -->\nold\n<!-- END t -->\nb\n<!-- BEGIN keep -->\nx\n<!-- END keep -->\n"
    out = page.replace_blocks(text, {"t": "new table"})
    assert out == "a\n<!-- BEGIN t -->\nnew table\n<!-- END t -->\nb\n<!-- BEGIN keep -->\nx\n<!-- END keep -->\n"
    with pytest.raises(ConfigError, match="nope"):
        page.replace_blocks(text, {"nope": "y"})


def test_figures_are_written(tmp_path):
    recs = [_rec(o, True, 3.0 + o / 10) for o in (0, 2, 4) for _ in range(3)]
    page.couple_figure(recs, str(tmp_path / "c.png"))
    page.decouple_figure([{"success": True, "time_s": 2.0}, {"success": False, "time_s": None}],
                         str(tmp_path / "d.png"))
    bench = {"results": [{"robots": n, "horizon": h, "median_ms": n * h / 10, "p95_ms": n * h / 8, "failures": 0}
                         for n in (2, 4) for h in (3, 10)]}
    page.bench_figure(bench, str(tmp_path / "b.png"))
    assert "| 4 | 1.2 / 1.5 | 4.0 / 5.0 | 0 |" in page.bench_table(bench)
    for name in ("c", "d", "b"):
        assert os.path.getsize(str(tmp_path / ("%s.png" % name))) > 5000


def _chain(seed, ok, pair=None):
    sep = None if ok else {"pair": pair, "time_s": 1.25, "pitch_rad": {"r1": 0.0, "r2": -0.3, "r3": -1.1},
                           "max_barb_rad": 1.9, "snap_rad": 0.84, "max_pullout_mm": 6.5}
    return {"seed": seed, "success": ok, "robots": 3, "upright_on_floor": 3 if ok else 1,
            "time_s": 12.0 if ok else None, "first_separation": sep}


def test_chain_table_and_figure_per_seed(tmp_path):
    recs = [_chain(2, False, "r2>r3"), _chain(1, True), _chain(3, False, "r1>r2")]
    rows = page.chain_table(recs).splitlines()
    assert rows[2].startswith("| 1 | **down** in 12.0 s | 3 of 3 | - |")
    assert rows[3] == ("| 2 | apart | 1 of 3 | r2>r3 | 1.25 | r1 0.00, r2 -0.30, r3 -1.10 | 1.90 / 0.84 | 6.5 |")
    assert rows[-1].startswith("| **all** | **1 of 3 down intact** |")
    page.chain_figure(recs, str(tmp_path / "chain.png"))
    assert os.path.getsize(str(tmp_path / "chain.png")) > 5000


def test_bench_summary_quotes_the_table_it_sits_beside():
    bench = {"steps": 50, "results": [{"robots": n, "horizon": h, "median_ms": n * h / 10, "p95_ms": n * h / 8,
                                       "max_ms": n * h / 6, "failures": 0} for n in (2, 8, 32) for h in (3, 10)]}
    text = page.bench_summary(bench)
    assert "8 robots with Hm = 10, one step takes 8.0 ms median (p95 10.0 ms" in text      # the table's 8 x 10
    assert "With 32 robots, one step takes 32.0 ms median (p95 40.0 ms" in text
    assert "32 % of the 100 ms control period" in text
    assert "Every configuration solved every step (6 configurations, 50 steps each)" in text
    bench["results"][0]["failures"] = 2
    assert "2 failed steps in all" in page.bench_summary(bench)


def test_chain_figure_marks_intact_chains_that_were_not_down(tmp_path):
    stuck = dict(_chain(4, True), success=False, time_s=None, upright_on_floor=1, timeout_s=30.0)
    page.chain_figure([_chain(1, True), stuck], str(tmp_path / "chain.png"))
    assert os.path.getsize(str(tmp_path / "chain.png")) > 5000
