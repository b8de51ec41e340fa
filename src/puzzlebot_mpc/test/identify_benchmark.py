#!/usr/bin/env python3
"""Benchmark of identify_model at lab size (not a test: prints tables).

For every scenario of test_identify_effects (each effect, pairs, none, robots
that differ, mocap artefacts, CSV command timing), simulates 3 robots x 150 s
of 100 Hz mocap (noise, dropped samples) with 10 Hz commands, writes the
scenario's bag or CSV (--format: all as one), runs the command-line tool on it as a user
would (``python -m puzzlebot_mpc.identify DATA --out --model-out --plot``,
wall and CPU time measured, including start-up, reading, plotting and writing), and
prints the recovery table: effects named, parameter errors, validation
position RMSE against the true model's, residual verdict, runtime.

    scripts/env.sh python src/puzzlebot_mpc/test/identify_benchmark.py [--robots 3] [--duration 150]
        [--seed 1] [--format bag] [SCENARIO ...]
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import identify_synth as synth  # noqa: E402
import test_identify_effects as scenarios  # noqa: E402
from puzzlebot_common.effects import ActuatorModel  # noqa: E402
from puzzlebot_mpc.identify import IdentifySettings, core, data, fit  # noqa: E402


def run(name, sc, args, tmp):
    rec = synth.lab_record(sc["effects"], n_robots=max(args.robots, sc.get("robots", 0)), duration=args.duration,
                           seed=args.seed, robot_effects=sc.get("robot_effects"), **sc.get("record", {}))
    fmt = args.format if args.format else sc["fmt"]
    path = os.path.join(tmp, "%s.%s" % ("".join(ch for ch in name if ch.isalnum()), fmt))
    if fmt == "bag":
        synth.write_bag(path, rec)
    else:
        synth.write_csv(path, rec, command_times=sc.get("csv_times", False))
    out = path + ".json"
    t0, c0 = time.time(), resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run([sys.executable, "-m", "puzzlebot_mpc.identify", path, "--out", out,
                           "--model-out", path + ".yaml", "--plot", path + ".png", "--quiet"],
                          capture_output=True, text=True)
    wall = time.time() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)
    if proc.returncode != 0:
        return "| %s | tool failed: %s |" % (name, proc.stderr.strip()), False, (wall, cpu)
    rep = json.load(open(out))
    model = ActuatorModel.load(path + ".yaml")
    truth = ActuatorModel()
    for robot in rec:
        for eff, ps in scenarios.true_effects(sc, robot).items():
            truth.add_for_robot(robot, eff, ps)
    settings = IdentifySettings()
    dataset = data.load(path)
    data.drop_glitches(dataset, settings)             # as the tool does
    problem = core.Problem([fit.RobotFit(r, settings) for r in dataset.robots], settings)
    true = problem.metric(truth)[0]
    ok, errs, found = True, [], set()
    for robot in rec:
        mine = model.for_robot(robot)
        names = sorted(mine.names())
        found.add(", ".join(names) or "none")
        ok &= names == sorted(scenarios.true_effects(sc, robot))
        for eff, ps in scenarios.true_effects(sc, robot).items():
            for key, value in ps.items():
                if value == 0.0:          # a zero truth: the error in the parameter's units
                    ok &= abs(mine.param(key)) <= 1e-3
                    errs.append("%s%s %.2g (true 0)" % ("" if "robot_effects" not in sc else robot + " ", key,
                                                        mine.param(key)))
                    continue
                rel = mine.param(key) / value - 1.0
                ok &= abs(rel) <= scenarios.PARAM_TOLERANCE
                errs.append("%s%s %.4g (%+.1f %%)" % ("" if "robot_effects" not in sc else robot + " ", key,
                                                      mine.param(key), 100 * rel))
    errs = list(dict.fromkeys(errs))      # shared parameters: once
    ratio = rep["after"]["rmse_pos_m"] / true.rmse_pos_m
    ok &= ratio <= scenarios.RMSE_FACTOR
    row = "| %s | %s | %s | %.2f | %.2f | %.2f | %.2f | %s | %.1f / %.1f |" % (
        name, " / ".join(sorted(found)), "; ".join(errs) or "-", 1e3 * rep["before"]["rmse_pos_m"],
        1e3 * rep["after"]["rmse_pos_m"], 1e3 * true.rmse_pos_m, ratio,
        "white" if rep["residual"]["white"] else "structured", wall, cpu)
    return row, ok, (wall, cpu)


def main(argv=None):
    p = argparse.ArgumentParser(description="identify_model benchmark at lab size")
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--duration", type=float, default=150.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--format", choices=["bag", "csv"], default=None, help="default: the scenario's")
    p.add_argument("scenario", nargs="*", help="default: all of test_identify_effects.SCENARIOS")
    args = p.parse_args(argv)
    names = args.scenario or list(scenarios.SCENARIOS)
    print("%d robots x %.0f s, 100 Hz mocap, %s, seed %d" % (args.robots, args.duration, args.format or "format of "
                                                             "each scenario", args.seed))
    print("| scenario | effects found | parameters (error) | pos RMSE nominal [mm] | identified [mm] | "
          "true model [mm] | ratio | residual | wall / CPU time [s] |")
    print("|---|---|---|---|---|---|---|---|---|")
    walls, passed = [], 0
    with tempfile.TemporaryDirectory(prefix="identify_bench_") as tmp:
        for name in names:
            row, ok, wall = run(name, scenarios.SCENARIOS[name], args, tmp)
            print(row + ("" if ok else " **FAIL**"), flush=True)
            walls.append(wall)
            passed += ok
    wall = sorted(w for w, _ in walls)
    cpu = sorted(c for _, c in walls)
    print("\n%d of %d scenarios pass (names exact, parameters within %.0f %%, RMSE within %.1fx of the true model); "
          "wall time median %.1f s, max %.1f s; CPU time median %.1f s, max %.1f s; load average %.1f"
          % (passed, len(names), 100 * scenarios.PARAM_TOLERANCE, scenarios.RMSE_FACTOR, wall[len(wall) // 2],
             wall[-1], cpu[len(cpu) // 2], cpu[-1], os.getloadavg()[0]))


if __name__ == "__main__":
    main()
