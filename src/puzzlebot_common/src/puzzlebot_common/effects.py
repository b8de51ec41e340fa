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
friction_offset    v_c, w_c               |u| becomes max(0, |u| - c), sign kept (Coulomb-like)
velocity_scale     k_v, k_w               actual = k x commanded
velocity_lag       tau_v_s, tau_w_s       first-order response of v and w
accel_limit        a_v, a_w               v and w change by at most a_v [m/s^2], a_w [rad/s^2]
gain_drift         rate_per_s             actual x (1 + rate_per_s (t - t_start)) (a battery running down)
yaw_rate_bias      w_per_v, w0            extra turn rate w_per_v * v + w0 while driven (wheel imbalance)
heading_offset     offset_rad             measured yaw = body heading + offset
=================  =====================  ==========================================

The chain, in this order whatever order the effects are listed in (u is one
component of the command, v or w):

1. ``input_delay``: a command issued at t acts from t + delay_s;
2. ``deadband``: |u| < v_min (w_min) gives 0, larger commands pass unchanged;
3. ``friction_offset``: u becomes sign(u) max(0, |u| - v_c) (w_c): a fixed amount
   off every command (unlike the deadband, large commands lose it too);
4. ``velocity_scale``: the target is k_v u (k_w u);
5. ``velocity_lag`` and ``accel_limit``: the velocity y follows the target with
   y' = clip((target - y) / tau, -a, a): a first-order lag whose rate of change
   is limited (the limit acts after the lag); without a lag (tau = 0) y ramps to
   the target at the rate a, without a limit (a = inf) it is the plain lag;
6. ``gain_drift``: the actual velocity is (1 + rate_per_s (t - t_start)) y, on
   top of the scale; t_start is the robot's first sample (identification: its
   first pose in the log; simulator and MPC: the time they start, or see the
   robot first);
7. ``yaw_rate_bias`` (the convention): the actual turn rate gets
   w_per_v v_actual + w0, where v_actual is the actual speed of step 6 (a wheel
   imbalance acts on what the wheels do: scaled, lagged, limited, drifted), and
   w0 acts only while the robot is driven, i.e. while the target of v or w of
   step 4 is nonzero: a robot commanded to rest does not turn;
8. ``heading_offset`` acts on the measurement only: the mocap's yaw is the body
   heading + offset_rad; the robot moves along yaw - offset.

The plant is exact for piecewise-constant commands: ``ActuatorPlant.advance(t,
dt)`` returns the mean body velocity over [t, t + dt) for any dt, including
commands that start to act inside the interval, ramps of the acceleration
limit and the drifting gain. A model file (``model.yaml``)::

    model:
      effects:                      # shared by every robot
        - name: input_delay
          params: {delay_s: 0.1}
        - name: velocity_lag
          params: {tau_v_s: 0.15, tau_w_s: 0.1}
      robots:                       # optional: a robot's own entries
        pz2:
          effects:
            - name: input_delay     # replaces the shared input_delay for pz2
              params: {delay_s: 0.3}

``ActuatorModel.for_robot(name)`` is the model of one robot: the shared list
with the robot's own entries replacing the shared ones of the same name (and
its other own entries appended). ``a_v``/``a_w`` may be ``.inf`` (no limit on
that component).

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

#: Effect name -> its parameter names, in the documented order (the chain's order).
EFFECTS = {
    "input_delay": ("delay_s",),
    "deadband": ("v_min", "w_min"),
    "friction_offset": ("v_c", "w_c"),
    "velocity_scale": ("k_v", "k_w"),
    "velocity_lag": ("tau_v_s", "tau_w_s"),
    "accel_limit": ("a_v", "a_w"),
    "gain_drift": ("rate_per_s",),
    "yaw_rate_bias": ("w_per_v", "w0"),
    "heading_offset": ("offset_rad",),
}

#: Parameter values of the nominal model (the effect absent).
NOMINAL = {"delay_s": 0.0, "v_min": 0.0, "w_min": 0.0, "v_c": 0.0, "w_c": 0.0, "k_v": 1.0, "k_w": 1.0,
           "tau_v_s": 0.0, "tau_w_s": 0.0, "a_v": math.inf, "a_w": math.inf, "rate_per_s": 0.0,
           "w_per_v": 0.0, "w0": 0.0, "offset_rad": 0.0}

