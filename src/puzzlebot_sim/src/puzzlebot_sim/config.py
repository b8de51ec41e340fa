"""The simulation's shipped configuration, put together as ``sim.launch`` puts it together.

``sim.launch`` loads, into the sim node's private namespace and in this
order: ``config/sim.yaml`` (sections ``sim``, ``world``, ``anchor_rest``),
``config/robot.yaml`` (``robot``, ``anchor``) and, for ``mocap:=NAME``, the
mocap profile ``config/mocap_NAME.yaml`` (overrides of ``sim``; the profile
``ideal`` is exact poses, no file). :func:`load_sim_config` does the same
without ROS, so every in-process tool (the experiments, scenario trials, the
loop demo) simulates what the launch file simulates.

Robot files: the model is the defaults of :mod:`puzzlebot_sim.params` with
``config/robot.yaml``'s changes on top (none as shipped: the shipped YAML
files hold only what differs from the defaults); :func:`load_model` reads it
(or another file, e.g. one holding the lab's measurements) with overrides on
top. Fields a file leaves out keep the defaults.
"""

import glob
import os
from dataclasses import dataclass, fields

from puzzlebot_common.config import load_section, load_yaml, shipped_config
from puzzlebot_common.errors import ConfigError
from puzzlebot_sim.params import AnchorParams, AnchorRestParams, RobotParams, SimParams, WorldParams

PACKAGE = "puzzlebot_sim"
IDEAL_MOCAP = "ideal"          # the mocap profile without a file: exact poses
MOCAP_KEYS = ("mocap_position_std", "mocap_yaw_std", "mocap_dropout", "mocap_heading_offset")


def config_file(name):
    """Path of a file in puzzlebot_sim/config."""
    return shipped_config(PACKAGE, name)


def robot_file():
    """Path of the package's robot file, config/robot.yaml."""
    return config_file("robot.yaml")


def override(params, values, where):
    """``params`` with the fields in ``values`` replaced (names, types and checks as for a YAML file)."""
    values = {} if values is None else values
    if not isinstance(values, dict):
        raise ConfigError("%s: expected a mapping of field: value, got %r" % (where, values))
    merged = {f.name: getattr(params, f.name) for f in fields(params)}
    merged.update(values)
    return type(params).from_dict(merged, where=where)


def load_model(path=None, robot=None, anchor=None):
    """(RobotParams, AnchorParams) of a robot file with overrides on top, checked.

    ``path``: a YAML file with the keys ``robot`` and ``anchor`` (default:
    :func:`robot_file`); ``robot`` / ``anchor``: {field: value} overrides,
    e.g. from ``--robot KEY=VALUE`` (errors name them ``--robot`` / ``--anchor``).
    """
    path = path or robot_file()
    data = load_yaml(path)
    if not isinstance(data, dict) or set(data) - {"robot", "anchor"}:
        raise ConfigError("%s: expected a mapping with the keys robot and/or anchor" % path)
    r = override(override(RobotParams(), data.get("robot"), "%s: robot" % path), robot, "--robot")
    a = override(override(AnchorParams(), data.get("anchor"), "%s: anchor" % path), anchor, "--anchor")
    a.check_fits(r, where="--anchor" if anchor else "--robot" if robot else "%s: anchor" % path)
    return r, a


def mocap_profiles():
    """Known mocap profile names: ``ideal`` and every ``config/mocap_NAME.yaml``, sorted."""
    directory = os.path.dirname(config_file("sim.yaml"))
    found = [os.path.basename(p)[len("mocap_"):-len(".yaml")]
             for p in glob.glob(os.path.join(directory, "mocap_*.yaml"))]
    return sorted(set(found) | {IDEAL_MOCAP})


def mocap_file(profile):
    """Path of a mocap profile's file (None for ``ideal``); ConfigError naming the known ones."""
    known = mocap_profiles()
    if profile not in known:
        raise ConfigError("unknown mocap profile %r; known profiles: %s" % (profile, ", ".join(known)))
    return None if profile == IDEAL_MOCAP else config_file("mocap_%s.yaml" % profile)


def load_mocap_overrides(profile):
    """The ``sim`` overrides of a mocap profile ({} for ``ideal``); only the mocap_* keys are allowed."""
    path = mocap_file(profile)
    if path is None:
        return {}
    section = load_section(path, "sim", required=True)
    unknown = sorted(set(section) - set(MOCAP_KEYS))
    if unknown:
        raise ConfigError("%s: unknown key(s) %s (a mocap profile sets only %s)"
                          % (path, ", ".join(unknown), ", ".join(MOCAP_KEYS)))
    return section


@dataclass(frozen=True)
class SimConfig:
    """The simulation's parameter sets as the sim node receives them from sim.launch."""

    sim: SimParams
    robot: RobotParams
    anchor: AnchorParams
    world: WorldParams
    anchor_rest: AnchorRestParams = AnchorRestParams()


def load_sim_config(mocap=IDEAL_MOCAP, robot_path=None):
    """SimConfig from config/sim.yaml, a robot file (default config/robot.yaml) and a mocap profile.

    ``mocap``: a profile name (:func:`mocap_profiles`; ``sim.launch``'s
    default is ``vicon``). Every part is checked; errors name the file.
    """
    sim_path, robot_path = config_file("sim.yaml"), robot_path or robot_file()
    sim_data = dict(load_section(sim_path, "sim"))
    sim_data.update(load_mocap_overrides(mocap))
    robot, anchor = load_model(robot_path)
    cfg = SimConfig(SimParams.from_dict(sim_data, where="%s: sim (mocap %s)" % (sim_path, mocap)), robot, anchor,
                    WorldParams.from_dict(load_section(sim_path, "world"), where="%s: world" % sim_path),
                    AnchorRestParams.from_dict(load_section(sim_path, "anchor_rest"),
                                               where="%s: anchor_rest" % sim_path))
    for part, where in ((cfg.sim, sim_path), (cfg.robot, robot_path), (cfg.anchor, robot_path),
                        (cfg.world, sim_path), (cfg.anchor_rest, sim_path)):
        part.check(where=where)
    return cfg

