"""The MPC controlling the Bullet world in-process, in lockstep, without ROS.

``ClosedLoop`` couples a :class:`~puzzlebot_sim.world.SimWorld` with the
MPC node's core, :class:`puzzlebot_mpc.control_loop.ControlLoop` -- the same
code the ``mpc_node`` runs -- exactly as ``sim.launch`` does in lockstep:
at every control tick t = k dt the measured (mocap) poses at t go in, one
control step runs, its commands drive the robots from t to t + dt. What the
ROS graph adds (messages, the lockstep handshake) does not change the
trajectory, so experiments run here by the thousand, in parallel processes.

Configuration is read from the packages' shipped files as ``sim.launch``
reads them: the simulation by :func:`puzzlebot_sim.config.load_sim_config`,
the controller by :func:`puzzlebot_mpc.config_files.load_settings` with
``sim=True`` (mpc.yaml with the simulation's overrides, mpc_sim.yaml).
"""

import math
from dataclasses import dataclass, replace

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import RobotGeometry, yaw_from_quaternion
from puzzlebot_common.stages import stages
from puzzlebot_mpc.behaviors import FAILED, RUNNING, SUCCEEDED
from puzzlebot_mpc.config_files import load_settings, load_target_file
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_sim.world import SimWorld


@dataclass(frozen=True)
class Tick:
    """One control tick: simulated time [s] and what the controller did."""

    time: float
    output: object          # puzzlebot_mpc.control_loop.StepOutput


class ClosedLoop:
    """A SimWorld driven by the MPC's ControlLoop in lockstep.

    ``world``: a SimWorld (its mocap model supplies the measurement noise);
    ``names``: the robots the controller knows (default: all of the world's);
    ``settings``: MPCSettings (default: mpc.yaml + mpc_sim.yaml, as sim.launch loads them).
    """

    def __init__(self, world, settings=None, names=None, geometry=None, targets=None):
        self.world = world
        self.settings = settings or load_settings(sim=True)
        self.names = list(names or world.names)
        self.geometry = geometry or RobotGeometry()
        if targets is None:
            targets = load_target_file(self.geometry)
        self.loop = ControlLoop(self.names, self.settings, self.geometry, targets,
                                stages=stages(world.world_name, world.world_params))
        self.control_steps = int(round(self.settings.dt / world.dt))
        if abs(self.control_steps * world.dt - self.settings.dt) > 1e-9:
            raise ConfigError("the control period (%g s) must be a whole number of physics steps (%g s)"
                              % (self.settings.dt, world.dt))
        self.failed_steps = 0
        self.steps = 0
        self.last = None

    @property
    def time(self):
        return self.world.time

    def measure(self):
        """Feed the controller the mocap measurement of every robot at the current time."""
        t = self.world.time
        for name in self.names:
            m = self.world.measure(name)
            if m is None:
                continue
            (x, y, _), q = m
            reason = self.loop.on_pose(name, t, x, y, yaw_from_quaternion(*q))
            if reason:
                raise RuntimeError(reason)

    def request(self, req):
        """Start a behaviour (puzzlebot_mpc.behaviors.BehaviorRequest) now; returns its id.

        Measures first, so the request sees the current poses (as the node,
        which always holds the latest ones). Raises BehaviorError if refused.
        """
        self.measure()
        request_id = self.loop.request(req, self.world.time)
        self.loop.mpc.prepare(self.loop.pair_keys())
        return request_id

    def tick(self):
        """One control period: measure, control step, drive the world for dt. Returns the Tick."""
        self.measure()
        t = self.world.time
        out = self.loop.step(t)
        self.steps += 1
        if not out.result.success:
            self.failed_steps += 1
        for name, (v, w) in out.commands.items():
            self.world.set_command(name, v, w)
        self.world.step(self.control_steps)
        self.last = Tick(t, out)
        return self.last

    def run_behavior(self, req, limit, on_tick=None):
        """Request ``req`` and tick until it ends (or ``limit`` s of simulated time).

        ``on_tick(tick)`` is called after every tick; if it returns True the
        run stops early. Returns (state, message, elapsed [s]) -- state is
        behaviors.SUCCEEDED / FAILED, or RUNNING when ``limit`` or
        ``on_tick`` stopped it.
        """
        request_id = self.request(req)
        t0 = self.world.time
        while self.world.time - t0 < limit - 1e-9:
            tick = self.tick()
            st = tick.output.status
            if on_tick is not None and on_tick(tick):
                return RUNNING, st.message, self.world.time - t0
            if st.request_id == request_id and st.state in (SUCCEEDED, FAILED):
                return st.state, st.message, tick.time - t0
        st = self.last.output.status if self.last else None
        return RUNNING, (st.message if st else "not started"), self.world.time - t0

    def physical(self):
        """{(anchor robot, opening robot) or (knob robot, hole robot): status} read off the Bullet bodies."""
        return {(p.anchor_robot, p.opening_robot): p.status
                for p in self.world.all_physical_pairs()}


def make_world(cfg, starts, seed, mocap=None, world="flat"):
    """A SimWorld from a SimConfig (puzzlebot_sim.config), built as the sim node builds it; ``mocap``: a
    puzzlebot_sim.mocap.MocapModel in place of the config's."""
    sim = replace(cfg.sim, seed=seed, world=world, gui=False)
    w = SimWorld.from_params(sim, cfg.robot, starts, cfg.anchor, cfg.world, anchor_rest=cfg.anchor_rest)
    if mocap is not None:
        w.mocap = mocap
    return w


def yaw_diff(a, b):
    return math.remainder(a - b, 2 * math.pi)
