"""The MPC node's behaviour action (actionlib side): /puzzlebot/mpc/behavior, puzzlebot_msgs/Behavior.

A goal is a behaviour request (the fields of SetBehavior.srv), validated
and started or queued exactly as the service's (the node's ``submit``):
refused -> the goal is rejected with the reason; accepted -> the goal is
ACTIVE under its request id. After every control step the node passes the
step to the ROS-free goals.GoalBook and hands its events to :meth:`apply`:
feedback (state, message, progress, errors, pairs) while a goal waits or
runs, then its result: SUCCEEDED, ABORTED (failed, or dropped from the
queue), PREEMPTED (replaced by a request that started at once, or
cancelled; the result's outcome says which, and its start time 0 that it
never ran). Goals are accepted at once, queued ones too (ACTIVE while they
wait), so none ends RECALLED.

Cancel (:meth:`on_cancel`): a queued goal leaves the queue; a running one
is replaced by ``stop`` (every robot comes to rest, coupled pairs stay
held) and the goals queued behind it are dropped (ControlLoop.cancel). The
result follows at the next control step.

Locks: actionlib calls on_goal / on_cancel holding its own (reentrant)
lock; they take the node's lock inside it. The node's step computes the
events under its lock and calls :meth:`apply` (actionlib's lock) after
releasing it, so the two are never taken in the other order.
"""

import actionlib
import rospy

from puzzlebot_common import names
from puzzlebot_msgs.msg import BehaviorAction, BehaviorFeedback, BehaviorStatus
from puzzlebot_mpc.behaviors import BehaviorError
from puzzlebot_mpc.goals import ABORTED, CANCELED, FEEDBACK, SUCCEEDED_EVENT, GoalBook
from puzzlebot_mpc.ros_conversions import feedback_msg, request_from_srv, result_msg


class BehaviorActionServer:
    """``node``: the MPC node (submit(req, on_accept), cancel(request_id, on_cancel))."""

    def __init__(self, node):
        self.node = node
        self.book = GoalBook()
        self.server = actionlib.ActionServer(names.BEHAVIOR_ACTION, BehaviorAction, self.on_goal, self.on_cancel,
                                             auto_start=False)
        self.server.start()

    def on_goal(self, handle):
        req = request_from_srv(handle.get_goal())

        def accept(request_id, queued):           # under the node's lock, before any step can report it
            self.book.add(request_id, handle, req.robots, queued, key=handle.get_goal_id().id)
            handle.set_accepted("request %d" % request_id)
            handle.publish_feedback(BehaviorFeedback(
                request_id=request_id, state=BehaviorStatus.IDLE if queued else BehaviorStatus.RUNNING,
                message="queued" if queued else "started", progress=float("nan")))
        try:
            self.node.submit(req, accept, source="action goal")
        except BehaviorError as e:
            handle.set_rejected(result_msg(outcome="refused", message=str(e)), str(e))

    def on_cancel(self, handle):
        request_id = self.book.request_of(handle.get_goal_id().id)     # actionlib wraps each call anew
        if request_id is None:
            return

        def cancelled(what, dropped):              # under the node's lock
            if what == "queued":
                self.book.finish(request_id, CANCELED, "cancelled", "cancelled before it started")
            elif what == "running":
                self.book.finish(request_id, CANCELED, "cancelled", "cancelled while running: every robot "
                                 "brought to rest (stop), coupled pairs held")
                for other in dropped:
                    self.book.finish(other, ABORTED, "dropped", "dropped: queued behind request %d, which was "
                                     "cancelled" % request_id)
        self.node.cancel(request_id, cancelled)

    def step(self, status, pending, last_id, pairs, now):
        """The events of a control step (goals.GoalBook.step); call under the node's lock."""
        return self.book.step(status, pending, last_id, pairs, now) if len(self.book) else []

    @staticmethod
    def apply(events):
        """Feedback and results of ``events`` to their goals; call without the node's lock."""
        for e in events:
            if e.kind == FEEDBACK:
                e.handle.publish_feedback(feedback_msg(e))
                continue
            result = result_msg(e)
            if e.kind == SUCCEEDED_EVENT:
                e.handle.set_succeeded(result, e.message)
            elif e.kind == ABORTED:
                e.handle.set_aborted(result, e.message)
            else:
                e.handle.set_canceled(result, e.message)
            rospy.loginfo("behaviour goal (request %d) %s: %s" % (e.request_id, e.outcome, e.message))
