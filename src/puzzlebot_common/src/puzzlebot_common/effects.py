"""Actuator and measurement effects the plain unicycle lacks, defined once.

The MPC plans with a unicycle that does exactly the commanded (v, w) at once.
Real robots do not. Each effect here is a physical mechanism with named
parameters (the names are part of the stack's contract: identification
reports, model files, the simulator's injectable effects and the MPC all use
them):

=================  =====================  ==========================================
effect             parameters             mechanism
=================  =====================  ==========================================
input_delay        delay_s                commands act ``delay_s`` seconds late
deadband           v_min, w_min           |v| < v_min (|w| < w_min) does nothing
velocity_scale     k_v, k_w               actual = k x commanded
velocity_lag       tau_v_s, tau_w_s       first-order response of v and w
yaw_rate_bias      w_per_v, w0            extra turn rate w_per_v * v + w0 (wheel imbalance)
heading_offset     offset_rad             measured yaw = body heading + offset
=================  =====================  ==========================================

Commands pass through delay -> deadband -> scale -> lag -> bias, in that
order, whatever order the effects are listed in. The plant is exact for
piecewise-constant commands: ``ActuatorPlant.advance(t, dt)`` returns the mean
body velocity over [t, t + dt) for any dt, including commands that start to
act inside the interval. A model file (``model.yaml``)::

    model:
      effects:
        - name: input_delay
          params: {delay_s: 0.1}
        - name: velocity_lag
          params: {tau_v_s: 0.15, tau_w_s: 0.1}

Prediction (used by the identification tool's error metric and by the MPC
to plan with the identified effects):

- ``actuator_state(model, commands, t)``: the actuator state at time t from
  the command history (the commands of the previous ``history_s`` seconds);
- ``predict(model, pose, state, commands, dt, n)``: open-loop prediction of
  the measured pose from a measured pose, an actuator state and the commands
  issued after it;
- ``actuator_velocities(params, cmd_t, cmd_v, cmd_w, t0, dt, n)``: the same
  plant, vectorised over a uniform time grid (fast; for long records).
"""

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Dict, List, Tuple

import numpy as np

import yaml

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import wrap_angle
from puzzlebot_common.model import unicycle_arc

#: Effect name -> its parameter names, in the documented order.
EFFECTS = {
    "input_delay": ("delay_s",),
    "deadband": ("v_min", "w_min"),
    "velocity_scale": ("k_v", "k_w"),
    "velocity_lag": ("tau_v_s", "tau_w_s"),
    "yaw_rate_bias": ("w_per_v", "w0"),
    "heading_offset": ("offset_rad",),
}

#: Parameter values of the nominal model (the effect absent).
NOMINAL = {"delay_s": 0.0, "v_min": 0.0, "w_min": 0.0, "k_v": 1.0, "k_w": 1.0, "tau_v_s": 0.0,
           "tau_w_s": 0.0, "w_per_v": 0.0, "w0": 0.0, "offset_rad": 0.0}

_NONNEGATIVE = {"delay_s", "v_min", "w_min", "tau_v_s", "tau_w_s"}
_POSITIVE = {"k_v", "k_w"}


@dataclass
class Effect:
    name: str
    params: Dict[str, float]


