"""The paper's experiments as one resumable run: ``make experiments`` (scripts/experiments).

1. coupling success vs lateral offset (puzzlebot_experiments.experiments, ``couple``);
2. decoupling (``decouple``);
3. MPC compute time vs robots and Hm (the benchmark JSON of ``make bench``);
4. the anchor force profile (puzzlebot_experiments.rig, the simulated probe);
5. the chain of three down the step (puzzlebot_experiments.trials.chain_step_trial);
6. lines of 2 to 16 scattered robots through the MPC (puzzlebot_experiments.assembly).

Trials are kept in one append-only results file, so an interrupted run
continues where it stopped; then the figures are drawn and the generated
blocks of docs/results.md are rewritten (puzzlebot_experiments.results_page).
"""

import json
import os
import platform
import sys
import time

from puzzlebot_common.errors import ConfigError
from puzzlebot_experiments import experiments as ex
from puzzlebot_experiments.executors import make_executor
from puzzlebot_experiments import results_page as page


def offsets_from(spec):
    """'0:30:2' -> [0, 2, ..., 30]; '0,4,8' -> [0, 4, 8] (mm)."""
    try:
        if ":" in spec:
            a, b, step = (float(v) for v in spec.split(":"))
            if step <= 0 or b < a:
                raise ValueError
            n = int(round((b - a) / step))
            return [round(a + k * step, 3) for k in range(n + 1)]
        return [float(v) for v in spec.split(",") if v.strip()]
    except ValueError:
        raise ConfigError("--offsets: expected START:STOP:STEP or a comma list of mm, got %r" % spec) from None


def machine():
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "load_avg_1_5_15": [round(v, 2) for v in load] if load else None}


def _chain_one(seed):
    from puzzlebot_sim.config import load_sim_config
    from puzzlebot_experiments.trials import chain_step_trial

    cfg = load_sim_config()
    return chain_step_trial(seed, sim=cfg.sim, robot=cfg.robot, anchor=cfg.anchor)


def chain_trials(seeds, executor, results):
    """Chain-of-three trials on ``executor``, kept in ``results`` (one JSON line each, keyed by seed and version)."""
    version = ex.config_hash({"experiment": "chain"})
    store = ex.ResultsFile(results)
    have = {r["seed"]: r for r in store.load() if r.get("experiment") == "chain" and r.get("config") == version}
    todo = [s for s in seeds if s not in have]
    progress = ex.Progress("chain down the step", len(seeds), len(seeds) - len(todo))
    progress.ok = sum(bool(have[s]["success"]) for s in seeds if s in have)
    progress.show()
    for rec in executor.run(_chain_one, todo):
        rec = dict(rec, experiment="chain", config=version)
        store.append(rec)
        have[rec["seed"]] = rec
        progress.update(rec["success"])
    return [have[s] for s in seeds]


def run(args, out=sys.stdout):
    """Run the suite (args: see scripts/experiments); returns the summary dict."""
    with make_executor(args.cluster, args.jobs or None) as executor:
        return _run(args, executor, out)


