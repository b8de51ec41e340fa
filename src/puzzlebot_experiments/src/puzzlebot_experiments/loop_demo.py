"""The loop closed, end to end in the Bullet simulation (no roscore).

1. **Inject** actuator and measurement effects into the simulation, unknown
   to the controller (``config/loop_demo.yaml``: input delays that differ
   between the robots and a motor lag through each robot's ``ActuatorPlant``,
   a wheel imbalance, a mocap heading offset, mocap noise and dropped samples).
2. **Record** a run of the plain-unicycle MPC on a tracking task (robots
   visiting random goals) as a ROS bag, as ``record.launch`` would:
   ``/vicon/<r>/<r>`` (the mocap measurements, 100 Hz) and ``/<r>/cmd_vel``
   (the commands, 10 Hz).
3. **Identify** the effects in the bag with ``identify_model``'s core (it is
   told nothing about the injected effects) and write ``model.yaml``.
4. **Rerun** the same seeds with the MPC planning with the identified model (each robot its own),
   with the plain unicycle, and with the injected effects as the reference
   ("true model"); report tracking errors measured on the simulated bodies
   (not the mocap), and coupling success of two robots with their anchors.

Every run is the in-process pair of ``puzzlebot_sim.world.SimWorld`` (the
sim node's core) and ``puzzlebot_mpc.control_loop.ControlLoop`` (the MPC
node's core) in lockstep, as ``sim.launch`` runs them: poses at 100 Hz fed
to the controller, one control step every 0.1 s of simulated time, the
command applied at once (the effects then delay and lag it).

    rosrun puzzlebot_experiments loop_demo [--seeds 1-5] [--record-seed 0] [--out-dir DIR] [--config loop_demo_timing]
                                       [--ablation] [--no-coupling] [--jobs 2]
"""

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace

import numpy as np

from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import yaw_from_quaternion
from puzzlebot_common.params import from_mapping, require_positive
from puzzlebot_mpc.compensation import describe_model

#: Controllers compared: the plain unicycle, the identified model, the injected effects (the
#: reference); and the plain MPC in the simulation without injected effects (the designed behaviour).
PLAIN, IDENTIFIED, TRUE, CLEAN = "plain", "identified", "true", "clean"
#: Bag time of simulated t = 0 [s] (a bag cannot start at time zero).
BAG_T0 = 1000.0
#: Spacing of the robots of a tracking run in one world [m] (far apart: no contact).
ROBOT_SPACING = 0.6
#: Tries to draw a goal at an allowed distance before giving up (a config error).
GOAL_DRAWS = 1000


@dataclass(frozen=True)
class DemoSettings:
    """The experiment (config/loop_demo.yaml, ``demo``)."""

    robots: int = 3                   # robots per tracking run, one Bullet world, ROBOT_SPACING apart
    legs: int = 6                     # goals per robot in an evaluation run
    record_legs: int = 16             # goals per robot in the recorded run (identification data)
    leg_s: float = 8.0                # s, time per goal (fixed: every controller gets the same schedule)
    leg_min: float = 0.08             # m, shortest distance between successive goals
    leg_max: float = 0.2              # m, longest
    area: float = 0.15                # m, goals within +-area of the robot's home in x and y
    hold_tolerance: float = 0.001     # m, go_to_goal tolerance: the robots keep regulating for the leg
    reach_tolerance: float = 0.005    # m, a goal is reached within this distance (the stack's default)
    settle_s: float = 2.0             # s, steady error = mean distance over the last settle_s of a leg
    wheel_imbalance: float = 0.03     # -, sim: right wheel x (1 + k), left x (1 - k)
    mocap_position_std: float = 0.0005  # m
    mocap_yaw_std: float = 0.005      # rad
    mocap_dropout: float = 0.01       # -, probability that a pose sample is lost
    mocap_heading_offset: float = 0.05  # rad, marker frame yaw - body yaw
    couple_trials: int = 6            # coupling trials per seed (two robots with anchors)
    couple_timeout: float = 40.0      # s, simulated
    couple_gap: float = 0.085         # m, start distance of the two robots' centres along x (paper: 65 mm)
    couple_offset_max: float = 0.03   # m, sideways offsets 0..max over the trials (paper: 0..30 mm)
    couple_yaw: float = 0.3           # rad, start headings uniform in +-couple_yaw

    @classmethod
    def from_dict(cls, data, where="demo"):
        return from_mapping(cls, data, where)

    def check(self, where="demo"):
        require_positive(self, ["robots", "legs", "record_legs", "leg_s", "leg_min", "leg_max", "area",
                                "hold_tolerance", "reach_tolerance", "settle_s", "couple_timeout", "couple_gap"],
                        where)
        if self.leg_min > self.leg_max or self.leg_max > 2 * self.area:
            raise ConfigError("%s: need leg_min <= leg_max <= 2 area" % where)
        if self.settle_s >= self.leg_s:
            raise ConfigError("%s.settle_s must be shorter than leg_s" % where)


