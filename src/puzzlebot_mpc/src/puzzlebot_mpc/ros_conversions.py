"""Conversions between the ROS-free core types and puzzlebot_msgs.

Only message classes are used (no rospy calls), so these run and are tested
without a roscore.
"""

import genpy
from geometry_msgs.msg import Point, Pose2D, Twist

from puzzlebot_common import names
from puzzlebot_msgs.msg import (BehaviorFeedback, BehaviorObjectives, BehaviorResult, BehaviorStatus, ConnectionPair,
                                ConnectionPairArray, PredictedTrajectories, RobotTrajectory, SolverStats)
from puzzlebot_mpc.behaviors import BehaviorRequest


def request_from_srv(req):
    """SetBehaviorRequest (or a BehaviorGoal: the same fields) -> BehaviorRequest."""
    return BehaviorRequest(behavior=req.behavior, robots=list(req.robots),
                           goals=[(g.x, g.y) for g in req.goals],
                           velocities=[(t.linear.x, t.angular.z) for t in req.velocities],
                           tolerance=req.tolerance, timeout=req.timeout, target=req.target,
                           slots=[(sl.x, sl.y, sl.theta) for sl in req.slots], pair=list(req.pair),
                           distance=req.distance, groups=list(req.groups), cross_edges=bool(req.cross_edges),
                           queue=req.queue, start_time=req.start_time)


def pose2d(p):
    return Pose2D(x=float(p[0]), y=float(p[1]), theta=float(p[2]))


def pair_msg(pair):
    """pairs.ConnectionPair -> puzzlebot_msgs/ConnectionPair."""
    return ConnectionPair(robot_i=pair.robot_i, robot_j=pair.robot_j, point_i=pose2d(pair.point_i),
                          point_j=pose2d(pair.point_j), type=pair.type, anchor_robot=pair.anchor_robot,
                          status=pair.status)


def pairs_msg(pairs, stamp):
    msg = ConnectionPairArray(pairs=[pair_msg(p) for p in pairs])
    msg.header.stamp = stamp
    msg.header.frame_id = names.WORLD_FRAME
    return msg


def predicted_msg(result, robot_names, stamp, dt):
    """The MPC's predicted states (N, H+1, 5) as PredictedTrajectories (empty after a failure)."""
    msg = PredictedTrajectories(dt=dt)
    msg.header.stamp = stamp
    msg.header.frame_id = names.WORLD_FRAME
    if result.success:
        for i, name in enumerate(robot_names):
            X = result.predicted[i]
            msg.robots.append(RobotTrajectory(robot=name, poses=[pose2d(x[:3]) for x in X],
                                              v=[float(x) for x in X[:, 3]], w=[float(x) for x in X[:, 4]]))
    return msg


def objectives_msg(view, stamp):
    """behaviors.DisplayObjectives -> puzzlebot_msgs/BehaviorObjectives."""
    msg = BehaviorObjectives(request_id=view.request_id, behavior=view.behavior, state=view.state,
                             target=view.target)
    msg.header.stamp = stamp
    msg.header.frame_id = names.WORLD_FRAME
    msg.goal_robots = [r for r, _ in view.goals]
    msg.goals = [Point(float(g[0]), float(g[1]), 0.0) for _, g in view.goals]
    msg.slot_robots = [r for r, _ in view.slots]
    msg.slots = [pose2d(sl) for _, sl in view.slots]
    return msg


def twist(v, w):
    msg = Twist()
    msg.linear.x = v
    msg.angular.z = w
    return msg


def solver_stats_msg(result, stamp, solver, robots, step_ms, active_pairs=0, coupled_pairs=0):
    msg = SolverStats()
    msg.header.stamp = stamp
    msg.solver = solver
    msg.success = result.success
    msg.status = result.status
    msg.solve_time_ms = result.solve_time_ms
    msg.step_time_ms = step_ms
    msg.iterations = max(0, result.iterations)
    msg.cost = result.cost
    msg.robots = robots
    msg.active_pairs = active_pairs
    msg.coupled_pairs = coupled_pairs
    msg.fallback = result.fallback
    return msg


def behavior_status_msg(status, stamp):
    msg = BehaviorStatus()
    msg.header.stamp = stamp
    msg.request_id = status.request_id
    msg.behavior = status.behavior
    msg.state = status.state
    msg.message = status.message
    msg.robots = list(status.robots)
    msg.errors = [float(e) for e in status.errors]
    return msg


def _time(t):
    """genpy.Time of ``t`` [s]; None (never) -> 0."""
    return genpy.Time.from_sec(0.0 if t is None else max(0.0, float(t)))


def feedback_msg(event):
    """goals.GoalEvent -> puzzlebot_msgs/BehaviorFeedback."""
    return BehaviorFeedback(request_id=event.request_id, state=event.state, message=event.message,
                            elapsed=event.elapsed, progress=float(event.progress), robots=list(event.robots),
                            errors=[float(e) for e in event.errors], pairs=[pair_msg(p) for p in event.pairs])


def result_msg(event=None, outcome="", message=""):
    """goals.GoalEvent (a final one) -> puzzlebot_msgs/BehaviorResult; without an event, a result of
    only ``outcome`` and ``message`` (a rejected goal)."""
    if event is None:
        return BehaviorResult(outcome=outcome, message=message)
    return BehaviorResult(request_id=event.request_id, outcome=event.outcome, message=event.message,
                          robots=list(event.robots), errors=[float(e) for e in event.errors],
                          started=_time(event.started), ended=_time(event.ended),
                          pairs=[pair_msg(p) for p in event.pairs])