@dataclass
class ActuatorModel:
    """An ordered list of effects (order = order of discovery, for reports)."""

    effects: List[Effect] = field(default_factory=list)

    # ------------------------------------------------------------ building
    @classmethod
    def from_dict(cls, data, where="model"):
        """Parse ``{"effects": [{"name": ..., "params": {...}}, ...]}`` (or the
        same under a top-level ``model`` key); raise ConfigError if malformed."""
        if isinstance(data, dict) and "model" in data:
            data = data["model"]
            where += ".model"
        if data is None:
            return cls()
        if not isinstance(data, dict):
            raise ConfigError("%s: expected a mapping with 'effects', got %r" % (where, data))
        unknown = set(data) - {"effects"}
        if unknown:
            raise ConfigError("%s: unknown key(s) %s" % (where, ", ".join(sorted(map(str, unknown)))))
        items = data.get("effects") or []
        if not isinstance(items, list):
            raise ConfigError("%s.effects: expected a list, got %r" % (where, items))
        model = cls()
        for i, item in enumerate(items):
            w = "%s.effects[%d]" % (where, i)
            if not isinstance(item, dict) or "name" not in item:
                raise ConfigError("%s: expected a mapping with 'name' and 'params'" % w)
            model.add(item["name"], item.get("params") or {}, where=w)
        return model

    @classmethod
    def load(cls, path):
        from puzzlebot_common.config import load_yaml

        return cls.from_dict(load_yaml(path), where=path)

    def add(self, name, params, where="effect"):
        """Append (or replace) an effect after checking its name and parameters."""
        if name not in EFFECTS:
            raise ConfigError("%s: unknown effect %r; known: %s" % (where, name, ", ".join(EFFECTS)))
        expected = EFFECTS[name]
        if not isinstance(params, dict) or set(params) != set(expected):
            raise ConfigError("%s: effect %s needs exactly the parameters %s, got %r"
                              % (where, name, ", ".join(expected), params))
        clean = {}
        for key in expected:
            value = params[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError("%s.params.%s: expected a finite number, got %r" % (where, key, value))
            if key in _NONNEGATIVE and value < 0:
                raise ConfigError("%s.params.%s: must be >= 0, got %r" % (where, key, value))
            if key in _POSITIVE and value <= 0:
                raise ConfigError("%s.params.%s: must be > 0, got %r" % (where, key, value))
            clean[key] = float(value)
        self.effects = [e for e in self.effects if e.name != name] + [Effect(name, clean)]
        return self

    # ------------------------------------------------------------- queries
    def names(self):
        return [e.name for e in self.effects]

    def param(self, key):
        """Value of a parameter, or its nominal value if its effect is absent."""
        for e in self.effects:
            if key in e.params:
                return e.params[key]
        return NOMINAL[key]

    def all_params(self):
        """Every parameter of every effect (nominal values for absent effects)."""
        return {key: self.param(key) for key in NOMINAL}

    def to_dict(self):
        return {"model": {"effects": [{"name": e.name, "params": dict(e.params)} for e in self.effects]}}

    def dump(self, path):
        with open(path, "w") as f:
            f.write("# PuzzleBot actuator model (puzzlebot_common/effects.py documents each effect)\n")
            yaml.safe_dump(self.to_dict(), f, sort_keys=False)


@dataclass(frozen=True)
class ActuatorState:
    """Actuator state of one robot at time ``t`` [s].

    ``v``, ``w``: lagged velocities [m/s, rad/s] (before the yaw-rate bias);
    ``active``: the command (v, w) in force after the delay (before deadband
    and scale); ``pending``: commands (t_issue, v, w) issued but not yet acting
    because of the delay, oldest first.
    """

    t: float
    v: float
    w: float
    active: Tuple[float, float] = (0.0, 0.0)
    pending: Tuple[Tuple[float, float, float], ...] = ()


def _lag_interval(x, u, tau, h):
    """First-order lag x' = (u - x) / tau with constant target u over h seconds:
    returns (mean of x over the interval, x at its end); exact."""
    if tau <= 0.0:
        return u, u
    decay = math.exp(-h / tau)
    return u + (x - u) * tau / h * (1.0 - decay), u + (x - u) * decay


class ActuatorPlant:
    """Numerical simulation of the effects for one robot, exact for
    piecewise-constant commands.

    ``command(t, v, w)`` records a command issued at time t [s] (in time
    order); ``advance(t, dt)`` returns the mean body velocity (v [m/s],
    w [rad/s]) the robot actually has over [t, t + dt), for any dt: commands
    that start to act inside the interval split it, and the lag is integrated
    in closed form. ``measured_yaw(yaw)`` applies the mocap heading offset.
    State: the delayed command queue, the command in force and the lagged
    velocities (``state(t)`` / ``from_state`` save and restore it).
    """

    #: Two events closer than this [s] are simultaneous (float round-off of t + delay).
    TIME_EPS = 1e-12

    def __init__(self, model):
        p = model.param
        self.delay = p("delay_s")
        self.v_min, self.w_min = p("v_min"), p("w_min")
        self.k_v, self.k_w = p("k_v"), p("k_w")
        self.tau_v, self.tau_w = p("tau_v_s"), p("tau_w_s")
        self.w_per_v, self.w0 = p("w_per_v"), p("w0")
        self.offset = p("offset_rad")
        self._queue = deque()          # (t_issue, v, w), oldest first
        self._active = (0.0, 0.0)      # command in force after the delay
        self.v = 0.0                   # lagged velocities
        self.w = 0.0

    @classmethod
    def from_state(cls, model, state):
        """A plant for ``model`` continuing from an :class:`ActuatorState`."""
        plant = cls(model)
        plant._queue = deque(tuple(map(float, c)) for c in state.pending)
        plant._active = (float(state.active[0]), float(state.active[1]))
        plant.v, plant.w = float(state.v), float(state.w)
        return plant

    def state(self, t):
        """The state at time ``t`` (the end of the last advance); commands due by ``t`` are
        active, and a velocity without lag is already at its target."""
        v_t, w_t = self._target(t)
        v = v_t if self.tau_v <= 0.0 else self.v
        w = w_t if self.tau_w <= 0.0 else self.w
        return ActuatorState(t=float(t), v=v, w=w, active=self._active, pending=tuple(self._queue))

    def command(self, t, v, w):
        self._queue.append((t, float(v), float(w)))

    def _activate(self, t):
        """Move every command acting by time t from the queue to ``active``."""
        while self._queue and self._queue[0][0] <= t - self.delay + self.TIME_EPS:
            _, v, w = self._queue.popleft()
            self._active = (v, w)

    def _target(self, t):
        self._activate(t)
        v, w = self._active
        if abs(v) < self.v_min:
            v = 0.0
        if abs(w) < self.w_min:
            w = 0.0
        return self.k_v * v, self.k_w * w

    def settle(self, t):
        """Activate the commands due by ``t`` and put the lagged velocities at the
        steady state of the command in force (the robot has been driving it for long)."""
        self.v, self.w = self._target(t)

    def advance(self, t, dt):
        t_end = t + dt
        s, sum_v, sum_w = t, 0.0, 0.0
        while s < t_end - self.TIME_EPS:
            v_t, w_t = self._target(s)
            nxt = t_end
            if self._queue:
                nxt = min(t_end, max(s, self._queue[0][0] + self.delay))
            h = nxt - s
            if h > self.TIME_EPS:
                mean_v, self.v = _lag_interval(self.v, v_t, self.tau_v, h)
                mean_w, self.w = _lag_interval(self.w, w_t, self.tau_w, h)
                sum_v += mean_v * h
                sum_w += mean_w * h
            s = nxt
        if dt <= self.TIME_EPS:   # zero-length step: the instantaneous velocity
            v_t, w_t = self._target(t)
            mean_v = v_t if self.tau_v <= 0.0 else self.v
            mean_w = w_t if self.tau_w <= 0.0 else self.w
        else:
            mean_v, mean_w = sum_v / dt, sum_w / dt
        return mean_v, mean_w + self.w_per_v * mean_v + self.w0

    def measured_yaw(self, yaw):
        return wrap_angle(yaw + self.offset)


def _sorted_commands(commands):
    cmds = sorted(((float(t), float(v), float(w)) for t, v, w in commands), key=lambda c: c[0])
    return cmds


def actuator_state(model, commands, t, history_s=2.0):
    """Actuator state at time ``t`` obtained by feeding the plant the commands
    (t_issue, v, w) of the previous ``history_s`` seconds.

    The plant starts at ``t - history_s`` in the steady state of the command
    in force then (commands issued before it count only through that), and
    runs exactly to ``t``. Commands issued after ``t`` are ignored; a command
    issued exactly at ``t`` is included (it is pending or acting at ``t``).
    """
    plant = ActuatorPlant(model)
    start = t - history_s
    cmds = _sorted_commands(commands)
    i = 0
    while i < len(cmds) and cmds[i][0] <= start:
        plant.command(*cmds[i])
        i += 1
    plant.settle(start)
    while i < len(cmds) and cmds[i][0] <= t:
        plant.command(*cmds[i])
        i += 1
    if history_s > 0:
        plant.advance(start, history_s)
    return plant.state(t)


def predict(model, pose, state, commands, dt, n, max_substep=0.01):
    """Open-loop prediction of the measured pose.

    ``pose`` = measured (x, y, yaw) at ``state.t`` (yaw as the mocap reports
    it: body heading + heading offset), ``state`` from :func:`actuator_state`,
    ``commands`` = (t_issue, v, w) issued after ``state.t``. Returns an
    (n + 1, 3) array of predicted measured poses at ``state.t + k dt``,
    k = 0..n; each step is integrated with exact arcs over sub-steps of at
    most ``max_substep`` seconds.
    """
    plant = ActuatorPlant.from_state(model, state)
    cmds = [c for c in _sorted_commands(commands) if c[0] > state.t]
    substeps = max(1, int(math.ceil(dt / max_substep - 1e-9)))
    h = dt / substeps
    body = np.array([pose[0], pose[1], pose[2] - plant.offset], dtype=float)
    out = np.empty((n + 1, 3))
    out[0] = pose[0], pose[1], wrap_angle(pose[2])
    i = 0
    for k in range(n):
        for j in range(substeps):
            t0 = state.t + k * dt + j * h
            while i < len(cmds) and cmds[i][0] < t0 + h:
                plant.command(*cmds[i])
                i += 1
            v, w = plant.advance(t0, h)
            body = unicycle_arc(body, v, w, h)
        out[k + 1] = body[0], body[1], wrap_angle(body[2] + plant.offset)
    return out


@dataclass(frozen=True)
class CommandPieces:
    """The grid t0 + k dt (k = 0..n) cut where commands start to act (for one delay):
    piece i lies in grid interval ``interval[i]``, lasts ``length[i]`` seconds, ends
    ``to_edge[i]`` seconds before its interval does, and carries command ``command[i]``
    (-1: before the first command)."""

    interval: np.ndarray
    length: np.ndarray
    to_edge: np.ndarray
    command: np.ndarray


def command_pieces(cmd_t, delay_s, t0, dt, n):
    cmd_t = np.asarray(cmd_t, dtype=float)
    edges = t0 + dt * np.arange(n + 1)
    act = cmd_t + delay_s                         # activation times (ascending)
    inner = act[(act > edges[0]) & (act < edges[-1])]
    cuts = np.insert(edges, np.searchsorted(edges, inner), inner)
    start, end = cuts[:-1], cuts[1:]
    k = np.clip(np.searchsorted(edges, start, side="right") - 1, 0, max(n - 1, 0))
    return CommandPieces(interval=k, length=end - start, to_edge=edges[k + 1] - end,
                         command=np.searchsorted(act, start + ActuatorPlant.TIME_EPS, side="right") - 1)


def actuator_velocities(params, cmd_t, cmd_v, cmd_w, t0, dt, n, initial=None, pieces=None):
    """The plant vectorised on the grid t0 + k dt, k = 0..n: mean body velocity
    (v, w) over each interval, as two arrays of length n.

    ``params``: every parameter name -> value (``ActuatorModel.all_params()``);
    ``cmd_*``: commands by issue time (ascending). Before the first command the
    command is zero. The lagged velocities start at ``initial`` = (v, w) or, by
    default, at the steady state of the first target. Exact, like
    ``ActuatorPlant`` stepped on the same grid: the grid intervals are cut
    where commands start to act, and the lag is integrated in closed form over
    every piece. ``pieces``: ``command_pieces(cmd_t, params["delay_s"], t0,
    dt, n)`` if the caller keeps it (it depends on the delay only).
    """
    from scipy.signal import lfilter

    p = pieces if pieces is not None else command_pieces(cmd_t, params["delay_s"], t0, dt, n)
    k, length, to_edge = p.interval, p.length, p.to_edge
    before = p.command < 0
    safe = np.maximum(p.command, 0)
    out = []
    for j, (values, v_min, gain, tau) in enumerate(((cmd_v, params["v_min"], params["k_v"], params["tau_v_s"]),
                                                     (cmd_w, params["w_min"], params["k_w"], params["tau_w_s"]))):
        values = np.asarray(values, dtype=float)
        if values.size == 0:
            u = np.zeros(length.size)
        else:
            target = gain * np.where(np.abs(values) < v_min, 0.0, values)
            u = np.where(before, 0.0, target[safe])
        if tau <= 0.0 or n == 0:
            out.append(np.bincount(k, u * length, minlength=n)[:n] / dt)
            continue
        decay = math.exp(-dt / tau)
        x0 = (u[0] if u.size else 0.0) if initial is None else initial[j]
        a = np.exp(-to_edge / tau)
        b = a * np.exp(-length / tau)
        drive = np.bincount(k, u * (a - b), minlength=n)[:n]          # x(end) = decay x(start) + drive
        ends = lfilter([1.0], [1.0, -decay], drive, zi=[decay * x0])[0]
        starts = np.concatenate([[x0], ends[:-1]])
        area = starts * tau * (1.0 - decay) + np.bincount(k, u * (length - tau * (a - b)), minlength=n)[:n]
        out.append(area / dt)
    v, w = out
    return v, w + params["w_per_v"] * v + params["w0"]
