"""The driver's control core, without ROS or sockets.

The node feeds it mocap poses (with their stamps) and cmd_vel messages (with
their arrival time) and calls :meth:`DriverCore.tick` at the loop rate; each
tick returns the PWM to send to every robot and why. Times are seconds of one
clock (ROS time in the node; wall time in the lab, so Vicon stamps and
arrival times compare directly).
"""

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Optional, Tuple

from puzzlebot_driver import safety
from puzzlebot_driver.controller import WheelController
from puzzlebot_driver.estimator import VelocityEstimator


@dataclass
class Decision:
    """What one robot gets this tick."""

    left: int
    right: int
    reason: str                       # safety.DRIVE or why the PWM is zero
    saturated: bool = False


@dataclass
class RobotState:
    """Everything the driver knows about one robot (read by diagnostics)."""

    name: str
    ip_octet: int
    pilot: bool
    pose: Optional[Tuple[float, float, float, float]] = None   # stamp, x, y, yaw (world)
    cmd: Optional[Tuple[float, float]] = None                  # last accepted (v, w)
    cmd_time: Optional[float] = None                           # its arrival time
    cmd_rejected: bool = False                                 # the latest command was rejected
    rejected_poses: int = 0
    rejected_commands: int = 0
    decision: Decision = field(default_factory=lambda: Decision(0, 0, safety.NO_POSE))
    pose_stamps: deque = field(default_factory=deque)          # for the mocap rate

    def mocap_rate(self):
        """Poses per second over the stamps of the last mocap_rate_window."""
        if len(self.pose_stamps) < 2:
            return 0.0
        span = self.pose_stamps[-1] - self.pose_stamps[0]
        return (len(self.pose_stamps) - 1) / span if span > 0 else 0.0

    def pose_age(self, now):
        return None if self.pose is None else now - self.pose[0]


class DriverCore:
    """Per-robot estimators, velocity loops and the safety rules."""

    def __init__(self, robots, config):
        """``robots``: parsed robot list; ``config``: params.DriverConfig."""
        self.params = config.params
        self.robots = {r.name: RobotState(r.name, r.ip_octet, r.pilot) for r in robots}
        self.order = [r.name for r in robots]
        p = self.params
        self.estimators = {n: VelocityEstimator(p.estimator_window, p.estimator_tau, p.estimator_max_gap)
                           for n in self.order}
        self.controllers = {n: WheelController(config.gains[n]) for n in self.order}
        self.estop = False
        self.estop_reason = ""

    # ------------------------------------------------------------------ inputs
    def on_pose(self, name, stamp, x, y, yaw, now=None):
        """A mocap pose; returns None if accepted, else why it was not.

        With ``now`` (the driver's clock at arrival), a stamp more than
        ``max_clock_skew`` in the future is rejected: the staleness rule
        needs the mocap clock and the driver's clock to agree.
        """
        state = self.robots.get(name)
        if state is None:
            return "pose for unknown robot %r" % name
        if now is not None and stamp - now > self.params.max_clock_skew:
            state.rejected_poses += 1
            return ("%s: pose stamped %.3f s in the future; is the mocap clock synchronised with this "
                    "machine?" % (name, stamp - now))
        reason = self.estimators[name].update(stamp, x, y, yaw)
        if reason is not None:
            state.rejected_poses += 1
            return "%s: %s" % (name, reason)
        state.pose = (stamp, x, y, yaw)
        stamps = state.pose_stamps
        stamps.append(stamp)
        while stamps and stamp - stamps[0] > self.params.mocap_rate_window:
            stamps.popleft()
        return None

    def on_cmd(self, name, now, v, w):
        """A cmd_vel arriving at ``now``; None if accepted, else why it was rejected.

        A rejected command stops the robot (it is not executed, and the
        previous one is not kept either) until a valid command arrives.
        """
        state = self.robots.get(name)
        if state is None:
            return "command for unknown robot %r" % name
        reason = safety.check_command(v, w, self.params)
        if reason is not None:
            state.cmd_rejected = True
            state.rejected_commands += 1
            return "%s: %s; robot stopped" % (name, reason)
        state.cmd, state.cmd_time, state.cmd_rejected = (float(v), float(w)), now, False
        return None

    def set_estop(self, engaged, reason=""):
        """Engage (latched) or release the e-stop; returns True if the state changed."""
        changed = engaged != self.estop
        self.estop, self.estop_reason = engaged, reason if engaged else ""
        return changed

    # -------------------------------------------------------------------- loop
    def estimate(self, name):
        return self.estimators[name].velocity()

    def tick(self, now, dt, connected=None):
        """Decide every robot's PWM at time ``now``; ``dt`` [s] since the previous tick;
        ``connected``: names of the robots with a link (None: all)."""
        out = {}
        for name in self.order:
            state = self.robots[name]
            linked = connected is None or name in connected
            reason = safety.zero_reason(now, self.estop, state.pose[0] if state.pose else None, state.cmd,
                                        state.cmd_time, state.cmd_rejected, self.params, linked)
            ctrl = self.controllers[name]
            if reason != safety.DRIVE:
                ctrl.reset()
                decision = Decision(0, 0, reason)
            else:
                cmd = ctrl.step(state.cmd[0], state.cmd[1], self.estimate(name), dt)
                decision = Decision(cmd.left, cmd.right, reason, cmd.saturated)
            state.decision = decision
            out[name] = decision
        return out


class LoopStats:
    """Achieved loop rate and jitter over the last ``window`` ticks."""

    def __init__(self, period, window=300):
        self.period = period
        self._ticks = deque(maxlen=window + 1)   # monotonic tick times
        self._work = deque(maxlen=window)        # s spent in each tick
        self.ticks = 0
        self.overruns = 0                        # ticks later than one full period

    def record(self, t, work):
        if self._ticks and t - self._ticks[-1] > 2.0 * self.period:
            self.overruns += 1
        self._ticks.append(t)
        self._work.append(work)
        self.ticks += 1

    def summary(self):
        """Dict: rate [Hz], period mean/std/max and p99 [ms], work mean/max [ms], ticks, overruns."""
        t = list(self._ticks)
        periods = [b - a for a, b in zip(t, t[1:])]
        if not periods:
            return {"rate_hz": 0.0, "period_mean_ms": math.nan, "period_std_ms": math.nan,
                    "period_max_ms": math.nan, "period_p99_ms": math.nan, "work_mean_ms": math.nan,
                    "work_max_ms": math.nan, "ticks": self.ticks, "overruns": self.overruns}
        n = len(periods)
        mean = sum(periods) / n
        std = math.sqrt(sum((p - mean) ** 2 for p in periods) / n)
        ordered = sorted(periods)
        p99 = ordered[min(n - 1, int(math.ceil(0.99 * n)) - 1)]
        work = list(self._work)
        return {"rate_hz": 1.0 / mean if mean > 0 else 0.0, "period_mean_ms": 1e3 * mean,
                "period_std_ms": 1e3 * std, "period_max_ms": 1e3 * ordered[-1], "period_p99_ms": 1e3 * p99,
                "work_mean_ms": 1e3 * sum(work) / len(work), "work_max_ms": 1e3 * max(work),
                "ticks": self.ticks, "overruns": self.overruns}
