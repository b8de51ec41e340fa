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
plain controller unchanged (``Compensation.create`` returns None).

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
from puzzlebot_common.effects import ActuatorModel, actuator_state, predict

#: Shortest command history fed to the actuator model [s] (the identification tool's).
MIN_HISTORY_S = 2.0
#: Lag time constants of history beyond the delay: the lag has decayed to e^-8 of a step.
LAG_SETTLE = 8.0


def lag_decay(tau, h):
    """d such that a first-order lag x' = (u - x) / tau ends h seconds later at u + d (x0 - u)."""
    if tau <= 0.0:
        return 0.0
    return math.exp(-h / tau)


def load_model(path, where="actuator_model"):
    """The ActuatorModel of a model.yaml, or None for an empty path or a model without effects (the
    plain unicycle). A missing or malformed file raises a one-line ConfigError naming the entry."""
    if path is None or path == "":
        return None
    if not isinstance(path, str):
        raise ConfigError("%s: expected the path of a model.yaml, got %r" % (where, path))
    try:
        model = ActuatorModel.load(path)
    except ConfigError as e:
        raise ConfigError("%s: %s" % (where, " ".join(str(e).split()))) from None
    return model if model.effects else None


def describe_model(model):
    """One line: the effects and their parameters, or "none (plain unicycle)"."""
    if model is None or not model.effects:
        return "none (plain unicycle)"
    return "; ".join("%s %s" % (e.name, " ".join("%s=%.4g" % kv for kv in e.params.items()))
                     for e in model.effects)


class Compensation:
    """Delay prediction, heading correction and the inverse actuator chain for N robots.

    ``model``: the identified ActuatorModel (shared by all robots), ``names``:
    robot names, ``settings``: MPCSettings (dt, v_max, w_max).
    """

    def __init__(self, model, names, settings):
        p = model.all_params()
        self.model = model
        self.names = list(names)
        self.dt = settings.dt
        self.v_max, self.w_max = settings.v_max, settings.w_max
        self.delay = p["delay_s"]
        self.offset = p["offset_rad"]
        self.k_v, self.k_w = p["k_v"], p["k_w"]
        self.v_min, self.w_min = p["v_min"], p["w_min"]
        self.w_per_v, self.w0 = p["w_per_v"], p["w0"]
        self.d_v = lag_decay(p["tau_v_s"], self.dt)
        self.d_w = lag_decay(p["tau_w_s"], self.dt)
        self.history_s = max(MIN_HISTORY_S, self.delay + LAG_SETTLE * max(p["tau_v_s"], p["tau_w_s"]) + self.dt)
        self._sent = {n: deque() for n in self.names}     # (t_issue, v, w) commands sent, oldest first
        self._lagged = {n: (0.0, 0.0) for n in self.names}  # lagged (v, w) at now + delay (before the bias)

    @classmethod
    def create(cls, model, names, settings):
        """A Compensation, or None for no model or a model without effects (the plain unicycle)."""
        if model is None or not model.effects:
            return None
        return cls(model, names, settings)

    # ------------------------------------------------------------- pose in
    def body_yaw(self, yaw):
        """Measured yaw -> body heading [rad]."""
        return wrap_angle(yaw - self.offset) if self.offset else yaw

    # ------------------------------------------------------- initial state
    def sent(self, name):
        """The commands (t_issue, v, w) sent to ``name`` that still matter, oldest first."""
        return list(self._sent[name])

    def predict_robot(self, name, pose, stamp, now):
        """Body pose and velocities (x, y, theta, v, w) of ``name`` at ``now + delay_s``, from its body
        pose at ``stamp`` and the commands sent; v, w are the actual velocities (w with the bias)."""
        cmds = self.sent(name)
        target = max(now + self.delay, stamp)
        state = actuator_state(self.model, cmds, stamp, self.history_s)
        measured = (pose[0], pose[1], pose[2] + self.offset)
        later = [c for c in cmds if c[0] > stamp]
        end = predict(self.model, measured, state, later, target - stamp, 1)[1]
        lag = actuator_state(self.model, cmds, target, self.history_s)
        self._lagged[name] = (lag.v, lag.w)
        theta = pose[2] + wrap_angle(end[2] - measured[2])      # continuous with the measured heading
        return end[0], end[1], theta, lag.v, lag.w + self.w_per_v * lag.v + self.w0

    def initial_states(self, x0, now, stamps, skip=()):
        """Replace the rows of ``x0`` ((N, 5): body pose, velocity) by the predicted state at
        ``now + delay_s``; ``stamps``: name -> stamp of the pose in x0; robots in ``skip`` (stale)
        keep their row."""
        for i, name in enumerate(self.names):
            if name in skip or stamps.get(name) is None:
                self._lagged[name] = (0.0, 0.0)
                continue
            x0[i] = self.predict_robot(name, x0[i, :3], stamps[name], now)
        return x0

    # -------------------------------------------------------- commands out
    def invert(self, name, v, w):
        """The command (v, w) that makes ``name``'s mean body velocity over the interval starting at
        ``now + delay_s`` equal to (v, w), within the command limits."""
        if v == 0.0 and w == 0.0:
            return 0.0, 0.0
        v0, w0_lag = self._lagged[name]
        w_lag = w - self.w_per_v * v - self.w0                  # the bias is added after the lag
        u_v = (v - self.d_v * v0) / (1.0 - self.d_v)            # the lag reaches v after dt
        u_w = (w_lag - self.d_w * w0_lag) / (1.0 - self.d_w)
        c_v = _out_of_band(u_v / self.k_v, self.v_min)
        c_w = _out_of_band(u_w / self.k_w, self.w_min)
        return float(np.clip(c_v, -self.v_max, self.v_max)), float(np.clip(c_w, -self.w_max, self.w_max))

    def record(self, name, now, v, w):
        """Remember a command sent at ``now``; forget what no longer matters."""
        sent = self._sent[name]
        sent.append((float(now), float(v), float(w)))
        cutoff = now - self.history_s - self.delay - self.dt
        while len(sent) >= 2 and sent[1][0] <= cutoff:        # keep the one in force at the cutoff
            sent.popleft()

    def to_commands(self, result, now, stale=()):
        """Turn the planned velocities of ``result.commands`` ((N, 2), in place) into commands and record
        them; the plan is kept in ``result.extra["planned"]``. A failed step or a stale robot gets
        zero."""
        planned = np.array(result.commands, dtype=float)
        result.extra["planned"] = planned.copy()
        for i, name in enumerate(self.names):
            if result.success and name not in stale:
                result.commands[i] = self.invert(name, planned[i, 0], planned[i, 1])
            else:
                result.commands[i] = 0.0
            self.record(name, now, result.commands[i, 0], result.commands[i, 1])
        return result


def _out_of_band(c, c_min):
    """A command inside the deadband does nothing: round it to 0 or to the band's edge, whichever is
    nearer."""
    if c_min <= 0.0 or abs(c) >= c_min:
        return c
    return math.copysign(c_min, c) if abs(c) >= 0.5 * c_min else 0.0