@dataclass
class Config:
    demo: DemoSettings
    injected: object          # effects.ActuatorModel applied by the simulation's ActuatorPlant
    true_model: object        # effects.ActuatorModel: everything injected, in model terms (the reference)
    sim: object               # puzzlebot_sim.config.SimConfig: the robot, anchor and rates as sim.launch has them


def config_path(name="loop_demo.yaml"):
    """A shipped configuration (config/NAME, ".yaml" optional) in the source or install space."""
    from puzzlebot_common.config import shipped_config

    return shipped_config("puzzlebot_experiments", name if name.endswith(".yaml") else name + ".yaml")


def load_config(path=None, overrides=None):
    """Config from loop_demo.yaml: ``demo`` (DemoSettings) and ``injected`` (a model.yaml mapping), with
    the simulation as sim.launch builds it (puzzlebot_sim.config; the demo's own mocap effects)."""
    from puzzlebot_common.effects import ActuatorModel
    from puzzlebot_sim.config import load_sim_config

    path = path or config_path()
    data = load_yaml(path)
    if not isinstance(data, dict) or set(data) - {"demo", "injected"}:
        raise ConfigError("%s: expected the keys 'demo' and 'injected'" % path)
    demo = DemoSettings.from_dict(dict(data.get("demo") or {}, **(overrides or {})), where="%s: demo" % path)
    injected = ActuatorModel.from_dict(data.get("injected"), where="%s: injected" % path)
    sim = load_sim_config()
    return Config(demo, injected, true_model(demo, injected, sim.robot), sim)


def true_model(demo, injected, robot):
    """The injected effects as an actuator model: the plant's effects, the wheel imbalance as a yaw-rate
    bias (right x (1 + k), left x (1 - k) turns by 2 k v / wheel base; the change of v, k w b / 2, is
    negligible), the mocap heading offset. Whatever the simulated robot itself adds to a unicycle (e.g.
    the ~30 ms of its torque-limited wheels) is not in it: nobody declared it. ``robot``: the simulated
    robot's RobotParams."""
    from puzzlebot_common.effects import ActuatorModel

    model = ActuatorModel.from_dict(injected.to_dict())
    if demo.wheel_imbalance:
        w_per_v = model.param("w_per_v") + 2.0 * demo.wheel_imbalance / robot.wheel_base
        model.add("yaw_rate_bias", {"w_per_v": w_per_v, "w0": model.param("w0")})
    if demo.mocap_heading_offset:
        model.add("heading_offset", {"offset_rad": model.param("offset_rad") + demo.mocap_heading_offset})
    return model


def mpc_settings():
    """The MPC's settings as sim.launch loads them (mpc.yaml with the simulation's mpc_sim.yaml)."""
    from puzzlebot_mpc.config_files import load_settings

    return load_settings(sim=True)


# ------------------------------------------------------------------ worlds
def make_world(cfg, starts, seed, anchors):
    """A SimWorld of ``cfg.sim``'s robot, anchor and physics rate, with the demo's injected effects."""
    from puzzlebot_sim.mocap import MocapModel
    from puzzlebot_sim.world import SimWorld

    demo = cfg.demo
    mocap = MocapModel(demo.mocap_position_std, demo.mocap_yaw_std, demo.mocap_dropout, demo.mocap_heading_offset)
    return SimWorld(cfg.sim.robot, starts, physics_rate=cfg.sim.sim.physics_rate,
                    anchor_params=cfg.sim.anchor if anchors else None, seed=seed,
                    actuator_model=cfg.injected if cfg.injected.has_effects() else None,
                    wheel_imbalance=demo.wheel_imbalance, mocap=mocap)


