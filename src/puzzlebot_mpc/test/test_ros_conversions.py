"""Message round trips (serialisation) and core <-> message conversions; no roscore."""

from io import BytesIO

from geometry_msgs.msg import Point, Pose2D
from puzzlebot_msgs.msg import BehaviorStatus, ConnectionPair, ConnectionPairArray
from puzzlebot_msgs.srv import SetBehaviorRequest

from puzzlebot_mpc import behaviors
from puzzlebot_mpc.behaviors import BehaviorStatus as CoreStatus
from puzzlebot_mpc.controller import MPCResult
from puzzlebot_mpc.ros_conversions import behavior_status_msg, request_from_srv, solver_stats_msg, twist

import numpy as np
import rospy


def round_trip(msg):
    buf = BytesIO()
    msg.serialize(buf)
    out = type(msg)()
    out.deserialize(buf.getvalue())
    return out


def test_connection_pair_array_round_trip():
    pair = ConnectionPair(robot_i="pz1", robot_j="pz2", point_i=Pose2D(-0.025, 0.0, 3.14159),
                          point_j=Pose2D(0.025, 0.0, 0.0), type=ConnectionPair.TYPE_ANCHOR,
                          anchor_robot="pz1", status=ConnectionPair.STATUS_HEAD_ALIGNED)
    arr = ConnectionPairArray(pairs=[pair, ConnectionPair(robot_i="pz2", robot_j="pz3", type=ConnectionPair.TYPE_KNOB)])
    arr.header.frame_id = "world"
    back = round_trip(arr)
    assert back.pairs[0].robot_i == "pz1" and back.pairs[0].point_i.x == -0.025
    assert back.pairs[0].status == ConnectionPair.STATUS_HEAD_ALIGNED
    assert back.pairs[1].type == ConnectionPair.TYPE_KNOB and back.header.frame_id == "world"


def test_status_constants_match_core():
    assert (BehaviorStatus.IDLE, BehaviorStatus.RUNNING, BehaviorStatus.SUCCEEDED, BehaviorStatus.FAILED) == (
        behaviors.IDLE, behaviors.RUNNING, behaviors.SUCCEEDED, behaviors.FAILED)
    assert (SetBehaviorRequest.GO_TO_GOAL, SetBehaviorRequest.FOLLOW_VELOCITY, SetBehaviorRequest.STOP) == (
        behaviors.GO_TO_GOAL, behaviors.FOLLOW_VELOCITY, behaviors.STOP)


def test_request_conversion():
    req = SetBehaviorRequest(behavior="go_to_goal", robots=["pz1", "pz2"],
                             goals=[Point(0.1, 0.2, 0.0), Point(-0.3, 0.4, 9.0)], tolerance=0.004)
    req.velocities = [twist(0.01, 0.5)]
    core = request_from_srv(round_trip(req))
    assert core.robots == ["pz1", "pz2"] and core.goals == [(0.1, 0.2), (-0.3, 0.4)]
    assert core.velocities == [(0.01, 0.5)] and core.tolerance == 0.004


def test_stats_and_status_messages():
    res = MPCResult(np.zeros((2, 2)), np.zeros((2, 3, 5)), False, "Infeasible", 12.5, 7, float("nan"), "stop")
    msg = round_trip(solver_stats_msg(res, rospy.Time(3, 5), "ipopt", 2, 13.0))
    assert (msg.success, msg.fallback, msg.solve_time_ms, msg.robots) == (False, "stop", 12.5, 2)
    assert msg.header.stamp == rospy.Time(3, 5)
    st = round_trip(behavior_status_msg(CoreStatus(4, "go_to_goal", 1, "started", ["pz1"], [0.01]), rospy.Time(1)))
    assert (st.request_id, st.state, st.robots, list(st.errors)) == (4, 1, ["pz1"], [0.01])


