"""SimWorld readouts -> ROS messages (message classes only: no rospy, testable without a roscore)."""

import math

from geometry_msgs.msg import Pose2D, TransformStamped

from puzzlebot_common import names
from puzzlebot_msgs.msg import ConnectionPair, ConnectionPairArray


def transform_msg(stamp, parent, child, pose):
    """TransformStamped from ``pose`` = (position xyz, quaternion xyzw)."""
    (x, y, z), (qx, qy, qz, qw) = pose
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = parent
    msg.child_frame_id = child
    t, r = msg.transform.translation, msg.transform.rotation
    t.x, t.y, t.z, r.x, r.y, r.z, r.w = x, y, z, qx, qy, qz, qw
    return msg


def physical_pairs_msg(pairs, stamp, body_side):
    """ConnectionPairArray of the physical couplings (puzzlebot_sim.coupling.PhysicalPair list).

    robot_i is the anchor robot, robot_j the opening robot; the connection
    points are the contract's C_a = (-L/2, 0) and C_o = (+L/2, 0). Knob pairs
    (``p.knob``): robot_i carries the knob, robot_j the hole; points (0, +L/2)
    and (0, -L/2), no anchor robot.
    """
    msg = ConnectionPairArray()
    msg.header.stamp = stamp
    msg.header.frame_id = names.WORLD_FRAME
    for p in pairs:
        cp = ConnectionPair()
        cp.robot_i, cp.robot_j = p.anchor_robot, p.opening_robot
        if p.knob:
            cp.point_i = Pose2D(x=0.0, y=body_side / 2.0, theta=math.pi / 2.0)
            cp.point_j = Pose2D(x=0.0, y=-body_side / 2.0, theta=-math.pi / 2.0)
            cp.type = ConnectionPair.TYPE_KNOB
        else:
            cp.point_i = Pose2D(x=-body_side / 2.0, y=0.0, theta=0.0)
            cp.point_j = Pose2D(x=body_side / 2.0, y=0.0, theta=0.0)
            cp.type = ConnectionPair.TYPE_ANCHOR
            cp.anchor_robot = p.anchor_robot
        cp.status = p.status
        msg.pairs.append(cp)
    return msg