class Lockstep:
    """A SimWorld and a ControlLoop stepped together; records what a bag would hold and the true poses."""

    def __init__(self, world, loop, names, dt, pose_rate, record=False):
        self.world, self.loop, self.names = world, loop, names
        self.per_pose = int(round(1.0 / (pose_rate * world.dt)))
        self.per_control = int(round(dt * pose_rate))
        self.pose_rate = pose_rate
        self.record = record
        self.poses = {n: [] for n in names}      # measured (t, x, y, yaw) as published
        self.commands = {n: [] for n in names}   # (t, v, w) as sent
        self.truth = {n: [] for n in names}      # true (t, x, y, yaw) of the body
        self.failures = 0
        self._feed()

    def _feed(self):
        w, t = self.world, self.world.time
        for n in self.names:
            x, y, yaw = w.pose2d(n)
            self.truth[n].append((t, x, y, yaw))
            m = w.measure(n)
            if m is None:
                continue
            (mx, my, _), q = m
            myaw = yaw_from_quaternion(*q)
            self.loop.on_pose(n, t, mx, my, myaw)
            if self.record:
                self.poses[n].append((t, mx, my, myaw))

    def settle(self, seconds):
        """Run the world with the robots at rest, feeding poses (the controller sees the robots first)."""
        for _ in range(int(round(seconds * self.pose_rate))):
            self.world.step(self.per_pose)
            self._feed()

    def control_step(self):
        t = round(self.world.time, 9)
        out = self.loop.step(t)
        self.failures += 0 if out.result.success else 1
        for n in self.names:
            v, w = out.commands[n]
            self.world.set_command(n, v, w)
            if self.record:
                self.commands[n].append((t, v, w))
        for _ in range(self.per_control):
            self.world.step(self.per_pose)
            self._feed()
        return out


# --------------------------------------------------------------- tracking
def draw_goals(rng, home, n, demo):
    """n goals within +-area of home, each leg_min..leg_max from the previous one (the first from home)."""
    goals, prev = [], np.asarray(home, float)
    for _ in range(n):
        for _ in range(GOAL_DRAWS):
            g = np.asarray(home, float) + rng.uniform(-demo.area, demo.area, 2)
            if demo.leg_min <= np.linalg.norm(g - prev) <= demo.leg_max:
                break
        else:
            raise ConfigError("cannot draw goals %g..%g m apart within +-%g m"
                              % (demo.leg_min, demo.leg_max, demo.area))
        goals.append((float(g[0]), float(g[1])))
        prev = g
    return goals


def tracking_task(seed, demo, legs):
    """Start poses and goal lists of a tracking run (the same for every controller of a seed)."""
    from puzzlebot_sim.world import RobotStart

    rng = np.random.default_rng(seed)
    names = ["pz%d" % (k + 1) for k in range(demo.robots)]
    starts, goals = [], {}
    for k, n in enumerate(names):
        home = (ROBOT_SPACING * k, 0.0)
        starts.append(RobotStart(n, home[0], home[1], float(rng.uniform(-math.pi, math.pi))))
        goals[n] = draw_goals(rng, home, legs, demo)
    return names, starts, goals


def leg_metrics(truth, t0, goal, demo):
    """Errors of one robot on one leg from its true poses (t, x, y, yaw) within [t0, t0 + leg_s)."""
    a = np.asarray(truth)
    sel = (a[:, 0] >= t0 - 1e-9) & (a[:, 0] < t0 + demo.leg_s - 1e-9)
    t, p = a[sel, 0] - t0, a[sel, 1:3]
    g = np.asarray(goal)
    d = np.linalg.norm(p - g, axis=1)
    axis = g - p[0]
    axis /= max(np.linalg.norm(axis), 1e-12)
    along = (p - g) @ axis                              # > 0: past the goal
    cross = (p - p[0]) @ np.array([-axis[1], axis[0]])  # beside the straight line start -> goal
    inside = np.flatnonzero(d <= demo.reach_tolerance)
    reached = inside.size > 0
    t_reach = float(t[inside[0]]) if reached else float("nan")
    after = d[inside[0]:] if reached else d[:0]
    return {"reached": bool(reached), "t_reach_s": t_reach,
            "overshoot_mm": 1e3 * float(max(0.0, along.max())),
            "steady_mm": 1e3 * float(d[t >= demo.leg_s - demo.settle_s].mean()),
            "cross_rms_mm": 1e3 * float(np.sqrt(np.mean(cross[:inside[0] + 1 if reached else None] ** 2))),
            "outside_after_reach": float((after > demo.reach_tolerance).mean()) if reached else 1.0}


