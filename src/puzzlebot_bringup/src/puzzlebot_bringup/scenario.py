"""Scenarios: start poses and a sequence of behaviour steps, from YAML.

A scenario file is loaded into the ``/puzzlebot`` namespace and holds the
robot list and the scenario::

    robots:
      - {name: pz1}
    scenario:
      name: goto3
      description: ...
      world: flat                        # optional: sim world it needs (flat, step, gap); default flat
      start: {pz1: [x, y, yaw]}          # m, m, rad, world frame; or instead:
      scatter:                           # start poses drawn from the run's seed (scatter_starts)
        rows: 1                          # robots split into rows in list order
        spacing: [0.10, 0.11]            # m, centre to centre along a row: uniform in [lo, hi]
        lateral: 0.04                    # m, each robot's sideways offset: uniform +/-
        yaw: 0.35                        # rad, each robot's heading offset: uniform +/-
        row_spacing: 0.2                 # m, between rows (optional)
        origin: [0.0, 0.0]               # m, the first robot's nominal position (optional)
        heading: 0.0                     # rad, the rows' direction; robots follow the first backwards
      steps:
        - behavior: go_to_goal
          goals: {pz1: [x, y]}           # m, world frame
          tolerance: 0.005               # m (optional)
          timeout: 40.0                  # s of simulated time (optional)
        - behavior: follow_velocity
          velocities: {pz1: [v, w]}      # m/s, rad/s
          timeout: 3.0                   # s: how long to follow it
        - behavior: stop
        - behavior: couple                 # robots form a target configuration
          robots: [pz1, pz2]               # (optional: all robots)
          target: line                     # line, row, a name from puzzlebot_mpc/config/targets.yaml ...
          slots: [[0, 0, 0], [-0.05, 0, 0]]  # ... or explicit slots [x, y, heading] (m, m, rad)
          timeout: 120.0
        - behavior: couple                 # several assemblies at once: each group forms its own target
          groups: [[pz1, pz2], [pz3, pz4]] # (instead of robots)
          target: line
          timeout: 120.0
        - behavior: assembly_to_goal       # each named robot leads its assembly to its goal
          goals: {pz1: [x, y], pz3: [x, y]}  # m, world frame; one robot per assembly
          tolerance: 0.02                  # m (optional)
          timeout: 60.0
        - behavior: drive_assembly         # the assembly of the first robot drives as one body
          robots: [pz1]
          velocity: [0.03, 0.0]            # m/s, rad/s in pz1's frame
          distance: 0.3                    # m (or give only a timeout: a duration)
          timeout: 30.0
          cross_edges: true                # (optional) may leave the stage: down a step, over a gap;
                                           # without it the MPC keeps every robot on its stage
        - behavior: decouple               # a coupled pair separates (its anchor robot wiggles)
          pair: [pz2, pz3]
          timeout: 60.0

``steps: []`` is a scenario without steps: the robots are placed and left
to the user (the runner reports that and waits).

This module parses and checks scenarios and formats the end-of-run summary.
"""

import math
from dataclasses import dataclass, field
from typing import Dict, List, Tuple

import numpy as np

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.params import check_keys

SCENARIO_KEYS = {"name", "description", "world", "start", "scatter", "steps"}
SCATTER_KEYS = {"rows", "spacing", "lateral", "yaw", "row_spacing", "origin", "heading"}
SCATTER_SEED_TAG = 0x5CA77E2      # mixed into the run's seed for the scatter's random numbers
SCATTER_REDRAWS = 200             # draws tried before a scatter that keeps overlapping is an error
STEP_KEYS = {"behavior", "goals", "velocities", "tolerance", "timeout", "robots", "target", "slots", "pair",
             "velocity", "distance", "groups", "cross_edges"}
BEHAVIORS = ("go_to_goal", "follow_velocity", "stop", "couple", "decouple", "drive_assembly", "assembly_to_goal")
_KEYS_OF = {"go_to_goal": {"goals", "tolerance", "timeout", "cross_edges"},
            "follow_velocity": {"velocities", "timeout", "cross_edges"},
            "stop": {"timeout"}, "couple": {"robots", "groups", "target", "slots", "timeout"},
            "decouple": {"pair", "timeout"},
            "drive_assembly": {"robots", "velocity", "distance", "timeout", "cross_edges"},
            "assembly_to_goal": {"goals", "tolerance", "timeout", "cross_edges"}}


