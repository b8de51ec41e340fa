"""MPC step-time benchmark on a real coupling run (no ROS needed).

One configuration: a chain of N robots, every neighbouring pair coupled
(N-1 anchor pairs, polygon constraints on for k = 1..Hc), drives as one
assembly along an S-curve (drive_assembly, v = 0.03 m/s, the turn rate
switching sign halfway) on the kinematic plant (model.unicycle_arc). Every
control step goes through ControlLoop.step: pair bookkeeping, behaviour
objectives, the MPC solve. The step time is the wall time of that call;
the first step (it builds the problem for the pair structure and starts
cold) is reported separately as ``first_step_ms`` and not in the
statistics. ``mpc_median_ms`` is the part of the step spent in the MPC
(MultiRobotMPC.make_step: QP assembly, solve, rollout), ``solver_median_ms``
the part of that spent inside the QP solver (the active set's working sets,
or Clarabel's set-up, data update and iterations); the rest of the step is
the control loop's (pair bookkeeping, behaviour objectives). ``fallbacks``
counts the steps in which a QP of the active set was solved by Clarabel.

The grid (``make bench``) runs N in GRID_ROBOTS at Hm = 10 and, up to 32
robots, at Hm = 3 and 5; then, interleaved with the default solver's runs
at N in SOLVER_REFERENCE, the same runs with Clarabel (the interior point),
and the N = 8, Hm = 10 run with IPOPT on the full NLP (the lab's kind of
solver, built once here) for comparison; it prints the tables and the
issue's targets (TARGETS) met or not, writes the JSON and, with ``--page``,
rewrites the generated block of docs/mpc.md.

    python -m puzzlebot_mpc.bench --robots 8 --horizon 10 --json
    python -m puzzlebot_mpc.bench --grid --out build/bench/mpc_bench.json --page docs/mpc.md
    python -m puzzlebot_mpc.bench --grid --grid-robots 64,128     # part of the grid (no files written)
    python -m puzzlebot_mpc.bench --robots 4 --couple-trials 24   # coupling success rate
"""

import argparse
import json
import math
import os
import platform
import sys
import time
from dataclasses import replace

import numpy as np

from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_mpc.behaviors import DRIVE_ASSEMBLY, BehaviorRequest
from puzzlebot_mpc.config_files import load_settings
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_mpc.controller import SOLVERS
from puzzlebot_common.model import unicycle_arc
from puzzlebot_mpc.pairs import ANCHOR, coupling_polygon, head_margin, make_pair

GRID_ROBOTS = (2, 4, 6, 8, 16, 32, 64, 128, 256)
GRID_HORIZONS = (3, 5, 10)
GRID_SHORT_MAX = 32   # Hm = 3 and 5 up to this many robots; Hm = 10 for every N
REFERENCE = (8, 10)   # (robots, Hm) of the IPOPT comparison
SOLVER_REFERENCE = (8, 128)   # robots (Hm = 10) run again with Clarabel, right after the default solver's run
#: decomposition runs: (robots, chains side by side) at Hm = 10, each as one joint QP, as separate QPs, two threads
DECOMPOSITION = ((32, 8), (128, 4))
DECOMPOSITION_MODES = (("one joint QP", dict(decompose=False)), ("separate QPs", dict(decompose=True)),
                       ("separate QPs, 2 threads", dict(decompose=True, solver_threads=2)))
#: measured targets (issue 28): (robots, Hm, statistic, limit [ms])
TARGETS = ((8, 10, "median_ms", 3.0), (128, 10, "p95_ms", 30.0), (256, 10, "p95_ms", 100.0))
PAGE_BEGIN, PAGE_END = "<!-- BEGIN bench_table -->", "<!-- END bench_table -->"
DRIVE_V = 0.03        # m/s, assembly speed
DRIVE_W = 0.15        # rad/s, turn rate (sign switches halfway: an S-curve)
PLANT_SUBSTEPS = 10   # plant integration steps per control period


