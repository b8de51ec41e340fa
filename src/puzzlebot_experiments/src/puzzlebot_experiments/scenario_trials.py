"""A scenario run in-process over seeds: the same steps sim.launch runs, checked in Bullet.

``sim.launch scenario:=NAME`` runs one scenario once through ROS; this runs it
many times, in parallel processes, without ROS: the Bullet world and the MPC
node's core in lockstep (``puzzlebot_experiments.closed_loop.ClosedLoop``) with the
lab's Vicon noise, exactly as the experiments of docs/results.md do. Trial k
of seed S uses the world seed drawn from ``SeedSequence([S, k])``.

A step counts only when the behaviour succeeded *and* Bullet agrees:

- couple / drive_assembly: every pair the controller holds coupled is seated
  in Bullet (both barb tips behind the lips);
- decouple: the pair's anchor is out of the opening, every other coupled pair
  still seated;
- after every step: every anchor still in its holder.

A trial succeeds when every step does; it stops at the first failed step.

One trial can be followed pair by pair (:class:`PairTrace`, ``scenario_trials
--trial K --trace A-B``): what the controller believed of the pair, the docking
manoeuvre's phase, what Bullet had, and the relative pose and commands,
every ``--trace-every`` s. The trace reads only what each control step already
measured (the mocap noise draws stay those of the untraced run), so a traced
trial is the same trial.
"""

import re
from collections import Counter
from dataclasses import replace

import numpy as np
import yaml

from puzzlebot_common.errors import ConfigError

from puzzlebot_common.robots import parse_robot_list
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.config_files import load_settings
from puzzlebot_mpc.docking import seat_measure
from puzzlebot_mpc.behaviors import FAILED, STATE_NAMES, SUCCEEDED, BehaviorRequest
from puzzlebot_experiments.closed_loop import ClosedLoop, make_world
from puzzlebot_sim.coupling import (BARB_FOLDED, BARB_ON_LIP, BARB_OUTSIDE, HEAD_ALIGNED, HEAD_INSERTED, KNOB_PARTLY,
                                    STATUS_NAMES as BULLET_STATUS)
from puzzlebot_experiments.experiments import MOCAP, anchor_in_holder
from puzzlebot_experiments.pull_check import PULLS, pull_pairs
from puzzlebot_sim.config import load_model, load_sim_config
from puzzlebot_sim.world import RobotStart

from puzzlebot_bringup.launch_config import sim_config
from puzzlebot_bringup.scenario import parse_scenario

SETTLE = 2.0     # s of simulated time a step may run past its own timeout before it counts as hung
SETTLE_AT_START = 0.3  # s the robots settle on the floor before the first step
NOT_IN_OPENING = "the anchor not in the opening"
NOT_AT_HOLE = "the knob not at the hole"


def world_seed(seed, trial):
    """The Bullet world's seed of trial ``trial`` of seed ``seed``."""
    return int(np.random.SeedSequence([seed, trial]).generate_state(1)[0])


def request_of(step):
    """BehaviorRequest of a scenario Step."""
    return BehaviorRequest(step.behavior, list(step.robots), [tuple(g) for g in step.goals],
                           [tuple(v) for v in step.velocities], step.tolerance, step.timeout, step.target,
                           [tuple(s) for s in step.slots], list(step.pair), step.distance, list(step.groups),
                           cross_edges=step.cross_edges)


def heights(cl):
    """{robot: base_link height [m]} in Bullet."""
    return {name: cl.world.pose(name)[0][2] for name in cl.names}


