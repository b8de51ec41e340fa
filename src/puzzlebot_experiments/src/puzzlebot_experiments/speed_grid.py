"""Simulation speed over a grid of robot counts, measured in one run (``speed_test --grid``).

Each count is run ``repeat`` times with puzzlebot_experiments.trials.speed_test,
the counts interleaved (2, 4, ..., 64, then again), so that the machine's
other load falls on every count alike; a cell is the median of its runs.
``table`` prints the result as Markdown (docs/sim.md's speed section is its
generated block ``speed_table``), with the machine's load average while it
ran: wall-clock figures on a shared machine are only comparable within one run.
"""

import os
import platform
import statistics
import time

from puzzlebot_sim.params import SimParams
from puzzlebot_experiments.trials import speed_test

#: Robot counts of the grid (docs/sim.md).
GRID_ROBOTS = (2, 4, 8, 16, 32, 64)
#: Name of the generated block in docs/sim.md.
PAGE_BLOCK = "speed_table"


def run_grid(robots=GRID_ROBOTS, sim_seconds=10.0, repeat=3, seed=0, sim=None, anchor_rest=None, anchors=True,
             progress=None):
    """Median speed_test figures per robot count: {"rows": [...], "load_avg": [...], ...}.

    ``sim`` (SimParams) and ``anchor_rest`` (AnchorRestParams) as for speed_test (None: defaults);
    ``anchors`` False: robots without anchors; ``progress(text)`` is called after every run.
    """
    kwargs = {k: v for k, v in (("sim", sim), ("anchor_rest", anchor_rest)) if v is not None}
    if not anchors:
        kwargs["anchor"] = None
    rate = (sim or SimParams()).physics_rate
    runs = {n: [] for n in robots}
    load = [os.getloadavg()[0]]
    t0 = time.monotonic()
    for k in range(repeat):
        for n in robots:
            r = speed_test(n, sim_seconds, seed=seed, **kwargs)
            runs[n].append(r)
            load.append(os.getloadavg()[0])
            if progress is not None:
                progress("run %d/%d, %d robots: %.2fx real time" % (k + 1, repeat, n, r["real_time_factor"]))
    rows = []
    for n in robots:
        rs = runs[n]
        factors = [r["real_time_factor"] for r in rs]
        rows.append({"robots": n, "real_time_factor": round(statistics.median(factors), 2),
                     "min": min(factors), "max": max(factors),
                     "cpu_factor": round(statistics.median(sim_seconds / r["cpu_seconds"] for r in rs), 2),
                     "ms_per_step": round(1e3 * statistics.median(r["wall_seconds"] for r in rs) / (sim_seconds * rate),
                                          3),
                     "coupled_pairs_at_end": rs[0]["coupled_pairs_at_end"],
                     "resting_anchors_at_end": rs[0]["resting_anchors_at_end"]})
    return {"rows": rows, "sim_seconds": sim_seconds, "repeat": repeat, "seed": seed, "physics_rate": rate,
            "anchors": anchors,
            "load_avg": [round(min(load), 2), round(max(load), 2)], "cores": os.cpu_count(),
            "python": platform.python_version(), "wall_s": round(time.monotonic() - t0, 1)}


def table(grid):
    """The grid as a Markdown table (robots as columns) with a line on how it was measured."""
    rows = grid["rows"]
    head = "| robots | " + " | ".join(str(r["robots"]) for r in rows) + " |"
    lines = [head, "| --- |" + " --- |" * len(rows),
             "| real-time factor (median) | " + " | ".join("**%.1fx**" % r["real_time_factor"] if r["robots"] == 32
                                                        else "%.1fx" % r["real_time_factor"] for r in rows) + " |",
             "| range of the %d runs | " % grid["repeat"]
             + " | ".join("%.1f-%.1fx" % (r["min"], r["max"]) for r in rows) + " |",
             "| CPU-time factor (sim s per CPU s) | " + " | ".join("%.1fx" % r["cpu_factor"] for r in rows) + " |",
             "| wall time per physics step (%g Hz) | " % grid["physics_rate"]
             + " | ".join("%.2f ms" % r["ms_per_step"] for r in rows) + " |",
             "| coupled pairs / resting anchors at the end | "
             + " | ".join("%d / %d" % (r["coupled_pairs_at_end"], r["resting_anchors_at_end"]) for r in rows) + " |",
             "",
             "`speed_test --grid%s` (%g s simulated, %d runs per count interleaved, seed %d): %d cores, Python %s, "
             "load average %.1f-%.1f while it ran, %.0f s in all."
             % ("" if grid.get("anchors", True) else " --no-anchors", grid["sim_seconds"], grid["repeat"], grid["seed"],
                grid["cores"] or 0, grid["python"],
                grid["load_avg"][0], grid["load_avg"][1], grid["wall_s"])]
    return "\n".join(lines)
