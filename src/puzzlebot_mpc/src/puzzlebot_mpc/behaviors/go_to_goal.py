"""``go_to_goal``: every named robot drives to its own goal (x, y) [m], world frame.

Succeeds when every robot is within ``tolerance`` (default the setting
``goal_tolerance``) of its goal; fails after ``timeout`` s (0: none), naming
the robots not there. Status errors: each robot's distance to its goal [m]
(NaN without a pose). Progress: the mean over the robots of the share of
its distance to the goal driven since the first status (1 within tolerance).
"""

import math

import numpy as np

from puzzlebot_mpc.behaviors.base import FAILED, SUCCEEDED, Behavior, BehaviorError, Progress, finite

GO_TO_GOAL = "go_to_goal"


class GoToGoal(Behavior):
    name = GO_TO_GOAL

    def validate(self, poses=None):
        for name, goal in self.one_per_robot(self.req.goals, "goal", "goal(s)"):
            if len(goal) != 2 or not finite(goal):
                raise BehaviorError("goal for %s is not a finite (x, y): %r" % (name, tuple(goal)))

    def start(self, now, poses, static):
        self.goals = np.array([tuple(g) for g in self.req.goals], float).reshape(-1, 2)
        self.first_errors = None
        for k, name in enumerate(self.robots):
            i = self.ctx.index[name]
            static.goal[i] = self.req.goals[k]
            static.goal_mask[i] = True
            static.velocity_mask[i] = False
        return super().start(now, poses, static)

    def tolerance(self):
        """[m]: the request's tolerance, or the setting goal_tolerance."""
        return self.req.tolerance or self.settings.goal_tolerance

    def goal_robots(self):
        """The robots the goals are for (one per goal), in order."""
        return self.robots

    def errors(self, poses):
        out = []
        for name, goal in zip(self.goal_robots(), self.goals):
            pose = poses.get(name)
            out.append(float("nan") if pose is None else math.hypot(pose[0] - goal[0], pose[1] - goal[1]))
        return out

    def status(self, now, poses, newly, lost, elapsed):
        errors, tol = self.errors(poses), self.tolerance()
        if errors and all(e <= tol for e in errors):
            return Progress(SUCCEEDED, "all %d robot(s) within %.1f mm of their goals after %.2f s"
                            % (len(errors), 1e3 * tol, elapsed), errors)
        return Progress(errors=errors)

    def completion(self, errors, elapsed):
        tol = self.tolerance()
        if self.first_errors is None and errors and all(e == e for e in errors):
            self.first_errors = list(errors)             # the distances when it started
        first = self.first_errors
        if first is None or len(errors) != len(first) or not all(e == e for e in errors):
            return float("nan")              # unknown (no poses, or a failure's Progress without distances)
        done = [1.0 if e <= tol or e0 <= tol else min(1.0, max(0.0, (e0 - e) / (e0 - tol)))
                for e, e0 in zip(errors, first)]
        return sum(done) / len(done)

    def timed_out(self, now, poses, errors, elapsed):
        tol = self.tolerance()
        far = [n for n, e in zip(self.goal_robots(), errors) if not e <= tol]
        return Progress(FAILED, "timeout after %.2f s; not at goal: %s" % (elapsed, ", ".join(far)), errors)

    def display(self, request_id, state):
        view = super().display(request_id, state)
        view.goals = [(n, tuple(g)) for n, g in zip(self.goal_robots(), self.req.goals)]
        return view
