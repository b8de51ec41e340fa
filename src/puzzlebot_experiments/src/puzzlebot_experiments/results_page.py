"""Tables and figures of docs/results.md from the experiments' results (no ROS, no Bullet).

``make experiments`` (scripts/experiments) runs the sweeps and then calls
:func:`update_page`: every block between ``<!-- BEGIN name -->`` and
``<!-- END name -->`` in docs/results.md is replaced by the generated table
of that name; the prose around the blocks is written by hand. Figures are
PNG files next to the page (docs/img/results_*.png).

Inputs (all produced by the sweep): coupling and decoupling records
(puzzlebot_experiments.experiments), the MPC benchmark JSON (``make bench``), the
force profile CSV (puzzlebot_experiments.rig) and the chain trial records
(puzzlebot_experiments.trials.chain_step_trial).
"""

import csv
import math
import re

import numpy as np

from puzzlebot_common.errors import ConfigError
from puzzlebot_experiments.experiments import summarize

#: The paper's figures (../shared/notes/facts.md, "Paper results to reproduce and beat").
PAPER_COUPLE_BEST = 0.975        # success rate at zero offset, the paper's best
PAPER_DECOUPLE_RATE = 0.99
PAPER_DECOUPLE_MEAN_S = 7.02
GOAL_COUPLE_RATE = 0.99          # issue goals: every offset 0-30 mm
GOAL_DECOUPLE_RATE = 1.0
GOAL_DECOUPLE_MEAN_S = 4.0
#: s, chain_step_trial's default timeout (records written before it recorded its own: timeout_s)
CHAIN_TIMEOUT_S = 30.0


def by_offset(records):
    """{offset_mm: [records]} of coupling records, offsets ascending."""
    out = {}
    for r in records:
        out.setdefault(round(float(r["offset_mm"]), 3), []).append(r)
    return dict(sorted(out.items()))


def _fmt(v, spec="%.2f"):
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else spec % v


def wilson_interval(successes, trials, z=1.96):
    """95 % Wilson score interval of a success rate (lower, upper)."""
    if trials == 0:
        return (float("nan"), float("nan"))
    p = successes / trials
    d = 1 + z * z / trials
    c = (p + z * z / (2 * trials)) / d
    h = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def couple_table(records):
    rows = ["| offset [mm] | trials | success | 95 % interval | mean time [s] | median [s] | max [s] | "
            "controller agreed | goal >= 99 % |", "|---|---|---|---|---|---|---|---|---|"]
    for off, recs in by_offset(records).items():
        s = summarize(recs)
        lo, hi = wilson_interval(s["successes"], s["trials"])
        agreed = sum((r.get("controller") == "succeeded") == bool(r["success"]) for r in recs)
        rows.append("| %g | %d | %.1f %% | %.1f-%.1f %% | %s | %s | %s | %d/%d | %s |" % (
            off, s["trials"], 100 * s["success_rate"], 100 * lo, 100 * hi, _fmt(s["mean_time_s"]),
            _fmt(s["median_time_s"]), _fmt(s["max_time_s"]), agreed, len(recs),
            "met" if s["success_rate"] >= GOAL_COUPLE_RATE else "**not met**"))
    return "\n".join(rows)


def decouple_table(records):
    s = summarize(records)
    times = [r["time_s"] for r in records if r["success"] and r.get("time_s") is not None]
    p90 = float(np.percentile(times, 90)) if times else None
    met = s["success_rate"] >= GOAL_DECOUPLE_RATE and (s["mean_time_s"] or math.inf) <= GOAL_DECOUPLE_MEAN_S
    return "\n".join([
        "| | trials | success | mean time [s] | median [s] | 90th pct [s] | max [s] |",
        "|---|---|---|---|---|---|---|",
        "| paper (hardware) | 100 | %.0f %% | %.2f | - | - | - |" % (100 * PAPER_DECOUPLE_RATE, PAPER_DECOUPLE_MEAN_S),
        "| this stack (Bullet) | %d | %.1f %% | %s | %s | %s | %s |" % (
            s["trials"], 100 * s["success_rate"], _fmt(s["mean_time_s"]), _fmt(s["median_time_s"]), _fmt(p90),
            _fmt(s["max_time_s"])),
        "",
        "Goal (100 %%, mean <= %.0f s): **%s**." % (GOAL_DECOUPLE_MEAN_S, "met" if met else "not met")])