def physical_problems(cl, step, coupled, body_side, z_start=None):
    """What Bullet contradicts after ``step`` (a list of short texts; empty: it agrees). ``z_start``: the
    robots' heights at the step's start ({robot: m}): a robot that went down by more than half the stage's
    height in a step without ``cross_edges`` left its stage (the MPC's stage edges should have held it)."""
    found = {(p.anchor_robot, p.opening_robot): p for p in cl.world.all_physical_pairs()}
    physical = {key: p.status for key, p in found.items()}
    problems = []
    for key in coupled:
        if physical.get(key, 0) != HEAD_INSERTED:
            pair = cl.loop.pairs.find(*key)
            absent = NOT_AT_HOLE if pair is not None and pair.type == pr.KNOB else NOT_IN_OPENING
            reason = found[key].reason if key in found else absent
            problems.append("%s-%s not seated%s" % (key + (" (%s)" % reason if reason else "",)))
    if step.behavior == "decouple":
        a, b = step.pair
        if max(physical.get((a, b), 0), physical.get((b, a), 0)) >= HEAD_ALIGNED:
            problems.append("%s-%s still in the opening" % (a, b))
    for name in cl.names:
        inside, x, yaw = anchor_in_holder(cl.world, name, body_side)
        if not inside:
            problems.append("%s's anchor out of its holder (x %.1f mm, yaw %.2f rad)" % (name, 1e3 * x, yaw))
    if z_start and not step.cross_edges:
        drop = 0.5 * cl.world.world_params.stage_height
        for name, z in heights(cl).items():
            if z < z_start[name] - drop:
                problems.append("%s left its stage (down %.0f mm)" % (name, 1e3 * (z_start[name] - z)))
    return problems


def held_pairs(cl, coupled, body_side):
    """The anchor pairs the controller holds coupled, as Bullet has them at the end of a step: a list of
    {"pair": "A-B", "seated": bool, "gap_mm", "lateral_mm", "dtheta", "anchor_turn"}.

    ``gap_mm`` (between the faces), ``lateral_mm`` (C_a from the opening's axis, in the opening robot's
    frame) and ``dtheta`` [rad] (anchor robot's heading minus the opening robot's) are
    :func:`puzzlebot_mpc.docking.seat_measure` of Bullet's true poses: what the controller measures, without
    the mocap noise. ``anchor_turn`` [rad] is the anchor's yaw in its holder, which only the simulation
    knows (the hardware has no sensor for it). Knob pairs are left out.
    """
    seated = {(p.anchor_robot, p.opening_robot) for p in cl.world.all_physical_pairs() if p.status == HEAD_INSERTED}
    out = []
    for key in coupled:
        pair = cl.loop.pairs.find(*key)
        if pair is None or pair.type != pr.ANCHOR:
            continue
        pose_i, pose_j = cl.world.pose2d(key[0]), cl.world.pose2d(key[1])
        gap, lateral, dtheta = seat_measure(pair, pose_i, pose_j)
        turn = anchor_in_holder(cl.world, key[0], body_side)[2]
        out.append({"pair": "%s-%s" % key, "seated": key in seated, "gap_mm": round(1e3 * gap, 2),
                    "lateral_mm": round(1e3 * lateral, 2), "dtheta": round(dtheta, 4), "anchor_turn": round(turn, 4)})
    return out


def parse_overrides(items):
    """{setting: value} of ``KEY=VALUE`` texts (values read as YAML scalars: 0.002, true, active_set);
    raises ConfigError on a malformed item or a setting MPCSettings does not have or accept."""
    out = {}
    for item in items or ():
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set %r: expected KEY=VALUE (an MPC setting, e.g. dock_pull_test=true)" % item)
        try:
            out[key.strip()] = yaml.safe_load(text)
        except yaml.YAMLError as e:
            raise ConfigError("--set %s: %s" % (item, e))
    if out:
        load_settings(sim=True, overrides=out)         # unknown keys, wrong types, ranges: a clear error now
    return out


