"""The paper's coupling and decoupling experiments: seeded trials, parallel, resumable.

Each trial is a Bullet world (puzzlebot_sim.world.SimWorld) driven by the MPC
node's own core (puzzlebot_mpc.control_loop.ControlLoop) in lockstep at
dt = 0.1 s through puzzlebot_experiments.closed_loop.ClosedLoop, with mocap-like
noise on the poses the controller sees. Success is judged physically, from
the simulated anchor (SimWorld.physical_pairs), not from the controller's
belief; the controller's own verdict is recorded beside it.

Experiments (parameters: config/experiments.yaml, ExperimentParams):

``couple``
    Robot ``a`` (anchor, in front) at the origin facing +x, robot ``o``
    (opening) ``separation`` = 65 mm behind it (centre to centre) and
    ``offset_mm`` to the side; seeded perturbations of every start pose
    (position, heading) and of a's anchor yaw in its holder. The MPC runs
    ``couple`` (target ``line``). Success: a's anchor physically seated in
    o's opening (or o's in a's: either coupling counts) within
    ``couple_timeout`` and still seated ``hold_time`` after the behaviour
    ended. Time: from the request to the first seated instant.
``decouple``
    The two robots start coupled (o mated behind a, seeded perturbation),
    the MPC learns the coupling (``couple`` on the coupled start), then runs
    ``decouple``. Success: the anchor physically out of the opening within
    ``decouple_timeout``, the behaviour succeeded (the controller saw it
    from the poses), and the robots still apart ``hold_time`` later. Time:
    from the request to the physical release.

A trial's randomness comes from ``numpy.random.SeedSequence([seed, trial,
experiment code, offset in um])``: trial k of seed S is the same trial on
any machine and in any order. Sweeps run trials on an executor
(puzzlebot_experiments.executors: a local process pool, or the workers of a
Dask cluster) and append each result as one JSON line to a results file; a sweep that is
interrupted continues where it stopped (finished trials are read back, keyed
by experiment, offset, seed, trial and the version: a hash of configuration and sources).
"""

import json
import math
import os
import sys
import time
from dataclasses import asdict, dataclass, replace
from functools import partial

import numpy as np

from puzzlebot_common.config import load_yaml, shipped_config
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.params import from_mapping, key_values, require_positive
from puzzlebot_mpc.behaviors import FAILED, RUNNING, STATE_NAMES, SUCCEEDED, BehaviorRequest
from puzzlebot_mpc.config_files import load_settings
from puzzlebot_mpc import pairs as pr
from puzzlebot_sim.config import load_sim_config
from puzzlebot_sim.coupling import DECOUPLED, HEAD_INSERTED
from puzzlebot_sim.world import RobotStart
from puzzlebot_experiments.closed_loop import ClosedLoop, make_world
from puzzlebot_experiments.executors import LocalPool, add_cluster_option, make_executor
from puzzlebot_experiments.trials import mated_pair
from puzzlebot_experiments.version import code_version, config_hash

#: The lab's motion capture: the trials see the poses the controller sees in the lab (sim.launch's default).
MOCAP = "vicon"

COUPLE, DECOUPLE = "couple", "decouple"
EXPERIMENT_CODES = {COUPLE: 1, DECOUPLE: 2}
#: Simulated time the robots rest on the floor before a trial starts [s].
SETTLE_S = 0.3
#: An anchor turned further than this in its holder [rad] has flipped round (holder freedom: +/-0.5 rad).
ANCHOR_YAW_BROKEN = 1.0
#: Start poses drawn again at most this often when they put an anchor inside the other robot.
MAX_REDRAWS = 100


