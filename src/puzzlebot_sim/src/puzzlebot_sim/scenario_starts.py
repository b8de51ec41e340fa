"""Start poses of the simulated robots, from the scenario's ``start`` mapping."""

import math

from puzzlebot_common.errors import ConfigError
from puzzlebot_sim.world import RobotStart


def starts_from_config(robots, start, where="scenario.start"):
    """Pair each robot of the robot list with its start pose.

    ``robots``: parsed robot list; ``start``: mapping name -> [x, y, yaw]
    (m, m, rad, world frame). Every robot needs a finite start pose and every
    start pose must name a robot of the list.
    """
    if not isinstance(start, dict):
        raise ConfigError("%s: expected a mapping robot name -> [x, y, yaw], got %r" % (where, start))
    known = {r.name for r in robots}
    extra = sorted(set(start) - known)
    if extra:
        raise ConfigError("%s: start pose(s) for robots not in the robot list: %s (robots: %s)"
                          % (where, ", ".join(map(str, extra)), ", ".join(sorted(known))))
    out = []
    for r in robots:
        if r.name not in start:
            raise ConfigError("%s: no start pose for robot %s" % (where, r.name))
        pose = start[r.name]
        if not isinstance(pose, (list, tuple)) or len(pose) != 3 or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in pose):
            raise ConfigError("%s.%s: expected [x, y, yaw] as three finite numbers, got %r"
                              % (where, r.name, pose))
        out.append(RobotStart(r.name, float(pose[0]), float(pose[1]), float(pose[2]), r.pilot))
    return out


def overlap_check(robot, anchor):
    """A function of {name: [x, y, yaw]} that raises ConfigError when bodies or anchors would start inside
    each other (as SimWorld does at start-up) for this robot and anchor model."""
    from puzzlebot_sim.world import anchor_reach, check_start_poses

    reach, half_width = anchor_reach(robot, anchor)

    def check(poses):
        check_start_poses([RobotStart(n, *p) for n, p in poses.items()], robot.body_side, reach, half_width)
    return check