def run_trial(directory, scenario, seed, trial, cfg=None, overrides=None, on_tick=None, pull_test=False, model=None):
    """One run of ``scenario`` (from ``directory``); returns a JSON-able record.

    ``cfg``: the simulation (default: as sim.launch builds it, with the lab's mocap noise).
    ``model``: another robot and anchor model for a sensitivity study, {"robot_file": path or None,
    "robot": {field: value}, "anchor": {field: value}} (puzzlebot_sim.config.load_model: the robot file,
    default config/robot.yaml, with the overrides on top); recorded as ``model``.
    ``overrides``: MPC settings on top of mpc.yaml + mpc_sim.yaml (:func:`parse_overrides`).
    ``on_tick(cl, step_index, tick)``: called after every control tick (a :class:`PairTrace`); it
    must only read (the closed loop ``cl``, the tick's output).
    ``pull_test``: after every couple step the controller completed, pull every anchor pair it holds
    coupled apart, one robot at a time (:func:`puzzlebot_experiments.pull_check.pull_pairs`), recorded as
    the step's ``pulls``; the trial then goes on from the state before the pulls, with resting anchors off.
    """
    cfg = cfg or load_sim_config(mocap=MOCAP)
    if model:
        robot, anchor = load_model(model.get("robot_file"), model.get("robot"), model.get("anchor"))
        cfg = replace(cfg, robot=robot, anchor=anchor)
    wseed = world_seed(seed, trial)
    launch = sim_config(directory, scenario, seed=wseed)
    specs = parse_robot_list(launch.robots, where="scenario %s: robots" % scenario)
    names = [s.name for s in specs]
    sc = parse_scenario(launch.scenario, names, where="scenario %s" % scenario)
    starts = [RobotStart(s.name, *sc.start[s.name][:3], pilot=s.pilot) for s in specs]
    w = make_world(cfg, starts, wseed, world=launch.world)
    steps, ok = [], True
    try:
        w.run(SETTLE_AT_START)
        cl = ClosedLoop(w, names=names, settings=load_settings(sim=True, overrides=overrides))
        for step in sc.steps:
            req = request_of(step)
            limit = (step.timeout or 60.0) + SETTLE
            t0, z0 = cl.time, heights(cl)
            hook = None if on_tick is None else (lambda tick, k=len(steps): on_tick(cl, k, tick) and False)
            try:
                state, message, elapsed = cl.run_behavior(req, limit, on_tick=hook)
            except RuntimeError as e:          # a pose the pose gate rejects (a robot fell off a stage): the
                state, message, elapsed = FAILED, "pose rejected: %s" % e, cl.time - t0    # trial fails there
            except Exception as e:             # a bug in the stack: this trial fails and says so, the sweep goes on
                state, message, elapsed = "error", "error in the stack: %s: %s" % (type(e).__name__, e), \
                    cl.time - t0
            coupled = sorted(cl.loop.pairs.coupled)
            problems = physical_problems(cl, step, coupled, cfg.robot.body_side, z0)
            step_ok = state == SUCCEEDED and not problems
            steps.append({"behavior": step.behavior, "state": STATE_NAMES.get(state, str(state)),
                          "sim_seconds": round(elapsed, 2), "ok": step_ok, "coupled_pairs": len(coupled),
                          "problems": problems, "message": message[:160], "held": held_pairs(cl, coupled, cfg.robot.body_side)})
            if pull_test and step.behavior == "couple" and state == SUCCEEDED:
                anchors = [k for k in coupled if cl.loop.pairs.find(*k).type == pr.ANCHOR]
                steps[-1]["pulls"] = pull_pairs(cl.world, anchors)
            if not step_ok:
                ok = False
                break
        failed_steps = cl.failed_steps
    finally:
        w.close()
    rec = {"scenario": scenario, "seed": seed, "trial": trial, "success": ok, "steps": steps,
           "failed_mpc_steps": failed_steps}
    if overrides:
        rec["mpc_overrides"] = dict(overrides)
    if model:
        rec["model"] = {k: v for k, v in model.items() if v}
    return rec


