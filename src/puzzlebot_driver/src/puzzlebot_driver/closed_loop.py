"""Driver core + emulated robots in one deterministic loop (no ROS, no sockets).

The same parts the nodes run, on a shared simulated clock: emulated robots
integrate at the emulator's physics rate, publish mocap poses at its pose
rate, and the driver core ticks at its loop rate, its PWM reaching the robots
immediately (the motor model adds the link delay). Used by the tests of the
velocity loop and the safety rules and to check gains before a lab session.
"""

import math
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional

from puzzlebot_driver.driver import DriverCore
from puzzlebot_driver.emulator import EmulatedRobot


@dataclass
class Trace:
    """Samples of one robot at every driver tick."""

    t: List[float] = field(default_factory=list)
    v: List[float] = field(default_factory=list)          # true body velocity
    w: List[float] = field(default_factory=list)
    v_cmd: List[float] = field(default_factory=list)
    w_cmd: List[float] = field(default_factory=list)
    left: List[int] = field(default_factory=list)
    right: List[int] = field(default_factory=list)
    reason: List[str] = field(default_factory=list)

    def mean(self, key, t0, t1):
        xs = [x for t, x in zip(self.t, getattr(self, key)) if t0 <= t < t1]
        return sum(xs) / len(xs) if xs else math.nan


def run(robots, driver_config, emulator_config, commands, duration, starts=None,
        mocap_muted: Optional[Callable[[str, float], bool]] = None, cmd_rate=10.0,
        mocap_fault: Optional[Callable] = None) -> Dict[str, Trace]:
    """Simulate ``duration`` s. ``commands(t)`` -> {name: (v, w)} is sent as cmd_vel
    at ``cmd_rate`` Hz (like the MPC); ``mocap_muted(name, t)`` -> True hides a
    robot's mocap pose at t; ``mocap_fault(name, t, (x, y, yaw))`` -> a
    puzzlebot_common.mocap_faults.MocapFrame replaces the measured pose at t
    (None: the pose as measured). Returns a Trace per robot."""
    ep = emulator_config.params
    core = DriverCore(robots, driver_config)
    import numpy as np

    streams = np.random.default_rng(ep.seed).spawn(len(robots))
    emu = {r.name: EmulatedRobot(r.name, emulator_config.motors[r.name],
                                 (starts or {}).get(r.name, (0.0, 0.15 * i, 0.0)), rng)
           for i, (r, rng) in enumerate(zip(robots, streams))}
    traces = {r.name: Trace() for r in robots}
    dt = 1.0 / ep.physics_rate
    pose_every = max(1, int(round(ep.physics_rate / ep.pose_rate)))
    period = driver_config.params.period
    next_tick, next_cmd, last_tick = 0.0, 0.0, None
    steps = int(round(duration / dt))
    for k in range(steps + 1):
        t = k * dt
        if t + 1e-9 >= next_cmd:
            for name, (v, w) in commands(t).items():
                core.on_cmd(name, t, v, w)
            next_cmd += 1.0 / cmd_rate
        if k % pose_every == 0:
            for name, robot in emu.items():
                if mocap_muted is None or not mocap_muted(name, t):
                    pose = robot.measured_pose(ep.noise_xy, ep.noise_yaw)
                    frame = mocap_fault(name, t, pose) if mocap_fault is not None else None
                    if frame is None:
                        core.on_pose(name, t, *pose)
                    else:
                        core.on_pose(name, frame.stamp, frame.x, frame.y, frame.q, z=frame.z)
        if t + 1e-9 >= next_tick:
            decisions = core.tick(t, period if last_tick is None else t - last_tick)
            last_tick = t
            next_tick += period
            for name, d in decisions.items():
                emu[name].command(t, d.left, d.right)
                tr, st = traces[name], core.robots[name]
                cmd = st.cmd or (0.0, 0.0)
                tr.t.append(t)
                tr.v.append(emu[name].v)
                tr.w.append(emu[name].w)
                tr.v_cmd.append(cmd[0])
                tr.w_cmd.append(cmd[1])
                tr.left.append(d.left)
                tr.right.append(d.right)
                tr.reason.append(d.reason)
        for robot in emu.values():
            robot.step(t, dt)
    return traces
