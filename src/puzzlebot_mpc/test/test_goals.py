"""The behaviour action's goals (puzzlebot_mpc.goals.GoalBook) over a control loop on a kinematic plant:
feedback, results, cancel (ControlLoop.cancel) and progress; no roscore."""

import math

import pytest

from puzzlebot_common.model import unicycle_arc
from puzzlebot_mpc.behaviors import IDLE, RUNNING, BehaviorRequest
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_mpc.goals import ABORTED, CANCELED, FEEDBACK, SUCCEEDED_EVENT, GoalBook
from puzzlebot_mpc.settings import MPCSettings

NAMES = ["pz1", "pz2"]
DT = 0.1


class Rig:
    """A control loop, a kinematic plant and a goal book; goals are requests added as the node does."""

    def __init__(self):
        self.loop = ControlLoop(NAMES, MPCSettings())
        self.book = GoalBook()
        self.poses = {"pz1": (0.0, 0.0, 0.0), "pz2": (0.0, 0.15, 0.0)}
        self.t = 0.0
        self.events = []
        self.speeds = []
        for n, p in self.poses.items():
            self.loop.on_pose(n, 0.0, *p)

    def goal(self, req, handle):
        rid = self.loop.request(req, self.t)
        self.book.add(rid, handle, req.robots, rid in self.loop.pending())
        return rid

    def step(self):
        out = self.loop.step(self.t)
        events = self.book.step(out.status, self.loop.pending(), self.loop.behaviors.last_id, out.pairs, self.t)
        self.events += events
        self.speeds.append(max(abs(v) for v, _ in out.commands.values()))
        for name in NAMES:
            v, w = out.commands[name]
            for _ in range(10):
                self.poses[name] = unicycle_arc(self.poses[name], v, w, DT / 10)
        self.t = round(self.t + DT, 6)
        for name, p in self.poses.items():
            self.loop.on_pose(name, self.t, *p)
        return events

    def of(self, handle):
        return [e for e in self.events if e.handle == handle]


def goto(x, **kw):
    return BehaviorRequest("go_to_goal", ["pz1"], [(x, 0.0)], tolerance=0.005, **kw)


def test_feedback_with_progress_then_the_result():
    rig = Rig()
    rig.goal(goto(0.06), "g")
    while not any(e.final for e in rig.events) and rig.t < 10:
        rig.step()
    events = rig.of("g")
    feedback, final = events[:-1], events[-1]
    assert all(e.kind == FEEDBACK and e.state == RUNNING for e in feedback)
    progress = [e.progress for e in feedback]
    assert progress[0] == pytest.approx(0.0, abs=0.05) and progress[-1] > 0.8
    assert all(b >= a - 0.02 for a, b in zip(progress, progress[1:]))      # it only grows (noise-free)
    assert feedback[-1].elapsed == pytest.approx(feedback[-1].now - feedback[0].now)
    assert final.kind == SUCCEEDED_EVENT and final.outcome == "succeeded" and final.errors[0] < 0.005
    assert final.started == 0.0 and final.ended == pytest.approx(rig.t - DT)
    assert len(rig.book) == 0


def test_queued_goals_wait_and_a_cancelled_running_one_stops_the_robots():
    rig = Rig()
    first = rig.goal(goto(0.3), "a")
    second = rig.goal(goto(0.0, queue=True), "b")
    for _ in range(10):
        rig.step()
    assert rig.speeds[-1] > 0.04                       # driving at v_max
    queued = rig.of("b")[-1]
    assert queued.kind == FEEDBACK and queued.state == IDLE and "queued" in queued.message
    assert rig.loop.cancel(first, rig.t) == "running"
    rig.book.finish(first, CANCELED, "cancelled", "cancelled while running")
    rig.book.finish(second, ABORTED, "dropped", "dropped: queued behind a cancelled request")
    rig.step()
    a, b = rig.of("a")[-1], rig.of("b")[-1]
    assert (a.kind, a.outcome) == (CANCELED, "cancelled") and a.ended > a.started
    assert (b.kind, b.outcome) == (ABORTED, "dropped") and b.started is None     # it never ran
    assert rig.loop.pending() == [] and len(rig.book) == 0
    for _ in range(5):
        rig.step()
    assert max(rig.speeds[-4:]) < 1e-3                 # every robot at rest (stop replaced the goal)


def test_cancel_a_queued_request_and_cancel_what_has_ended():
    rig = Rig()
    rig.goal(goto(0.02), "a")
    queued = rig.goal(goto(0.0, queue=True), "b")
    assert rig.loop.cancel(queued, rig.t) == "queued" and rig.loop.pending() == []
    for _ in range(40):
        rig.step()
    assert rig.loop.cancel(queued, rig.t) is None      # nothing left to cancel
    assert rig.of("a")[-1].outcome == "succeeded"


def test_replaced_and_dropped_goals():
    rig = Rig()
    rig.goal(goto(0.3), "a")
    rig.step()
    rig.goal(goto(0.0), "b")                           # starts at once: replaces a
    rig.step()
    a = rig.of("a")[-1]
    assert (a.kind, a.outcome) == (CANCELED, "replaced") and "replaced by request 2" in a.message
    # a queue dropped when the goal before it fails: the timeout
    rig = Rig()
    rig.goal(goto(0.3, timeout=0.3), "a")
    rig.goal(goto(0.0, queue=True), "b")
    for _ in range(8):
        rig.step()
    a, b = rig.of("a")[-1], rig.of("b")[-1]
    assert (a.kind, a.outcome) == (ABORTED, "failed") and "timeout" in a.message
    assert (b.kind, b.outcome) == (ABORTED, "dropped") and "dropped" in b.message


def test_progress_of_each_behaviour():
    rig = Rig()
    rig.goal(BehaviorRequest("follow_velocity", ["pz2"], velocities=[(0.02, 0.0)], timeout=1.0), "f")
    for _ in range(6):
        rig.step()
    assert rig.of("f")[-1].progress == pytest.approx(0.5, abs=0.11)
    rig.goal(BehaviorRequest("follow_velocity", ["pz2"], velocities=[(0.02, 0.0)]), "g")   # no duration
    rig.step()
    assert math.isnan(rig.of("g")[-1].progress)
    rig.goal(BehaviorRequest("stop"), "s")
    rig.step()
    assert rig.of("s")[-1].progress == 1.0 and rig.of("s")[-1].outcome == "succeeded"