@dataclass(frozen=True)
class ExperimentParams:
    """Set-up of the experiments (config/experiments.yaml, ``experiments``)."""

    separation: float = 0.065          # m, centre to centre along x (couple)
    position_noise: float = 0.001      # m, start x and y of each robot: uniform +/-
    heading_noise: float = 0.05        # rad, start heading of each robot: uniform +/-
    anchor_yaw_noise: float = 0.3      # rad, a's anchor in its holder: uniform +/-
    couple_timeout: float = 60.0       # s, simulated
    mated_lateral_noise: float = 0.0003  # m, o's lateral offset at a coupled start: uniform +/-
    mated_heading_noise: float = 0.01  # rad, o's heading at a coupled start: uniform +/-
    decouple_timeout: float = 60.0     # s, simulated
    hold_time: float = 1.0             # s at rest after the behaviour: the result must still hold

    @classmethod
    def from_dict(cls, data, where="experiments"):
        return from_mapping(cls, data, where)

    def check(self, where="experiments"):
        require_positive(self, ["separation", "couple_timeout", "decouple_timeout"], where)
        for key in ("position_noise", "heading_noise", "anchor_yaw_noise", "mated_lateral_noise",
                    "mated_heading_noise", "hold_time"):
            if not getattr(self, key) >= 0:
                raise ConfigError("%s.%s: must be >= 0, got %r" % (where, key, getattr(self, key)))


def load_experiment_params(path=None):
    path = path or shipped_config("puzzlebot_experiments", "experiments.yaml")
    data = load_yaml(path)
    if not isinstance(data, dict) or not isinstance(data.get("experiments"), dict):
        raise ConfigError("%s: expected a mapping with key 'experiments'" % path)
    p = ExperimentParams.from_dict(data["experiments"], where="%s: experiments" % path)
    p.check(where="%s: experiments" % path)
    return p


# ----------------------------------------------------------------- trials
def trial_rng(experiment, seed, trial, offset_mm=0.0):
    ss = np.random.SeedSequence([int(seed), int(trial), EXPERIMENT_CODES[experiment],
                                 int(round(1000 * offset_mm))])
    return np.random.default_rng(ss), int(ss.generate_state(1)[0])


class _Context:
    """Configuration shared by the trials of a process (loaded once); ``overrides``: MPC settings to change."""

    def __init__(self, params=None, cfg=None, settings=None, overrides=None):
        self.params = params or load_experiment_params()
        self.cfg = cfg or load_sim_config(mocap=MOCAP)
        self.settings = settings or load_settings(sim=True)
        if overrides:
            try:
                self.settings = replace(self.settings, **overrides)
            except TypeError as e:
                raise ConfigError("unknown MPC setting in %s: %s" % (sorted(overrides), e)) from None
            self.settings.check()


def anchor_in_holder(world, name, body_side):
    """(in holder?, base x in the robot frame [m], yaw in the holder [rad]) of ``name``'s anchor.

    The anchor's base ball sits in a pocket behind the back face and turns
    in it within about +/-0.5 rad (facts.md). A base centre outside the body
    (x < -body_side / 2) or an anchor turned by more than
    ANCHOR_YAW_BROKEN means it was pulled out of its holder or flipped round
    in it: a simulation failure (the real anchor is mounted), never a success.
    """
    rx, ry, ryaw = world.pose2d(name)
    ax, ay, ayaw = world.anchor_pose2d(name)
    x = math.cos(ryaw) * (ax - rx) + math.sin(ryaw) * (ay - ry)
    yaw = math.remainder(ayaw - ryaw, 2 * math.pi)
    return x >= -body_side / 2.0 and abs(yaw) <= ANCHOR_YAW_BROKEN, x, yaw


def _pair_status(physical, a, b):
    """Physical status of the anchor coupling between robots a and b (either way round)."""
    return max(physical.get((a, b), DECOUPLED), physical.get((b, a), DECOUPLED))


def _rest(cl, seconds, on_tick=None):
    """Stop every robot and let the world run ``seconds`` (the controller keeps running: stop behaviour)."""
    cl.request(BehaviorRequest("stop"))
    t0 = cl.time
    while cl.time - t0 < seconds - 1e-9:
        tick = cl.tick()
        if on_tick is not None:
            on_tick(tick)


class FirstTime:
    """``on_tick`` watcher: the first time [s after ``t0``] the a-o pair's physical status is ``status``."""

    def __init__(self, cl, status):
        self.cl, self.status, self.t0, self.t = cl, status, cl.time, None

    def __call__(self, tick):
        if self.t is None and _pair_status(self.cl.physical(), "a", "o") == self.status:
            self.t = self.cl.time - self.t0
        return False


