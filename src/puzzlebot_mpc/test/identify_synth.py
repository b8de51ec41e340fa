"""Synthetic lab data for the identification tests (tests and benchmarks only).

Lab-like records: several robots, 10 Hz commands that excite the system
(steps, ramps, turns, straight runs, random sequences, small commands held
and swept slowly, stops),
the true effects simulated by ``ActuatorPlant`` with exact unicycle arcs at a
fine step, then 100 Hz mocap with noise and dropped samples. The tool under
test only ever sees the written file (bag or CSV).
"""

import csv
import math

import numpy as np

from puzzlebot_common.geometry import quaternion_from_yaw, wrap_angle
from puzzlebot_common.effects import ActuatorModel, ActuatorPlant
from puzzlebot_common.model import unicycle_arc

CMD_RATE = 10.0          # Hz
MOCAP_RATE = 100.0       # Hz
POS_NOISE = 0.0005       # m (std)
YAW_NOISE = 0.005        # rad (std)
DROP_FRACTION = 0.02     # samples dropped at random
DROP_BURSTS_PER_MIN = 2  # plus bursts of 5-30 consecutive samples
CMD_JITTER = 0.004       # s: command times jitter by up to this
CLOCK_DRIFT = (1.5e-4, 4e-4)  # relative rate error of the commanding node's clock
V_MAX = 0.15             # m/s
W_MAX = 2.5              # rad/s


def model_of(effects):
    """ActuatorModel from {name: params}."""
    m = ActuatorModel()
    for name, params in effects.items():
        m.add(name, params)
    return m


def make_commands(rng, duration, on_rows=None):
    """Commands (t_issue, v, w) at CMD_RATE with a few ms of jitter; ``on_rows`` = (phase, period):
    each command issued at a pose sample time instead (a controller that answers each pose)."""
    period = 1.0 / CMD_RATE
    n = int(duration * CMD_RATE)
    v = np.zeros(n)
    w = np.zeros(n)
    i = 0
    while i < n:
        kind = rng.choice(["step", "straight", "turn", "ramp", "random", "small", "sweep", "stop"],
                          p=[0.2, 0.12, 0.12, 0.12, 0.12, 0.12, 0.12, 0.08])
        m = min(n - i, int(rng.integers(8, 30)))
        sign = 1.0 if rng.random() < 0.8 else -1.0
        if kind == "step":
            v[i:i + m], w[i:i + m] = sign * rng.uniform(0.03, V_MAX), rng.uniform(-1.5, 1.5)
        elif kind == "straight":
            v[i:i + m], w[i:i + m] = sign * rng.uniform(0.03, V_MAX), 0.0
        elif kind == "turn":
            v[i:i + m], w[i:i + m] = rng.uniform(0.0, 0.05), rng.choice([-1, 1]) * rng.uniform(0.8, W_MAX)
        elif kind == "ramp":
            v[i:i + m] = np.linspace(rng.uniform(-0.05, V_MAX), rng.uniform(-0.05, V_MAX), m)
            w[i:i + m] = np.linspace(rng.uniform(-2, 2), rng.uniform(-2, 2), m)
        elif kind == "random":
            v[i:i + m] = rng.uniform(-0.05, V_MAX, m)
            w[i:i + m] = rng.uniform(-W_MAX, W_MAX, m)
        elif kind == "sweep":      # slow ramps through small commands (where a deadband shows)
            v[i:i + m] = np.linspace(*rng.uniform(-0.04, 0.04, 2), m)
            w[i:i + m] = np.linspace(*rng.uniform(-0.6, 0.6, 2), m)
        elif kind == "small":
            hold = int(rng.integers(3, 8))
            vals_v = rng.uniform(-0.04, 0.04, m // hold + 1)
            vals_w = rng.uniform(-0.6, 0.6, m // hold + 1)
            v[i:i + m] = np.repeat(vals_v, hold)[:m]
            w[i:i + m] = np.repeat(vals_w, hold)[:m]
        i += m
    # The commanding node's clock drifts against the mocap's (so the command times sweep
    # through the mocap frames, as in the lab) and each command has a few ms of jitter.
    drift = rng.choice([-1, 1]) * rng.uniform(*CLOCK_DRIFT)
    t = period * (1.0 + drift) * np.arange(n) + rng.uniform(0.0, CMD_JITTER, n)
    if on_rows is not None:
        phase, pose_period = on_rows
        t = phase + pose_period * np.ceil((t - phase) / pose_period - 1e-9)
    return list(zip(t, v, w))


def simulate(model, commands, duration, dt=0.002, pose0=(0.0, 0.0, 0.0), t_start=0.0):
    """True body poses at t = k dt: ActuatorPlant + exact unicycle arcs."""
    plant = ActuatorPlant(model, t_start)
    n = int(round(duration / dt))
    poses = np.empty((n + 1, 3))
    pose = np.array(pose0, dtype=float)
    poses[0] = pose
    i = 0
    for k in range(n):
        t = k * dt
        while i < len(commands) and commands[i][0] < t + dt:
            plant.command(*commands[i])
            i += 1
        v, w = plant.advance(t, dt)
        pose = unicycle_arc(pose, v, w, dt)
        poses[k + 1] = pose
    return poses, plant


def lab_record(effects, n_robots=3, duration=150.0, seed=0, pos_noise=POS_NOISE, yaw_noise=YAW_NOISE,
               drop=DROP_FRACTION, dt=0.002, mutate=None, robot_effects=None, commands_on_rows=False,
               latency=0.0, outliers=0, bursts_per_min=DROP_BURSTS_PER_MIN):
    """Synthetic record: {robot: dict(t, x, y, yaw, cmd)} with the true ``effects`` ({name: params})
    on every robot, or ``robot_effects`` ({robot: {name: params}}) replacing them for some.

    ``mutate(t, x, y, yaw, v_body, w_body)`` may alter the measured poses to inject an effect
    outside the candidate set (for the "unknown effect left" test); ``commands_on_rows``: commands
    issued at pose sample times; ``latency`` [s]: the mocap stamps each pose this late; ``outliers``:
    this many marker swaps (a pose 5 cm off) per robot. The first pose sample is never dropped (the
    plant's drifting gain starts there, as the tool assumes).
    """
    rng = np.random.default_rng(seed)
    robots = {}
    for j in range(n_robots):
        name = "pz%d" % (j + 1)
        model = model_of((robot_effects or {}).get(name, effects))
        step = int(round(1.0 / (MOCAP_RATE * dt)))
        phase = int(rng.integers(0, step))
        cmds = make_commands(rng, duration, (phase * dt, step * dt) if commands_on_rows else None)
        pose0 = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-math.pi, math.pi))
        poses, plant = simulate(model, cmds, duration, dt, pose0, t_start=phase * dt + latency)
        idx = np.arange(phase, poses.shape[0], step)
        t = idx * dt
        x, y, th = poses[idx, 0], poses[idx, 1], poses[idx, 2]
        if mutate is not None:
            x, y, th = mutate(t, x, y, th)
        yaw = wrap_angle(th + model.param("offset_rad") + rng.normal(0, yaw_noise, t.size))
        x = x + rng.normal(0, pos_noise, t.size)
        y = y + rng.normal(0, pos_noise, t.size)
        for k in rng.choice(np.arange(10, t.size - 10), outliers, replace=False) if outliers else []:
            x[k] += 0.05
        keep = rng.random(t.size) >= drop
        for _ in range(int(bursts_per_min * duration / 60.0)):
            s = int(rng.integers(0, t.size))
            keep[s:s + int(rng.integers(5, 30))] = False
        keep[0] = True
        robots[name] = dict(t=t[keep] + latency, x=x[keep], y=y[keep], yaw=yaw[keep], cmd=cmds)
    return robots


