#!/usr/bin/env python3
"""Record lab-like identification data from the Bullet simulation (no roscore).

Each robot drives alone in its own Bullet world (no collisions) under the
exciting 10 Hz commands of identify_synth; optional actuator effects sit
between the commands and the simulated motors (an ActuatorPlant, as the
sim's injectable effects will), and optional mocap effects (heading offset,
noise, dropped samples) on the 100 Hz poses. Writes a bag like record.launch
does (/vicon/<r>/<r>, /<r>/cmd_vel) or a CSV.

    scripts/env.sh python src/puzzlebot_mpc/test/identify_sim_record.py out.bag \\
        [--effect input_delay:delay_s=0.1 ...] [--robots 3] [--duration 150] [--seed 0] [--clean]
"""

import argparse
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import identify_synth as synth  # noqa: E402
from puzzlebot_common.geometry import wrap_angle  # noqa: E402
from puzzlebot_common.effects import ActuatorPlant  # noqa: E402

PHYSICS_RATE = 400   # Hz (sim.yaml)
POSE_RATE = 100      # Hz


def record(effects, n_robots=3, duration=150.0, seed=0, noise=True):
    """{robot: dict(t, x, y, yaw, cmd)} from the Bullet simulation."""
    from puzzlebot_sim.params import RobotParams
    from puzzlebot_sim.world import RobotStart, SimWorld

    rng = np.random.default_rng(seed)
    model = synth.model_of(effects)
    out = {}
    for j in range(n_robots):
        name = "pz%d" % (j + 1)
        cmds = synth.make_commands(rng, duration)
        with SimWorld(RobotParams(), [RobotStart(name, 0.0, 0.0, rng.uniform(-math.pi, math.pi))],
                      physics_rate=PHYSICS_RATE) as world:
            plant = ActuatorPlant(model)
            dt, per_pose = world.dt, PHYSICS_RATE // POSE_RATE
            samples, i = [], 0
            for k in range(int(round(duration * PHYSICS_RATE))):
                t = k * dt
                while i < len(cmds) and cmds[i][0] < t + dt:
                    plant.command(*cmds[i])
                    i += 1
                v, w = plant.advance(t, dt)
                world.set_command(name, v, w)
                world.step()
                if (k + 1) % per_pose == 0:
                    samples.append((world.time,) + tuple(world.pose2d(name)))
        a = np.array(samples)
        t, x, y, th = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
        yaw = th + model.param("offset_rad")
        keep = np.ones(t.size, bool)
        if noise:
            x = x + rng.normal(0, synth.POS_NOISE, t.size)
            y = y + rng.normal(0, synth.POS_NOISE, t.size)
            yaw = yaw + rng.normal(0, synth.YAW_NOISE, t.size)
            keep = rng.random(t.size) >= synth.DROP_FRACTION
        out[name] = dict(t=t[keep], x=x[keep], y=y[keep], yaw=wrap_angle(yaw[keep]), cmd=cmds)
    return out


def parse_effect(text):
    """'input_delay:delay_s=0.1' or 'velocity_lag:tau_v_s=0.1,tau_w_s=0.05' -> (name, params)."""
    name, _, rest = text.partition(":")
    params = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        params[key.strip()] = float(value)
    return name.strip(), params


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", help="output .bag or .csv")
    p.add_argument("--effect", action="append", default=[], help="name:param=value,... (repeatable)")
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--duration", type=float, default=150.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--clean", action="store_true", help="no mocap noise or dropped samples")
    args = p.parse_args(argv)
    effects = dict(parse_effect(e) for e in args.effect)
    rec = record(effects, args.robots, args.duration, args.seed, noise=not args.clean)
    (synth.write_csv if args.out.endswith(".csv") else synth.write_bag)(args.out, rec)
    print("wrote %s: %d robots x %.0f s, effects %s" % (args.out, args.robots, args.duration, effects or "none"))


if __name__ == "__main__":
    main()
