"""What each control step tells the behaviour action's goals, without ROS.

The MPC node serves the action ``/puzzlebot/mpc/behavior``
(puzzlebot_msgs/Behavior.action; behavior_action.py is the actionlib side).
Every accepted goal is a behaviour request of the control loop
(ControlLoop.request) under its request id; a :class:`GoalBook` keeps the
goals by that id and, after every control step, turns the step's behaviour
status into one :class:`GoalEvent` per goal:

- the goal's request runs: ``feedback`` (state RUNNING, message, progress,
  errors, the pairs of its robots); it ended this step: ``succeeded`` or
  ``aborted`` (outcome ``failed``: its timeout, a lost pair, refused when it
  was due, ...);
- it waits in the queue: ``feedback`` (state IDLE, "queued");
- it is neither running nor queued: another request replaced it
  (``canceled``, outcome ``replaced``; actionlib: PREEMPTED), or the queue
  was dropped before it started (``aborted``, outcome ``dropped``);
- it was cancelled (:meth:`GoalBook.finish`, from the action's cancel): the
  outcome given, at the next step (its result has that step's errors).

Goals whose id is newer than the step (accepted while it ran) wait for the
next one.
"""

from dataclasses import dataclass, field
from typing import List

from puzzlebot_mpc.behaviors import FAILED, IDLE, RUNNING, SUCCEEDED

FEEDBACK, SUCCEEDED_EVENT, ABORTED, CANCELED = "feedback", "succeeded", "aborted", "canceled"


@dataclass
class GoalEvent:
    """One goal's news from a control step (kind: FEEDBACK, SUCCEEDED_EVENT, ABORTED or CANCELED)."""

    kind: str
    request_id: int
    handle: object                  # the caller's goal handle
    state: int                      # behaviour state (IDLE while queued)
    outcome: str = ""               # final events: succeeded, failed, replaced, dropped, cancelled
    message: str = ""
    robots: List[str] = field(default_factory=list)
    errors: List[float] = field(default_factory=list)
    progress: float = float("nan")
    pairs: list = field(default_factory=list)   # the pairs (pairs.ConnectionPair) that involve its robots
    started: float = None           # s, ROS time of the control step it started at (None: it never ran)
    ended: float = None             # s, ROS time of the control step it ended at (None: not yet, or never ran)
    now: float = 0.0                # s, the step's time

    @property
    def final(self):
        return self.kind != FEEDBACK

    @property
    def elapsed(self):
        """s since it started (0 while queued)."""
        if self.started is None:
            return 0.0
        return (self.now if self.ended is None else self.ended) - self.started


@dataclass
class _Goal:
    handle: object
    key: object                     # what identifies the goal to the caller (actionlib: its goal id)
    robots: List[str]
    queued: bool                    # it was queued when accepted (queue or a later start_time)
    started: float = None
    last: tuple = None              # (robots, errors, progress) of the last step it was the current request
    finish: tuple = None            # (kind, outcome, message) forced by finish()


def involving(pairs, robots):
    """The pairs with a robot of ``robots`` (all pairs when ``robots`` is empty: a request for all)."""
    if not robots:
        return list(pairs)
    named = set(robots)
    return [p for p in pairs if p.robot_i in named or p.robot_j in named]


class GoalBook:
    """The action's goals by request id (module docstring). Not thread-safe: the node calls it under
    the lock that guards its control loop."""

    def __init__(self):
        self._goals = {}

    def __contains__(self, request_id):
        return request_id in self._goals

    def __len__(self):
        return len(self._goals)

    def add(self, request_id, handle, robots, queued, key=None):
        """An accepted goal: request ``request_id`` of ``robots`` (empty: all), ``queued`` or started at once;
        ``key`` identifies it for request_of (default: the handle)."""
        self._goals[request_id] = _Goal(handle, handle if key is None else key, list(robots), queued)

    def handle(self, request_id):
        goal = self._goals.get(request_id)
        return goal.handle if goal is not None else None

    def request_of(self, key):
        """The request id of the goal with ``key`` (None: not a goal of this book, or ended)."""
        return next((rid for rid, g in self._goals.items() if g.key == key), None)

    def finish(self, request_id, kind, outcome, message):
        """End goal ``request_id`` at the next step with ``kind`` (ABORTED or CANCELED) and ``outcome``."""
        goal = self._goals.get(request_id)
        if goal is not None and goal.finish is None:
            goal.finish = (kind, outcome, message)

    def step(self, status, pending, last_id, pairs, now):
        """The events of a control step at ``now`` [s]: ``status`` (behaviors.BehaviorStatus of the
        step), ``pending`` (ControlLoop.pending(), taken with it), ``last_id`` (the last request id
        handed out by then), ``pairs`` (the step's ConnectionPairs). Goals that ended leave the book."""
        events = []
        for rid in sorted(self._goals):
            if rid > last_id:
                continue                # accepted after this step was taken: the next step tells
            g = self._goals[rid]
            current = rid == status.request_id
            if current and g.started is None and status.state != IDLE:
                g.started = now
            event = GoalEvent(FEEDBACK, rid, g.handle, IDLE, robots=list(g.robots), pairs=involving(pairs, g.robots),
                              started=g.started, now=now)
            if current:
                event.state, event.message = status.state, status.message
                g.last = (list(status.robots), list(status.errors), status.progress)
            if g.last is not None:      # a goal that ended while another runs: what it had last
                event.robots, event.errors, event.progress = g.last
                event.pairs = involving(pairs, event.robots)
            if g.finish is not None:
                event.kind, event.outcome, event.message = g.finish
                event.state = FAILED
            elif current and status.state == SUCCEEDED:
                event.kind, event.outcome = SUCCEEDED_EVENT, "succeeded"
            elif current and status.state == FAILED:
                event.kind, event.outcome = ABORTED, "failed"
            elif current and status.state == RUNNING:
                pass
            elif rid in pending:
                event.message = "queued: waits for %s" % ("the requests before it" if pending.index(rid) else
                                                          "the running behaviour or its start time")
            elif g.started is not None or not g.queued:
                event.kind, event.outcome, event.state = CANCELED, "replaced", FAILED
                event.message = "replaced by request %d (%s)" % (status.request_id, status.behavior)
            else:
                event.kind, event.outcome, event.state = ABORTED, "dropped", FAILED
                event.message = "dropped before it started: %s" % status.message
            if event.final:
                event.ended = now if g.started is not None else None
                del self._goals[rid]
            events.append(event)
        return events

