"""The package's shipped configuration: MPC settings and target configurations.

Files are found in the source tree (tests, benchmark) or through rospkg
(devel and install space): puzzlebot_common.config.shipped_config.
"""

from puzzlebot_common.config import load_section, load_yaml, shipped_config
from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_mpc.settings import MPCSettings
from puzzlebot_mpc.targets import load_targets


def config_path(name):
    """Path of a file in puzzlebot_mpc/config."""
    return shipped_config("puzzlebot_mpc", name)


def load_settings(path=None, sim=False, overrides=None):
    """MPCSettings from config/mpc.yaml (key ``mpc``), checked.

    ``sim``: with the simulation's overrides, config/mpc_sim.yaml, on top, as
    sim.launch loads them (lab.launch loads mpc.yaml alone). ``overrides``:
    a mapping of settings applied last (e.g. an experiment's ``--set``),
    checked as the files are.
    """
    paths = [path or config_path("mpc.yaml")] + ([config_path("mpc_sim.yaml")] if sim else [])
    data = {}
    for p in paths:
        data.update(load_section(p, "mpc", required=p == paths[0]))
    where = "%s: mpc" % " + ".join(paths)
    if overrides:
        data.update(overrides)
        where += " + overrides %s" % ", ".join(sorted(overrides))
    settings = MPCSettings.from_dict(data, where=where)
    settings.check(where=where)
    return settings


def load_target_file(geometry=None, path=None):
    """Named targets from config/targets.yaml (key ``targets``)."""
    path = path or config_path("targets.yaml")
    data = load_yaml(path)
    return load_targets(data.get("targets") if isinstance(data, dict) else data, geometry or RobotGeometry(),
                        where="%s: targets" % path)