class PairTrace:
    """The timeline of one pair in a trial (an ``on_tick`` for :func:`run_trial`).

    ``anchor_robot``, ``opening_robot``: the pair (the anchor robot's anchor in the
    opening robot's mouth; for a knob pair the knob robot and the hole robot:
    then ``gap_mm`` is the knob's distance out from the hole's side, ``lateral_mm``
    along it from the hole, and ``docking`` "knob lane" while the pair is
    active); ``every`` [s]: one row per this much simulated time
    (0: every control step). Each row (``rows``, dicts): ``t`` [s] simulated,
    ``step`` (index in the scenario), ``controller`` (the controller's status of
    the pair while it is a goal or coupled; "-" otherwise, e.g. while a decouple
    owns it), ``docking`` (phase, pushes started,
    aim [mm]), ``bullet`` (Bullet's status of the pair, "-": not in the
    opening), ``gap_mm`` (between the faces), ``lateral_mm`` (C_a off the
    opening's axis), ``dtheta`` [rad] (anchor robot's heading minus the opening
    robot's), all from the poses the controller measured this step, and each
    robot's command (v [m/s], w [rad/s]).
    """

    COLUMNS = ("t", "step", "controller", "docking", "bullet", "gap_mm", "lateral_mm", "dtheta", "anchor_cmd",
               "opening_cmd")

    def __init__(self, anchor_robot, opening_robot, every=0.5):
        self.anchor_robot, self.opening_robot, self.every = anchor_robot, opening_robot, float(every)
        self.rows, self._next = [], -np.inf

    def __call__(self, cl, step, tick):
        if tick.time < self._next - 1e-9:
            return
        self._next = tick.time + self.every
        a, o = self.anchor_robot, self.opening_robot
        book, out = cl.loop.pairs, tick.output
        pair = book.find(a, o)
        controller, docking = "-", "-"
        if pair is not None and pair.robot_i == a:
            controller = "coupled" if pair.key in book.coupled else pr.STATUS_NAMES[pair.status]
            d = book.docking.get(pair.key)
            if d is not None:
                docking = "%s %d %+.1f" % (d.phase, d.attempts, 1e3 * d.aim)
            elif pair in book.active and pair.type == pr.KNOB:
                docking = "knob lane"
        else:
            pair = pr.make_pair(a, o, pr.ANCHOR, cl.geometry)
        pa, po = out.poses.get(a), out.poses.get(o)
        if pa is None or po is None:
            gap, lateral, dtheta = (np.nan,) * 3
        elif pair.type == pr.KNOB:
            gap, lateral, dtheta = pr.knob_measure(pair, pa, po)
        else:
            gap, lateral, dtheta = seat_measure(pair, pa, po)
        bullet = cl.physical().get((a, o))
        self.rows.append({"t": round(tick.time, 2), "step": step, "controller": controller, "docking": docking,
                          "bullet": "-" if bullet is None else BULLET_STATUS[bullet],
                          "gap_mm": round(1e3 * gap, 1), "lateral_mm": round(1e3 * lateral, 1),
                          "dtheta": round(dtheta, 3), "anchor_cmd": tuple(round(c, 3) for c in out.commands[a]),
                          "opening_cmd": tuple(round(c, 3) for c in out.commands[o])})

    def table(self):
        """The rows as a Markdown table."""
        lines = ["| " + " | ".join(self.COLUMNS) + " |", "|" + "---|" * len(self.COLUMNS)]
        for r in self.rows:
            cells = ["%.2f" % r["t"] if c == "t" else "(%.3f, %.2f)" % r[c] if c.endswith("_cmd") else str(r[c])
                     for c in self.COLUMNS]
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)


def parse_pair(text, names=None):
    """'A-B' -> (A, B): an anchor pair named anchor robot first; ``names``: the robots it must be among."""
    parts = text.split("-")
    if len(parts) != 2 or not all(parts) or parts[0] == parts[1]:
        raise ConfigError("--trace %r: give the pair as ANCHOR_ROBOT-OPENING_ROBOT, e.g. pz7-pz8" % text)
    unknown = [p for p in parts if names is not None and p not in names]
    if unknown:
        raise ConfigError("--trace %s: no robot %s in this scenario (robots: %s)"
                          % (text, ", ".join(unknown), ", ".join(names)))
    return tuple(parts)


def run_task(task):
    """run_trial for a (directory, scenario, seed, trial[, overrides[, pull_test[, model]]]) tuple (a worker
    process's entry point)."""
    directory, scenario, seed, trial = task[:4]
    return run_trial(directory, scenario, seed, trial, overrides=task[4] if len(task) > 4 else None,
                     pull_test=bool(task[5]) if len(task) > 5 else False, model=task[6] if len(task) > 6 else None)


def pull_summary(records):
    """The pull tests of the records (run_trial's ``pull_test``) counted by Bullet's verdict before the pull:
    {"seated" | "not seated: <kind>": [pulls, pulls the pair held]}, each pair pulled twice (both robots);
    a folded barb's kind also names its tip's offset from the opening's axis, in whole millimetres."""
    out = {}
    for r in records:
        for st in r["steps"]:
            for p in st.get("pulls", []):
                why = unseated_kind(p["reason"]) if p["reason"] else p["before"]
                kind = "seated" if why == "head_inserted" else "not seated: %s" % why
                offset = re.search(r"folded into the mouth \(([0-9.]+) mm", p["reason"])
                if offset and why.endswith(BARB_FOLDED):
                    mm = int(float(offset.group(1)))
                    kind += ", tip %d-%d mm off the axis" % (mm, mm + 1)
                counts = out.setdefault(kind, [0, 0])
                for driver, _ in PULLS:
                    counts[0] += 1
                    counts[1] += bool(p[driver]["held"])
    return out