def bench_table(bench):
    """MPC step time table (median / p95 ms) from the benchmark JSON, robots x Hm."""
    res = bench.get("results", [])
    hms = sorted({r["horizon"] for r in res})
    ns = sorted({r["robots"] for r in res})
    cell = {(r["robots"], r["horizon"]): r for r in res}
    rows = ["| robots | " + " | ".join("Hm = %d: median / p95 [ms]" % h for h in hms) + " | failures |",
            "|---|" + "---|" * len(hms) + "---|"]
    for n in ns:
        cells, fails = [], 0
        for h in hms:
            r = cell.get((n, h))
            cells.append("%.1f / %.1f" % (r["median_ms"], r["p95_ms"]) if r else "-")
            fails += r["failures"] if r else 0
        rows.append("| %d | %s | %d |" % (n, " | ".join(cells), fails))
    return "\n".join(rows)


def bench_summary(bench, period_ms=100.0, paper_robots=8, horizon=10):
    """The prose figures beside the MPC time table, from the same JSON (never typed by hand): the
    paper's largest size and the largest one measured at Hm = ``horizon``, as shares of the control
    period, and the failures of every configuration."""
    res = bench.get("results", [])
    cell = {(r["robots"], r["horizon"]): r for r in res}
    fails = sum(r["failures"] for r in res)
    largest = max((r["robots"] for r in res if r["horizon"] == horizon), default=None)
    parts = []
    for n, what in ((paper_robots, "At the paper's largest size, %d robots with Hm = %d," % (paper_robots, horizon)),
                    (largest, "With %s robots," % largest)):
        r = cell.get((n, horizon))
        if r is not None:
            parts.append("%s one step takes %.1f ms median (p95 %.1f ms, max %.1f ms): %.0f %% of the %.0f ms "
                         "control period." % (what, r["median_ms"], r["p95_ms"], r["max_ms"],
                                              100 * r["median_ms"] / period_ms, period_ms))
    parts.append("%s (%d configurations, %d steps each)." % (
        "Every configuration solved every step" if fails == 0 else "%d failed steps in all" % fails, len(res),
        bench.get("steps", 0)))
    return "\n".join(parts)


def force_table(summary):
    return "\n".join([
        "| | paper (measured rig) | this simulation |", "|---|---|---|",
        "| forward push, peak | < 0.2 N | %.3f N |" % summary["forward_peak_n"],
        "| backward pull at 4 mm | 0.5-0.7 N | %.3f N |" % summary["backward_at_4mm_n"]])


def chain_table(records):
    """Per seed: outcome, robots upright on the floor, and the first pair that came apart (when, the
    pitch of every robot then, that pair's largest barb angle against the snap angle, and how far its
    anchor was pulled out of its holder); a total row."""
    rows = ["| seed | outcome | upright on the floor | first pair apart (anchor>opening) | at [s] | "
            "pitch then [rad] | barb max / snap [rad] | anchor pulled out [mm] |",
            "|---|---|---|---|---|---|---|---|"]
    for r in sorted(records, key=lambda r: r["seed"]):
        f = r.get("first_separation")
        if r["success"]:
            outcome = "**down** in %s s" % _fmt(r.get("time_s"), "%.1f")
        else:
            outcome = "apart" if f else "not down"
        sep = ["-"] * 5
        if f:
            sep = [f["pair"], "%.2f" % f["time_s"], ", ".join("%s %.2f" % kv for kv in sorted(f["pitch_rad"].items())),
                   "%.2f / %.2f" % (f["max_barb_rad"], f["snap_rad"]), "%.1f" % f["max_pullout_mm"]]
        rows.append("| %s | %s | %d of %d | %s |" % (r["seed"], outcome, r["upright_on_floor"], r["robots"],
                                                   " | ".join(sep)))
    ok = sum(bool(r["success"]) for r in records)
    rows.append("| **all** | **%d of %d down intact** | | | | | | |" % (ok, len(records)))
    return "\n".join(rows)


