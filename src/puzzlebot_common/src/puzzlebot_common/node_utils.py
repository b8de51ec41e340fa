"""Small helpers shared by the thin rospy node shells.

rospy is imported inside the functions: the rest of puzzlebot_common stays
importable without ROS.
"""

import sys

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.robots import parse_robot_list


def run_node(main):
    """Run a node's main(); a ConfigError is logged as one fatal line and the
    process exits with status 2 instead of printing a traceback."""
    import rospy

    try:
        main()
    except ConfigError as e:
        msg = "configuration error: %s" % e
        if rospy.core.is_initialized():
            rospy.logfatal(msg)
        print("[%s] %s" % (rospy.get_name() if rospy.core.is_initialized() else "puzzlebot", msg),
              file=sys.stderr)
        sys.exit(2)
    except rospy.ROSInterruptException:
        pass


def get_param(name, default=None, required=False):
    """rospy.get_param with a ConfigError naming the parameter when it is required and absent."""
    import rospy

    if rospy.has_param(name):
        return rospy.get_param(name)
    if required:
        raise ConfigError("required parameter %s is not set (is the config loaded by the launch file?)"
                          % rospy.resolve_name(name))
    return default


def robot_list_from_param(name="/puzzlebot/robots"):
    """Parsed robot list from the parameter server (ConfigError if missing or malformed)."""
    return parse_robot_list(get_param(name, required=True), where=name)


def stamp_to_sec(stamp):
    return stamp.secs + 1e-9 * stamp.nsecs


def sleep_until(t):
    """Block until ROS time reaches ``t`` (absolute, seconds), in wall or simulated time.

    Unlike ``rospy.sleep(t - now)`` this cannot overshoot when /clock moves
    between reading the time and starting to sleep: the condition is checked
    under the lock that rospy notifies on every clock update. A simulator
    waiting in lockstep for this node therefore never deadlocks with it.
    """
    import time

    import rospy

    if rospy.rostime.is_wallclock():
        delay = t - rospy.get_time()
        if delay > 0:
            time.sleep(delay)
        return
    cond = rospy.rostime.get_rostime_cond()
    with cond:
        while rospy.get_time() < t - 1e-6 and not rospy.is_shutdown():
            cond.wait(0.1)


def diagnostic_array(statuses, stamp):
    """diagnostic_msgs/DiagnosticArray of puzzlebot_common.diagnostics.Status objects, stamped ``stamp``."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    msg = DiagnosticArray()
    msg.header.stamp = stamp
    for s in statuses:
        msg.status.append(DiagnosticStatus(level=s.level, name=s.name, message=s.message,
                                           hardware_id=s.hardware_id,
                                           values=[KeyValue(key=k, value=v) for k, v in s.values]))
    return msg
