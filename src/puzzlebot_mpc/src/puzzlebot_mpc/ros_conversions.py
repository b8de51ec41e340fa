"""Conversions between the ROS-free core types and puzzlebot_msgs.

Only message classes are used (no rospy calls), so these run and are tested
without a roscore.
"""

from geometry_msgs.msg import Twist

from puzzlebot_msgs.msg import BehaviorStatus, SolverStats
from puzzlebot_mpc.behaviors import BehaviorRequest


def request_from_srv(req):
    """SetBehaviorRequest -> BehaviorRequest."""
    return BehaviorRequest(behavior=req.behavior, robots=list(req.robots),
                           goals=[(g.x, g.y) for g in req.goals],
                           velocities=[(t.linear.x, t.angular.z) for t in req.velocities],
                           tolerance=req.tolerance, timeout=req.timeout)


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
