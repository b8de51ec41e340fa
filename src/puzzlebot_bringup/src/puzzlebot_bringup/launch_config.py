"""What sim.launch and lab.launch put on the parameter server, checked at launch time.

The launch files call ``rosrun puzzlebot_bringup launch_config PART ...``
from ``<param command=...>`` tags, so roslaunch runs this while it reads the
launch file, before any node starts. A wrong argument (unknown scenario or
world, robot count 0, a robot list that is missing or does not fit the
scenario) stops ``roslaunch`` with one line naming it; nothing is started.

Arguments, as the launch files pass them:

- ``scenario``: NAME of ``config/scenarios/NAME.yaml`` (sim: required; lab:
  optional, "" = no scenario);
- ``robots`` (sim): "" = the scenario's robots; an integer N >= 1 = the
  first N robots of the scenario (their start poses; steps naming other
  robots are refused); a path to a robot list file (``.yaml``) = those robots
  (each needs a start pose in the scenario; e.g. to mark pilots);
- ``robots`` (lab): the robot list file (required; every robot needs an
  ``ip_octet``); a scenario's robots must all be in it;
- ``world`` (sim): "" = the scenario's ``world`` (default ``flat``), or a
  world name of puzzlebot_sim (flat, step, gap); (lab): the stage the robots
  stand on, "" = ``flat`` (no edges), ``step`` or ``gap`` as built to
  puzzlebot_sim's config/sim.yaml ``world`` dimensions;
- ``seed`` (sim): the run's seed; a scenario with ``scatter`` instead of
  ``start`` gets its start poses drawn from it (scenario.scatter_starts),
  so a seed gives the same starts in sim.launch and in scenario_trials;
- ``mocap`` (sim): a mocap profile of puzzlebot_sim
  (``puzzlebot_sim.config.mocap_profiles()``: ``ideal`` and every
  ``config/mocap_NAME.yaml``); an unknown one (``mocap:=vikon``) is refused.

Parts printed (YAML): ``robots`` -> /puzzlebot/robots, ``scenario`` ->
/puzzlebot/scenario, ``world`` -> the sim node's ``sim/world`` and the MPC
node's ``world``, ``world_params`` (the world's dimensions: puzzlebot_sim's
config/sim.yaml ``world``, over puzzlebot_common.stages.WorldParams) -> the
MPC node's ``world_params`` (its stage edges); and (URDF) ``description`` ->
/robot_description (``description()``).
"""

import glob
import os
from dataclasses import dataclass
from typing import List

from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.robots import parse_robot_list, robot_names
from puzzlebot_common.stages import WORLD_NAMES

from puzzlebot_bringup.scenario import parse_scenario, scatter_starts

DEFAULT_WORLD = "flat"


@dataclass
class LaunchConfig:
    robots: List[dict]     # robot list entries (as in a robot list file)
    scenario: dict         # the scenario mapping ({} when there is none)
    world: str             # world name (the sim's; the lab's stage, flat by default)
    world_params: dict     # its dimensions (stages.WorldParams fields)


def known_scenarios(directory):
    """Scenario names (file stems) in ``directory``, sorted."""
    return sorted(os.path.splitext(os.path.basename(p))[0] for p in glob.glob(os.path.join(directory, "*.yaml")))


def _quiet_import(module):
    """Import ``module`` of puzzlebot_sim. It loads pybullet, whose C library prints its build time on
    stderr: that line is kept off the launch output (stderr is redirected around the import)."""
    import importlib
    import sys

    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            return importlib.import_module(module)
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def known_worlds():
    """World names of puzzlebot_sim."""
    return sorted(_quiet_import("puzzlebot_sim.worlds").WORLDS)


def world_params():
    """The worlds' dimensions as the simulation builds them (puzzlebot_sim's config/sim.yaml ``world``
    over the defaults), a mapping of stages.WorldParams fields."""
    from dataclasses import asdict

    return {k: float(v) for k, v in asdict(_quiet_import("puzzlebot_sim.config").load_sim_config().world).items()}


def description(config, anchor):
    """``/robot_description`` of the configuration's robots (puzzlebot_sim.description: the URDFs the
    simulation loads, pilots and not, with their anchors): ``anchor`` "tf" (sim: the sim node
    publishes where each anchor is) or "nominal" (lab: each anchor drawn at rest in its holder)."""
    from puzzlebot_common.robots import parse_robot_list as parse

    model = _quiet_import("puzzlebot_sim.description")
    robot, anchor_params = _quiet_import("puzzlebot_sim.config").load_model()
    return model.robot_description(parse(config.robots), robot, anchor_params, anchor=anchor)


def load_scenario(directory, name):
    """The scenario file's data (robots + scenario), or ConfigError naming the known scenarios."""
    known = known_scenarios(directory)
    if name not in known:
        raise ConfigError("unknown scenario %r; known scenarios: %s (files in %s)"
                          % (name, ", ".join(known) or "none", directory))
    data = load_yaml(os.path.join(directory, name + ".yaml"))
    if not isinstance(data, dict) or "robots" not in data or "scenario" not in data:
        raise ConfigError("scenario file %s.yaml needs 'robots' and 'scenario'" % name)
    return data


def _entries(specs):
    """Robot list entries (mappings) of parsed RobotSpecs, without unset keys."""
    out = []
    for s in specs:
        e = {"name": s.name, "pilot": s.pilot}
        if s.mocap is not None:
            e["mocap"] = s.mocap
        if s.ip_octet is not None:
            e["ip_octet"] = s.ip_octet
        out.append(e)
    return out