@dataclass
class Step:
    behavior: str
    robots: List[str] = field(default_factory=list)
    goals: List[Tuple[float, float]] = field(default_factory=list)
    velocities: List[Tuple[float, float]] = field(default_factory=list)
    tolerance: float = 0.0
    timeout: float = 0.0
    target: str = ""
    slots: List[Tuple[float, float, float]] = field(default_factory=list)
    pair: List[str] = field(default_factory=list)
    distance: float = 0.0
    groups: List[int] = field(default_factory=list)   # couple: robots per group (consecutive in robots)
    cross_edges: bool = False                          # its robots may leave their stage

    def describe(self):
        if self.behavior in ("go_to_goal", "assembly_to_goal"):
            return self.behavior + " " + ", ".join("%s->(%.3f, %.3f)" % (r, g[0], g[1])
                                             for r, g in zip(self.robots, self.goals))
        if self.behavior == "follow_velocity":
            return "follow_velocity %.1f s " % self.timeout + ", ".join(
                "%s (%.3f m/s, %.2f rad/s)" % (r, v[0], v[1]) for r, v in zip(self.robots, self.velocities))
        if self.behavior == "couple" and self.groups:
            return "couple %d groups of %s robots, each into %s" % (
                len(self.groups), "/".join(str(k) for k in sorted(set(self.groups))), self.target)
        if self.behavior == "couple":
            return "couple %s into %s" % (", ".join(self.robots) or "all robots",
                                          self.target or "%d slots" % len(self.slots))
        if self.behavior == "decouple":
            return "decouple %s-%s" % tuple(self.pair)
        if self.behavior == "drive_assembly":
            v, w = self.velocities[0]
            how = "%.3f m" % self.distance if self.distance > 0 else "%.1f s" % self.timeout
            return "drive_assembly of %s at (%.3f m/s, %.2f rad/s) for %s" % (self.robots[0], v, w, how)
        return self.behavior


@dataclass
class Scenario:
    name: str
    description: str
    start: Dict[str, list]
    steps: List[Step]
    world: str = "flat"


@dataclass
class StepResult:
    step: Step
    outcome: str                 # "succeeded", "failed", "refused", "timeout"
    message: str
    sim_seconds: float
    final_errors: Dict[str, float] = field(default_factory=dict)
    pairs: str = ""              # connection pairs at the end of the step (coupling steps)
    start: float = float("nan")  # s, ROS time of the step's first control step (its status stamps)
    end: float = float("nan")    # s, ROS time of the control step that ended it


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


def _numbers(value, width, where):
    if not isinstance(value, (list, tuple)) or len(value) != width or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        raise ConfigError("%s: expected %d finite numbers, got %r" % (where, width, value))
    return [float(v) for v in value]


def _names(value, where, robots, allow_empty=False):
    if not isinstance(value, list) or (not value and not allow_empty):
        raise ConfigError("%s: expected a list of robot names, got %r" % (where, value))
    for name in value:
        if name not in robots:
            raise ConfigError("%s: unknown robot %r; robots: %s" % (where, name, ", ".join(robots)))
    return list(value)


def _groups(step, where, robots):
    """A couple step's ``groups`` (lists of robot names, each of at least two, no robot twice): the robots
    in order and the group sizes."""
    groups = step["groups"]
    if "robots" in step:
        raise ConfigError("%s: give either 'robots' or 'groups', not both" % where)
    if not isinstance(groups, list) or not groups:
        raise ConfigError("%s.groups: expected a list of robot lists, got %r" % (where, groups))
    names = []
    for k, g in enumerate(groups):
        group = _names(g, "%s.groups[%d]" % (where, k), robots)
        if len(group) < 2:
            raise ConfigError("%s.groups[%d]: a group needs at least two robots, got %r" % (where, k, g))
        names += group
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ConfigError("%s.groups: robot(s) %s in more than one group" % (where, ", ".join(twice)))
    return names, [len(g) for g in groups]