def tracking_run(cfg, model, seed, legs=None, record=False):
    """One tracking run: every robot visits its goals, ``leg_s`` seconds each, under the MPC with the
    actuator ``model`` (None: plain unicycle). Returns metrics per robot and leg, the true paths, and
    (``record``) the measured poses and commands."""
    from puzzlebot_mpc.behaviors import GO_TO_GOAL, BehaviorRequest
    from puzzlebot_mpc.control_loop import ControlLoop

    demo = cfg.demo
    legs = legs or demo.legs
    names, starts, goals = tracking_task(seed, demo, legs)
    settings = mpc_settings()
    loop = ControlLoop(names, settings, actuator_model=model)
    with make_world(cfg, starts, seed, anchors=False) as world:
        ls = Lockstep(world, loop, names, settings.dt, cfg.sim.sim.pose_rate, record)
        steps = int(round(demo.leg_s / settings.dt))
        for k in range(legs):
            t0 = round(world.time, 9)
            loop.request(BehaviorRequest(GO_TO_GOAL, names, [goals[n][k] for n in names],
                                         tolerance=demo.hold_tolerance, timeout=demo.leg_s), t0)
            for _ in range(steps):
                ls.control_step()
    metrics = [dict(robot=n, leg=k, **leg_metrics(ls.truth[n], k * demo.leg_s, goals[n][k], demo))
               for n in names for k in range(legs)]
    out = {"seed": seed, "controller_model": model.names() if model else [], "metrics": metrics,
           "goals": goals, "truth": {n: np.asarray(ls.truth[n])[:, :3].tolist() for n in names},
           "failed_steps": ls.failures}
    if record:
        out["record"] = {n: {"poses": ls.poses[n], "commands": ls.commands[n]} for n in names}
    return out


def write_bag(path, record, t0=BAG_T0):
    """ROS 1 bag like record.launch's: /vicon/<r>/<r> TransformStamped (header stamp = pose time) and
    /<r>/cmd_vel Twist (record time = command time). No roscore needed."""
    from puzzlebot_mpc.identify.data import write_messages
    import rospy
    from geometry_msgs.msg import TransformStamped, Twist

    from puzzlebot_common import names as topics

    msgs = []
    for name, r in record.items():
        for t, x, y, yaw in r["poses"]:
            m = TransformStamped()
            m.header.stamp = rospy.Time.from_sec(t0 + t)
            m.header.frame_id = "world"
            m.child_frame_id = name
            m.transform.translation.x, m.transform.translation.y = x, y
            m.transform.rotation.z, m.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)
            msgs.append((t0 + t, topics.vicon_topic(name), m))
        for t, v, w in r["commands"]:
            m = Twist()
            m.linear.x, m.angular.z = v, w
            msgs.append((t0 + t, topics.cmd_vel_topic(name), m))
    write_messages(path, msgs)


# --------------------------------------------------------------- coupling
def coupling_trial(cfg, model, seed, trial, trials):
    """Two robots with anchors couple into a line in Bullet (the paper's experiment: 65 mm apart in x,
    sideways offset 0..30 mm over the trials, headings +-0.3 rad). Success: the MPC's couple
    behaviour succeeds within ``couple_timeout`` and the anchor is physically seated (HEAD_INSERTED)."""
    from puzzlebot_mpc.behaviors import COUPLE, FAILED, SUCCEEDED, BehaviorRequest
    from puzzlebot_mpc.control_loop import ControlLoop
    from puzzlebot_sim.coupling import HEAD_INSERTED
    from puzzlebot_sim.world import RobotStart

    demo = cfg.demo
    rng = np.random.default_rng([seed, trial])
    offset = demo.couple_offset_max * trial / max(1, trials - 1)
    names = ["pz1", "pz2"]      # named like the tracking robots: each has its own injected and identified model
    starts = [RobotStart(names[0], 0.0, 0.0, float(rng.uniform(-demo.couple_yaw, demo.couple_yaw))),
              RobotStart(names[1], -demo.couple_gap, offset, float(rng.uniform(-demo.couple_yaw, demo.couple_yaw)))]
    settings = mpc_settings()
    loop = ControlLoop(names, settings, actuator_model=model)
    result = {"seed": seed, "trial": trial, "offset_mm": 1e3 * offset, "coupled": False, "time_s": float("nan"),
              "physical": False, "message": ""}
    with make_world(cfg, starts, seed * 1000 + trial, anchors=True) as world:
        ls = Lockstep(world, loop, names, settings.dt, cfg.sim.sim.pose_rate)
        ls.settle(settings.dt)
        rid = loop.request(BehaviorRequest(COUPLE, names, target="line", timeout=demo.couple_timeout),
                           round(world.time, 9))
        for _ in range(int(round((demo.couple_timeout + 1.0) / settings.dt))):
            out = ls.control_step()
            if out.status.request_id == rid and out.status.state in (SUCCEEDED, FAILED):
                result["message"] = out.status.message
                if out.status.state == SUCCEEDED:
                    result["coupled"], result["time_s"] = True, round(world.time, 2)
                break
        if result["coupled"]:
            world.run(1.0)       # the robots rest: is the anchor seated?
            result["physical"] = any(p.status == HEAD_INSERTED for p in world.physical_pairs())
        result["failed_steps"] = ls.failures
    return result


