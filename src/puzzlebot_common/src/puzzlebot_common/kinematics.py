"""Differential-drive kinematics: body velocity <-> wheel rim speeds.

``v`` [m/s] is the forward speed of the body centre, ``w`` [rad/s] the yaw
rate (counter-clockwise positive); ``wheel_base`` [m] is the distance between
the left and right wheel contact points.
"""


def wheel_speeds(v, w, wheel_base):
    """Left and right wheel rim speeds (m/s) for body velocity (v, w)."""
    return v - 0.5 * wheel_base * w, v + 0.5 * wheel_base * w


def body_velocity(v_left, v_right, wheel_base):
    """Body velocity (v, w) from left and right wheel rim speeds (m/s)."""
    return 0.5 * (v_left + v_right), (v_right - v_left) / wheel_base
