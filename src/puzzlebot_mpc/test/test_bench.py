"""The benchmark script runs a real coupling run and reports the agreed JSON fields (not a timed test)."""

import json

from puzzlebot_mpc import bench


def test_one_configuration_prints_one_json_line(capsys):
    assert bench.main(["--robots", "3", "--horizon", "3", "--steps", "8", "--json"]) == 0
    line = capsys.readouterr().out.strip().splitlines()
    assert len(line) == 1
    r = json.loads(line[0])
    for key in ("robots", "horizon", "steps", "median_ms", "p95_ms", "failures"):
        assert key in r
    assert (r["robots"], r["horizon"], r["steps"], r["failures"]) == (3, 3, 8, 0)
    assert r["coupled_pairs"] == 2 and r["pairs_lost"] == 0 and r["min_pip_margin_mm"] >= 0.0
    assert r["lead_moved_m"] > 0.02            # the assembly really drove
    assert 0 < r["solver_median_ms"] <= r["mpc_median_ms"] <= r["median_ms"]
    assert r["solver"] == "active_set" and r["fallbacks"] == 0


def test_table_lists_every_configuration():
    rows = [{"robots": n, "horizon": h, "median_ms": 1.0, "p95_ms": 2.0, "failures": 0}
            for n in (2, 4) for h in (3, 5)]
    text = bench.table(rows)
    assert "Hm=3" in text and "Hm=5" in text and "| 4 |" in text


def test_grid_covers_256_robots_at_hm_10_and_short_horizons_up_to_32():
    cells = bench.grid()
    assert (256, 10) in cells and (128, 10) in cells and (2, 10) in cells
    assert (32, 3) in cells and (64, 3) not in cells


def test_targets_and_page_block(tmp_path):
    """The targets table says met or not from the figures; --page rewrites only the marked block."""
    rows = [{"robots": n, "horizon": 10, "median_ms": m, "p95_ms": p, "failures": 0, "pairs_lost": 0,
             "solver_median_ms": 1.0, "qp_iterations_median": 11.0, "build_s": 0.01}
            for n, m, p in ((8, 2.0, 2.5), (128, 20.0, 40.0))]
    text = bench.targets_table(rows)
    assert "| 8 robots, Hm = 10: median <= 3 ms | 2.0 ms | yes |" in text
    assert "| 128 robots, Hm = 10: p95 <= 30 ms | 40.0 ms | **no** |" in text
    assert "256 robots" in text and "not run" in text
    page = tmp_path / "page.md"
    page.write_text("before\n%s\nold\n%s\nafter\n" % (bench.PAGE_BEGIN, bench.PAGE_END))
    doc = {"time": "now", "steps": 50, "constraint_horizon": 3, "results": rows,
           "machine": {"cpu_count": 2, "load_avg_1_5_15": [1.0, 1.0, 1.0]},
           "reference": [dict(rows[0], median_ms=80.0, p95_ms=90.0, solver="ipopt")]}
    bench.update_page(str(page), bench.page_block(doc))
    out = page.read_text()
    assert out.startswith("before\n") and out.endswith("after\n") and "old" not in out
    assert "| 8, 10 | 2.0 / 2.5 | 80.0 / 90.0 | 40x |" in out


def test_solver_comparison_table():
    mine = [{"robots": 8, "horizon": 10, "median_ms": 2.0, "p95_ms": 2.5, "solver": "active_set",
             "solver_median_ms": 0.5, "qp_iterations_median": 1.0}]
    ref = [dict(mine[0], median_ms=6.0, p95_ms=7.0, solver="clarabel", solver_median_ms=4.0,
                qp_iterations_median=12.0)]
    text = bench.solver_comparison_table(mine, ref)
    assert "| 8, 10 | 2.0 / 2.5 | 6.0 / 7.0 | 0.5 / 4.0 | 1 / 12 | 3.0x |" in text
