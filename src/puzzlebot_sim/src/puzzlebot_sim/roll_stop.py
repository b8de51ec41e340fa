"""The holder's stop on the anchor's roll (AnchorParams ``roll_limit``).

In Bullet the anchor can roll about its own x axis far more than the
hardware's: every collision shape is rounded by the 1 mm margin, so the 3 x 4
mm bar turns through the 5 x 4.5 mm slot of the holder, and the ball with
it. Rolled past about 1.5 rad the anchor lies on its side: its barbs stand
up and down, the opening's floor and ceiling fold them against the bar, and
the anchor sits in the mouth without holding (a pair that looks seated from
the poses and comes out under one robot's pull). The facts give the
anchor's freedoms in its holder as yaw, x, y and pitch; the printed beam
twists a little, it does not turn over.

The stop acts only beyond ``roll_limit``: before each physics step, an anchor
rolled further than that relative to its robot gets the part of its angular
velocity that rolls it further replaced by a return at ``1 / return_time``
of the excess. It works on velocities (an inelastic stop, like a contact),
so it adds no stiffness for the solver; within the limit the anchor moves as
before.

Frames: the anchor base's x axis points to its robot (the head towards -x);
roll is about that axis, relative to the robot's base_link, in radians.
"""

import math

import numpy as np
import pybullet as pb

#: s: an anchor rolled beyond the limit returns the excess at this time constant
RETURN_TIME = 0.05


def relative_roll(robot_orn, anchor_orn):
    """Roll [rad] of the anchor about its own x axis relative to its robot (quaternions xyzw, world frame):
    the angle of the anchor's y axis out of the robot's x-y plane, measured about the anchor's x axis."""
    r = np.array(pb.getMatrixFromQuaternion(robot_orn)).reshape(3, 3)
    a = np.array(pb.getMatrixFromQuaternion(anchor_orn)).reshape(3, 3)
    rel = r.T @ a                   # anchor axes in the robot's frame
    return math.atan2(rel[2, 1], rel[2, 2])


def stopped_velocity(roll, limit, omega_anchor, omega_robot, x_axis, return_time=RETURN_TIME):
    """The anchor's angular velocity (world frame, rad/s) after the stop, or None when it needs none.

    ``roll``: its roll relative to the robot [rad]; ``omega_*``: world angular velocities; ``x_axis``: the
    anchor's x axis (unit, world). Beyond ``limit`` the relative roll rate is set to return the excess at
    ``1 / return_time`` when it is not already returning faster."""
    excess = abs(roll) - limit
    if limit <= 0 or excess <= 0:
        return None
    sign = math.copysign(1.0, roll)
    x = np.asarray(x_axis, dtype=float)
    rate = float(np.dot(np.subtract(omega_anchor, omega_robot), x))      # relative roll rate [rad/s]
    wanted = -sign * excess / return_time
    if sign * rate <= sign * wanted:    # already returning at least that fast
        return None
    return np.asarray(omega_anchor, dtype=float) + (wanted - rate) * x


class AnchorRollStop:
    """Applies the stop to every awake anchor of a SimWorld before each physics step (see the module)."""

    def __init__(self, limit, client):
        self.limit = limit
        self.client = client

    def apply(self, robots, frozen):
        """``robots``: the world's robots (``body``, ``anchor``); ``frozen(name)``: the anchor is at rest."""
        if self.limit <= 0:
            return
        c = self.client
        for name, robot in robots.items():
            if robot.anchor is None or frozen(name) is not None:
                continue
            _, a_orn = pb.getBasePositionAndOrientation(robot.anchor, physicsClientId=c)
            _, r_orn = pb.getBasePositionAndOrientation(robot.body, physicsClientId=c)
            roll = relative_roll(r_orn, a_orn)
            if abs(roll) <= self.limit:
                continue
            a_lin, a_ang = pb.getBaseVelocity(robot.anchor, physicsClientId=c)
            _, r_ang = pb.getBaseVelocity(robot.body, physicsClientId=c)
            x_axis = pb.getMatrixFromQuaternion(a_orn)[0::3]
            omega = stopped_velocity(roll, self.limit, a_ang, r_ang, x_axis)
            if omega is not None:
                pb.resetBaseVelocity(robot.anchor, a_lin, omega.tolist(), physicsClientId=c)
