"""Differential-drive kinematics: body velocity <-> wheel rim speeds, pure pursuit's arc.

``v`` [m/s] is the forward speed of the body centre, ``w`` [rad/s] the yaw
rate (counter-clockwise positive); ``wheel_base`` [m] is the distance between
the left and right wheel contact points.
"""

import math


def wheel_speeds(v, w, wheel_base):
    """Left and right wheel rim speeds (m/s) for body velocity (v, w)."""
    return v - 0.5 * wheel_base * w, v + 0.5 * wheel_base * w


def body_velocity(v_left, v_right, wheel_base):
    """Body velocity (v, w) from left and right wheel rim speeds (m/s)."""
    return 0.5 * (v_left + v_right), (v_right - v_left) / wheel_base


def pursuit_curvature(pose, point):
    """[1/m] (left positive): the arc from ``pose`` (x, y, theta) tangent to its heading through ``point``
    (x, y), world frame (pure pursuit: 2 sin(bearing) / distance)."""
    dx, dy = point[0] - pose[0], point[1] - pose[1]
    bearing = math.atan2(dy, dx) - pose[2]
    return 2.0 * math.sin(bearing) / max(math.hypot(dx, dy), 1e-6)