def _number(spec, key, where, default=None, minimum=0.0):
    value = spec.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < minimum:
        raise ConfigError("%s.%s: expected a number >= %g, got %r" % (where, key, minimum, value))
    return float(value)


def scatter_starts(spec, robots, seed, check=None, where="scenario.scatter"):
    """Start poses {name: [x, y, yaw]} drawn for ``robots`` (names, in order) from ``spec`` and ``seed``.

    The robots stand in ``rows`` rows (row r holds the r-th block of
    ceil(N / rows) robots), each row along ``heading`` with the first robot
    in front at ``origin`` + r ``row_spacing`` to its left, the next ones
    behind it: gaps uniform in ``spacing`` [lo, hi], sideways offsets
    uniform in +/- ``lateral``, headings ``heading`` +/- ``yaw``. The same
    seed gives the same poses (sim.launch and scenario_trials draw them from
    the run's seed). ``check(poses)``: raises ConfigError when poses
    overlap (e.g. puzzlebot_sim.world.check_start_poses); a draw that fails
    it is drawn again, up to SCATTER_REDRAWS times.
    """
    if not isinstance(spec, dict):
        raise ConfigError("%s: expected a mapping, got %r" % (where, spec))
    check_keys(spec, SCATTER_KEYS, where)
    rows = spec.get("rows", 1)
    if isinstance(rows, bool) or not isinstance(rows, int) or not 1 <= rows <= max(1, len(robots)):
        raise ConfigError("%s.rows: expected an integer from 1 to the robot count (%d), got %r"
                          % (where, len(robots), rows))
    lo, hi = _numbers(spec.get("spacing"), 2, where + ".spacing")
    if not 0 < lo <= hi:
        raise ConfigError("%s.spacing: expected [lo, hi] with 0 < lo <= hi, got %r" % (where, spec.get("spacing")))
    lateral = _number(spec, "lateral", where, 0.0)
    yaw = _number(spec, "yaw", where, 0.0)
    row_spacing = _number(spec, "row_spacing", where, 0.2)
    origin = _numbers(spec.get("origin", [0.0, 0.0]), 2, where + ".origin")
    heading = _number(spec, "heading", where, 0.0, minimum=-math.inf)
    per_row = -(-len(robots) // rows)
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, SCATTER_SEED_TAG])
    c, s = math.cos(heading), math.sin(heading)
    last = None
    for _ in range(SCATTER_REDRAWS):
        poses = {}
        for r in range(rows):
            along = 0.0
            for k, name in enumerate(robots[r * per_row:(r + 1) * per_row]):
                if k:
                    along -= rng.uniform(lo, hi)
                side = r * row_spacing + rng.uniform(-lateral, lateral)
                poses[name] = [origin[0] + c * along - s * side, origin[1] + s * along + c * side,
                               heading + rng.uniform(-yaw, yaw)]
        if check is None:
            return poses
        try:
            check(poses)
            return poses
        except ConfigError as e:
            last = e
    raise ConfigError("%s: %d draws all put robots into each other (last: %s); widen spacing or row_spacing"
                      % (where, SCATTER_REDRAWS, last))


def check_target(step, n, where):
    """A couple step's target must be one the MPC can form with its ``n`` robots: a generator, a target of
    puzzlebot_mpc/config/targets.yaml or valid slots (no overlap, one connected assembly), one slot per
    robot. Raise ConfigError naming the step, at load rather than when the step runs."""
    from puzzlebot_common.geometry import RobotGeometry
    from puzzlebot_mpc.config_files import load_target_file
    from puzzlebot_mpc.targets import TargetError, resolve_target

    geometry = RobotGeometry()
    try:
        target = resolve_target(step.target, step.slots, n, load_target_file(geometry), geometry)
    except TargetError as e:
        raise ConfigError("%s: %s" % (where, e))
    if len(target.slots) != n:
        raise ConfigError("%s: target %r has %d slots for the step's %d robots (name the robots in 'robots', "
                          "or pick a target of %d)" % (where, target.name, len(target.slots), n, n))