def _robot_list_file(path):
    if not os.path.isfile(path):
        raise ConfigError("robot list file %s does not exist" % path)
    return parse_robot_list(load_yaml(path), where=path)


def _count(value):
    try:
        n = int(value)
    except ValueError:
        raise ConfigError("robots:=%s: expected a robot count (an integer >= 1) or a robot list file (.yaml)"
                          % value) from None
    if n < 1:
        raise ConfigError("robots:=%s: the robot count must be at least 1" % value)
    return n


def _scatter_check():
    """The sim's start-pose check for the shipped robot model (bodies and anchors must not overlap)."""
    from puzzlebot_sim.config import load_model
    from puzzlebot_sim.scenario_starts import overlap_check

    return overlap_check(*load_model())


def check_mocap(mocap):
    """ConfigError unless ``mocap`` is a mocap profile of puzzlebot_sim (names the known ones)."""
    from puzzlebot_sim.config import mocap_profiles

    known = mocap_profiles()
    if mocap not in known:
        raise ConfigError("mocap:=%s: unknown mocap profile %r; known profiles: %s (puzzlebot_sim/config/mocap_NAME"
                          ".yaml; ideal = exact poses)" % (mocap, mocap, ", ".join(known)))


def sim_config(directory, scenario, robots="", world="", seed=0, mocap=None):
    """LaunchConfig of sim.launch (see the module docstring for the arguments; ``mocap`` None: not checked)."""
    if mocap is not None:
        check_mocap(mocap)
    if not scenario:
        raise ConfigError("scenario:= is empty; known scenarios: %s" % ", ".join(known_scenarios(directory)))
    data = load_scenario(directory, scenario)
    specs = parse_robot_list(data["robots"], where="scenario %s: robots" % scenario)
    sc = dict(data["scenario"]) if isinstance(data["scenario"], dict) else data["scenario"]
    if isinstance(sc, dict) and "scatter" in sc and "start" not in sc:
        sc["start"] = scatter_starts(sc.pop("scatter"), robot_names(specs), seed, check=_scatter_check(),
                                     where="scenario %s: scatter" % scenario)
    if not isinstance(sc, dict) or not isinstance(sc.get("start"), dict):
        raise ConfigError("scenario %s: 'scenario' needs a 'start' mapping robot -> [x, y, yaw] (or a "
                          "'scatter')" % scenario)
    hint = ""
    robots = str(robots).strip()
    if robots.endswith((".yaml", ".yml")) or os.sep in robots:
        specs = _robot_list_file(robots)
        missing = [s.name for s in specs if s.name not in sc["start"]]
        if missing:
            raise ConfigError("robots:=%s: %s not in scenario %s (its robots: %s)"
                              % (robots, ", ".join(missing), scenario, ", ".join(sorted(sc["start"]))))
        hint = " (robot list %s)" % robots
    elif robots:
        n = _count(robots)
        if n > len(specs):
            raise ConfigError("robots:=%d but scenario %s has %d robot(s): %s"
                              % (n, scenario, len(specs), ", ".join(robot_names(specs))))
        specs = specs[:n]
        hint = " (robots:=%d keeps %s)" % (n, ", ".join(robot_names(specs)))
    names = robot_names(specs)
    sc["start"] = {k: v for k, v in sc["start"].items() if k in names}
    try:
        parse_scenario(sc, names, where="scenario %s" % scenario)
    except ConfigError as e:
        raise ConfigError("%s%s" % (e, hint)) from None
    scenario_world = sc.get("world", DEFAULT_WORLD)
    world = world or scenario_world
    worlds = known_worlds()
    for w, where in ((world, "world:=%s" % world), (scenario_world, "scenario %s: world" % scenario)):
        if w not in worlds:
            raise ConfigError("%s: unknown world %r; known worlds: %s" % (where, w, ", ".join(worlds)))
    return LaunchConfig(_entries(specs), sc, world, world_params())


def lab_config(directory, robots, scenario="", world=""):
    """LaunchConfig of lab.launch: the robot list file wins; an optional scenario must fit it; ``world``: the
    stage the robots stand on ("" = flat)."""
    world = world or DEFAULT_WORLD
    if world not in WORLD_NAMES:
        raise ConfigError("world:=%s: unknown world; known worlds: %s" % (world, ", ".join(WORLD_NAMES)))
    if not str(robots).strip():
        raise ConfigError("lab.launch needs a robot list: robots:=FILE (e.g. $(find puzzlebot_bringup)"
                          "/config/robots/lab.yaml; name, ip_octet, mocap, pilot per robot)")
    specs = _robot_list_file(robots)
    no_link = [s.name for s in specs if s.ip_octet is None]
    if no_link:
        raise ConfigError("robot list %s: %s without ip_octet (the driver tells robots apart by it)"
                          % (robots, ", ".join(no_link)))
    sc = {}
    if scenario:
        data = load_scenario(directory, scenario)
        sc = dict(data["scenario"])
        sc.pop("scatter", None)           # the lab's robots start where they stand
        names = robot_names(specs)
        scenario_robots = robot_names(parse_robot_list(data["robots"], where="scenario %s: robots" % scenario))
        missing = [n for n in scenario_robots if n not in names]
        if missing:
            raise ConfigError("scenario %s uses %s, not in the robot list %s (robots: %s)"
                              % (scenario, ", ".join(missing), robots, ", ".join(names)))
        sc["start"] = {k: v for k, v in (sc.get("start") or {}).items() if k in names}
        parse_scenario(sc, names, where="scenario %s" % scenario)
    return LaunchConfig(_entries(specs), sc, world, world_params())
