"""The driver's control core, without ROS or sockets.

The node feeds it mocap poses (with their stamps) and cmd_vel messages (with
their arrival time) and calls :meth:`DriverCore.tick` at the loop rate; each
tick returns the PWM to send to every robot and why. Times are seconds of one
clock (ROS time in the node; wall time in the lab, so Vicon stamps and
arrival times compare directly).

Every pose goes through the robot's pose gate (puzzlebot_common.pose_gate,
bounds ``v_limit`` / ``w_limit`` x ``speed_margin``) before the velocity
estimator sees it: a rejected frame is counted and not used, so the last
accepted pose ages and the staleness rule stops the robot if rejections go on.
"""

import math
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Optional, Tuple

from puzzlebot_common.pose_gate import PoseGate, Verdict
from puzzlebot_driver import safety
from puzzlebot_driver.controller import WheelController
from puzzlebot_driver.estimator import VelocityEstimator

CLOCK = "clock"                   # rejection kind of a pose stamped in the future (the driver's own rule)
UNKNOWN_ROBOT = "unknown robot"


@dataclass
class Decision:
    """What one robot gets this tick."""

    left: int
    right: int
    reason: str                       # safety.DRIVE or why the PWM is zero
    saturated: bool = False
    detail: str = ""                  # for the loop's own zero reasons (safety.ESTIMATE_INVALID, ...): what


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
    gate: Optional[PoseGate] = None                            # the pose gate of this robot
    rejected_poses: int = 0                                    # by the gate or the clock check
    clock_rejections: int = 0                                  # poses stamped too far in the future
    rejected_commands: int = 0
    loop_faults: int = 0                                       # ticks zeroed by the loop's own checks
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
        p = self.params
        self.robots = {r.name: RobotState(r.name, r.ip_octet, r.pilot,
                                          gate=PoseGate(r.name, p.v_limit, p.w_limit, config.pose_gate))
                       for r in robots}
        self.order = [r.name for r in robots]
        self.estimators = {n: VelocityEstimator(p.estimator_window, p.estimator_tau, p.estimator_max_gap)
                           for n in self.order}
        self.controllers = {n: WheelController(config.gains[n]) for n in self.order}
        self.estop = False
        self.estop_reason = ""

    # ------------------------------------------------------------------ inputs
    def on_pose(self, name, stamp, x, y, heading, now=None, z=0.0):
        """A mocap pose: ``heading`` is the yaw [rad] or the quaternion (x, y, z, w); ``z`` [m].

        Returns the pose gate's Verdict (``reason`` prefixed with the robot's
        name). With ``now`` (the driver's clock at arrival), a stamp more than
        ``max_clock_skew`` in the future is rejected (kind ``clock``): the
        staleness rule needs the mocap clock and the driver's clock to agree.
        """
        state = self.robots.get(name)
        if state is None:
            return Verdict(False, kind=UNKNOWN_ROBOT, reason="pose for unknown robot %r" % name)
        if now is not None and stamp - now > self.params.max_clock_skew:     # before the gate: not a track
            state.clock_rejections += 1
            state.rejected_poses += 1
            return Verdict(False, kind=CLOCK, reason="%s: pose stamped %.3f s in the future; is the mocap clock "
                                                     "synchronised with this machine?" % (name, stamp - now))
        quaternion = tuple(heading) if isinstance(heading, (tuple, list)) else None
        verdict = state.gate.check(stamp, x, y, yaw=None if quaternion else heading, quaternion=quaternion, z=z)
        if not verdict.accepted:
            state.rejected_poses += 1
            return replace(verdict, reason="%s: %s" % (name, verdict.reason))
        if verdict.duplicate:
            return verdict
        estimator = self.estimators[name]
        if verdict.reacquired:
            estimator.reset()          # the track jumped: no velocity across the jump
        problem = estimator.update(stamp, x, y, verdict.yaw)
        if problem is not None:
            state.rejected_poses += 1
            return Verdict(False, kind="estimator", reason="%s: %s" % (name, problem))
        state.pose = (stamp, x, y, verdict.yaw)
        stamps = state.pose_stamps
        stamps.append(stamp)
        while stamps and stamp - stamps[0] > self.params.mocap_rate_window:
            stamps.popleft()
        return replace(verdict, reason="%s: %s" % (name, verdict.reason)) if verdict.reason else verdict

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

    def plausible_estimate(self, name, estimate):
        """None if the (v, w) estimate may drive the loop, else why not (non-finite, beyond the gate's bounds)."""
        gate = self.robots[name].gate
        v, w = estimate
        if not (math.isfinite(v) and math.isfinite(w)):
            return "non-finite velocity estimate (%r, %r)" % (v, w)
        if abs(v) > gate.max_speed or abs(w) > gate.max_turn_rate:
            return ("velocity estimate (%.3g m/s, %.3g rad/s) beyond what the robot can do (%.2f m/s, %.1f rad/s)"
                    % (v, w, gate.max_speed, gate.max_turn_rate))
        return None

    def _drive(self, name, state, dt):
        """The velocity loop's decision for a robot allowed to drive (zero on invalid estimate or output)."""
        ctrl = self.controllers[name]
        estimate = self.estimate(name)
        problem = None if estimate is None else self.plausible_estimate(name, estimate)
        if problem is not None:
            self.estimators[name].reset()
            ctrl.reset()
            return Decision(0, 0, safety.ESTIMATE_INVALID, detail=problem + "; estimate restarted")
        cmd = ctrl.step(state.cmd[0], state.cmd[1], estimate, dt)
        if cmd.invalid:
            return Decision(0, 0, safety.OUTPUT_INVALID, detail=cmd.invalid)
        return Decision(cmd.left, cmd.right, safety.DRIVE, cmd.saturated)

    def tick(self, now, dt, connected=None):
        """Decide every robot's PWM at time ``now``; ``dt`` [s] since the previous tick;
        ``connected``: names of the robots with a link (None: all). One robot's
        arithmetic failure zeroes that robot (reason ``internal error``), never the loop."""
        out = {}
        for name in self.order:
            state = self.robots[name]
            linked = connected is None or name in connected
            reason = safety.zero_reason(now, self.estop, state.pose[0] if state.pose else None, state.cmd,
                                        state.cmd_time, state.cmd_rejected, self.params, linked)
            if reason != safety.DRIVE:
                self.controllers[name].reset()
                if reason in (safety.NO_POSE, safety.POSE_STALE):
                    self.estimators[name].reset()     # no velocity across the gap: feed-forward only on resume
                decision = Decision(0, 0, reason)
            else:
                try:
                    decision = self._drive(name, state, dt)
                except (ArithmeticError, ValueError) as e:
                    self.controllers[name].reset()
                    self.estimators[name].reset()
                    decision = Decision(0, 0, safety.INTERNAL_ERROR, detail="%s: %s" % (type(e).__name__, e))
            if decision.detail:
                state.loop_faults += 1
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