def parse_scenario(data, robots, where="scenario"):
    """Parse the ``scenario`` mapping; ``robots`` is the list of robot names.

    A ``scatter`` must have been turned into ``start`` poses first (scatter_starts: they depend on the seed).
    """
    if not isinstance(data, dict):
        raise ConfigError("%s: expected a mapping, got %r" % (where, data))
    if "scatter" in data and "start" in data:
        raise ConfigError("%s: give either 'start' or 'scatter', not both" % where)
    if "scatter" in data:
        raise ConfigError("%s: 'scatter' start poses are drawn from a seed: scatter_starts first" % where)
    for key in ("name", "start", "steps"):
        if key not in data:
            raise ConfigError("%s: missing '%s'" % (where, key))
    check_keys(data, SCENARIO_KEYS, where)
    if not isinstance(data["start"], dict):
        raise ConfigError("%s.start: expected a mapping robot -> [x, y, yaw], got %r" % (where, data["start"]))
    if not isinstance(data.get("world", "flat"), str):
        raise ConfigError("%s.world: expected a world name, got %r" % (where, data["world"]))
    steps_data = data["steps"]
    if not isinstance(steps_data, list):
        raise ConfigError("%s.steps: expected a list of steps ([] for none)" % where)
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
        misplaced = set(s) - _KEYS_OF[behavior] - {"behavior"}
        if misplaced:
            raise ConfigError("%s: key(s) %s do not apply to %s" % (w, ", ".join(sorted(misplaced)), behavior))
        step = Step(behavior)
        for key in ("tolerance", "timeout", "distance"):
            value = s.get(key, 0.0)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value < 0:
                raise ConfigError("%s.%s: expected a number >= 0, got %r" % (w, key, value))
            setattr(step, key, float(value))
        step.cross_edges = s.get("cross_edges", False)
        if not isinstance(step.cross_edges, bool):
            raise ConfigError("%s.cross_edges: expected true or false, got %r" % (w, step.cross_edges))
        if behavior in ("go_to_goal", "assembly_to_goal"):
            step.robots, step.goals = _pairs(s.get("goals"), w + ".goals", robots, 2)
        elif behavior == "follow_velocity":
            step.robots, step.velocities = _pairs(s.get("velocities"), w + ".velocities", robots, 2)
            if step.timeout <= 0:
                raise ConfigError("%s.timeout: follow_velocity needs a duration > 0" % w)
        elif behavior == "couple":
            step.robots = _names(s.get("robots", []), w + ".robots", robots, allow_empty=True)
            if "groups" in s:
                step.robots, step.groups = _groups(s, w, robots)
            step.target = s.get("target", "")
            if not isinstance(step.target, str):
                raise ConfigError("%s.target: expected a target name, got %r" % (w, step.target))
            step.slots = [tuple(_numbers(sl, 3, "%s.slots[%d]" % (w, k))) for k, sl in enumerate(s.get("slots", []))]
            if bool(step.target) == bool(step.slots):
                raise ConfigError("%s: couple needs either 'target' or 'slots'" % w)
            if step.groups and step.slots:
                raise ConfigError("%s: groups need a target name (each group forms its own copy), not slots" % w)
            for n in sorted(set(step.groups)) or [len(step.robots) or len(robots)]:
                check_target(step, n, w)
        elif behavior == "decouple":
            step.pair = _names(s.get("pair"), w + ".pair", robots)
            if len(step.pair) != 2:
                raise ConfigError("%s.pair: expected two robot names, got %r" % (w, s.get("pair")))
        elif behavior == "drive_assembly":
            step.robots = _names(s.get("robots"), w + ".robots", robots)
            step.velocities = [tuple(_numbers(s.get("velocity"), 2, w + ".velocity"))]
            if step.distance <= 0 and step.timeout <= 0:
                raise ConfigError("%s: drive_assembly needs a distance or a timeout > 0" % w)
        steps.append(step)
    return Scenario(str(data["name"]), str(data.get("description", "")), data["start"], steps,
                    data.get("world", "flat"))


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
        if r.pairs:
            lines.append("        pairs: " + r.pairs)
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
