"""Behaviour requests: validation, per-robot objectives, progress status.

One behaviour runs at a time; it names the robots it drives and every other
robot is brought to rest. Requests are validated completely before they
replace the running behaviour, so a bad request changes nothing.
"""

import math
from dataclasses import dataclass, field
from typing import List, Sequence, Tuple

from puzzlebot_mpc.controller import Objectives

GO_TO_GOAL = "go_to_goal"
FOLLOW_VELOCITY = "follow_velocity"
STOP = "stop"
BEHAVIORS = (GO_TO_GOAL, FOLLOW_VELOCITY, STOP)

# Behaviour states; same values as puzzlebot_msgs/BehaviorStatus.
IDLE, RUNNING, SUCCEEDED, FAILED = 0, 1, 2, 3
STATE_NAMES = {IDLE: "idle", RUNNING: "running", SUCCEEDED: "succeeded", FAILED: "failed"}


class BehaviorError(ValueError):
    """A behaviour request was refused; the message says why."""


@dataclass
class BehaviorRequest:
    behavior: str
    robots: Sequence[str] = ()                     # empty: all robots
    goals: Sequence[Tuple[float, float]] = ()      # go_to_goal, world frame [m]
    velocities: Sequence[Tuple[float, float]] = ()  # follow_velocity, (v [m/s], w [rad/s])
    tolerance: float = 0.0                         # [m], 0 = default
    timeout: float = 0.0                           # [s], 0 = none; follow_velocity: duration


@dataclass
class BehaviorStatus:
    request_id: int
    behavior: str
    state: int
    message: str
    robots: List[str] = field(default_factory=list)
    errors: List[float] = field(default_factory=list)   # per robot; go_to_goal: distance [m]


def _finite(values):
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


class BehaviorManager:
    """Holds the running behaviour and turns it into MPC objectives."""

    def __init__(self, robot_names, settings):
        self.names = list(robot_names)
        self.index = {name: i for i, name in enumerate(self.names)}
        self.settings = settings
        self._request_id = 0
        self._req = BehaviorRequest(STOP)
        self._robots = []
        self._start = None
        self._state = IDLE
        self._message = "no behaviour requested yet"
        self._objectives = Objectives.stop_all(len(self.names))

    # ------------------------------------------------------------- requests
    def validate(self, req):
        """Return the list of robots a request applies to, or raise BehaviorError."""
        if req.behavior not in BEHAVIORS:
            raise BehaviorError("unknown behaviour %r; known: %s" % (req.behavior, ", ".join(BEHAVIORS)))
        robots = list(req.robots) or list(self.names)
        unknown = [r for r in robots if r not in self.index]
        if unknown:
            raise BehaviorError("unknown robot(s) %s; known: %s"
                                % (", ".join(map(repr, unknown)), ", ".join(self.names)))
        if len(set(robots)) != len(robots):
            raise BehaviorError("a robot is named twice in %s" % robots)
        if not _finite([req.tolerance, req.timeout]) or req.tolerance < 0 or req.timeout < 0:
            raise BehaviorError("tolerance and timeout must be finite and >= 0 (got %r, %r)"
                                % (req.tolerance, req.timeout))
        if req.behavior == GO_TO_GOAL:
            if len(req.goals) != len(robots):
                raise BehaviorError("go_to_goal needs one goal per robot: %d robot(s), %d goal(s)"
                                    % (len(robots), len(req.goals)))
            for name, goal in zip(robots, req.goals):
                if len(goal) != 2 or not _finite(goal):
                    raise BehaviorError("goal for %s is not a finite (x, y): %r" % (name, tuple(goal)))
        if req.behavior == FOLLOW_VELOCITY:
            if len(req.velocities) != len(robots):
                raise BehaviorError("follow_velocity needs one velocity per robot: %d robot(s), %d velocity(ies)"
                                    % (len(robots), len(req.velocities)))
            s = self.settings
            for name, vel in zip(robots, req.velocities):
                if len(vel) != 2 or not _finite(vel):
                    raise BehaviorError("velocity for %s is not a finite (v, w): %r" % (name, tuple(vel)))
                if abs(vel[0]) > s.v_max + 1e-12 or abs(vel[1]) > s.w_max + 1e-12:
                    raise BehaviorError("velocity for %s (%.3f m/s, %.3f rad/s) exceeds the limits "
                                        "v_max %.3f m/s, w_max %.3f rad/s"
                                        % (name, vel[0], vel[1], s.v_max, s.w_max))
        return robots

    def request(self, req, now):
        """Validate and start a behaviour at time ``now`` [s]; return its id."""
        robots = self.validate(req)
        n = len(self.names)
        obj = Objectives.stop_all(n)
        for k, name in enumerate(robots):
            i = self.index[name]
            if req.behavior == GO_TO_GOAL:
                obj.goal[i] = req.goals[k]
                obj.goal_mask[i] = True
                obj.velocity_mask[i] = False
            elif req.behavior == FOLLOW_VELOCITY:
                obj.velocity[i] = req.velocities[k]
        self._request_id += 1
        self._req, self._robots, self._start = req, robots, now
        self._objectives = obj
        self._state, self._message = RUNNING, "started"
        return self._request_id

    def objectives(self):
        return self._objectives

    # --------------------------------------------------------------- status
    def update(self, now, poses):
        """Advance the behaviour's state given ``poses`` (name -> (x, y, theta) or None)."""
        req = self._req
        errors = []
        if req.behavior == GO_TO_GOAL:
            for name in self._robots:
                pose = poses.get(name)
                goal = self._objectives.goal[self.index[name]]
                errors.append(float("nan") if pose is None else math.hypot(pose[0] - goal[0], pose[1] - goal[1]))
        if self._state == RUNNING:
            elapsed = now - self._start
            tol = req.tolerance or self.settings.goal_tolerance
            if req.behavior == STOP:
                self._state, self._message = SUCCEEDED, "stopped"
            elif req.behavior == GO_TO_GOAL and errors and all(e <= tol for e in errors):
                self._state = SUCCEEDED
                self._message = "all %d robot(s) within %.1f mm of their goals after %.2f s" % (
                    len(errors), 1e3 * tol, elapsed)
            elif req.timeout and elapsed >= req.timeout:
                if req.behavior == FOLLOW_VELOCITY:
                    self._state, self._message = SUCCEEDED, "followed the velocity for %.2f s" % elapsed
                else:
                    far = [n for n, e in zip(self._robots, errors) if not e <= tol]
                    self._state = FAILED
                    self._message = "timeout after %.2f s; not at goal: %s" % (elapsed, ", ".join(far))
                self._objectives = Objectives.stop_all(len(self.names))
        return BehaviorStatus(self._request_id, req.behavior, self._state, self._message,
                              list(self._robots), errors)