ASSEMBLY_SPACING = 0.3   # m: side by side distance of the chains with --assemblies


def chain(n, geometry, assemblies=1):
    """Names and poses of ``assemblies`` straight chains along +x (first robot in front), side by side;
    returns (names, poses, chains as name lists). The first chain is the one that drives."""
    names = ["b%d" % (k + 1) for k in range(n)]
    chains = [list(c) for c in np.array_split(names, assemblies)]
    poses = {}
    for a, c in enumerate(chains):
        for k, name in enumerate(c):
            poses[name] = (-k * geometry.body_side, a * ASSEMBLY_SPACING, 0.0)
    return names, poses, chains


def run(robots, horizon, constraint_horizon=3, steps=50, settings=None, solver=None, assemblies=1):
    """Benchmark one configuration; returns the result dict (JSON line fields and extras).

    ``assemblies`` > 1: the robots form that many chains side by side (independent subproblems); the
    first drives, the others hold still (every one is solved every step)."""
    base = settings or load_settings()
    s = replace(base, horizon=horizon, constraint_horizon=min(constraint_horizon, horizon))
    if solver:
        s = replace(s, solver=solver)
    s.check()
    geometry = RobotGeometry()
    names, poses, chains = chain(robots, geometry, assemblies)
    t_build = time.perf_counter()
    loop = ControlLoop(names, s, geometry)
    setup_s = time.perf_counter() - t_build
    for c in chains:
        for a, o in zip(c[:-1], c[1:]):
            loop.pairs.add_coupled(make_pair(a, o, ANCHOR, geometry))
    t = 0.0
    for name, p in poses.items():
        loop.on_pose(name, t, *p)
    loop.request(BehaviorRequest(DRIVE_ASSEMBLY, [names[0]], velocities=[(DRIVE_V, DRIVE_W)],
                                 timeout=(steps + 5) * s.dt), t)
    times, failures, first_ms, lost, fallbacks = [], 0, None, 0, 0
    min_margin = math.inf
    qp_iterations, solver_ms, mpc_ms = [], [], []
    for k in range(steps + 1):
        if k == steps // 2 + 1:        # second half of the S-curve
            loop.request(BehaviorRequest(DRIVE_ASSEMBLY, [names[0]], velocities=[(DRIVE_V, -DRIVE_W)],
                                         timeout=(steps + 5) * s.dt), t)
        t0 = time.perf_counter()
        out = loop.step(t)
        ms = 1e3 * (time.perf_counter() - t0)
        if k == 0:
            first_ms = ms
        else:
            times.append(ms)
            qp_iterations.append(out.result.iterations)
            solver_ms.append(out.result.extra.get("solver_ms", float("nan")))
            mpc_ms.append(out.result.solve_time_ms)
            fallbacks += "fallback" in out.result.status
        failures += 0 if out.result.success else 1
        lost += len(out.lost or [])
        sub = s.dt / PLANT_SUBSTEPS
        for name in names:
            v, w = out.commands[name]
            p = poses[name]
            for _ in range(PLANT_SUBSTEPS):
                p = unicycle_arc(p, v, w, sub)
            poses[name] = tuple(p)
        t += s.dt
        for name, p in poses.items():
            loop.on_pose(name, t, *p)
        for pair in loop.pairs.coupled.values():
            min_margin = min(min_margin, head_margin(pair, poses[pair.robot_i], poses[pair.robot_j],
                                                     coupling_polygon(pair, geometry)))
    arr = np.array(times)
    lead_moved = math.hypot(poses[names[0]][0], poses[names[0]][1])
    return {"robots": robots, "assemblies": assemblies, "solver_threads": s.solver_threads,
            "horizon": horizon, "constraint_horizon": s.constraint_horizon,
            "steps": steps, "median_ms": round(float(np.median(arr)), 3),
            "p95_ms": round(float(np.percentile(arr, 95)), 3), "max_ms": round(float(arr.max()), 3),
            "failures": failures, "solver": s.solver, "first_step_ms": round(first_ms, 1),
            "setup_s": round(setup_s, 3), "build_s": round(loop.mpc.build_seconds, 3),
            "coupled_pairs": len(loop.pairs.coupled), "pairs_lost": lost,
            "min_pip_margin_mm": round(1e3 * min_margin, 2), "lead_moved_m": round(lead_moved, 3),
            "qp_iterations_median": float(np.median(qp_iterations)),
            "solver_median_ms": round(float(np.median(solver_ms)), 3),
            "solver_p95_ms": round(float(np.percentile(solver_ms, 95)), 3),
            "mpc_median_ms": round(float(np.median(mpc_ms)), 3),
            "mpc_p95_ms": round(float(np.percentile(mpc_ms, 95)), 3), "fallbacks": fallbacks}