# ---------------------------------------------------------------- summary
def summarize(runs, demo):
    """Aggregate tracking metrics over runs (all robots and legs)."""
    m = [x for r in runs for x in r["metrics"]]
    reached = [x for x in m if x["reached"]]
    return {"legs": len(m), "reached": len(reached),
            "held": sum(x["steady_mm"] <= 1e3 * demo.reach_tolerance for x in m),
            "t_reach_median_s": float(np.median([x["t_reach_s"] for x in reached])) if reached else float("nan"),
            "overshoot_mean_mm": float(np.mean([x["overshoot_mm"] for x in m])),
            "overshoot_max_mm": float(np.max([x["overshoot_mm"] for x in m])),
            "steady_mean_mm": float(np.mean([x["steady_mm"] for x in m])),
            "steady_max_mm": float(np.max([x["steady_mm"] for x in m])),
            "cross_rms_mm": float(np.sqrt(np.mean([x["cross_rms_mm"] ** 2 for x in m]))),
            "outside_after_reach": float(np.mean([x["outside_after_reach"] for x in reached])) if reached else 1.0,
            "failed_steps": int(sum(r["failed_steps"] for r in runs))}


def summarize_robots(runs, demo):
    """summarize() per robot: {robot: summary}."""
    robots = sorted({x["robot"] for r in runs for x in r["metrics"]})
    return {n: summarize([dict(r, metrics=[x for x in r["metrics"] if x["robot"] == n], failed_steps=0)
                          for r in runs], demo) for n in robots}


def robot_table(labels, per_robot, cfg, identified):
    """Markdown table: each robot's injected delay, identified delay, and goals held / error at the end
    under each controller (before / after per robot)."""
    keys = [(k, lab) for k, lab in labels if k in (PLAIN, IDENTIFIED, TRUE) and k in per_robot]
    head = "| robot | injected delay [s] | identified delay [s] | " + " | ".join(
        "%s: held, error mean / max [mm]" % lab for _, lab in keys) + " |"
    rows = [head, "|---|---|---|" + "---|" * len(keys)]
    for robot in sorted(per_robot[PLAIN]):
        ident = identified.for_robot(robot).param("delay_s") if identified is not None else 0.0
        cells = ["%d / %d, %.2f / %.2f" % (per_robot[k][robot]["held"], per_robot[k][robot]["legs"],
                                           per_robot[k][robot]["steady_mean_mm"], per_robot[k][robot]["steady_max_mm"])
                 for k, _ in keys]
        rows.append("| %s | %.3f | %.3f | %s |" % (robot, cfg.true_model.for_robot(robot).param("delay_s"), ident,
                                                   " | ".join(cells)))
    return "\n".join(rows)


def summarize_coupling(trials):
    ok = [t for t in trials if t["coupled"] and t["physical"]]
    times = [t["time_s"] for t in ok]
    return {"trials": len(trials), "coupled": sum(t["coupled"] for t in trials), "seated": len(ok),
            "time_mean_s": float(np.mean(times)) if ok else float("nan"),
            "time_std_s": float(np.std(times)) if ok else float("nan"),
            "time_max_s": float(np.max(times)) if ok else float("nan"),
            "failed_steps": int(sum(t.get("failed_steps", 0) for t in trials))}


def table(labels, summary, coupling=None):
    """Markdown table, one row per controller (in the order of ``labels``)."""
    head = ("| controller | goals reached (5 mm) | goals held at the end (5 mm) | time to 5 mm, median [s] | "
            "error at the end, mean / max [mm] | overshoot mean / max [mm] | time outside 5 mm after reaching |")
    rule = "|---|---|---|---|---|---|---|"
    if coupling:
        head += " coupled and seated | time to couple mean / sd / max [s] |"
        rule += "---|---|"
    rows = [head, rule]
    for key, label in labels:
        s = summary.get(key)
        if s is None:
            continue
        row = "| %s | %d / %d | %d / %d | %.2f | %.2f / %.2f | %.2f / %.2f | %.1f %% |" % (
            label, s["reached"], s["legs"], s["held"], s["legs"], s["t_reach_median_s"], s["steady_mean_mm"],
            s["steady_max_mm"], s["overshoot_mean_mm"], s["overshoot_max_mm"], 100 * s["outside_after_reach"])
        if coupling:
            k = coupling.get(key)
            row += (" %d / %d | %.1f / %.1f / %.1f |" % (k["seated"], k["trials"], k["time_mean_s"], k["time_std_s"],
                                                          k["time_max_s"]) if k else " - | - |")
        rows.append(row)
    return "\n".join(rows)