def read_force_csv(path):
    """(displacement_mm, forward_n, backward_n) arrays of a force_profile.csv."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows or set(rows[0]) != {"displacement_mm", "forward_n", "backward_n"}:
        raise ConfigError("%s: expected columns displacement_mm, forward_n, backward_n" % path)
    return tuple(np.array([float(r[k]) for r in rows]) for k in ("displacement_mm", "forward_n", "backward_n"))


def force_summary(d, fwd, back):
    return {"forward_peak_n": float(np.max(fwd)), "backward_at_4mm_n": float(np.interp(4.0, d, back))}


# ----------------------------------------------------------------- figures
def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _finish(fig, axes, path, which="major"):
    """Legend and grid on every axis, then save the figure as PNG and close it."""
    for ax in axes:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3, which=which)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _plt().close(fig)


def couple_figure(records, path):
    plt = _plt()
    groups = by_offset(records)
    offs = list(groups)
    stats = [summarize(groups[o]) for o in offs]
    rate = [100 * s["success_rate"] for s in stats]
    lo_hi = [wilson_interval(s["successes"], s["trials"]) for s in stats]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    a1.errorbar(offs, rate, yerr=[[max(0.0, r - 100 * l) for r, (l, _) in zip(rate, lo_hi)],
                                  [max(0.0, 100 * h - r) for r, (_, h) in zip(rate, lo_hi)]],
                fmt="o-", capsize=3, label="this stack (Bullet, MPC)")
    a1.axhline(100 * PAPER_COUPLE_BEST, color="C3", ls="--", label="paper: best (97.5 %, 0 mm)")
    a1.axhline(100 * GOAL_COUPLE_RATE, color="C2", ls=":", label="goal: 99 %")
    a1.set_xlabel("lateral offset [mm]")
    a1.set_ylabel("coupled within 60 s [%]")
    a1.set_ylim(min(80, min(rate) - 5), 101)
    times = [[r["time_s"] for r in groups[o] if r["success"] and r.get("time_s") is not None] for o in offs]
    a2.boxplot([t if t else [float("nan")] for t in times], positions=offs, widths=1.2, showfliers=True)
    a2.plot(offs, [np.mean(t) if t else np.nan for t in times], "o-", color="C1", label="mean")
    a2.set_xlabel("lateral offset [mm]")
    a2.set_ylabel("coupling time [s]")
    a2.set_xticks(offs)
    a2.set_xticklabels(["%g" % o for o in offs], fontsize=7)
    _finish(fig, (a1, a2), path)


def decouple_figure(records, path):
    """Left: histogram of the decoupling times with their median and mean (the times are bimodal: most
    free on the first swing, the rest after a reseat or more; the mean alone misleads). Right: their
    empirical CDF (share of trials decoupled by a time), the paper's mean and the goal marked."""
    plt = _plt()
    times = np.sort([r["time_s"] for r in records if r["success"] and r.get("time_s") is not None])
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6))
    if len(times):
        a1.hist(times, bins=np.arange(0, times[-1] + 1.0, 0.5), color="C0", alpha=0.8,
                label="this stack (%d decoupled)" % len(times))
        a1.axvline(np.median(times), color="k", ls="-", label="median %.2f s" % np.median(times))
        a1.axvline(np.mean(times), color="C1", ls="-.", label="mean %.2f s" % np.mean(times))
        a2.step(np.concatenate([[0.0], times]), np.arange(len(times) + 1) / len(records) * 100.0, where="post",
                color="C0", label="this stack: %d of %d trials" % (len(times), len(records)))
        for q in (50, 90):
            t = np.percentile(times, q)
            a2.plot([t], [q * len(times) / len(records)], "o", color="k", ms=4)
            a2.annotate("%d %%: %.1f s" % (q, t), (t, q * len(times) / len(records)), textcoords="offset points",
                        xytext=(6, -10), fontsize=8)
    for ax in (a1, a2):
        ax.axvline(PAPER_DECOUPLE_MEAN_S, color="C3", ls="--", label="paper: mean 7.02 s")
        ax.axvline(GOAL_DECOUPLE_MEAN_S, color="C2", ls=":", label="goal: mean <= 4 s")
        ax.set_xlabel("decoupling time [s]")
    a1.set_ylabel("trials")
    a2.set_ylabel("decoupled by then [% of trials]")
    a2.set_ylim(0, 102)
    _finish(fig, (a1, a2), path)