def test_coupling_request_fields_convert():
    from geometry_msgs.msg import Pose2D as P2
    req = SetBehaviorRequest(behavior=SetBehaviorRequest.COUPLE, robots=["pz1", "pz2"], target="",
                             slots=[P2(0.0, 0.0, 0.0), P2(-0.05, 0.0, 0.0)])
    core = request_from_srv(round_trip(req))
    assert core.behavior == behaviors.COUPLE and core.slots == [(0.0, 0.0, 0.0), (-0.05, 0.0, 0.0)]
    req = SetBehaviorRequest(behavior=SetBehaviorRequest.DECOUPLE, pair=["pz2", "pz3"])
    assert request_from_srv(round_trip(req)).pair == ["pz2", "pz3"]
    req = SetBehaviorRequest(behavior=SetBehaviorRequest.DRIVE_ASSEMBLY, robots=["pz1"], distance=0.3)
    req.velocities = [twist(0.03, 0.0)]
    core = request_from_srv(round_trip(req))
    assert core.distance == 0.3 and core.velocities == [(0.03, 0.0)] and core.cross_edges is False
    req.cross_edges = True
    assert request_from_srv(round_trip(req)).cross_edges is True
    assert (SetBehaviorRequest.COUPLE, SetBehaviorRequest.DECOUPLE, SetBehaviorRequest.DRIVE_ASSEMBLY) == (
        behaviors.COUPLE, behaviors.DECOUPLE, behaviors.DRIVE_ASSEMBLY)


def test_pairs_and_predicted_messages():
    from puzzlebot_common.geometry import RobotGeometry
    from puzzlebot_mpc.pairs import ANCHOR, HEAD_INSERTED, make_pair
    from puzzlebot_mpc.ros_conversions import pairs_msg, predicted_msg

    geo = RobotGeometry()
    pair = make_pair("pz1", "pz2", ANCHOR, geo, status=HEAD_INSERTED)
    msg = round_trip(pairs_msg([pair], rospy.Time(2, 0)))
    assert msg.pairs[0].anchor_robot == "pz1" and msg.pairs[0].status == ConnectionPair.STATUS_HEAD_INSERTED
    assert msg.pairs[0].point_i.x == -0.025 and msg.header.frame_id == "world"
    X = np.zeros((2, 4, 5))
    X[0, :, 0] = [0.0, 0.01, 0.02, 0.03]
    res = MPCResult(np.zeros((2, 2)), X, True, "Solved", 1.0, 10, 0.5)
    pred = round_trip(predicted_msg(res, ["pz1", "pz2"], rospy.Time(2, 0), 0.1))
    assert [r.robot for r in pred.robots] == ["pz1", "pz2"] and len(pred.robots[0].poses) == 4
    assert pred.robots[0].poses[3].x == 0.03 and pred.dt == 0.1
    failed = MPCResult(np.zeros((2, 2)), X, False, "x", 1.0, 0, float("nan"), fallback="stop")
    assert predicted_msg(failed, ["pz1", "pz2"], rospy.Time(2, 0), 0.1).robots == []


def test_objectives_message_carries_goals_and_placed_slots():
    from puzzlebot_mpc.behaviors import BehaviorManager, BehaviorRequest
    from puzzlebot_mpc.ros_conversions import objectives_msg
    from puzzlebot_mpc.settings import MPCSettings

    m = BehaviorManager(["pz1", "pz2", "pz3"], MPCSettings())
    empty = round_trip(objectives_msg(m.display_objectives(), rospy.Time(1, 0)))
    assert empty.goals == [] and empty.slots == [] and empty.request_id == 0
    m.request(BehaviorRequest("go_to_goal", robots=["pz2"], goals=[(0.3, -0.1)]), 0.0)
    msg = round_trip(objectives_msg(m.display_objectives(), rospy.Time(1, 0)))
    assert msg.behavior == "go_to_goal" and msg.goal_robots == ["pz2"] and (msg.goals[0].x, msg.goals[0].y) == (0.3, -0.1)
    poses = {"pz1": (0.0, 0.0, 0.0), "pz2": (-0.09, 0.01, 0.1), "pz3": (-0.2, -0.02, 0.0)}
    m.request(BehaviorRequest("couple", target="line"), 1.0, poses)
    msg = round_trip(objectives_msg(m.display_objectives(), rospy.Time(2, 0)))
    assert msg.target == "line" and sorted(msg.slot_robots) == ["pz1", "pz2", "pz3"] and msg.goals == []
    slot = {r: (s.x, s.y, s.theta) for r, s in zip(msg.slot_robots, msg.slots)}
    # a line: neighbouring slots one body apart, equal headings
    order = sorted(slot, key=lambda r: -(slot[r][0] * np.cos(slot[r][2]) + slot[r][1] * np.sin(slot[r][2])))
    for a, b in zip(order, order[1:]):
        assert abs(np.hypot(slot[a][0] - slot[b][0], slot[a][1] - slot[b][1]) - 0.05) < 1e-9
        assert abs(slot[a][2] - slot[b][2]) < 1e-9
