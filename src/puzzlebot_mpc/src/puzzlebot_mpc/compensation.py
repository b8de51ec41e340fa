"""Planning with identified actuator effects around the unicycle MPC, without ROS.

The MPC (controller.py, ocp.py) plans with a unicycle that does the planned
(v, w) at once. A robot with the effects of an identified ``model.yaml``
(puzzlebot_common/effects.py) does not: its commands act ``delay_s`` late, its
velocities lag, it turns when told to go straight, its speed is scaled, and
the mocap's yaw is off its body axis. :class:`Compensation` makes the MPC plan
for that robot without changing the optimal control problem, in three places
of :class:`~puzzlebot_mpc.control_loop.ControlLoop`:

1. **pose in** (``body_yaw``): measured yaw -> body heading (yaw - ``offset_rad``);
   pair bookkeeping, behaviours and the MPC all see the body heading;
2. **initial state** (``initial_states``): from the latest pose (at its stamp)
   and the commands actually sent to each robot, ``effects.actuator_state`` and
   ``effects.predict`` give the pose and the velocities the robot will have at
   ``now + delay_s``, when the command chosen now starts to act. The MPC plans
   from there: its first interval is exactly the one the new command governs;
3. **commands out** (``to_commands``): the planned velocity of that interval
   is what the robot should do over it; the inverse of the actuator chain
   gives the command: minus the yaw-rate bias, the first-order lag inverted
   so that the lagged velocity reaches the planned one by the end of the
   control period (from the predicted lagged velocity), divided by the
   scale, pushed out of the deadband, clipped to the command limits
   ``v_max``, ``w_max``. The commands sent are recorded for the next
   prediction.

Why not the effects in the OCP dynamics: the delay is not a whole number of
Euler steps (0.15 s at dt = 0.1 s) and prediction is exact for any delay;
scale, bias and deadband are static maps, inverted exactly; and the OCP, its
sparsity, warm start and tuning stay the same, so an empty model is the
plain controller unchanged (``Compensation.create`` returns a
:class:`NullCompensation`, which changes nothing).

Per robot: a model with ``robots:`` entries (``ActuatorModel.for_robot``) gives
each robot its own effects; a robot whose model is empty is planned as the
plain unicycle. The acceleration limit is inverted exactly (the command whose
saturated response reaches the plan at the end of the period, or the largest
change the limit allows); the drifting gain is taken from the robot's first
pose (its t_start), the friction offset is added back, sign kept.

The lag inverse brings the lagged velocity to the plan at the end of each
period (deadbeat), not its mean over the period to the plan: matching the
mean needs 1/(1 - a) times the change (a = tau/dt (1 - e^(-dt/tau)), 2.7x
for tau = dt) and leaves the lagged velocity ringing with a pole at
d - a (1 - d)/(1 - a) = -0.72 (d = e^(-dt/tau)): the commands alternated
every step in the Bullet runs. Deadbeat needs 1/(1 - d) = 1.6x and does not
ring; the mean over the period is between the previous and the planned
velocity, which the next prediction knows. A change of plan larger than
the command limits allow is clipped; the next step predicts from the
commands actually sent, so the plan stays consistent with the robot.

Safety: a zero plan (the fallback stop, a stale robot, a robot at rest) is
sent as an exact zero command, never as a command that compensates a bias.
"""

import math
from collections import deque

import numpy as np

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import wrap_angle
from puzzlebot_common.effects import (ActuatorModel, lag_response, actual_velocity, actuator_state, predict)

#: Shortest command history fed to the actuator model [s] (the identification tool's).
MIN_HISTORY_S = 2.0
#: Lag time constants of history beyond the delay: the lag has decayed to e^-8 of a step.
LAG_SETTLE = 8.0
#: Bisection steps of the acceleration-limited lag inverse (relative resolution 2^-50).
INVERSE_STEPS = 50


def lag_decay(tau, h):
    """d such that a first-order lag x' = (u - x) / tau ends h seconds later at u + d (x0 - u)."""
    if tau <= 0.0:
        return 0.0
    return math.exp(-h / tau)


