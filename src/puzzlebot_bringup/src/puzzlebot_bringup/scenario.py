"""Scenarios: start poses and a sequence of behaviour steps, from YAML.

A scenario file is loaded into the ``/puzzlebot`` namespace and holds the
robot list and the scenario::

    robots:
      - {name: pz1}
    scenario:
      name: goto3
      description: ...
      start: {pz1: [x, y, yaw]}          # m, m, rad, world frame
      steps:
        - behavior: go_to_goal
          goals: {pz1: [x, y]}           # m, world frame
          tolerance: 0.005               # m (optional)
          timeout: 40.0                  # s of simulated time (optional)
        - behavior: follow_velocity
          velocities: {pz1: [v, w]}      # m/s, rad/s
          timeout: 3.0                   # s: how long to follow it
        - behavior: stop

This module parses and checks scenarios and formats the end-of-run summary.
"""

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

from puzzlebot_common.errors import ConfigError

STEP_KEYS = {"behavior", "goals", "velocities", "tolerance", "timeout"}
BEHAVIORS = ("go_to_goal", "follow_velocity", "stop")


@dataclass
class Step:
    behavior: str
    robots: List[str] = field(default_factory=list)
    goals: List[Tuple[float, float]] = field(default_factory=list)
    velocities: List[Tuple[float, float]] = field(default_factory=list)
    tolerance: float = 0.0
    timeout: float = 0.0

    def describe(self):
        if self.behavior == "go_to_goal":
            return "go_to_goal " + ", ".join("%s->(%.3f, %.3f)" % (r, g[0], g[1])
                                             for r, g in zip(self.robots, self.goals))
        if self.behavior == "follow_velocity":
            return "follow_velocity %.1f s " % self.timeout + ", ".join(
                "%s (%.3f m/s, %.2f rad/s)" % (r, v[0], v[1]) for r, v in zip(self.robots, self.velocities))
        return self.behavior


@dataclass
class Scenario:
    name: str
    description: str
    start: Dict[str, list]
    steps: List[Step]


@dataclass
class StepResult:
    step: Step
    outcome: str                 # "succeeded", "failed", "refused", "timeout"
    message: str
    sim_seconds: float
    final_errors: Dict[str, float] = field(default_factory=dict)


def _pairs(value, where, robots, width):
    if not isinstance(value, dict) or not value:
        raise ConfigError("%s: expected a mapping robot -> [%s], got %r"
                          % (where, ", ".join(["x", "y"] if width == 2 else ["v", "w"]), value))
    out_r, out_v = [], []
    for name, vec in value.items():
        if name not in robots:
            raise ConfigError("%s: unknown robot %r; robots: %s" % (where, name, ", ".join(robots)))
        if not isinstance(vec, (list, tuple)) or len(vec) != width or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in vec):
            raise ConfigError("%s.%s: expected %d finite numbers, got %r" % (where, name, width, vec))
        out_r.append(name)
        out_v.append(tuple(float(v) for v in vec))
    return out_r, out_v


def parse_scenario(data, robots, where="scenario"):
    """Parse the ``scenario`` mapping; ``robots`` is the list of robot names."""
    if not isinstance(data, dict):
        raise ConfigError("%s: expected a mapping, got %r" % (where, data))
    for key in ("name", "start", "steps"):
        if key not in data:
            raise ConfigError("%s: missing '%s'" % (where, key))
    steps_data = data["steps"]
    if not isinstance(steps_data, list) or not steps_data:
        raise ConfigError("%s.steps: expected a non-empty list of steps" % where)
    steps = []
    for i, s in enumerate(steps_data):
        w = "%s.steps[%d]" % (where, i)
        if not isinstance(s, dict) or "behavior" not in s:
            raise ConfigError("%s: expected a mapping with 'behavior'" % w)
        unknown = set(s) - STEP_KEYS
        if unknown:
            raise ConfigError("%s: unknown key(s) %s" % (w, ", ".join(sorted(map(str, unknown)))))
        behavior = s["behavior"]
        if behavior not in BEHAVIORS:
            raise ConfigError("%s.behavior: unknown behaviour %r; known: %s" % (w, behavior, ", ".join(BEHAVIORS)))
        step = Step(behavior)
        for key in ("tolerance", "timeout"):
            value = s.get(key, 0.0)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value < 0:
                raise ConfigError("%s.%s: expected a number >= 0, got %r" % (w, key, value))
            setattr(step, key, float(value))
        if behavior == "go_to_goal":
            step.robots, step.goals = _pairs(s.get("goals"), w + ".goals", robots, 2)
        elif behavior == "follow_velocity":
            step.robots, step.velocities = _pairs(s.get("velocities"), w + ".velocities", robots, 2)
            if step.timeout <= 0:
                raise ConfigError("%s.timeout: follow_velocity needs a duration > 0" % w)
        steps.append(step)
    return Scenario(str(data["name"]), str(data.get("description", "")), data["start"], steps)


def format_summary(scenario, results, wall_seconds, sim_seconds):
    """One-screen text summary of a finished scenario run."""
    title = "Scenario '%s'" % scenario.name + (": " + scenario.description if scenario.description else "")
    lines = ["", "=" * 72, title, "-" * 72]
    for i, r in enumerate(results):
        lines.append("step %d  %s" % (i + 1, r.step.describe()))
        lines.append("        -> %s after %.2f s sim: %s" % (r.outcome.upper(), r.sim_seconds, r.message))
        if r.final_errors:
            lines.append("        final distance to goal: " + ", ".join(
                "%s %.1f mm" % (n, 1e3 * e) for n, e in sorted(r.final_errors.items())))
    skipped = len(scenario.steps) - len(results)
    if skipped:
        lines.append("(%d later step(s) not run)" % skipped)
    ok = len(results) == len(scenario.steps) and all(r.outcome == "succeeded" for r in results)
    lines.append("-" * 72)
    lines.append("%s: %d/%d steps succeeded in %.1f s simulated, %.1f s wall (%.1fx real time)"
                 % ("PASSED" if ok else "FAILED", sum(r.outcome == "succeeded" for r in results),
                    len(scenario.steps), sim_seconds, wall_seconds,
                    sim_seconds / wall_seconds if wall_seconds > 0 else float("nan")))
    lines.append("=" * 72)
    return "\n".join(lines), ok