_NONNEGATIVE = {"delay_s", "v_min", "w_min", "v_c", "w_c", "tau_v_s", "tau_w_s"}
_POSITIVE = {"k_v", "k_w", "a_v", "a_w"}
_MAY_BE_INFINITE = {"a_v", "a_w"}    # .inf: no limit on that component


@dataclass
class Effect:
    name: str
    params: Dict[str, float]


def _check_params(name, params, where):
    if name not in EFFECTS:
        raise ConfigError("%s: unknown effect %r; known: %s" % (where, name, ", ".join(EFFECTS)))
    expected = EFFECTS[name]
    if not isinstance(params, dict) or set(params) != set(expected):
        raise ConfigError("%s: effect %s needs exactly the parameters %s, got %r"
                          % (where, name, ", ".join(expected), params))
    clean = {}
    for key in expected:
        value = params[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value) \
                or (math.isinf(value) and not (key in _MAY_BE_INFINITE and value > 0)):
            raise ConfigError("%s.params.%s: expected a finite number, got %r" % (where, key, value))
        if key in _NONNEGATIVE and value < 0:
            raise ConfigError("%s.params.%s: must be >= 0, got %r" % (where, key, value))
        if key in _POSITIVE and value <= 0:
            raise ConfigError("%s.params.%s: must be > 0, got %r" % (where, key, value))
        clean[key] = float(value)
    return clean


@dataclass
class ActuatorModel:
    """An ordered list of effects (order = order of discovery, for reports), shared by every
    robot, and optionally each robot's own entries (``robots``: name -> ActuatorModel), which
    replace the shared entry of the same effect for that robot (:meth:`for_robot`)."""

    effects: List[Effect] = field(default_factory=list)
    robots: Dict[str, "ActuatorModel"] = field(default_factory=dict)

    # ------------------------------------------------------------ building
    @classmethod
    def from_dict(cls, data, where="model"):
        """Parse ``{"effects": [{"name": ..., "params": {...}}, ...], "robots": {name: {"effects":
        [...]}}}`` (or the same under a top-level ``model`` key); raise ConfigError if malformed."""
        if isinstance(data, dict) and "model" in data:
            data = data["model"]
            where += ".model"
        model = cls._effects_from(data, where, ("effects", "robots"))
        robots = (data or {}).get("robots") or {}
        if not isinstance(robots, dict):
            raise ConfigError("%s.robots: expected a mapping robot name -> {effects: [...]}, got %r"
                              % (where, robots))
        for name, entry in robots.items():
            if not isinstance(name, str) or not name:
                raise ConfigError("%s.robots: robot names must be non-empty strings, got %r" % (where, name))
            model.robots[name] = cls._effects_from(entry, "%s.robots.%s" % (where, name), ("effects",))
        return model

    @classmethod
    def _effects_from(cls, data, where, keys):
        if data is None:
            return cls()
        if not isinstance(data, dict):
            raise ConfigError("%s: expected a mapping with 'effects', got %r" % (where, data))
        unknown = set(data) - set(keys)
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
        """Append (or replace) a shared effect after checking its name and parameters."""
        clean = _check_params(name, params, where)
        self.effects = [e for e in self.effects if e.name != name] + [Effect(name, clean)]
        return self

    def add_for_robot(self, robot, name, params, where="effect"):
        """A robot's own entry for an effect (replacing the shared one for that robot)."""
        self.robots.setdefault(robot, ActuatorModel()).add(name, params, where)
        return self

    # ------------------------------------------------------------- queries
    def names(self):
        return [e.name for e in self.effects]

    def param(self, key):
        """Value of a shared parameter, or its nominal value if its effect is absent."""
        for e in self.effects:
            if key in e.params:
                return e.params[key]
        return NOMINAL[key]

    def all_params(self):
        """Every parameter of every shared effect (nominal values for absent effects)."""
        return {key: self.param(key) for key in NOMINAL}

    def for_robot(self, name):
        """The model of robot ``name``: the shared effects, each replaced by the robot's own entry of
        the same name where it has one (in place), then the robot's other own entries."""
        own = self.robots.get(name)
        effects = [Effect(e.name, dict(e.params)) for e in self.effects]
        if own is not None:
            mine = {e.name: e for e in own.effects}
            effects = [Effect(e.name, dict(mine[e.name].params)) if e.name in mine else e for e in effects]
            shared = {e.name for e in self.effects}
            effects += [Effect(e.name, dict(e.params)) for e in own.effects if e.name not in shared]
        return ActuatorModel(effects)

    def has_effects(self):
        """True if any robot has an effect (shared or its own)."""
        return bool(self.effects) or any(m.effects for m in self.robots.values())

    def to_dict(self):
        out = {"effects": [{"name": e.name, "params": dict(e.params)} for e in self.effects]}
        if self.robots:
            out["robots"] = {name: {"effects": [{"name": e.name, "params": dict(e.params)} for e in m.effects]}
                             for name, m in self.robots.items()}
        return {"model": out}

    def dump(self, path):
        with open(path, "w") as f:
            f.write("# PuzzleBot actuator model (puzzlebot_common/effects.py documents each effect)\n")
            yaml.safe_dump(self.to_dict(), f, sort_keys=False)