def lag_inverse(target, y0, tau, a, dt):
    """The constant target u that brings y' = clip((u - y) / tau, -a, a) from y0 to ``target`` after
    dt seconds (deadbeat); if the limit cannot reach it within dt, a target that ramps all the way."""
    d = lag_decay(tau, dt)
    u = (target - d * y0) / (1.0 - d) if tau > 0.0 else target
    if math.isinf(a) or abs(u - y0) <= a * tau or target == y0:
        return u
    if abs(target - y0) >= a * dt:            # out of reach: saturate for the whole period
        return y0 + math.copysign(a * (dt + tau), target - y0) if tau > 0.0 else target
    lo, hi = y0, y0 + math.copysign(a * (dt + tau) + abs(target - y0), target - y0)
    for _ in range(INVERSE_STEPS):
        mid = 0.5 * (lo + hi)
        if (lag_response(y0, mid, tau, a, dt)[2] - target) * (hi - lo) < 0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def load_model(path, where="actuator_model"):
    """The ActuatorModel of a model.yaml, or None for an empty path or a model without effects for any
    robot (the plain unicycle). A missing or malformed file raises a one-line ConfigError naming the entry."""
    if path is None or path == "":
        return None
    if not isinstance(path, str):
        raise ConfigError("%s: expected the path of a model.yaml, got %r" % (where, path))
    try:
        model = ActuatorModel.load(path)
    except ConfigError as e:
        raise ConfigError("%s: %s" % (where, " ".join(str(e).split()))) from None
    return model if model.has_effects() else None


def _describe(model):
    return "; ".join("%s %s" % (e.name, " ".join("%s=%.4g" % kv for kv in e.params.items())) for e in model.effects)


def describe_model(model):
    """One line: the shared effects and each robot's own, or "none (plain unicycle)"."""
    if model is None or not model.has_effects():
        return "none (plain unicycle)"
    parts = [_describe(model)] if model.effects else []
    parts += ["%s: %s" % (name, _describe(m)) for name, m in model.robots.items() if m.effects]
    return " | ".join(parts)


class NullCompensation:
    """No actuator model: the plain unicycle, nothing is changed."""

    active = False

    def body_yaw(self, name, stamp, yaw):
        return yaw

    def initial_states(self, x0, now, stamps, skip=()):
        return x0

    def to_commands(self, result, now, stale=()):
        return result


class RobotCompensation:
    """Delay prediction, heading correction and the inverse actuator chain of one robot (its
    ActuatorModel), with the commands sent to it."""

    def __init__(self, model, settings):
        p = model.all_params()
        self.model = model
        self.dt = settings.dt
        self.v_max, self.w_max = settings.v_max, settings.w_max
        self.delay = p["delay_s"]
        self.offset = p["offset_rad"]
        self.k_v, self.k_w = p["k_v"], p["k_w"]
        self.v_min, self.w_min = p["v_min"], p["w_min"]
        self.v_c, self.w_c = p["v_c"], p["w_c"]
        self.tau_v, self.tau_w = p["tau_v_s"], p["tau_w_s"]
        self.a_v, self.a_w = p["a_v"], p["a_w"]
        self.rate = p["rate_per_s"]
        self.w_per_v, self.w0 = p["w_per_v"], p["w0"]
        ramp = max(0.0 if math.isinf(self.a_v) else settings.v_max / self.a_v,
                   0.0 if math.isinf(self.a_w) else settings.w_max / self.a_w)
        self.history_s = max(MIN_HISTORY_S, self.delay + LAG_SETTLE * max(self.tau_v, self.tau_w) + ramp + self.dt)
        self.t_start = None                 # the first pose's stamp: where the drifting gain is 1
        self.sent = deque()                 # (t_issue, v, w) commands sent, oldest first
        self.lagged = (0.0, 0.0)            # lagged (v, w) at now + delay (before gain and bias)

    def body_yaw(self, stamp, yaw):
        if self.t_start is None:
            self.t_start = stamp
        return wrap_angle(yaw - self.offset) if self.offset else yaw

    def gain(self, t):
        return 1.0 + self.rate * (t - (self.t_start or 0.0))

    def predict(self, pose, stamp, now):
        """Body pose and velocities (x, y, theta, v, w) at ``now + delay_s`` from the body pose at
        ``stamp`` and the commands sent; v, w are the actual velocities (gain and bias applied)."""
        cmds = list(self.sent)
        target = max(now + self.delay, stamp)
        t_start = self.t_start or 0.0
        state = actuator_state(self.model, cmds, stamp, self.history_s)
        measured = (pose[0], pose[1], pose[2] + self.offset)
        later = [c for c in cmds if c[0] > stamp]
        end = predict(self.model, measured, state, later, target - stamp, 1, t_start=t_start)[1]
        lag = actuator_state(self.model, cmds, target, self.history_s)
        self.lagged = (lag.v, lag.w)
        theta = pose[2] + wrap_angle(end[2] - measured[2])      # continuous with the measured heading
        v, w = actual_velocity(self.model, lag, t_start)
        return end[0], end[1], theta, v, w

    def invert(self, now, v, w):
        """The command (v, w) that makes the robot's body velocity over the interval starting at
        ``now + delay_s`` reach (v, w) by its end, within the command limits."""
        if v == 0.0 and w == 0.0:
            return 0.0, 0.0
        g = self.gain(now + self.delay + 0.5 * self.dt)
        g = g if g > 1e-6 else 1e-6
        v0, w0_lag = self.lagged
        y_v = v / g                                              # the lagged speed that gives v
        y_w = (w - self.w_per_v * v - self.w0) / g               # the bias acts on the actual speed
        u_v = lag_inverse(y_v, v0, self.tau_v, self.a_v, self.dt)
        u_w = lag_inverse(y_w, w0_lag, self.tau_w, self.a_w, self.dt)
        c_v = _out_of_band(_with_friction(u_v / self.k_v, self.v_c), self.v_min)
        c_w = _out_of_band(_with_friction(u_w / self.k_w, self.w_c), self.w_min)
        return float(np.clip(c_v, -self.v_max, self.v_max)), float(np.clip(c_w, -self.w_max, self.w_max))

    def record(self, now, v, w):
        """Remember a command sent at ``now``; forget what no longer matters."""
        sent = self.sent
        sent.append((float(now), float(v), float(w)))
        cutoff = now - self.history_s - self.delay - self.dt
        while len(sent) >= 2 and sent[1][0] <= cutoff:        # keep the one in force at the cutoff
            sent.popleft()


