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
order, whatever order the effects are listed in. A model file (``model.yaml``)::

    model:
      effects:
        - name: input_delay
          params: {delay_s: 0.1}
        - name: velocity_lag
          params: {tau_v_s: 0.15, tau_w_s: 0.1}
"""

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Dict, List

import yaml

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import wrap_angle

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

    def to_dict(self):
        return {"model": {"effects": [{"name": e.name, "params": dict(e.params)} for e in self.effects]}}

    def dump(self, path):
        with open(path, "w") as f:
            f.write("# PuzzleBot actuator model (puzzlebot_mpc/effects.py documents each effect)\n")
            yaml.safe_dump(self.to_dict(), f, sort_keys=False)


class ActuatorPlant:
    """Numerical simulation of the effects for one robot.

    ``command(t, v, w)`` records a command issued at time t [s];
    ``advance(t, dt)`` returns the body velocity (v [m/s], w [rad/s]) the
    robot actually has over [t, t + dt). ``measured_yaw(yaw)`` applies the
    mocap heading offset. State: the delayed command queue and the lagged
    velocities.
    """

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

    def command(self, t, v, w):
        self._queue.append((t, float(v), float(w)))

    def _target(self, t):
        while self._queue and self._queue[0][0] <= t - self.delay + 1e-12:
            _, v, w = self._queue.popleft()
            self._active = (v, w)
        v, w = self._active
        if abs(v) < self.v_min:
            v = 0.0
        if abs(w) < self.w_min:
            w = 0.0
        return self.k_v * v, self.k_w * w

    def advance(self, t, dt):
        v_t, w_t = self._target(t)
        self.v = v_t if self.tau_v <= 0 else self.v + (v_t - self.v) * (1.0 - math.exp(-dt / self.tau_v))
        self.w = w_t if self.tau_w <= 0 else self.w + (w_t - self.w) * (1.0 - math.exp(-dt / self.tau_w))
        return self.v, self.w + self.w_per_v * self.v + self.w0

    def measured_yaw(self, yaw):
        return wrap_angle(yaw + self.offset)