#: why Bullet found a pair the controller held coupled not seated (summarize's ``not_seated_by``)
UNSEATED_KINDS = tuple((words, "a barb " + words) for words in (BARB_FOLDED, BARB_ON_LIP, BARB_OUTSIDE)) + (
    (NOT_IN_OPENING, NOT_IN_OPENING), (KNOB_PARTLY, KNOB_PARTLY), (NOT_AT_HOLE, NOT_AT_HOLE))


def unseated_kind(problem):
    """The kind (UNSEATED_KINDS) of a "... not seated (reason)" problem text, by its first reason; "not told"
    for records written before the reasons were recorded."""
    found = [(problem.find(key), kind) for key, kind in UNSEATED_KINDS if key in problem]
    return min(found)[1] if found else "not told"


def summarize(records, scenario_steps):
    """trials, successes, and per step: how many trials got through it and its median time [s]; pairs_held:
    the pairs the controller held coupled at the end of a step, summed over every step of every trial, and
    pairs_not_seated: how many of them Bullet found not seated (the controller's belief against the physics),
    not_seated_by: those counted by why (:func:`unseated_kind`, the first barb's reason)."""
    per_step = []
    for k, step in enumerate(scenario_steps):
        done = [r["steps"][k] for r in records if len(r["steps"]) > k]
        ok = [s for s in done if s["ok"]]
        per_step.append({"step": step.describe(), "reached": len(done), "succeeded": len(ok),
                         "median_s": round(float(np.median([s["sim_seconds"] for s in ok])), 2) if ok else None,
                         "max_s": round(max(s["sim_seconds"] for s in ok), 2) if ok else None})
    held = sum(st.get("coupled_pairs", 0) for r in records for st in r["steps"])
    unseated = [p for r in records for st in r["steps"] for p in st.get("problems", []) if "not seated" in p]
    by = dict(Counter(unseated_kind(p) for p in unseated))
    return {"trials": len(records), "successes": sum(r["success"] for r in records),
            "pairs_held": held, "pairs_not_seated": len(unseated), "not_seated_by": by,
            "failed_trials": sorted(r["trial"] for r in records if not r["success"]),
            "failed_mpc_steps": int(sum(r["failed_mpc_steps"] for r in records)), "steps": per_step}


def held_pose_ranges(records):
    """The relative poses of the pairs held coupled (the steps' ``held``, :func:`held_pairs`), split by
    Bullet's verdict: {"seated": ..., "not seated": ...}, each with the count and (min, median, max) of
    |lateral_mm|, gap_mm and |anchor_turn|; a verdict with no pairs is left out. Records written before
    ``held`` was kept contribute nothing."""
    groups = {}
    for r in records:
        for st in r["steps"]:
            for h in st.get("held", []):
                groups.setdefault("seated" if h["seated"] else "not seated", []).append(h)

    def spread(values):
        v = np.asarray(values, float)
        v = v[np.isfinite(v)]
        return (float(v.min()), float(np.median(v)), float(v.max())) if len(v) else None

    return {verdict: {"pairs": len(hs), "lateral_mm": spread([abs(h["lateral_mm"]) for h in hs]),
                      "gap_mm": spread([h["gap_mm"] for h in hs]),
                      "anchor_turn": spread([abs(h["anchor_turn"]) for h in hs])}
            for verdict, hs in sorted(groups.items(), key=lambda kv: kv[0] != "seated")}