@dataclass(frozen=True)
class ActuatorState:
    """Actuator state of one robot at time ``t`` [s].

    ``v``, ``w``: lagged velocities [m/s, rad/s] (after lag and acceleration limit, before the
    drifting gain and the yaw-rate bias); ``active``: the command (v, w) in force after the delay
    (before deadband, friction and scale); ``pending``: commands (t_issue, v, w) issued but not yet
    acting because of the delay, oldest first.
    """

    t: float
    v: float
    w: float
    active: Tuple[float, float] = (0.0, 0.0)
    pending: Tuple[Tuple[float, float, float], ...] = ()


def _ramp_time(e, tau, a):
    """How long y' = clip(e / tau, -a, a) stays saturated for a distance e to the target [s]."""
    if e == 0.0 or math.isinf(a):
        return 0.0
    return max(0.0, (abs(e) - a * tau) / a)


def lag_response(y0, u, tau, a, h):
    """y' = clip((u - y) / tau, -a, a) from y0 over h seconds with a constant target u (tau = 0: y
    jumps to u, or ramps to it at the rate a): returns (integral of y, integral of s y with s from
    the start, y at the end); exact."""
    e = u - y0
    T = min(h, _ramp_time(e, tau, a))
    i0 = i1 = 0.0
    y = y0
    if T > 0.0:
        s = a if e > 0 else -a
        i0 = y0 * T + s * T * T / 2.0
        i1 = y0 * T * T / 2.0 + s * T ** 3 / 3.0
        y = y0 + s * T
    q = h - T
    if q <= 0.0:
        return i0, i1, y
    if tau <= 0.0:
        return i0 + u * q, i1 + u * (T * q + q * q / 2.0), u
    decay = math.exp(-q / tau)
    d = y - u
    i0 += u * q + d * tau * (1.0 - decay)
    i1 += u * (T * q + q * q / 2.0) + d * (T * tau * (1.0 - decay) + tau * (tau - (tau + q) * decay))
    return i0, i1, u + d * decay


def _shaped(u, u_min, c):
    """Deadband then friction offset of one command component."""
    if abs(u) < u_min:
        return 0.0
    if c > 0.0:
        return math.copysign(max(0.0, abs(u) - c), u)
    return u