def couple_trials(robots, trials, seed=0, timeout=120.0, settings=None):
    """Coupling success on the kinematic plant from random scattered starts.

    Two robots: the paper's experiment -- 65 mm apart along x, y offsets
    0..30 mm, headings within +-0.3 rad. More robots: spaced 90 mm along x
    (+-20 mm), +-40 mm sideways, headings within +-0.6 rad; target "line".
    Returns a dict: trials, coupled, coupling times [s], failed solves.
    """
    s = settings or load_settings()
    geometry = RobotGeometry()
    rng = np.random.default_rng(seed)
    times, failures = [], 0
    for trial in range(trials):
        names = ["c%d" % (k + 1) for k in range(robots)]
        if robots == 2:
            offset = 0.030 * trial / max(1, trials - 1)
            poses = {names[0]: (0.0, 0.0, rng.uniform(-0.3, 0.3)),
                     names[1]: (-0.065, offset, rng.uniform(-0.3, 0.3))}
        else:
            poses = {n: (-0.09 * k + rng.uniform(-0.02, 0.02), rng.uniform(-0.04, 0.04), rng.uniform(-0.6, 0.6))
                     for k, n in enumerate(names)}
        loop = ControlLoop(names, s, geometry)
        t = 0.0
        for name, p in poses.items():
            loop.on_pose(name, t, *p)
        rid = loop.request(BehaviorRequest("couple", names, target="line", timeout=timeout), t)
        while t < timeout + 1.0:
            out = loop.step(t)
            failures += 0 if out.result.success else 1
            for name in names:
                v, w = out.commands[name]
                p = poses[name]
                for _ in range(PLANT_SUBSTEPS):
                    p = unicycle_arc(p, v, w, s.dt / PLANT_SUBSTEPS)
                poses[name] = tuple(p)
            t += s.dt
            for name, p in poses.items():
                loop.on_pose(name, t, *p)
            if out.status.request_id == rid and out.status.state != 1:
                if out.status.state == 2:
                    times.append(t)
                break
    return {"robots": robots, "trials": trials, "coupled": len(times),
            "mean_s": round(float(np.mean(times)), 2) if times else None,
            "max_s": round(float(np.max(times)), 2) if times else None, "failed_solves": failures}


def machine():
    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    return {"cpu_count": os.cpu_count(), "machine": platform.machine(), "python": platform.python_version(),
            "load_avg_1_5_15": [round(x, 2) for x in load]}


def table(results):
    """Markdown table: rows N, columns Hm (median / p95 ms)."""
    horizons = sorted({r["horizon"] for r in results})
    lines = ["| N | " + " | ".join("Hm=%d median / p95 [ms]" % h for h in horizons) + " | failures |",
             "|---|" + "---|" * len(horizons) + "---|"]
    for n in sorted({r["robots"] for r in results}):
        row = [r for r in results if r["robots"] == n]
        cells = []
        for h in horizons:
            c = [r for r in row if r["horizon"] == h]
            cells.append("%.1f / %.1f" % (c[0]["median_ms"], c[0]["p95_ms"]) if c else "-")
        lines.append("| %d | %s | %d |" % (n, " | ".join(cells), sum(r["failures"] for r in row)))
    return "\n".join(lines)