def bench_figure(bench, path):
    plt = _plt()
    res = bench.get("results", [])
    fig, ax = plt.subplots(figsize=(6, 3.8))
    for h in sorted({r["horizon"] for r in res}):
        pts = sorted((r["robots"], r["median_ms"], r["p95_ms"]) for r in res if r["horizon"] == h)
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label="Hm = %d (median)" % h)
        ax.fill_between([p[0] for p in pts], [p[1] for p in pts], [p[2] for p in pts], alpha=0.15)
    ax.axhline(100.0, color="k", ls=":", label="control period 100 ms")
    ax.set_xlabel("robots")
    ax.set_ylabel("MPC step [ms] (band: median-p95)")
    ax.set_yscale("log")
    _finish(fig, (ax,), path, which="both")


def force_figure(d, fwd, back, path):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(d, fwd, label="pushed in (forward)")
    ax.plot(d, back, label="pulled back")
    ax.errorbar([4.0], [0.6], yerr=[[0.1], [0.1]], fmt="none", ecolor="C1", elinewidth=6, alpha=0.5, capsize=0,
                label="paper: 0.5-0.7 N back at 4 mm")
    ax.axhline(0.2, color="C0", ls=":", label="paper: forward peak < 0.2 N")
    ax.set_xlabel("probe displacement [mm]")
    ax.set_ylabel("force [N]")
    _finish(fig, (ax,), path)


def chain_figure(records, path):
    """Left: per seed, when the first pair came apart (marker: which pair), when the chain was down, or
    (grey) that it stayed intact but not every robot was down when the trial's time ran out.
    Right: the separating pair's largest barb angle against the snap angle (beyond it the barbs fold
    and the anchor comes out through the force profile)."""
    plt = _plt()
    recs = sorted(records, key=lambda r: r["seed"])
    seeds = [r["seed"] for r in recs]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6))
    pairs = sorted({r["first_separation"]["pair"] for r in recs if r.get("first_separation")})
    for k, pair in enumerate(pairs):
        pts = [(r["seed"], r["first_separation"]["time_s"]) for r in recs
               if r.get("first_separation") and r["first_separation"]["pair"] == pair]
        a1.plot([p[0] for p in pts], [p[1] for p in pts], "x", ms=9, mew=2, color="C%d" % (k + 3),
                label="pair %s came apart" % pair)
    down = [(r["seed"], r["time_s"]) for r in recs if r["success"] and r.get("time_s") is not None]
    if down:
        a1.plot([p[0] for p in down], [p[1] for p in down], "o", ms=9, color="C2", label="all down, intact")
    stuck = [r for r in recs if not r["success"] and not r.get("first_separation")]
    if stuck:                  # intact, but not every robot on the floor when the trial's time ran out
        a1.plot([r["seed"] for r in stuck], [r.get("timeout_s", CHAIN_TIMEOUT_S) for r in stuck], "v", ms=9,
                color="0.4", label="intact, not all down in time")
        for r in stuck:
            a1.annotate("%d/%d on the floor" % (r.get("upright_on_floor", 0), r.get("robots", 3)),
                        (r["seed"], r.get("timeout_s", CHAIN_TIMEOUT_S)), textcoords="offset points",
                        xytext=(0, -16), ha="center", fontsize=7, color="0.3")
    a1.set_xlabel("seed")
    a1.set_ylabel("time from the start [s]")
    a1.set_xticks(seeds)
    sep = [r for r in recs if r.get("first_separation")]
    if sep:
        a2.bar([r["seed"] for r in sep], [r["first_separation"]["max_barb_rad"] for r in sep], color="C0",
               label="largest barb angle of that pair")
        a2.axhline(sep[0]["first_separation"]["snap_rad"], color="C3", ls="--", label="snap angle")
        a2.set_ylim(0.0, 1.35 * max(r["first_separation"]["max_barb_rad"] for r in sep))
    a2.set_xlabel("seed")
    a2.set_ylabel("barb angle from rest [rad]")
    a2.set_xticks(seeds)
    _finish(fig, (a1, a2), path)


