"""SimWorld readouts -> ROS messages (message classes only: no rospy, testable without a roscore)."""

from geometry_msgs.msg import Pose2D, TransformStamped

from puzzlebot_common import names
from puzzlebot_common.geometry import RobotGeometry
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
    points are the contract's C_a and C_o (RobotGeometry.anchor_point /
    opening_point). Knob pairs (``p.knob``): robot_i carries the knob,
    robot_j the hole; points RobotGeometry.knob_point / hole_point, no anchor
    robot.
    """
    g = RobotGeometry(body_side=body_side)
    points = {False: (_pose2d(g.anchor_point()), _pose2d(g.opening_point())),
              True: (_pose2d(g.knob_point()), _pose2d(g.hole_point()))}
    msg = ConnectionPairArray()
    msg.header.stamp = stamp
    msg.header.frame_id = names.WORLD_FRAME
    for p in pairs:
        cp = ConnectionPair()
        cp.robot_i, cp.robot_j = p.anchor_robot, p.opening_robot
        cp.point_i, cp.point_j = points[p.knob]
        cp.type = ConnectionPair.TYPE_KNOB if p.knob else ConnectionPair.TYPE_ANCHOR
        if not p.knob:
            cp.anchor_robot = p.anchor_robot
        cp.status = p.status
        msg.pairs.append(cp)
    return msg


def _pose2d(point):
    return Pose2D(x=float(point[0]), y=float(point[1]), theta=float(point[2]))