def _record(experiment, offset_mm, seed, trial, **fields):
    rec = {"experiment": experiment, "offset_mm": offset_mm, "seed": seed, "trial": trial}
    rec.update(fields)
    return rec


def couple_trial(offset_mm, seed, trial, ctx=None):
    """One coupling trial (module docstring); returns its record (a JSON-able dict)."""
    ctx = ctx or _Context()
    p, L = ctx.params, ctx.cfg.robot.body_side
    rng, world_seed = trial_rng(COUPLE, seed, trial, offset_mm)
    wall0 = time.perf_counter()

    def noisy(x, y):
        return (x + rng.uniform(-p.position_noise, p.position_noise),
                y + rng.uniform(-p.position_noise, p.position_noise),
                rng.uniform(-p.heading_noise, p.heading_noise))

    redrawn = -1
    while True:       # starts that put a's anchor inside o are drawn again (SimWorld refuses them)
        redrawn += 1
        a0, o0 = noisy(0.0, 0.0), noisy(-p.separation, 1e-3 * offset_mm)
        try:
            world = make_world(ctx.cfg, [RobotStart("a", *a0), RobotStart("o", *o0)], world_seed)
            break
        except ConfigError:
            if redrawn >= MAX_REDRAWS:
                raise
    anchor_yaw = rng.uniform(-p.anchor_yaw_noise, p.anchor_yaw_noise)
    try:
        world.reset_anchor("a", anchor_yaw)
        world.run(SETTLE_S)
        cl = ClosedLoop(world, ctx.settings)
        seated = FirstTime(cl, HEAD_INSERTED)
        state, message, elapsed = cl.run_behavior(
            BehaviorRequest(COUPLE, ["a", "o"], target="line", timeout=p.couple_timeout),
            p.couple_timeout + 1.0, on_tick=seated)
        _rest(cl, p.hold_time, seated)     # the barbs spring into the slits when the push ends
        final = cl.physical()
        final_status = _pair_status(final, "a", "o")
        geo = cl.geometry
        pair = pr.make_pair("a", "o", pr.ANCHOR, geo)
        pa, po = world.pose2d("a"), world.pose2d("o")
        gap = -pr.connection_margin(pair, pa, po, geo.footprint())
        lateral = pr.point_in_robot(po, pr.world_point(pa, pair.point_i))[1]
        dyaw = pr.alignment_error(pair, pa, po)[1]
        held, ax, ayaw = anchor_in_holder(world, "a", L)
        ok = (seated.t is not None and seated.t <= p.couple_timeout and final_status == HEAD_INSERTED
              and held)
        return _record(COUPLE, offset_mm, seed, trial, success=bool(ok), anchor_in_holder=held,
                       anchor_x_mm=round(1e3 * ax, 1),
                       time_s=round(seated.t, 2) if seated.t is not None else None,
                       controller=STATE_NAMES[state], controller_time_s=round(elapsed, 2),
                       controller_message=message, final_status=int(final_status),
                       pairs=sorted("%s>%s" % k for k, v in final.items() if v == HEAD_INSERTED),
                       gap_mm=round(1e3 * gap, 2), lateral_mm=round(1e3 * lateral, 2), dyaw=round(dyaw, 3),
                       anchor_yaw_end=round(ayaw, 3),
                       steps=cl.steps, failed_steps=cl.failed_steps,
                       start={"a": [round(v, 5) for v in a0], "o": [round(v, 5) for v in o0],
                              "anchor_yaw": round(anchor_yaw, 4)},
                       redrawn=redrawn, wall_s=round(time.perf_counter() - wall0, 2))
    finally:
        world.close()