def solver_table(results, horizon=10):
    """Markdown table at one Hm: step median / p95, the MPC's and the solver's part of it, QP iterations,
    Clarabel fallbacks, failures, lost pairs."""
    lines = ["| N | step median / p95 [ms] | in the MPC: median / p95 [ms] | in the QP solver: median [ms] "
             "| QP iterations | steps with a fallback | build [s] | failures | pairs lost |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted((r for r in results if r["horizon"] == horizon), key=lambda r: r["robots"]):
        lines.append("| %d | %.1f / %.1f | %.1f / %.1f | %.1f | %g | %d | %.3f | %d | %d |" % (
            r["robots"], r["median_ms"], r["p95_ms"], r.get("mpc_median_ms", float("nan")),
            r.get("mpc_p95_ms", float("nan")), r.get("solver_median_ms", float("nan")),
            r["qp_iterations_median"], r.get("fallbacks", 0), r["build_s"], r["failures"], r["pairs_lost"]))
    return "\n".join(lines)


def _matched(results, others):
    """(result, other) for each of ``others`` with a result of the same robots and horizon (the first
    such result), in the order of ``others``."""
    for other in others:
        mine = [r for r in results if (r["robots"], r["horizon"]) == (other["robots"], other["horizon"])]
        if mine:
            yield mine[0], other


def solver_comparison_table(results, clarabel):
    """The default solver against Clarabel, the same N run right after each other."""
    name = results[0].get("solver", "default") if results else "default"
    rows = ["| N, Hm | %s: step median / p95 [ms] | Clarabel: step median / p95 [ms] | in the solver: %s / "
            "Clarabel, median [ms] | QP iterations | ratio of step medians |" % (name, name),
            "|---|---|---|---|---|---|"]
    for m, ref in _matched(results, clarabel):
        rows.append("| %d, %d | %.1f / %.1f | %.1f / %.1f | %.1f / %.1f | %g / %g | %.1fx |" % (
            ref["robots"], ref["horizon"], m["median_ms"], m["p95_ms"], ref["median_ms"], ref["p95_ms"],
            m["solver_median_ms"], ref["solver_median_ms"], m["qp_iterations_median"],
            ref["qp_iterations_median"], ref["median_ms"] / m["median_ms"]))
    return "\n".join(rows)


def reference_table(results, reference):
    """The RTI (the default solver) against IPOPT on the full NLP, same run and robots."""
    rows = ["| N, Hm | RTI (%s): median / p95 [ms] | IPOPT, full NLP: median / p95 [ms] | ratio of medians |"
            % (results[0].get("solver", "default") if results else "default"), "|---|---|---|---|"]
    for m, ref in _matched(results, reference):
        rows.append("| %d, %d | %.1f / %.1f | %.1f / %.1f | %.0fx |" % (
            ref["robots"], ref["horizon"], m["median_ms"], m["p95_ms"], ref["median_ms"], ref["p95_ms"],
            ref["median_ms"] / m["median_ms"]))
    return "\n".join(rows)


def decomposition_table(rows):
    """Several chains side by side solved jointly, as separate QPs, and on two threads."""
    out = ["| robots, chains | solved as | step median / p95 [ms] | in the solver, summed over threads [ms] "
           "| QP iterations | failures |",
           "|---|---|---|---|---|---|"]
    for r in rows:
        out.append("| %d, %d | %s | %.1f / %.1f | %.1f | %g | %d |" % (
            r["robots"], r["assemblies"], r["mode"], r["median_ms"], r["p95_ms"], r["solver_median_ms"],
            r["qp_iterations_median"], r["failures"]))
    return "\n".join(out)


def targets_table(results):
    """The measured targets (TARGETS), no failed solve and no lost pair: met or not."""
    rows = ["| target | measured | met |", "|---|---|---|"]
    cell = {(r["robots"], r["horizon"]): r for r in results}
    for n, h, stat, limit in TARGETS:
        r = cell.get((n, h))
        got = "%.1f ms" % r[stat] if r else "not run"
        rows.append("| %d robots, Hm = %d: %s <= %g ms | %s | %s |" % (
            n, h, stat.replace("_ms", ""), limit, got, ("yes" if r[stat] <= limit else "**no**") if r else "-"))
    fails = sum(r["failures"] for r in results)
    lost = sum(r["pairs_lost"] for r in results)
    rows.append("| no failed solve | %d failed | %s |" % (fails, "yes" if fails == 0 else "**no**"))
    rows.append("| no pair lost in the drive | %d lost | %s |" % (lost, "yes" if lost == 0 else "**no**"))
    return "\n".join(rows)


def page_block(doc):
    """The generated block of docs/mpc.md: set-up line and the tables of one grid run."""
    res, m = doc["results"], doc["machine"]
    return "\n\n".join([
        "`make bench` of %s: %d steps per configuration, Hc = %d, %d cores, load average %s at the end "
        "(ms; median / p95 of the whole control step)." % (doc["time"], doc["steps"], doc["constraint_horizon"],
                                                          m["cpu_count"], m["load_avg_1_5_15"]),
        table(res), "At Hm = 10, where the time goes:", solver_table(res),
        "Against Clarabel (each run right after the default solver's):",
        solver_comparison_table(res, doc.get("clarabel", [])),
        "Against IPOPT on the full NLP (same run):", reference_table(res, doc.get("reference", [])),
        "Independent assemblies (chains side by side, the first drives):",
        decomposition_table(doc.get("decomposition", [])),
        "Targets:", targets_table(res)])


def update_page(path, block):
    """Replace the text between PAGE_BEGIN and PAGE_END in ``path`` by ``block``."""
    with open(path) as f:
        text = f.read()
    a, b = text.find(PAGE_BEGIN), text.find(PAGE_END)
    if a < 0 or b < a:
        raise ValueError("%s: no %s ... %s block" % (path, PAGE_BEGIN, PAGE_END))
    with open(path, "w") as f:
        f.write(text[:a + len(PAGE_BEGIN)] + "\n" + block + "\n" + text[b:])


def grid(robots=GRID_ROBOTS):
    """(N, Hm) pairs of the grid."""
    return [(n, h) for n in robots for h in GRID_HORIZONS if h == 10 or n <= GRID_SHORT_MAX]


def main(argv=None):
    ap = argparse.ArgumentParser(description="MPC step time on a coupled chain driving as one assembly.")
    ap.add_argument("--robots", type=int, default=8, help="robots in the chain (N-1 coupled pairs)")
    ap.add_argument("--horizon", type=int, default=10, help="prediction horizon Hm")
    ap.add_argument("--constraint-horizon", type=int, default=3, help="constraint horizon Hc <= Hm")
    ap.add_argument("--steps", type=int, default=50, help="control steps measured (>= 50 for the table)")
    ap.add_argument("--solver", choices=SOLVERS, default=None, help="override mpc.yaml's solver")
    ap.add_argument("--assemblies", type=int, default=1,
                    help="one configuration: the robots form this many chains side by side; the first drives")
    ap.add_argument("--solver-threads", type=int, default=None, help="override mpc.yaml's solver_threads")
    ap.add_argument("--json", action="store_true", help="print one JSON line")
    ap.add_argument("--grid", action="store_true",
                    help="run N in %s at Hm = 10 (and 3, 5 up to %d robots), then the IPOPT reference, and print "
                         "the tables" % (GRID_ROBOTS, GRID_SHORT_MAX))
    ap.add_argument("--grid-robots", default=None, metavar="N,N,...",
                    help="with --grid: only these N (development; files are still written if asked)")
    ap.add_argument("--out", action="append", default=[], help="with --grid: write the results as JSON here")
    ap.add_argument("--page", default=None, help="with --grid: rewrite the generated block of this page "
                                                 "(docs/mpc.md)")
    ap.add_argument("--couple-trials", type=int, default=0, metavar="T",
                    help="instead: T coupling trials of --robots robots from random starts (kinematic plant)")
    args = ap.parse_args(argv)
    if args.couple_trials > 0:
        r = couple_trials(args.robots, args.couple_trials)
        print(json.dumps(r))
        return 0
    if args.robots < 2 or args.horizon < 1 or args.steps < 1 or args.constraint_horizon < 1:
        ap.error("need --robots >= 2, --horizon >= 1, --constraint-horizon >= 1, --steps >= 1")
    if not 1 <= args.assemblies <= args.robots // 2 or (args.solver_threads is not None and args.solver_threads < 1):
        ap.error("need 1 <= --assemblies <= robots / 2 and --solver-threads >= 1")
    settings = load_settings()
    if args.solver_threads:
        settings = replace(settings, solver_threads=args.solver_threads)
    if not args.grid:
        r = run(args.robots, args.horizon, args.constraint_horizon, args.steps, settings=settings,
                solver=args.solver, assemblies=args.assemblies)
        if args.json:
            print(json.dumps(r))
        else:
            print("N=%d Hm=%d Hc=%d: median %.2f ms, p95 %.2f ms, failures %d (%s)"
                  % (r["robots"], r["horizon"], r["constraint_horizon"], r["median_ms"], r["p95_ms"],
                     r["failures"], r["solver"]))
        return 0 if r["failures"] == 0 else 1
    robots = GRID_ROBOTS
    if args.grid_robots:
        try:
            robots = tuple(int(v) for v in args.grid_robots.split(","))
        except ValueError:
            ap.error("--grid-robots: a comma list of robot counts, got %r" % args.grid_robots)
        if min(robots) < 2:
            ap.error("--grid-robots: every N must be >= 2")
    results, reference, clarabel = [], [], []
    for n, h in grid(robots):
        r = run(n, h, args.constraint_horizon, args.steps, settings=settings, solver=args.solver)
        print(json.dumps(r), flush=True)
        results.append(r)
        if h == 10 and n in SOLVER_REFERENCE and r["solver"] != "clarabel":
            c = run(n, h, args.constraint_horizon, args.steps, settings=settings, solver="clarabel")
            print(json.dumps(c), flush=True)
            clarabel.append(c)
    if REFERENCE[0] in robots and args.solver != "ipopt":
        r = run(REFERENCE[0], REFERENCE[1], args.constraint_horizon, args.steps, settings=settings, solver="ipopt")
        print(json.dumps(r), flush=True)
        reference.append(r)
    decomposition = []
    for n, k in DECOMPOSITION:
        if n not in robots:
            continue
        for label, over in DECOMPOSITION_MODES:
            r = run(n, 10, args.constraint_horizon, args.steps, settings=replace(settings, **over), solver=args.solver,
                    assemblies=k)
            r["mode"] = label
            print(json.dumps(r), flush=True)
            decomposition.append(r)
    doc = {"benchmark": "puzzlebot_mpc.bench", "machine": machine(), "steps": args.steps,
           "constraint_horizon": args.constraint_horizon, "time": time.strftime("%Y-%m-%d %H:%M:%S"),
           "results": results, "reference": reference, "clarabel": clarabel, "decomposition": decomposition}
    for path in args.out:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        with open(path, "w") as f:
            json.dump(doc, f, indent=1)
    block = page_block(doc)
    if args.page:
        update_page(args.page, block)
    print()
    print("MPC step time (ControlLoop.step wall time), chain of N coupled robots driving")
    print(block)
    return 0 if all(r["failures"] == 0 for r in results + reference + clarabel) else 1


if __name__ == "__main__":
    sys.exit(main())
