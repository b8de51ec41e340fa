"""The package's shipped configuration: MPC settings and target configurations.

Files are found next to this module in the source tree (tests, benchmark)
or through rospkg (install space).
"""

import os

from puzzlebot_common.config import load_yaml, package_path
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_mpc.settings import MPCSettings
from puzzlebot_mpc.targets import load_targets


def config_path(name):
    here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "config", name)
    if os.path.isfile(here):
        return os.path.normpath(here)
    return package_path("puzzlebot_mpc", "config", name)


def load_settings(path=None):
    """MPCSettings from config/mpc.yaml (key ``mpc``)."""
    path = path or config_path("mpc.yaml")
    data = load_yaml(path)
    if not isinstance(data, dict) or "mpc" not in data:
        raise ConfigError("%s: expected a mapping with key 'mpc'" % path)
    return MPCSettings.from_dict(data["mpc"], where="%s: mpc" % path)


def load_target_file(geometry=None, path=None):
    """Named targets from config/targets.yaml (key ``targets``)."""
    path = path or config_path("targets.yaml")
    data = load_yaml(path)
    return load_targets(data.get("targets") if isinstance(data, dict) else data, geometry or RobotGeometry(),
                        where="%s: targets" % path)