def decouple_trial(seed, trial, ctx=None):
    """One decoupling trial (module docstring); returns its record."""
    ctx = ctx or _Context()
    p, L = ctx.params, ctx.cfg.robot.body_side
    rng, world_seed = trial_rng(DECOUPLE, seed, trial)
    wall0 = time.perf_counter()
    dy = rng.uniform(-p.mated_lateral_noise, p.mated_lateral_noise)
    dyaw = rng.uniform(-p.mated_heading_noise, p.mated_heading_noise)
    world = make_world(ctx.cfg, mated_pair(ctx.cfg.robot, dy, dyaw), world_seed)
    try:
        world.run(SETTLE_S)
        fields = {"start": {"o_lateral_mm": round(1e3 * dy, 3), "o_heading": round(dyaw, 4)}}
        if _pair_status(world_physical(world), "a", "o") != HEAD_INSERTED:
            return _record(DECOUPLE, 0.0, seed, trial, success=False, time_s=None,
                           controller="not run", error="the coupled start is not seated", **fields)
        cl = ClosedLoop(world, ctx.settings)
        state, message, _ = cl.run_behavior(BehaviorRequest(COUPLE, ["a", "o"], target="line", timeout=5.0), 6.0)
        if state != SUCCEEDED:
            return _record(DECOUPLE, 0.0, seed, trial, success=False, time_s=None,
                           controller="couple " + STATE_NAMES[state], controller_message=message, **fields)
        released = FirstTime(cl, DECOUPLED)
        state, message, elapsed = cl.run_behavior(
            BehaviorRequest(DECOUPLE, pair=["a", "o"], timeout=p.decouple_timeout),
            p.decouple_timeout + 1.0, on_tick=released)
        _rest(cl, p.hold_time, released)
        final_status = _pair_status(cl.physical(), "a", "o")
        held, ax, ayaw = anchor_in_holder(world, "a", L)
        ok = (released.t is not None and released.t <= p.decouple_timeout and state == SUCCEEDED
              and final_status == DECOUPLED and held)
        return _record(DECOUPLE, 0.0, seed, trial, success=bool(ok), anchor_in_holder=held,
                       anchor_x_mm=round(1e3 * ax, 1), anchor_yaw_end=round(ayaw, 3),
                       time_s=round(released.t, 2) if released.t is not None else None,
                       controller=STATE_NAMES[state], controller_time_s=round(elapsed, 2),
                       controller_message=message, final_status=int(final_status), steps=cl.steps,
                       failed_steps=cl.failed_steps, wall_s=round(time.perf_counter() - wall0, 2), **fields)
    finally:
        world.close()


def world_physical(world):
    return {(q.anchor_robot, q.opening_robot): q.status for q in world.physical_pairs()}


# ----------------------------------------------------------------- sweeps
@dataclass(frozen=True)
class Task:
    experiment: str
    offset_mm: float
    seed: int
    trial: int

    def key(self, version):
        return (self.experiment, round(float(self.offset_mm), 3), int(self.seed), int(self.trial), version)


def record_key(rec):
    return (rec["experiment"], round(float(rec["offset_mm"]), 3), int(rec["seed"]), int(rec["trial"]),
            rec.get("config"))


def tasks_for(experiment, trials, seed, offsets_mm=(0.0,)):
    return [Task(experiment, float(off), int(seed), k) for off in offsets_mm for k in range(trials)]


class ResultsFile:
    """Append-only JSON lines: one finished trial per line, flushed as it comes."""

    def __init__(self, path):
        self.path = path

    def load(self):
        """All records in the file (a torn last line from an interrupted run is skipped)."""
        out = []
        if not os.path.isfile(self.path):
            return out
        with open(self.path) as f:
            for line in f:
                line = line.strip()
                if not line:
                    continue
                try:
                    out.append(json.loads(line))
                except ValueError:
                    continue
        return out

    def append(self, rec):
        os.makedirs(os.path.dirname(os.path.abspath(self.path)), exist_ok=True)
        with open(self.path, "a") as f:
            if f.tell() > 0:
                with open(self.path, "rb") as check:      # a torn line from a killed run: start a new one
                    check.seek(-1, os.SEEK_END)
                    if check.read(1) != b"\n":
                        f.write("\n")
            f.write(json.dumps(rec, sort_keys=True) + "\n")
            f.flush()
            os.fsync(f.fileno())


_CTX = None