class Compensation:
    """The actuator models of N robots around the MPC (module docstring).

    ``model``: the identified ActuatorModel (shared effects and each robot's own), ``names``: robot
    names, ``settings``: MPCSettings (dt, v_max, w_max). Robots whose model is empty are left as
    the plain unicycle.
    """

    active = True

    def __init__(self, model, names, settings):
        self.model = model
        self.names = list(names)
        self.robots = {}
        for n in self.names:
            own = model.for_robot(n)
            if own.effects:
                self.robots[n] = RobotCompensation(own, settings)

    @classmethod
    def create(cls, model, names, settings):
        """A Compensation, or a NullCompensation for no model or a model without effects for any robot."""
        if model is None or not model.has_effects() or not any(model.for_robot(n).effects for n in names):
            return NullCompensation()
        return cls(model, names, settings)

    def robot(self, name):
        """The compensation of one robot (None: planned as the plain unicycle)."""
        return self.robots.get(name)

    # ------------------------------------------------------------- pose in
    def body_yaw(self, name, stamp, yaw):
        """Measured yaw -> body heading [rad]."""
        part = self.robots.get(name)
        return part.body_yaw(stamp, yaw) if part is not None else yaw

    # ------------------------------------------------------- initial state
    def sent(self, name):
        """The commands (t_issue, v, w) sent to ``name`` that still matter, oldest first."""
        return list(self.robots[name].sent)

    def initial_states(self, x0, now, stamps, skip=()):
        """Replace the rows of ``x0`` ((N, 5): body pose, velocity) by the predicted state at
        ``now + delay_s``; ``stamps``: name -> stamp of the pose in x0; robots in ``skip`` (stale)
        keep their row."""
        for i, name in enumerate(self.names):
            part = self.robots.get(name)
            if part is None:
                continue
            if name in skip or stamps.get(name) is None:
                part.lagged = (0.0, 0.0)
                continue
            x0[i] = part.predict(x0[i, :3], stamps[name], now)
        return x0

    # -------------------------------------------------------- commands out
    def invert(self, name, v, w, now=0.0):
        return self.robots[name].invert(now, v, w)

    def record(self, name, now, v, w):
        self.robots[name].record(now, v, w)

    def to_commands(self, result, now, stale=()):
        """Turn the planned velocities of ``result.commands`` ((N, 2), in place) into commands and record
        them; the plan is kept in ``result.extra["planned"]``. A failed step or a stale robot gets
        zero."""
        planned = np.array(result.commands, dtype=float)
        result.extra["planned"] = planned.copy()
        for i, name in enumerate(self.names):
            part = self.robots.get(name)
            if part is None:
                continue
            if result.success and name not in stale:
                result.commands[i] = part.invert(now, planned[i, 0], planned[i, 1])
            else:
                result.commands[i] = 0.0
            part.record(now, result.commands[i, 0], result.commands[i, 1])
        return result


def _with_friction(c, c_f):
    """The command that friction reduces to c: |c| + c_f, sign kept (0 stays 0)."""
    return c + math.copysign(c_f, c) if c != 0.0 and c_f > 0.0 else c


def _out_of_band(c, c_min):
    """A command inside the deadband does nothing: round it to 0 or to the band's edge, whichever is
    nearer."""
    if c_min <= 0.0 or abs(c) >= c_min:
        return c
    return math.copysign(c_min, c) if abs(c) >= 0.5 * c_min else 0.0
