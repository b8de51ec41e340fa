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


def test_table_lists_every_configuration():
    rows = [{"robots": n, "horizon": h, "median_ms": 1.0, "p95_ms": 2.0, "failures": 0}
            for n in (2, 4) for h in (3, 5)]
    text = bench.table(rows)
    assert "Hm=3" in text and "Hm=5" in text and "| 4 |" in text