def _init_worker(overrides=None):
    """A worker process's set-up: the configuration its trials share (executors' ``setup``)."""
    global _CTX
    _CTX = _Context(overrides=overrides)


def run_task(task):
    """Run one Task in this process (uses the process's shared context)."""
    global _CTX
    if _CTX is None:
        _CTX = _Context()
    if task.experiment == COUPLE:
        return couple_trial(task.offset_mm, task.seed, task.trial, _CTX)
    return decouple_trial(task.seed, task.trial, _CTX)


class Progress:
    """A progress bar on a stream (a line per 10 % when it is not a terminal)."""

    def __init__(self, label, total, done=0, stream=None, width=30):
        self.label, self.total, self.done, self.width = label, total, done, width
        self.ok = 0
        self.stream = stream if stream is not None else sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.t0 = time.monotonic()
        self.new = 0
        self._last_decile = -1

    def update(self, success):
        self.done += 1
        self.new += 1
        self.ok += bool(success)
        self.show()

    def show(self, final=False):
        if self.total == 0:
            return
        frac = self.done / self.total
        rate = (time.monotonic() - self.t0) / self.new if self.new else float("nan")
        eta = rate * (self.total - self.done)
        bar = "#" * int(round(frac * self.width)) + "." * (self.width - int(round(frac * self.width)))
        text = "%s [%s] %d/%d  successes %d  %.1f s/trial  eta %s" % (
            self.label, bar, self.done, self.total, self.ok, rate, _hms(eta) if math.isfinite(eta) else "-")
        if self.tty:
            self.stream.write("\r" + text + ("\n" if final or self.done == self.total else ""))
            self.stream.flush()
        else:
            decile = int(10 * frac)
            if decile != self._last_decile or final:
                self._last_decile = decile
                self.stream.write(text + "\n")
                self.stream.flush()