class ActuatorPlant:
    """Numerical simulation of the effects for one robot, exact for
    piecewise-constant commands.

    ``command(t, v, w)`` records a command issued at time t [s] (in time
    order); ``advance(t, dt)`` returns the mean body velocity (v [m/s],
    w [rad/s]) the robot actually has over [t, t + dt), for any dt: commands
    that start to act inside the interval split it, and lag, acceleration limit
    and drifting gain are integrated in closed form. ``measured_yaw(yaw)`` applies
    the mocap heading offset. ``t_start`` [s]: the time the drifting gain is 1.
    State: the delayed command queue, the command in force and the lagged
    velocities (``state(t)`` / ``from_state`` save and restore it).
    ``model``: one robot's model (``ActuatorModel.for_robot``); its shared part is used.
    """

    #: Two events closer than this [s] are simultaneous (float round-off of t + delay).
    TIME_EPS = 1e-12

    def __init__(self, model, t_start=0.0):
        p = model.param
        self.delay = p("delay_s")
        self.v_min, self.w_min = p("v_min"), p("w_min")
        self.v_c, self.w_c = p("v_c"), p("w_c")
        self.k_v, self.k_w = p("k_v"), p("k_w")
        self.tau_v, self.tau_w = p("tau_v_s"), p("tau_w_s")
        self.a_v, self.a_w = p("a_v"), p("a_w")
        self.rate, self.t_start = p("rate_per_s"), float(t_start)
        self.w_per_v, self.w0 = p("w_per_v"), p("w0")
        self.offset = p("offset_rad")
        self._stateless_v = self.tau_v <= 0.0 and math.isinf(self.a_v)
        self._stateless_w = self.tau_w <= 0.0 and math.isinf(self.a_w)
        self._queue = deque()          # (t_issue, v, w), oldest first
        self._active = (0.0, 0.0)      # command in force after the delay
        self.v = 0.0                   # lagged velocities
        self.w = 0.0

    @classmethod
    def from_state(cls, model, state, t_start=0.0):
        """A plant for ``model`` continuing from an :class:`ActuatorState`."""
        plant = cls(model, t_start)
        plant._queue = deque(tuple(map(float, c)) for c in state.pending)
        plant._active = (float(state.active[0]), float(state.active[1]))
        plant.v, plant.w = float(state.v), float(state.w)
        return plant

    def state(self, t):
        """The state at time ``t`` (the end of the last advance); commands due by ``t`` are
        active, and a velocity without lag or limit is already at its target."""
        v_t, w_t = self._target(t)
        v = v_t if self._stateless_v else self.v
        w = w_t if self._stateless_w else self.w
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
        return self.k_v * _shaped(v, self.v_min, self.v_c), self.k_w * _shaped(w, self.w_min, self.w_c)

    def gain(self, t):
        """The drifting gain at time t."""
        return 1.0 + self.rate * (t - self.t_start)

    def settle(self, t):
        """Activate the commands due by ``t`` and put the lagged velocities at the steady state of the
        command in force (the robot has been driving it for long)."""
        self.v, self.w = self._target(t)

    def velocity(self, t):
        """The actual body velocity (v, w) at time ``t`` (the end of the last advance)."""
        v_t, w_t = self._target(t)
        g = self.gain(t)
        v = g * (v_t if self._stateless_v else self.v)
        w = g * (w_t if self._stateless_w else self.w)
        driven = v_t != 0.0 or w_t != 0.0
        return v, w + self.w_per_v * v + (self.w0 if driven else 0.0)

    def advance(self, t, dt):
        if dt <= self.TIME_EPS:   # zero-length step: the instantaneous velocity
            return self.velocity(t)
        t_end = t + dt
        s, sum_v, sum_w, driven = t, 0.0, 0.0, 0.0
        while s < t_end - self.TIME_EPS:
            v_t, w_t = self._target(s)
            nxt = t_end
            if self._queue:
                nxt = min(t_end, max(s, self._queue[0][0] + self.delay))
            h = nxt - s
            if h > self.TIME_EPS:
                iv0, iv1, self.v = lag_response(self.v, v_t, self.tau_v, self.a_v, h)
                iw0, iw1, self.w = lag_response(self.w, w_t, self.tau_w, self.a_w, h)
                g = self.gain(s)
                sum_v += g * iv0 + self.rate * iv1
                sum_w += g * iw0 + self.rate * iw1
                if v_t != 0.0 or w_t != 0.0:
                    driven += h
            s = nxt
        mean_v, mean_w = sum_v / dt, sum_w / dt
        return mean_v, mean_w + self.w_per_v * mean_v + self.w0 * driven / dt

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


def actual_velocity(model, state, t_start=0.0):
    """The actual body velocity (v, w) of a robot in ``state`` (drifting gain and bias applied)."""
    return ActuatorPlant.from_state(model, state, t_start).velocity(state.t)


