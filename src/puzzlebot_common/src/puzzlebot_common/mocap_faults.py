"""Implausible motion-capture frames, as a faulty Vicon delivers them: for tests and fault injection.

Each fault turns a robot's true pose ``(stamp [s], x [m], y [m], yaw [rad])``
into the frame the motion capture would publish instead, a
:class:`MocapFrame` (the fields of a geometry_msgs/TransformStamped): jumps
of the position (a ghost marker, a reflection), a heading flipped by pi (a
marker swap), broken quaternions and NaN or inf in any field (a broken
bridge). :data:`FAULTS` maps each fault's name to the function and to the
pose gate's rejection kind (puzzlebot_common.pose_gate) it must produce; the
pose gate's unit tests, the driver's and the MPC's tests all use it.
"""

import math
from dataclasses import dataclass, replace
from typing import Tuple

from puzzlebot_common import pose_gate
from puzzlebot_common.geometry import quaternion_from_yaw, wrap_angle

FIELDS = ("translation.x", "translation.y", "translation.z", "rotation.x", "rotation.y", "rotation.z", "rotation.w")


@dataclass(frozen=True)
class MocapFrame:
    """One published frame: stamp [s], translation (x, y, z) [m], rotation quaternion (x, y, z, w)."""

    stamp: float
    x: float
    y: float
    z: float
    q: Tuple[float, float, float, float]

    def set(self, field, value):
        """This frame with one of FIELDS replaced by ``value``."""
        group, axis = field.split(".")
        if group == "translation":
            return replace(self, **{axis: value})
        q = list(self.q)
        q["xyzw".index(axis)] = value
        return replace(self, q=tuple(q))


def clean(stamp, x, y, yaw):
    """The frame of a true pose, as a healthy motion capture publishes it."""
    return MocapFrame(stamp, x, y, 0.0, quaternion_from_yaw(yaw))


def _jump(dx):
    return lambda stamp, x, y, yaw: clean(stamp, x + dx, y, yaw)


def _x(value):
    return lambda stamp, x, y, yaw: clean(stamp, value, y, yaw)


def _field(field, value):
    return lambda stamp, x, y, yaw: clean(stamp, x, y, yaw).set(field, value)


FAULTS = {
    "jump 0.1 m": (_jump(0.1), pose_gate.JUMP),
    "jump 1 m": (_jump(1.0), pose_gate.JUMP),
    "jump 1000 m": (_jump(1000.0), pose_gate.OUT_OF_RANGE),
    "x = 1e300": (_x(1e300), pose_gate.OUT_OF_RANGE),
    "x = 1.7e308": (_x(1.7e308), pose_gate.OUT_OF_RANGE),
    "heading flipped by pi": (lambda stamp, x, y, yaw: clean(stamp, x, y, wrap_angle(yaw + math.pi)), pose_gate.TURN),
    "zero quaternion": (lambda stamp, x, y, yaw: replace(clean(stamp, x, y, yaw), q=(0.0, 0.0, 0.0, 0.0)),
                        pose_gate.QUATERNION),
    "non-unit quaternion": (lambda stamp, x, y, yaw: replace(clean(stamp, x, y, yaw),
                                                             q=tuple(1.5 * c for c in quaternion_from_yaw(yaw))),
                            pose_gate.QUATERNION),
}
for _f in FIELDS:
    for _value in (math.nan, math.inf):
        FAULTS["%s = %r" % (_f, _value)] = (_field(_f, _value), pose_gate.NON_FINITE)
