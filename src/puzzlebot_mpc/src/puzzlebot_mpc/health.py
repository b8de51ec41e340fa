"""The MPC node's health on /diagnostics, without ROS: solve time, failures, fallbacks, late steps.

The node feeds an ``MpcHealth`` every control step (``on_step``: the step's
MPCResult, its wall time, whether it ended after the next step was due, the
robots commanded zero for a stale or rejected pose, the behaviour status);
every ``period`` [s, wall] (``due``) it publishes ``status()``, computed over
the steps since the last one:

- solve time (median, 95th percentile, max, ms) and control step time;
- failed solves (every robot commanded zero: fallback ``stop``), late
  steps (ended after the next was due: commanded zero), in the period and
  since the start;
- the robots held (pose gate) or stale (no fresh pose) at the last step;
- the running behaviour (request id, name, state).

Level: ERROR when every step of the period failed; WARN on a failure, a
fallback, a late step, or a robot held or stale; else OK.
"""

import time

import numpy as np

from puzzlebot_common.diagnostics import ERROR, OK, WARN, Status, fmt
from puzzlebot_mpc.behaviors import STATE_NAMES

NAME = "puzzlebot_mpc: controller"


class MpcHealth:
    """Health over the last period [s, wall] (``clock``: wall time, default time.monotonic)."""

    def __init__(self, solver, robots, period=1.0, clock=time.monotonic, name=NAME):
        self.solver, self.robots, self.period, self.name = solver, robots, period, name
        self._clock = clock
        self.total_steps = self.total_failures = self.total_fallbacks = self.total_late = 0
        self._last = None
        self._reset(clock())

    def _reset(self, wall):
        self._wall0 = wall
        self._solve, self._step = [], []
        self._failures = self._fallbacks = self._late = 0

    def on_step(self, result, step_ms, late, stale=(), held=(), status=None):
        """A control step: ``result`` (controller.MPCResult), ``step_ms`` [ms, wall], ``late`` (it ended
        after the next step was due), ``stale`` / ``held``: robots commanded zero for an old or a
        rejected pose, ``status``: behaviors.BehaviorStatus."""
        self._solve.append(result.solve_time_ms)
        self._step.append(step_ms)
        failed = not result.success
        self._failures += failed
        self._fallbacks += bool(result.fallback)
        self._late += bool(late)
        self.total_steps += 1
        self.total_failures += failed
        self.total_fallbacks += bool(result.fallback)
        self.total_late += bool(late)
        self._last = (result, list(stale), list(held), status)

    def due(self):
        return self._clock() - self._wall0 >= self.period

    def status(self):
        """The Status of the steps since the last call; starts a new period."""
        now = self._clock()
        n = len(self._solve)
        solve = np.array(self._solve) if n else np.array([np.nan])
        step = np.array(self._step) if n else np.array([np.nan])
        result, stale, held, behaviour = self._last if self._last else (None, [], [], None)
        problems, level = [], OK
        if n and self._failures == n:
            problems.append("every solve failed (%d of %d steps): robots stopped" % (self._failures, n))
            level = ERROR
        elif self._failures:
            problems.append("%d of %d solves failed (robots stopped those steps)" % (self._failures, n))
            level = WARN
        if self._fallbacks and self._fallbacks != self._failures:
            problems.append("%d fallback(s)" % self._fallbacks)
            level = max(level, WARN)
        if self._late:
            problems.append("%d late step(s) (commanded zero)" % self._late)
            level = max(level, WARN)
        if held or stale:
            problems.append("commanded zero: %s" % ", ".join(["%s (pose rejected)" % r for r in held] +
                                                            ["%s (no fresh pose)" % r for r in stale]))
            level = max(level, WARN)
        if not n:
            message = "no control step in %.1f s" % (now - self._wall0)
            level = max(level, WARN)
        elif problems:
            message = "; ".join(problems)
        else:
            message = "%d steps, solve %.1f ms median" % (n, float(np.median(solve)))
        values = [
            ("solver", self.solver),
            ("robots", str(self.robots)),
            ("steps", str(n)),
            ("solve time median [ms]", fmt(float(np.median(solve)), "%.2f")),
            ("solve time p95 [ms]", fmt(float(np.percentile(solve, 95)), "%.2f")),
            ("solve time max [ms]", fmt(float(np.max(solve)), "%.2f")),
            ("step time median [ms]", fmt(float(np.median(step)), "%.2f")),
            ("step time max [ms]", fmt(float(np.max(step)), "%.2f")),
            ("failed solves", str(self._failures)),
            ("failed solves (total)", str(self.total_failures)),
            ("fallbacks", str(self._fallbacks)),
            ("fallbacks (total)", str(self.total_fallbacks)),
            ("late steps", str(self._late)),
            ("late steps (total)", str(self.total_late)),
            ("steps (total)", str(self.total_steps)),
            ("last solver status", result.status if result is not None else ""),
            ("robots held (pose rejected)", ", ".join(held)),
            ("robots stale (no fresh pose)", ", ".join(stale)),
        ]
        if behaviour is not None:
            values += [("behaviour", "%s (request %d): %s" % (behaviour.behavior or "none", behaviour.request_id,
                                                             STATE_NAMES.get(behaviour.state, "?"))),
                       ("behaviour message", behaviour.message)]
        self._reset(now)
        return Status(self.name, level, message, self.solver, values)