def predict(model, pose, state, commands, dt, n, max_substep=0.01, t_start=0.0):
    """Open-loop prediction of the measured pose.

    ``pose`` = measured (x, y, yaw) at ``state.t`` (yaw as the mocap reports
    it: body heading + heading offset), ``state`` from :func:`actuator_state`,
    ``commands`` = (t_issue, v, w) issued after ``state.t``, ``t_start``: the time
    the drifting gain is 1. Returns an (n + 1, 3) array of predicted measured
    poses at ``state.t + k dt``, k = 0..n; each step is integrated with exact
    arcs over sub-steps of at most ``max_substep`` seconds.
    """
    plant = ActuatorPlant.from_state(model, state, t_start)
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
    (-1: before the first command). ``derived``: what the integration computes from the
    pieces alone (not from the commanded values), kept for the next call (``_derived``)."""

    interval: np.ndarray
    length: np.ndarray
    to_edge: np.ndarray
    command: np.ndarray
    derived: dict = field(default_factory=dict, compare=False, repr=False)


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


DERIVED_KEPT = 4   # entries of one kind (e.g. lag factors, one per time constant) kept with the pieces


def _derived(p, key, compute):
    """``compute()``, a quantity that depends on the pieces ``p`` and ``key`` only (a tuple: kind,
    then what else it depends on), computed once and kept with the pieces (at most DERIVED_KEPT of
    a kind; the oldest is dropped). Fits evaluate many parameter sets on the same pieces."""
    d = p.derived
    if key not in d:
        same = [k for k in d if k[0] == key[0]]
        for old in same[:max(0, len(same) - DERIVED_KEPT + 1)]:
            del d[old]
        d[key] = compute()
    return d[key]


def _targets(values, u_min, c, gain, p):
    """Target of one component per piece (deadband, friction, scale; 0 before the first command)."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return np.zeros(p.length.size)
    x = np.where(np.abs(values) < u_min, 0.0, values)
    if c > 0.0:
        x = np.sign(x) * np.maximum(0.0, np.abs(x) - c)
    before, command = _derived(p, ("command",), lambda: (p.command < 0, np.maximum(p.command, 0)))
    return np.where(before, 0.0, gain * x[command])


def _lag_weights(p, tau):
    """The weights of each piece's target in the plain lag's state and integral over its grid
    interval (time constant tau > 0 [s]), what _lag_integrals multiplies by the targets:
    (e^-(dt - q)/tau, e^-(dt - s)/tau, weight in the interval-end state, weight in the integral of
    y), with s and q the piece's start and end within its interval."""
    a = np.exp(-p.to_edge / tau)          # e^-(dt - q)/tau
    b = a * np.exp(-p.length / tau)       # e^-(dt - s)/tau
    return a, b, a - b, p.length - tau * (a - b)


def _lag_moment_weights(p, tau, dt):
    """The weight of each piece's target in the integral of (s - interval start) y over its grid
    interval (tau = 0: no lag)."""
    length, to_edge = p.length, p.to_edge
    q = dt - to_edge                    # piece end and start within its interval
    s = q - length
    if tau <= 0.0:
        return q * q - s * s
    a, b = _derived(p, ("lag", tau), lambda: _lag_weights(p, tau))[:2]
    # first moment of the response to a unit step starting at s (or q), to the interval's end
    step_s = (dt * dt - s * s) / 2.0 - (s * tau + tau * tau) * (1.0 - b) + tau * (dt - s) * b
    step_q = (dt * dt - q * q) / 2.0 - (q * tau + tau * tau) * (1.0 - a) + tau * to_edge * a
    return step_s - step_q


def _lag_integrals(u, tau, p, dt, n, x0, moment):
    """Plain lag (no acceleration limit): per grid interval, the integral of y and (``moment``) of
    (s - interval start) y. Linear: the interval-end states by one recursive filter."""
    from scipy.signal import lfilter

    k = p.interval
    tau = tau if n > 0 else 0.0

    def in_moment():
        return _derived(p, ("lag moment", tau, dt), lambda: _lag_moment_weights(p, tau, dt))

    if tau <= 0.0:
        i0 = np.bincount(k, u * p.length, minlength=n)[:n]
        i1 = np.bincount(k, u * in_moment() / 2.0, minlength=n)[:n] if moment else None
        return i0, i1
    to_end, in_integral = _derived(p, ("lag", tau), lambda: _lag_weights(p, tau))[2:]
    decay = math.exp(-dt / tau)
    drive = np.bincount(k, u * to_end, minlength=n)[:n]          # x(end) = decay x(start) + drive
    ends = lfilter([1.0], [1.0, -decay], drive, zi=[decay * x0])[0]
    starts = np.concatenate([[x0], ends[:-1]])
    i0 = starts * tau * (1.0 - decay) + np.bincount(k, u * in_integral, minlength=n)[:n]
    if not moment:
        return i0, None
    free = tau * tau * (1.0 - decay) - tau * dt * decay
    i1 = starts * free + np.bincount(k, u * in_moment(), minlength=n)[:n]
    return i0, i1


