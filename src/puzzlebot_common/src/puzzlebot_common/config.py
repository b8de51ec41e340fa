"""Loading YAML configuration files with errors that name the file."""

import os

import yaml

from puzzlebot_common.errors import ConfigError


def load_yaml(path):
    """Read a YAML file; missing files and syntax errors raise ConfigError."""
    if not os.path.isfile(path):
        raise ConfigError("%s: no such file" % path)
    try:
        with open(path) as f:
            data = yaml.safe_load(f)
    except yaml.YAMLError as e:
        raise ConfigError("%s: not valid YAML: %s" % (path, e)) from None
    return {} if data is None else data


def package_path(package, *parts):
    """Absolute path of a file inside a catkin package (source or install space).

    Uses rospkg, which reads ROS_PACKAGE_PATH and needs no roscore.
    """
    import rospkg

    try:
        root = rospkg.RosPack().get_path(package)
    except rospkg.ResourceNotFound:
        raise ConfigError("package %r not found on ROS_PACKAGE_PATH; source devel/setup.bash"
                          % package) from None
    return os.path.join(root, *parts)


def shipped_config(package, *parts):
    """Path of a file or directory shipped in ``<package>/config/`` (``shipped_config("puzzlebot_sim", "robot.yaml")``).

    The source tree first (a checkout: tests, tools run without sourcing a
    workspace), then the package rospkg finds (devel or install space).
    """
    here = os.path.dirname(os.path.abspath(__file__))
    in_tree = os.path.normpath(os.path.join(here, "..", "..", "..", package, "config", *parts))
    if os.path.exists(in_tree):
        return in_tree
    return package_path(package, "config", *parts)


def load_section(path, key, required=False):
    """The mapping under ``key`` in a YAML file ({} if absent and not ``required``); ConfigError otherwise."""
    data = load_yaml(path)
    if not isinstance(data, dict) or (required and key not in data):
        raise ConfigError("%s: expected a mapping with key %r" % (path, key))
    section = data.get(key)
    if section is None:
        return {}
    if not isinstance(section, dict):
        raise ConfigError("%s: %s must be a mapping, got %r" % (path, key, section))
    return section
