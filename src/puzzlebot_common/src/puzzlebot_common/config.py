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