@dataclass(frozen=True)
class _Segments:
    """The pieces grouped by command (a segment: consecutive pieces of one command, a constant
    target), what _limited_integrals needs of the pieces alone."""

    first: np.ndarray      # first piece of each segment
    lengths: list          # segment durations [s]
    sig: np.ndarray        # from its segment's start: every piece's start, then every segment's end [s]
    idx: np.ndarray        # ... the segment of each of these
    end: np.ndarray        # per piece: where in sig its end is (the next piece's start, or its segment's end)
    shift: np.ndarray      # per piece: its segment's start minus its interval's start [s]

    @classmethod
    def of(cls, p, t0, dt, n):
        """The segments of the pieces ``p`` of the grid t0 + k dt, k = 0..n."""
        k, length = p.interval, p.length
        start_t = t0 + dt * (k + 1) - p.to_edge - length          # piece start times
        new = np.ones(k.size, bool)
        new[1:] = p.command[1:] != p.command[:-1]
        first = np.flatnonzero(new)
        seg = np.cumsum(new) - 1
        seg_t0 = start_t[first]
        seg_len = np.append(seg_t0[1:], t0 + n * dt) - seg_t0
        n_p = k.size
        last = np.ones(n_p, bool)
        last[:-1] = seg[1:] != seg[:-1]                            # the last piece of its segment
        nxt = np.minimum(np.arange(1, n_p + 1), n_p - 1)
        return cls(first=first, lengths=seg_len.tolist(), sig=np.concatenate([start_t - seg_t0[seg], seg_len]),
                   idx=np.concatenate([seg, np.arange(first.size)]), end=np.where(last, n_p + seg, nxt),
                   shift=seg_t0[seg] - (t0 + dt * k))


def _limited_integrals(u, tau, a, p, t0, dt, n, x0):
    """Lag with an acceleration limit: per grid interval, the integrals of y and of
    (s - interval start) y. Nonlinear: the state at each command's start is found command by
    command, then every piece is integrated in closed form (ramp, then exponential)."""
    k = p.interval
    sg = _derived(p, ("segments", t0, dt, n), lambda: _Segments.of(p, t0, dt, n))
    seg_u = u[sg.first]
    y0, ramp = _segment_starts(seg_u.tolist(), sg.lengths, float(x0), tau, a)
    sign = np.sign(seg_u - y0)
    # the integrals from each segment's start to every piece start and to the segment's end, in one go
    idx = sg.idx
    f0, f1 = _segment_integrals(sg.sig, y0[idx], seg_u[idx], ramp[idx], sign[idx], tau, a)
    n_p = k.size
    d0 = f0[sg.end] - f0[:n_p]
    d1 = f1[sg.end] - f1[:n_p] + sg.shift * d0      # moment about the interval's start
    return np.bincount(k, d0, minlength=n)[:n], np.bincount(k, d1, minlength=n)[:n]


def _segment_starts(us, lengths, y, tau, a):
    """The lagged velocity at the start of each segment (constant target us[i] for lengths[i] s) and
    how long it stays saturated there: the sequential part of _limited_integrals (a tight loop; the
    same arithmetic as lag_response)."""
    n = len(us)
    y0, ramp = [0.0] * n, [0.0] * n
    atau = a * tau
    exp = math.exp
    for i in range(n):
        u, L = us[i], lengths[i]
        y0[i] = y
        e = u - y
        ae = e if e >= 0.0 else -e
        if ae > atau:
            r = (ae - atau) / a
            ramp[i] = r
            if L <= r:
                y += a * L if e > 0.0 else -a * L
                continue
            y = u - atau if e > 0.0 else u + atau
            L -= r
        y = u + (y - u) * exp(-L / tau) if tau > 0.0 else u
    return np.array(y0), np.array(ramp)


