"""Assemblies of growing size: a line of N scattered robots through the MPC, every step checked in Bullet.

For each N the robots start scattered in a rough row as in the shipped
``line8`` scenario (0.10-0.11 m apart, +/-40 mm sideways, +/-0.35 rad, drawn
from the trial's seed: puzzlebot_bringup.scenario.scatter_starts), couple
into a line (timeout ``COUPLE_S_PER_ROBOT`` x N + ``COUPLE_S_BASE``), then
the line drives 0.2 m. A trial runs through
:func:`puzzlebot_experiments.scenario_trials.run_trial`, the same in-process
run as ``scenario_trials`` (Bullet + the MPC node's core in lockstep, the
lab's mocap noise), so a step counts only when Bullet agrees: every pair the
controller holds coupled is seated.

Trials are kept in the experiments' results file (experiment ``assembly``),
keyed by N, seed, trial and the results version, so a sweep continues where
it stopped.
"""

import os
import tempfile

import yaml

from puzzlebot_experiments import experiments as ex

#: Line sizes of the sweep (the paper's experiments reach lines of 2-8).
SIZES = (2, 4, 6, 8, 12, 16)
COUPLE_S_PER_ROBOT = 20.0     # s simulated per robot for the couple step ...
COUPLE_S_BASE = 30.0          # ... plus this
SCATTER = {"spacing": [0.10, 0.11], "lateral": 0.04, "yaw": 0.35}
DRIVE_M = 0.2
EXPERIMENT = "assembly"


def line_scenario(n):
    """The scenario file's data of a line of ``n`` robots (pz1 in front)."""
    names = ["pz%d" % (k + 1) for k in range(n)]
    return {"robots": [{"name": r} for r in names],
            "scenario": {"name": "line%d" % n, "description": "%d scattered robots couple into a line" % n,
                         "scatter": dict(SCATTER),
                         "steps": [{"behavior": "couple", "target": "line",
                                    "timeout": COUPLE_S_PER_ROBOT * n + COUPLE_S_BASE},
                                   {"behavior": "drive_assembly", "robots": ["pz1"], "velocity": [0.03, 0.0],
                                    "distance": DRIVE_M, "timeout": 30.0}]}}


_DIRECTORY = None


def scenario_directory():
    """A directory (one per process) holding the line scenarios of every size in SIZES."""
    global _DIRECTORY
    if _DIRECTORY is None:
        _DIRECTORY = tempfile.mkdtemp(prefix="puzzlebot_assembly_")
    return _DIRECTORY


def _scenario_file(n):
    directory = scenario_directory()
    path = os.path.join(directory, "line%d.yaml" % n)
    if not os.path.isfile(path):
        with open(path, "w") as f:
            yaml.safe_dump(line_scenario(n), f)
    return directory, "line%d" % n


def assembly_trial(task):
    """One trial (n, seed, trial) -> a JSON-able record (scenario_trials.run_trial's, plus n)."""
    from puzzlebot_experiments.scenario_trials import run_trial

    n, seed, trial = task
    directory, name = _scenario_file(n)
    rec = run_trial(directory, name, seed, trial)
    couple = rec["steps"][0] if rec["steps"] else {}
    return dict(rec, n=n, couple_ok=bool(couple.get("ok")), couple_s=couple.get("sim_seconds"),
                controller_coupled=couple.get("state") == "succeeded",
                pairs_coupled=couple.get("coupled_pairs", 0),
                not_seated=[p for p in couple.get("problems", []) if "not seated" in p])


def assembly_sweep(sizes, trials, seed, executor, results):
    """Every (n, trial) of ``sizes`` x ``trials`` on ``executor``, resumable in ``results``; returns the records."""
    version = ex.config_hash({"experiment": EXPERIMENT})
    store = ex.ResultsFile(results)
    key = lambda r: (r["n"], r["seed"], r["trial"])          # noqa: E731
    have = {key(r): r for r in store.load() if r.get("experiment") == EXPERIMENT and r.get("config") == version}
    tasks = [(n, seed, t) for n in sizes for t in range(trials)]
    todo = [t for t in tasks if t not in have]
    progress = ex.Progress("lines of %s robots" % ",".join(map(str, sizes)), len(tasks), len(tasks) - len(todo))
    progress.ok = sum(bool(have[t]["success"]) for t in tasks if t in have)
    progress.show()
    for rec in executor.run(assembly_trial, todo):
        rec = dict(rec, experiment=EXPERIMENT, config=version)
        store.append(rec)
        have[key(rec)] = rec
        progress.update(rec["success"])
    return [have[t] for t in tasks]


def summarize(records):
    """{n: {trials, successes, couple_successes, median_couple_s, controller_coupled, mismatches,
    pairs_coupled, pairs_not_seated}}: mismatches = trials whose couple step the controller called done
    with a pair Bullet finds not seated; pairs_*: over every trial's couple step, the pairs the controller
    held coupled at its end and how many of those Bullet found not seated."""
    import numpy as np

    out = {}
    for n in sorted({r["n"] for r in records}):
        rs = [r for r in records if r["n"] == n]
        ok = [r["couple_s"] for r in rs if r["couple_ok"]]
        out[n] = {"trials": len(rs), "successes": sum(bool(r["success"]) for r in rs),
                  "couple_successes": len(ok),
                  "median_couple_s": round(float(np.median(ok)), 1) if ok else None,
                  "controller_coupled": sum(bool(r["controller_coupled"]) for r in rs),
                  "mismatches": sum(bool(r["controller_coupled"]) and not r["couple_ok"] for r in rs),
                  "pairs_coupled": sum(r.get("pairs_coupled", 0) for r in rs),
                  "pairs_not_seated": sum(len(r.get("not_seated", [])) for r in rs)}
    return out
