"""Scheduled behaviour requests (ControlLoop.request with queue / start_time), on a kinematic plant."""

import pytest

from puzzlebot_mpc.behaviors import FAILED, IDLE, RUNNING, SUCCEEDED, BehaviorError, BehaviorRequest
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_common.model import unicycle_arc
from puzzlebot_mpc.settings import MPCSettings

NAMES = ["pz1", "pz2"]
DT = 0.1


def make_loop():
    loop = ControlLoop(NAMES, MPCSettings())
    poses = {"pz1": (0.0, 0.0, 0.0), "pz2": (0.0, 0.15, 0.0)}
    for n, p in poses.items():
        loop.on_pose(n, 0.0, *p)
    return loop, poses


def tick(loop, poses, t):
    """One control step at ``t`` and the plant moved for DT; returns the step's status."""
    out = loop.step(t)
    for name in NAMES:
        v, w = out.commands[name]
        for _ in range(10):
            poses[name] = unicycle_arc(poses[name], v, w, DT / 10)
    for name, p in poses.items():
        loop.on_pose(name, t + DT, *p)
    return out.status


def goal(x, tol=0.005):
    return BehaviorRequest("go_to_goal", ["pz1"], [(x, 0.0)], tolerance=tol)


def run(loop, poses, steps, t0=0.0):
    """Statuses (time, request id, state) of ``steps`` control steps from t0."""
    log = []
    for k in range(steps):
        t = t0 + k * DT
        s = tick(loop, poses, t)
        log.append((round(t, 3), s.request_id, s.state))
    return log


def first(log, request_id, state):
    return next((t for t, rid, st in log if rid == request_id and st == state), None)


def test_start_time_waits_for_the_control_step_at_or_after_it():
    loop, poses = make_loop()
    rid = loop.request(BehaviorRequest("go_to_goal", ["pz1"], [(0.05, 0.0)], start_time=0.5), now=0.0)
    assert loop.pending() == [rid]
    log = run(loop, poses, 8)
    assert first(log, rid, RUNNING) == 0.5          # not before: the robot rests until then
    assert all(st == IDLE for t, _, st in log if t < 0.5)
    assert loop.pending() == []


def test_queued_requests_run_in_order_each_starting_the_step_after_the_one_before_ends():
    loop, poses = make_loop()
    a = loop.request(goal(0.03), now=0.0)
    b = loop.request(BehaviorRequest("go_to_goal", ["pz1"], [(0.06, 0.0)], tolerance=0.005, queue=True), now=0.0)
    c = loop.request(BehaviorRequest("stop", queue=True), now=0.0)
    assert (a, b, c) == (1, 2, 3) and loop.pending() == [b, c]
    log = run(loop, poses, 120)
    end_a, start_b = first(log, a, SUCCEEDED), first(log, b, RUNNING)
    assert end_a is not None and start_b == pytest.approx(end_a + DT)
    end_b = first(log, b, SUCCEEDED)
    assert end_b is not None and first(log, c, SUCCEEDED) == pytest.approx(end_b + DT)
    assert abs(poses["pz1"][0] - 0.06) <= 0.006


def test_a_failed_behaviour_drops_the_queue_behind_it():
    loop, poses = make_loop()
    a = loop.request(BehaviorRequest("go_to_goal", ["pz1"], [(1.0, 0.0)], timeout=0.3), now=0.0)
    b = loop.request(BehaviorRequest("stop", queue=True), now=0.0)
    c = loop.request(BehaviorRequest("stop", queue=True), now=0.0)
    log = run(loop, poses, 10)
    assert first(log, a, FAILED) is not None
    assert first(log, b, RUNNING) is None and first(log, b, SUCCEEDED) is None and loop.pending() == []
    t, rid, st = log[-1]
    assert (rid, st) == (a, FAILED)
    assert "queued request(s) %d, %d dropped" % (b, c) in loop.behaviors.update(t, {}).message
    with pytest.raises(BehaviorError, match="failed; nothing to queue behind"):
        loop.request(BehaviorRequest("stop", queue=True), now=t)


def test_an_immediate_request_replaces_the_running_one_and_cancels_the_queue():
    loop, poses = make_loop()
    loop.request(goal(0.2), now=0.0)
    loop.request(BehaviorRequest("stop", queue=True), now=0.0)
    loop.request(goal(0.1, tol=0.01), now=0.0)
    assert loop.pending() == []
    s = loop.request(BehaviorRequest("stop"), now=0.0)
    log = run(loop, poses, 2)
    assert log[0][1:] == (s, SUCCEEDED)


def test_state_checks_run_when_due_and_a_refusal_is_reported_with_the_request_id():
    loop, poses = make_loop()
    # pz1 and pz2 are not coupled: a decouple passes the state-free checks when queued ...
    d = loop.request(BehaviorRequest("decouple", pair=["pz1", "pz2"], queue=True, start_time=0.2), now=0.0)
    later = loop.request(BehaviorRequest("stop", queue=True), now=0.0)
    log = run(loop, poses, 4)
    assert first(log, d, FAILED) == 0.2             # ... and is refused when it is due
    status = loop.behaviors.update(0.4, {})
    assert "refused when due" in status.message and "not coupled" in status.message
    assert first(log, later, RUNNING) is None and first(log, later, SUCCEEDED) is None


@pytest.mark.parametrize("req, match", [
    (BehaviorRequest("fly", queue=True), "unknown behaviour"),
    (BehaviorRequest("stop", ["pz9"], queue=True), "unknown robot"),
    (BehaviorRequest("couple", slots=[(0.0, 0.0, 0.0), (0.05, 0.0, 0.0), (0.1, 0.0, 0.0)], queue=True),
     "3 slots"),
    (BehaviorRequest("decouple", pair=["pz1"], queue=True), "pair's two robots"),
    (BehaviorRequest("stop", start_time=float("nan")), "start_time"),
    (BehaviorRequest("stop", start_time=-1.0), "start_time"),
])
def test_state_free_checks_refuse_a_queued_request_at_once(req, match):
    loop, _ = make_loop()
    with pytest.raises(BehaviorError, match=match):
        loop.request(req, now=0.0)
    assert loop.pending() == []