def write_csv(path, robots, t0=0.0, command_times=False):
    """CSV in the tool's format: one row per pose sample, with the command in force then (and, with
    ``command_times``, the t_cmd column: when that command was issued)."""
    rows = []
    for name, r in robots.items():
        ct = np.array([c[0] for c in r["cmd"]])
        for k in range(r["t"].size):
            i = np.searchsorted(ct, r["t"][k] + 1e-9, side="right") - 1
            v, w, tc = (r["cmd"][i][1], r["cmd"][i][2], ct[i] + t0) if i >= 0 else ("", "", "")
            rows.append((r["t"][k] + t0, name, r["x"][k], r["y"][k], r["yaw"][k], v, w, tc))
    rows.sort(key=lambda row: row[0])
    with open(path, "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["t", "robot", "x", "y", "yaw", "v_cmd", "w_cmd"] + (["t_cmd"] if command_times else []))
        for row in rows:
            wr.writerow([repr(float(row[0]))] + [row[1]] + ["%.7f" % row[2], "%.7f" % row[3], "%.7f" % row[4]]
                        + [("%.6f" % c) if c != "" else "" for c in row[5:7]]
                        + ([repr(float(row[7])) if row[7] != "" else ""] if command_times else []))


def write_bag(path, robots, t0=1.7e9, cmd_robots=None, pose_robots=None):
    """ROS 1 bag: /vicon/<r>/<r> TransformStamped (header stamp = pose time) and
    /<r>/cmd_vel Twist (record time = command time). No roscore needed."""
    from puzzlebot_mpc.identify.data import write_messages
    import rospy
    from geometry_msgs.msg import TransformStamped, Twist

    from puzzlebot_common import names

    cmd_robots = list(robots) if cmd_robots is None else cmd_robots
    pose_robots = list(robots) if pose_robots is None else pose_robots
    msgs = []
    for name, r in robots.items():
        if name in pose_robots:
            for k in range(r["t"].size):
                m = TransformStamped()
                stamp = rospy.Time.from_sec(t0 + r["t"][k])
                m.header.stamp = stamp
                m.header.frame_id = "world"
                m.child_frame_id = name
                m.transform.translation.x, m.transform.translation.y = r["x"][k], r["y"][k]
                q = quaternion_from_yaw(r["yaw"][k])
                m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z, m.transform.rotation.w = q
                msgs.append((t0 + r["t"][k] + 0.002, names.vicon_topic(name), m))
        if name in cmd_robots:
            for t, v, w in r["cmd"]:
                m = Twist()
                m.linear.x, m.angular.z = v, w
                msgs.append((t0 + t, names.cmd_vel_topic(name), m))
    write_messages(path, msgs)