def _hms(s):
    s = int(round(s))
    return "%d:%02d:%02d" % (s // 3600, s % 3600 // 60, s % 60) if s >= 3600 else "%d:%02d" % (s // 60, s % 60)


def run_sweep(tasks, results_path, jobs=None, nice=0, label="trials", stream=None, overrides=None, executor=None):
    """Run the tasks not yet in ``results_path`` and return the records of all tasks.

    The trials run on ``executor`` (puzzlebot_experiments.executors: a Dask
    cluster, ...; None: a local process pool of ``jobs`` processes with
    niceness ``nice``). Each finished trial is appended to the results file
    at once, so an interrupted sweep loses at most the trials that were
    running. ``overrides``: MPC settings to change (tuning); part of the version.
    """
    overrides = dict(overrides or {})
    _Context(overrides=overrides)          # bad overrides fail here, before any worker starts
    version = config_hash(overrides)
    results = ResultsFile(results_path)
    have = {record_key(r): r for r in results.load() if r.get("experiment") in EXPERIMENT_CODES}
    todo = [t for t in tasks if t.key(version) not in have]
    progress = Progress(label, len(tasks), len(tasks) - len(todo), stream)
    progress.ok = sum(bool(have[t.key(version)]["success"]) for t in tasks if t.key(version) in have)
    commit = code_version()
    progress.show()
    own = executor is None
    executor = LocalPool(jobs, nice) if own else executor
    try:
        for rec in executor.run(run_task, todo, setup=partial(_init_worker, overrides)):
            rec["config"] = version
            rec["commit"] = commit
            if overrides:
                rec["overrides"] = overrides
            results.append(rec)
            have[record_key(rec)] = rec
            progress.update(rec["success"])
    finally:
        if own:
            executor.close()
    return [have[t.key(version)] for t in tasks]


def summarize(records):
    """trials, successes, rate, mean/median time [s] of the successful trials, controller agreement."""
    ok = [r for r in records if r["success"]]
    times = [r["time_s"] for r in ok if r.get("time_s") is not None]
    out = {"trials": len(records), "successes": len(ok),
           "success_rate": round(len(ok) / len(records), 4) if records else None,
           "mean_time_s": round(float(np.mean(times)), 2) if times else None,
           "median_time_s": round(float(np.median(times)), 2) if times else None,
           "max_time_s": round(float(np.max(times)), 2) if times else None,
           "controller_succeeded": sum(r.get("controller") == "succeeded" for r in records),
           "failed_mpc_steps": int(sum(r.get("failed_steps", 0) for r in records))}
    return out


# -------------------------------------------------------------------- CLI
def _parse(argv, experiment):
    import argparse

    ap = argparse.ArgumentParser(prog="%s_trials" % experiment, description=(
        "Seeded %s trials in the Bullet simulation with the MPC (docs/results.md). Progress on stderr, "
        "then one JSON line on stdout." % experiment))
    if experiment == COUPLE:
        ap.add_argument("--offset-mm", type=float, default=0.0, help="lateral offset of robot o [mm], >= 0")
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--seed", default="1", help="integer seed, or 'fresh': one drawn from the OS now (printed)")
    ap.add_argument("--jobs", type=int, default=0, help="worker processes (default: all cores)")
    ap.add_argument("--nice", type=int, default=0, help="niceness increment of the workers")
    add_cluster_option(ap)
    ap.add_argument("--results", default=os.path.join("build", "experiments", "results.jsonl"),
                    help="append-only results file (JSON lines); finished trials are not rerun")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override an MPC setting (tuning; recorded with the results), e.g. wiggle_periods=[2.0,1.5]")
    ap.add_argument("--json", action="store_true", help="stdout: only the JSON line")
    return ap.parse_args(argv)


def _fail(prog, message):
    sys.stderr.write("%s: %s\n" % (prog, message))
    return 2


def main(experiment, argv=None):
    prog = "%s_trials" % experiment
    args = _parse(argv, experiment)
    if args.trials < 1:
        return _fail(prog, "--trials must be >= 1 (got %d)" % args.trials)
    if args.jobs < 0:
        return _fail(prog, "--jobs must be >= 0 (got %d)" % args.jobs)
    offset = getattr(args, "offset_mm", 0.0)
    if not (math.isfinite(offset) and offset >= 0):
        return _fail(prog, "--offset-mm must be a finite number >= 0 (got %r)" % offset)
    if args.seed == "fresh":
        seed = int.from_bytes(os.urandom(4), "little")
        sys.stderr.write("%s: fresh seed %d\n" % (prog, seed))
    else:
        try:
            seed = int(args.seed)
        except ValueError:
            return _fail(prog, "--seed must be an integer or 'fresh' (got %r)" % args.seed)
        if seed < 0:
            return _fail(prog, "--seed must be >= 0 (got %d)" % seed)
    try:
        overrides = key_values(args.set, "--set")
        load_experiment_params()
        tasks = tasks_for(experiment, args.trials, seed, (offset,))
        label = "%s %s mm" % (experiment, ("%g" % offset)) if experiment == COUPLE else experiment
        with make_executor(args.cluster, args.jobs or None, args.nice) as executor:
            records = run_sweep(tasks, args.results, label=label, overrides=overrides, executor=executor)
    except ConfigError as e:
        return _fail(prog, str(e))
    except KeyboardInterrupt:
        return _fail(prog, "interrupted; finished trials are kept in %s (run again to continue)" % args.results)
    summary = summarize(records)
    out = {"trials": summary["trials"], "successes": summary["successes"],
           "mean_time_s": summary["mean_time_s"], "median_time_s": summary["median_time_s"]}
    if experiment == COUPLE:
        out["offset_mm"] = offset
    out.update({"seed": seed, "success_rate": summary["success_rate"], "max_time_s": summary["max_time_s"],
                "controller_succeeded": summary["controller_succeeded"],
                "failed_mpc_steps": summary["failed_mpc_steps"], "config": config_hash(overrides)})
    if overrides:
        out["overrides"] = overrides
    if not args.json:
        failed = [r for r in records if not r["success"]]
        for r in failed[:10]:
            sys.stdout.write("failed: trial %d: %s (%s)\n" % (r["trial"], r.get("controller"),
                                                               r.get("controller_message", r.get("error", ""))))
    sys.stdout.write(json.dumps(out) + "\n")
    return 0