COLORS = {PLAIN: "tab:red", IDENTIFIED: "tab:blue", TRUE: "tab:green", CLEAN: "0.5"}


def figure(path, runs, summary, labels, cfg, identified_model, trials=None):
    """(a) true paths and (b) distance to goal of one robot under each controller; (c) summary bars;
    (d) time to couple of every coupling trial. Two panels a row (readable at a page's width); the
    injected and identified models written out below the panels, one line per robot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    demo = cfg.demo
    shown = [(k, lab) for k, lab in labels if k in COLORS and runs.get(k)]
    first = {k: runs[k][0] for k, _ in shown}
    name = sorted(first[PLAIN]["truth"])[0]
    fig, grid = plt.subplots(2, 2, figsize=(12, 9.5))
    ax = grid.ravel()
    if not trials:
        ax[3].axis("off")
    goals = np.asarray(first[PLAIN]["goals"][name])
    style = {PLAIN: ("-", 1.2), TRUE: ("-", 2.2), IDENTIFIED: ("--", 1.2)}
    for k in (PLAIN, TRUE, IDENTIFIED):            # the identified model dashed over the true one
        lab = dict(shown)[k]
        p = np.asarray(first[k]["truth"][name])
        ls, lw = style[k]
        ax[0].plot(p[:, 1], p[:, 2], color=COLORS[k], ls=ls, lw=lw, label=lab)
        t = np.arange(p.shape[0]) / cfg.sim.sim.pose_rate
        leg = np.minimum((t / demo.leg_s).astype(int), len(goals) - 1)
        d = np.linalg.norm(p[:, 1:3] - goals[leg], axis=1)
        ax[1].semilogy(t, np.maximum(1e3 * d, 0.05), color=COLORS[k], ls=ls, lw=lw, label=lab)
    ax[0].plot(goals[:, 0], goals[:, 1], "k+", ms=10, label="goals")
    for i, g in enumerate(goals):
        ax[0].add_patch(plt.Circle(g, demo.reach_tolerance, fill=False, ls=":", color="k"))
        ax[0].annotate(str(i + 1), g, textcoords="offset points", xytext=(5, 5))
    ax[0].set_aspect("equal")
    ax[0].set_xlabel("x [m]")
    ax[0].set_ylabel("y [m]")
    ax[0].set_title("(a) %s, seed %d: paths of the simulated body" % (name, first[PLAIN]["seed"]), fontsize=10)
    ax[0].legend(fontsize=8, loc="best")
    ax[1].axhline(1e3 * demo.reach_tolerance, color="k", ls=":", lw=0.8)
    for k in range(1, len(goals)):
        ax[1].axvline(k * demo.leg_s, color="0.8", lw=0.8)
    ax[1].set_xlabel("t [s] (a new goal every %.0f s)" % demo.leg_s)
    ax[1].set_ylabel("distance to the current goal [mm]")
    ax[1].set_title("(b) distance to the current goal (5 mm dotted)", fontsize=10)
    keys = [("steady_mean_mm", "error at the end\nmean [mm]"), ("steady_max_mm", "error at the end\nmax [mm]"),
            ("t_reach_median_s", "time to 5 mm\nmedian [s]")]
    x = np.arange(len(keys))
    width = 0.8 / len(shown)
    for j, (k, lab) in enumerate(shown):
        ax[2].bar(x + (j - (len(shown) - 1) / 2) * width, [summary[k][key] for key, _ in keys], width,
                  color=COLORS[k], label=lab)
    ax[2].axhline(1e3 * demo.reach_tolerance, color="k", ls=":", lw=0.8)
    ax[2].set_xticks(x)
    ax[2].set_xticklabels([label for _, label in keys], fontsize=9)
    ax[2].set_title("(c) seeds %s: every robot and goal" % ", ".join(str(r["seed"]) for r in runs[PLAIN]),
                    fontsize=10)
    ax[2].legend(fontsize=8)
    if trials:
        rng = np.random.default_rng(0)
        keys = [k for k, _ in shown if k in trials]
        for j, k in enumerate(keys):
            tt = np.array([t["time_s"] if t["coupled"] and t["physical"] else np.nan for t in trials[k]])
            fail = np.isnan(tt)
            x = j + rng.uniform(-0.2, 0.2, tt.size)
            ax[3].plot(x[~fail], tt[~fail], "o", ms=4, color=COLORS[k], alpha=0.7)
            ax[3].plot(x[fail], np.full(fail.sum(), demo.couple_timeout), "x", ms=7, color=COLORS[k])
        ax[3].set_xticks(range(len(keys)))
        ax[3].set_xticklabels([dict(shown)[k].replace(" (", "\n(") for k in keys], fontsize=9)
        ax[3].set_ylabel("time to couple [s] (x: not coupled and seated)")
        ax[3].set_title("(d) two robots couple with their anchors: %d trials each" % len(trials[PLAIN]),
                        fontsize=10)
    models = ["injected: " + line for line in describe_model(cfg.true_model).split(" | ")]
    models += ["identified: " + line for line in describe_model(identified_model).split(" | ")]
    fig.tight_layout(rect=(0, 0.03 * len(models) / 2 + 0.02, 1, 1))
    fig.text(0.01, 0.005, "\n".join(models), fontsize=8, va="bottom", family="monospace")
    fig.savefig(path, dpi=100)
    plt.close(fig)


# -------------------------------------------------------------------- main
def parse_seeds(text):
    """'1-5' or '1,4,7' -> [1, ..]; ValueError if malformed."""
    seeds = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        seeds.extend(range(int(a), int(b) + 1) if b else [int(a)])
    if not seeds:
        raise ValueError("no seeds in %r" % text)
    return seeds


def clean_config(cfg):
    """The same experiment with nothing injected (mocap noise and dropouts stay): the designed behaviour."""
    from puzzlebot_common.effects import ActuatorModel

    demo = replace(cfg.demo, wheel_imbalance=0.0, mocap_heading_offset=0.0)
    return Config(demo, ActuatorModel(), ActuatorModel(), cfg.sim)


def variants(cfg, identified, clean=True, ablation=False):
    """(key, label, config, controller model) of every controller to evaluate."""
    from puzzlebot_common.effects import ActuatorModel

    out = [(PLAIN, "plain unicycle MPC (before)", cfg, None),
           (IDENTIFIED, "identified model (after)", cfg, identified),
           (TRUE, "true model (reference)", cfg, cfg.true_model)]
    if ablation:
        for e in cfg.true_model.effects:
            only = ActuatorModel().add(e.name, e.params)
            for robot, own in cfg.true_model.robots.items():      # each robot's own value of that effect
                for mine in own.effects:
                    if mine.name == e.name:
                        only.add_for_robot(robot, e.name, mine.params)
            out.append(("only_" + e.name, "true model, only %s" % e.name, cfg, only))
    if clean:
        out.append((CLEAN, "plain MPC, nothing injected", clean_config(cfg), None))
    return out


def _tracking_job(args):
    return tracking_run(*args)


def _coupling_job(args):
    return coupling_trial(*args)


def run(cfg, seeds, record_seed, out_dir, jobs=1, coupling=True, ablation=False, figure_path=None, say=print):
    """The whole demonstration; returns the results (also written to out_dir/loop_demo.json)."""
    from puzzlebot_mpc.identify import core, report

    os.makedirs(out_dir, exist_ok=True)
    t_start = time.time()
    demo = cfg.demo
    say("injected: %s (as a model: %s)" % (describe_model(cfg.injected), describe_model(cfg.true_model)))
    say("sim: wheel imbalance %g, mocap heading offset %g rad, noise %g m / %g rad, dropout %g"
        % (demo.wheel_imbalance, demo.mocap_heading_offset, demo.mocap_position_std, demo.mocap_yaw_std,
           demo.mocap_dropout))
    say("1. recording the plain MPC: seed %d, %d robots x %d goals x %g s"
        % (record_seed, demo.robots, demo.record_legs, demo.leg_s))
    rec = tracking_run(cfg, None, record_seed, legs=demo.record_legs, record=True)
    bag = os.path.join(out_dir, "loop_demo_record.bag")
    write_bag(bag, rec["record"])
    say("2. identifying the effects in %s (the tool is told nothing)" % bag)
    ident = core.identify(bag)
    model_path = os.path.join(out_dir, "model.yaml")
    ident.model.dump(model_path)
    with open(os.path.join(out_dir, "identify_report.json"), "w") as f:
        json.dump(report.report_dict(ident), f, indent=1)
    say(report.table(ident))
    identified = ident.model if ident.model.has_effects() else None
    todo = variants(cfg, identified, ablation=ablation)
    labels = [(k, lab) for k, lab, _, _ in todo]
    say("3. tracking, seeds %s: %s" % (",".join(map(str, seeds)), "; ".join(lab for _, lab in labels)))
    pool = ProcessPoolExecutor(jobs) if jobs > 1 else None
    mapper = pool.map if pool else map
    jobs_list = [(c, m, s) for _, _, c, m in todo for s in seeds]
    results = list(mapper(_tracking_job, jobs_list))
    runs = {k: results[i * len(seeds):(i + 1) * len(seeds)] for i, (k, _, _, _) in enumerate(todo)}
    summary = {k: summarize(runs[k], demo) for k in runs}
    per_robot = {k: summarize_robots(runs[k], demo) for k in runs}
    couple, trials = None, None
    if coupling and demo.couple_trials > 0:
        n = demo.couple_trials
        main = [v for v in todo if not v[0].startswith("only_")]
        say("4. coupling two robots with anchors: %d trials per seed x %d seeds per controller" % (n, len(seeds)))
        jobs_list = [(c, m, s, k, n) for _, _, c, m in main for s in seeds for k in range(n)]
        results = list(mapper(_coupling_job, jobs_list))
        per = n * len(seeds)
        trials = {k: results[i * per:(i + 1) * per] for i, (k, _, _, _) in enumerate(main)}
        couple = {k: summarize_coupling(trials[k]) for k in trials}
    if pool:
        pool.shutdown()
    say("")
    say(table(labels, summary, couple))
    say("")
    say(robot_table(labels, per_robot, cfg, identified))
    fig = figure_path or os.path.join(out_dir, "loop_demo.png")
    figure(fig, runs, summary, labels, cfg, identified, trials)
    result = {"injected": cfg.injected.to_dict(), "true_model": cfg.true_model.to_dict(),
              "identified_model": ident.model.to_dict(), "identify_rmse": {
                  "before": report.report_dict(ident)["before"], "after": report.report_dict(ident)["after"]},
              "demo": asdict(demo), "seeds": seeds, "record_seed": record_seed, "labels": labels,
              "summary": summary, "per_robot": per_robot, "coupling": couple,
              "per_run": {k: [{key: r[key] for key in ("seed", "metrics", "failed_steps")} for r in runs[k]]
                          for k in runs},
              "coupling_trials": trials, "wall_s": round(time.time() - t_start, 1)}
    out_json = os.path.join(out_dir, "loop_demo.json")
    with open(out_json, "w") as f:
        json.dump(result, f, indent=1, default=float)
    say("wrote %s, %s, %s, %s (%.0f s wall)" % (bag, model_path, fig, out_json, time.time() - t_start))
    return result


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-5", help="evaluation seeds, e.g. 1-5 or 1,4,7 (default 1-5)")
    ap.add_argument("--record-seed", type=int, default=0, help="seed of the recorded (identification) run")
    ap.add_argument("--out-dir", default="loop_demo_out", help="bag, model.yaml, reports, figure, JSON")
    ap.add_argument("--figure", default=None, help="write the figure here (default OUT_DIR/loop_demo.png)")
    ap.add_argument("--config", default=None,
                    help="a loop_demo.yaml: a path, or the name of a shipped one (loop_demo, loop_demo_timing)")
    ap.add_argument("--jobs", type=int, default=1, help="parallel processes for the evaluation runs")
    ap.add_argument("--no-coupling", action="store_true", help="skip the coupling trials")
    ap.add_argument("--ablation", action="store_true", help="also the true model restricted to each effect")
    args = ap.parse_args(argv)
    try:
        path = args.config
        if path and not os.path.isfile(path) and os.sep not in path:
            path = config_path(path)
        cfg = load_config(path)
        seeds = parse_seeds(args.seeds)
        if args.jobs < 1:
            raise ValueError("--jobs must be >= 1")
    except (ConfigError, ValueError) as e:
        print("loop_demo: error: %s" % " ".join(str(e).split()), file=sys.stderr)
        return 2
    run(cfg, seeds, args.record_seed, args.out_dir, args.jobs, not args.no_coupling, args.ablation, args.figure,
        say=lambda msg: print(msg, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
