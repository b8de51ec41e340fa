"""Implausible motion-capture frames, as a faulty Vicon delivers them: for tests and fault injection.

Each fault turns a robot's true pose ``(stamp [s], x [m], y [m], yaw [rad])``
into the frame the motion capture would publish instead, a
:class:`MocapFrame` (the fields of a geometry_msgs/TransformStamped): jumps
of the position (a ghost marker, a reflection), a heading flipped by pi (a
marker swap), broken quaternions and NaN or inf in any field (a broken
bridge). :data:`FAULTS` maps each fault's name to the function and to the
pose gate's rejection kind (puzzlebot_common.pose_gate) it must produce; the
pose gate's unit tests, the driver's and the MPC's tests all use it.
A :class:`FaultPlan` says which fault (or :data:`SILENCE`) replaces a robot's
frames when: the rostests schedule every fault with it.
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

#: Not a frame at all (the motion capture lost the robot): a FaultPlan window of no frames.
SILENCE = "silence"


class FaultPlan:
    """Which fault replaces a robot's frames when: windows [t0, t1) [s] per robot, each a FAULTS name or
    SILENCE. Windows may be added while another thread reads the plan (a rostest's publishing thread)."""

    def __init__(self):
        self.windows = {}                        # robot -> [(t0, t1, fault)]

    def add(self, robot, t0, t1, fault):
        if fault != SILENCE and fault not in FAULTS:
            raise ValueError("unknown fault %r: a name of mocap_faults.FAULTS or SILENCE" % (fault,))
        self.windows.setdefault(robot, []).append((t0, t1, fault))

    def fault(self, robot, t):
        """``robot``'s fault at time ``t`` [s]: a FAULTS name, SILENCE, or None (clean frames); of
        overlapping windows, the first added."""
        return next((f for t0, t1, f in self.windows.get(robot, ()) if t0 <= t < t1), None)

    def frame(self, robot, stamp, x, y, yaw):
        """The MocapFrame published for ``robot``'s true pose at ``stamp`` [s] (x, y [m], yaw [rad]): the
        clean one, the fault's, or None under SILENCE."""
        fault = self.fault(robot, stamp)
        if fault == SILENCE:
            return None
        return clean(stamp, x, y, yaw) if fault is None else FAULTS[fault][0](stamp, x, y, yaw)

    def every_fault(self, robots, t0, spacing, rate, bursts=(1, 10)):
        """Add every fault of FAULTS once per burst length (in frames at ``rate`` [Hz]): on ``robots`` in
        turn, as many at a time as there are robots, ``spacing`` [s] apart from ``t0`` [s], each starting
        half a frame period after a multiple of the period (between two frames of a stream stamped on
        that grid). Returns the schedule [(robot, fault, burst, start [s])] in that order."""
        schedule = []
        for i, (fault, burst) in enumerate((f, b) for f in sorted(FAULTS) for b in bursts):
            robot, t = robots[i % len(robots)], t0 + spacing * (i // len(robots))
            t = math.floor(t * rate) / rate + 0.5 / rate
            schedule.append((robot, fault, burst, t))
            self.add(robot, t, t + burst / rate, fault)
        return schedule