def _run(args, executor, out):
    t0 = time.monotonic()
    offsets = offsets_from(args.offsets)
    os.makedirs(args.img, exist_ok=True)
    summary = {"machine": machine(), "seed": args.seed, "trials": args.trials, "commit": ex.code_version(),
               "config": ex.config_hash(), "executor": executor.describe()}

    t = time.monotonic()
    couple = ex.run_sweep(ex.tasks_for(ex.COUPLE, args.trials, args.seed, offsets), args.results,
                          label="couple %g-%g mm" % (offsets[0], offsets[-1]), executor=executor)
    summary["couple_wall_s"] = round(time.monotonic() - t, 1)
    summary["couple"] = {"%g" % o: ex.summarize(r) for o, r in page.by_offset(couple).items()}
    page.couple_figure(couple, os.path.join(args.img, "results_coupling.png"))

    t = time.monotonic()
    decouple = ex.run_sweep(ex.tasks_for(ex.DECOUPLE, args.trials, args.seed), args.results,
                            label="decouple", executor=executor)
    summary["decouple_wall_s"] = round(time.monotonic() - t, 1)
    summary["decouple"] = ex.summarize(decouple)
    page.decouple_figure(decouple, os.path.join(args.img, "results_decoupling.png"))

    blocks = {"couple_table": page.couple_table(couple), "decouple_table": page.decouple_table(decouple)}

    if os.path.isfile(args.bench):
        with open(args.bench) as f:
            bench = json.load(f)
        page.bench_figure(bench, os.path.join(args.img, "results_mpc_time.png"))
        blocks["bench_table"] = page.bench_table(bench)
        blocks["bench_summary"] = page.bench_summary(bench)
    else:
        out.write("experiments: no benchmark file %s (make bench writes it): MPC table not updated\n" % args.bench)

    from puzzlebot_sim.config import load_sim_config
    from puzzlebot_experiments.rig import characterise

    cfg = load_sim_config()
    force_dir = os.path.join(os.path.dirname(os.path.abspath(args.results)), "force_profile")
    characterise(force_dir, cfg.robot, cfg.anchor, physics_rate=cfg.sim.physics_rate,
                 solver_iterations=cfg.sim.solver_iterations)
    d, fwd, back = page.read_force_csv(os.path.join(force_dir, "force_profile.csv"))
    page.force_figure(d, fwd, back, os.path.join(args.img, "results_force_profile.png"))
    summary["force"] = page.force_summary(d, fwd, back)
    blocks["force_table"] = page.force_table(summary["force"])

    t = time.monotonic()
    chain = chain_trials(list(range(args.seed, args.seed + args.chain_trials)), executor, args.results)
    summary["chain_wall_s"] = round(time.monotonic() - t, 1)
    summary["chain"] = {"trials": len(chain), "successes": sum(bool(r["success"]) for r in chain)}
    blocks["chain_table"] = page.chain_table(chain)
    page.chain_figure(chain, os.path.join(args.img, "results_chain.png"))

    if args.assembly_trials:
        from puzzlebot_experiments import assembly

        t = time.monotonic()
        sizes = [int(v) for v in str(args.assembly_sizes).split(",") if v.strip()]
        lines = assembly.assembly_sweep(sizes, args.assembly_trials, args.seed, executor, args.results)
        summary["assembly_wall_s"] = round(time.monotonic() - t, 1)
        summary["assembly"] = assembly.summarize(lines)
        blocks["assembly_table"] = page.assembly_table(summary["assembly"])
        page.assembly_figure(summary["assembly"], os.path.join(args.img, "results_assembly.png"))

    summary["wall_s"] = round(time.monotonic() - t0, 1)
    blocks["run_info"] = run_info(summary)
    if args.page:
        page.update_page(args.page, blocks)
    with open(os.path.join(os.path.dirname(os.path.abspath(args.results)), "summary.json"), "w") as f:
        json.dump(summary, f, indent=1)
    return summary


def run_info(s):
    m = s["machine"]
    return "\n".join([
        "| | |", "|---|---|",
        "| command | `make experiments` (seed %d, %d trials per offset and for decoupling) |" % (s["seed"], s["trials"]),
        "| code | `%s`, configuration hash `%s` |" % (s["commit"], s["config"]),
        "| machine | %s, %d cores, Python %s, load average %s at the end |" % (
            m["cpu"], m["cores"] or 0, m["python"], m["load_avg_1_5_15"]),
        "| trials ran on | %s |" % s.get("executor", "a local process pool"),
        "| wall time | coupling %.0f s, decoupling %.0f s, chain %.0f s, lines %.0f s, all %.0f s (trials already "
        "in the results file are not rerun) |" % (s["couple_wall_s"], s["decouple_wall_s"], s["chain_wall_s"],
                                                 s.get("assembly_wall_s", 0.0), s["wall_s"])])