def format_pose_ranges(ranges):
    """Markdown table of :func:`held_pose_ranges`: min / median / max per verdict (absolute values of the offset
    and the turn)."""
    rows = ["| Bullet | pairs | C_a off the axis [mm] | gap between the faces [mm] | anchor's turn in its holder "
            "[rad] |",
            "|---|---|---|---|---|"]

    def cell(t, fmt):
        return "-" if t is None else " / ".join(fmt % x for x in t)

    for verdict, g in ranges.items():
        rows.append("| %s | %d | %s | %s | %s |" % (verdict, g["pairs"], cell(g["lateral_mm"], "%.1f"),
                                                      cell(g["gap_mm"], "%.1f"), cell(g["anchor_turn"], "%.2f")))
    return "\n".join(rows)


def scenario_steps(directory, scenario):
    """The parsed steps of a scenario (for the summary)."""
    launch = sim_config(directory, scenario)
    names = [s.name for s in parse_robot_list(launch.robots, where="scenario %s: robots" % scenario)]
    return parse_scenario(launch.scenario, names, where="scenario %s" % scenario).steps


def format_table(summary):
    """Markdown table of the per-step summary."""
    rows = ["| step | reached | succeeded (checked in Bullet) | median [s] | max [s] |", "|---|---|---|---|---|"]
    for s in summary["steps"]:
        rows.append("| %s | %d | %d | %s | %s |" % (s["step"], s["reached"], s["succeeded"],
                                                     "-" if s["median_s"] is None else "%.1f" % s["median_s"],
                                                     "-" if s["max_s"] is None else "%.1f" % s["max_s"]))
    return "\n".join(rows)


def failure_text(reason, width=95):
    """A step's failure reason for the timeline: the behaviour's "timeout after 90.00 s; not coupled: ..."
    as "timeout (90 s): not coupled: ...", whole words, at most ``width`` characters."""
    import re

    text = re.sub(r"timeout after ([0-9.]+) s; ", lambda m: "timeout (%g s): " % float(m.group(1)), str(reason))
    if len(text) > width:
        text = text[:width].rsplit(" ", 1)[0].rstrip(",;:") + " ..."
    return text


def step_failure(step):
    """Why a step record failed, in one line: what Bullet contradicts after a step the controller called
    done; the behaviour's message (a timeout), then what Bullet contradicts, when it did not end well."""
    problems = ", ".join(step.get("problems", []))
    if step.get("state") == "succeeded":
        return problems or "failed"
    message = step.get("message") or step.get("state", "failed")
    return "%s; %s" % (problems, message) if problems else message


def plot_trials(records, scenario_steps, path, title=""):
    """PNG timeline: one row per trial, one bar per step it reached (length: simulated seconds), green
    when the step succeeded and Bullet agreed, red when it did not, with the reason next to it (the
    first problem Bullet found, or the behaviour's message)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    records = sorted(records, key=lambda r: r["trial"])
    fig, ax = plt.subplots(figsize=(12, 1.2 + 0.22 * len(records)))
    hatches = ["", "//", "..", "xx", "\\\\"]
    t_max = 1.0
    for row, rec in enumerate(records):
        t = 0.0
        for k, st in enumerate(rec["steps"]):
            ax.barh(row, st["sim_seconds"], left=t, height=0.7, color="C2" if st["ok"] else "C3",
                    hatch=hatches[k % len(hatches)], edgecolor="white", linewidth=0.5)
            t += st["sim_seconds"]
            if not st["ok"]:
                why = failure_text(step_failure(st))
                ax.text(t + 0.5, row, why, va="center", fontsize=7, color="C3", clip_on=False)
        t_max = max(t_max, t)
    handles = [Patch(facecolor="0.6", hatch=hatches[k % len(hatches)], edgecolor="white",
                     label="%d. %s" % (k + 1, step.describe())) for k, step in enumerate(scenario_steps)]
    handles += [Patch(color="C2", label="succeeded, checked in Bullet"), Patch(color="C3", label="failed")]
    ok = sum(r["success"] for r in records)
    ax.set_title("%s: %d of %d trials succeeded" % (title, ok, len(records)), fontsize=10)
    ax.set_yticks(range(len(records)))
    ax.set_yticklabels([str(r["trial"]) for r in records], fontsize=7)
    ax.set_ylim(len(records) - 0.5, -0.5)
    ax.set_xlim(0.0, 1.45 * t_max)
    ax.set_ylabel("trial")
    ax.set_xlabel("simulated time from the first step [s]")
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.6 / (1.2 + 0.22 * len(records))),
              ncol=min(3, len(handles)))
    ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