def _segment_integrals(sig, y0, u, ramp, sign, tau, a):
    """Integrals of y and of s y over [0, sig] of a segment starting at y0 with target u (vectorised
    lag_response)."""
    T = np.minimum(sig, ramp)
    sa = sign * a
    f0 = y0 * T + sa * T * T / 2.0
    f1 = T * T * (y0 / 2.0 + sa * T / 3.0)
    yT = y0 + sa * T
    q = sig - T
    f0 = f0 + u * q
    f1 = f1 + u * (T * q + q * q / 2.0)
    if tau > 0.0:
        decay = np.exp(-q / tau)
        d = yT - u
        f0 = f0 + d * tau * (1.0 - decay)
        f1 = f1 + d * (T * tau * (1.0 - decay) + tau * (tau - (tau + q) * decay))
    return f0, f1


#: Parameters each velocity component depends on (before the bias); a memo keyed by them lets a
#: caller that varies one component's parameters (finite differences) reuse the other.
COMPONENT_KEYS = (("delay_s", "v_min", "v_c", "k_v", "tau_v_s", "a_v", "rate_per_s"),
                  ("delay_s", "w_min", "w_c", "k_w", "tau_w_s", "a_w", "rate_per_s"))
MEMO_SIZE = 4   # entries kept per component


def actuator_velocities(params, cmd_t, cmd_v, cmd_w, t0, dt, n, initial=None, pieces=None, t_start=0.0,
                        memo=None):
    """The plant vectorised on the grid t0 + k dt, k = 0..n: mean body velocity
    (v, w) over each interval, as two arrays of length n.

    ``params``: every parameter name -> value (``ActuatorModel.all_params()``);
    ``cmd_*``: commands by issue time (ascending). Before the first command the
    command is zero. The lagged velocities start at ``initial`` = (v, w) or, by
    default, at the steady state of the first target. ``t_start``: the time the
    drifting gain is 1. Exact, like ``ActuatorPlant`` stepped on the same grid:
    the grid intervals are cut where commands start to act, and lag, limit and
    gain are integrated in closed form over every piece. ``pieces``:
    ``command_pieces(cmd_t, params["delay_s"], t0, dt, n)`` if the caller keeps it
    (it depends on the delay only).
    """
    p = pieces if pieces is not None else command_pieces(cmd_t, params["delay_s"], t0, dt, n)
    rate = params["rate_per_s"]
    specs = ((cmd_v, params["v_min"], params["v_c"], params["k_v"], params["tau_v_s"], params["a_v"]),
             (cmd_w, params["w_min"], params["w_c"], params["k_w"], params["tau_w_s"], params["a_w"]))
    out, targets = [], []
    for j, (values, u_min, c, gain, tau, a) in enumerate(specs):
        key = (j, tuple(params[k] for k in COMPONENT_KEYS[j]), initial)
        if memo is not None and key in memo:
            mean, u = memo[key]
        else:
            u = _targets(values, u_min, c, gain, p)
            x0 = (u[0] if u.size else 0.0) if initial is None else initial[j]
            if math.isinf(a) or n == 0:
                i0, i1 = _lag_integrals(u, tau, p, dt, n, x0, rate != 0.0)
            else:
                i0, i1 = _limited_integrals(u, tau, a, p, t0, dt, n, x0)
            if rate != 0.0:
                g = 1.0 + rate * (t0 + dt * np.arange(n) - t_start)
                mean = (g * i0 + rate * i1) / dt
            else:
                mean = i0 / dt
            if memo is not None:
                if len(memo) >= 2 * MEMO_SIZE:
                    memo.pop(next(iter(memo)))
                memo[key] = (mean, u)
        out.append(mean)
        targets.append(u)
    v, w = out
    w = w + params["w_per_v"] * v
    if params["w0"] != 0.0:
        driven = (targets[0] != 0.0) | (targets[1] != 0.0)
        w = w + params["w0"] * np.bincount(p.interval, driven * p.length, minlength=n)[:n] / dt
    return v, w