def assembly_table(summary):
    """Per line size N (puzzlebot_experiments.assembly.summarize): trials, lines coupled and checked in
    Bullet, lines that then drove 0.2 m, the median couple time, and how often the controller said
    "coupled" while Bullet found a pair not seated."""
    rows = ["| robots N | trials | coupled (checked in Bullet) | coupled and drove 0.2 m | median couple [s] | "
            "controller said coupled, a pair not seated | pairs held coupled: seated in Bullet |",
            "|---|---|---|---|---|---|---|"]
    for n, s in sorted(summary.items()):
        held, bad = s.get("pairs_coupled", 0), s.get("pairs_not_seated", 0)
        rows.append("| %d | %d | %d | %d | %s | %d | %s |" % (
            n, s["trials"], s["couple_successes"], s["successes"],
            "-" if s["median_couple_s"] is None else "%.1f" % s["median_couple_s"], s["mismatches"],
            "%d of %d" % (held - bad, held) if held else "-"))
    return "\n".join(rows)


def assembly_figure(summary, path, paper=(2, 8)):
    """Success rate and median couple time against the line size, the paper's reach shaded."""
    plt = _plt()
    ns = sorted(summary)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax in (a1, a2):
        ax.axvspan(paper[0] - 0.5, paper[1] + 0.5, color="0.9", zorder=0,
                   label="the paper's lines (%d-%d robots)" % paper)
    a1.plot(ns, [summary[n]["couple_successes"] / summary[n]["trials"] for n in ns], "o-", color="C0",
            label="coupled, checked in Bullet")
    a1.plot(ns, [summary[n]["successes"] / summary[n]["trials"] for n in ns], "s--", color="C2",
            label="coupled and drove 0.2 m")
    a1.set_ylim(-0.05, 1.05)
    a1.set_xlabel("robots in the line")
    a1.set_ylabel("share of trials")
    timed = [n for n in ns if summary[n]["median_couple_s"] is not None]
    a2.plot(timed, [summary[n]["median_couple_s"] for n in timed], "o-", color="C1",
            label="median couple time (successes)")
    a2.set_xlabel("robots in the line")
    a2.set_ylabel("simulated time [s]")
    for ax in (a1, a2):
        ax.set_xticks(ns)
    _finish(fig, (a1, a2), path)


# -------------------------------------------------------------------- page
_BLOCK = re.compile(r"(<!-- BEGIN (?P<name>[a-z_]+) -->\n)(?P<body>.*?)(<!-- END (?P=name) -->)", re.S)


def replace_blocks(text, blocks):
    """``text`` with the body of every named block replaced; unknown blocks are kept, missing ones raise."""
    found = set()

    def sub(m):
        name = m.group("name")
        if name not in blocks:
            return m.group(0)
        found.add(name)
        return m.group(1) + blocks[name].rstrip("\n") + "\n" + m.group(4)

    out = _BLOCK.sub(sub, text)
    missing = sorted(set(blocks) - found)
    if missing:
        raise ConfigError("no <!-- BEGIN name --> ... <!-- END name --> block for %s" % ", ".join(missing))
    return out


def update_page(path, blocks):
    with open(path) as f:
        text = f.read()
    new = replace_blocks(text, blocks)
    with open(path, "w") as f:
        f.write(new)
    return new != text
