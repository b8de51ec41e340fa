"""The sim node's health on /diagnostics, without ROS: real-time factor, step overruns, lockstep waits.

The node feeds a ``SimHealth`` every physics step (``on_step``: simulated
time, wall time the step took, how far the paced loop is behind) and every
lockstep handshake (``on_handshake``: whether the controller's message came,
how long it waited); every ``diagnostics_period`` [s, wall] (``due``) it
publishes ``status()``, computed over the period since the last one:

- real-time factor achieved: simulated seconds per wall second;
- step overruns (paced, ``real_time_factor`` > 0): times the loop fell more
  than OVERRUN_TOLERANCE behind its wall-clock pace, and the largest lag;
- physics step wall time (mean, max, ms);
- lockstep (``sync_topic`` set): handshakes, time spent waiting for the
  controller (share of the period), waits that timed out (the simulation ran
  on without the controller's step).

Level: WARN on an overrun, a lockstep timeout, or (paced) an achieved factor
below UNDERRUN_RATIO of the requested one; ERROR when simulated time did not
advance over a whole period although nothing was waited for; else OK.
"""

from puzzlebot_common.diagnostics import ERROR, OK, WARN, Status, fmt
from puzzlebot_sim.wall_clock import WallClock

#: s (wall): a paced loop this far behind its pace counts as one overrun (until it catches up)
OVERRUN_TOLERANCE = 0.01
#: paced runs: an achieved real-time factor below this fraction of the requested one is a warning
UNDERRUN_RATIO = 0.9
NAME = "puzzlebot_sim: simulation"


class SimHealth:
    """Health over the last diagnostics period. ``sim``: SimParams (real_time_factor,
    sync_topic, diagnostics_period); ``clock``: wall time (default WallClock)."""

    def __init__(self, sim, clock=None, name=NAME):
        self.sim = sim
        self.name = name
        self._clock = clock if clock is not None else WallClock()
        self.total_overruns = 0
        self.total_sync_timeouts = 0
        self._behind = False
        self._reset(self._clock.now(), None)

    def _reset(self, wall, sim_time):
        self._wall0, self._sim0 = wall, sim_time
        self._sim_last = sim_time
        self._steps, self._step_wall, self._step_max = 0, 0.0, 0.0
        self._overruns, self._max_lag = 0, 0.0
        self._handshakes, self._waited, self._sync_timeouts = 0, 0.0, 0

    def on_step(self, sim_time, step_wall, lag):
        """A physics step ended at ``sim_time`` [s]; it took ``step_wall`` [s, wall]; the paced loop is
        ``lag`` [s, wall] behind its pace (stepper.Stepper.pace)."""
        if self._sim0 is None:                  # the first step: the period started one step before
            self._sim0 = sim_time - 1.0 / self.sim.physics_rate
        self._sim_last = sim_time
        self._steps += 1
        self._step_wall += step_wall
        self._step_max = max(self._step_max, step_wall)
        behind = lag > OVERRUN_TOLERANCE
        if behind and not self._behind:
            self._overruns += 1
            self.total_overruns += 1
        self._behind = behind
        self._max_lag = max(self._max_lag, lag)

    def on_handshake(self, ok, waited):
        """A lockstep handshake: the controller's message came (``ok``) after ``waited`` [s, wall]."""
        self._handshakes += 1
        self._waited += waited
        if not ok:
            self._sync_timeouts += 1
            self.total_sync_timeouts += 1

    def due(self):
        """True when a diagnostics period [wall] has passed since the last status."""
        return self._clock.now() - self._wall0 >= self.sim.diagnostics_period

    def status(self):
        """The Status of the period since the last call; starts a new period."""
        now = self._clock.now()
        wall = max(now - self._wall0, 1e-9)
        sim_dt = (self._sim_last - self._sim0) if self._sim0 is not None else 0.0
        rtf = sim_dt / wall
        requested = self.sim.real_time_factor
        lockstep = bool(self.sim.sync_topic)
        problems, level = [], OK
        if self._overruns:
            problems.append("%d step overrun(s), up to %.0f ms behind" % (self._overruns, 1e3 * self._max_lag))
            level = WARN
        if self._sync_timeouts:
            problems.append("%d lockstep wait(s) timed out: ran on without the controller" % self._sync_timeouts)
            level = WARN
        if requested > 0 and rtf < UNDERRUN_RATIO * requested:
            problems.append("real-time factor %.2f of %.2f requested" % (rtf, requested))
            level = WARN
        if sim_dt <= 0 and self._waited < 0.5 * wall:
            problems.append("simulated time did not advance")
            level = ERROR
        if problems:
            message = "; ".join(problems)
        elif lockstep:
            message = "lockstep with the controller, real-time factor %.2f" % rtf
        else:
            message = "running, real-time factor %.2f%s" % (rtf, " (paced at %.2f)" % requested if requested else "")
        values = [
            ("real-time factor", "%.3f" % rtf),
            ("requested real-time factor", "%.2f (0 = as fast as possible)" % requested),
            ("simulated time [s]", fmt(self._sim_last, "%.2f")),
            ("period [s, wall]", "%.2f" % wall),
            ("physics steps", str(self._steps)),
            ("physics step mean [ms]", fmt(1e3 * self._step_wall / self._steps if self._steps else None, "%.3f")),
            ("physics step max [ms]", fmt(1e3 * self._step_max if self._steps else None, "%.3f")),
            ("step overruns", str(self._overruns)),
            ("step overruns (total)", str(self.total_overruns)),
            ("largest lag [ms]", "%.1f" % (1e3 * self._max_lag)),
            ("lockstep", "on (%s)" % self.sim.sync_topic if lockstep else "off"),
            ("lockstep handshakes", str(self._handshakes)),
            ("waiting for the controller [share]", "%.3f" % (self._waited / wall)),
            ("lockstep timeouts", str(self._sync_timeouts)),
            ("lockstep timeouts (total)", str(self.total_sync_timeouts)),
        ]
        self._reset(now, self._sim_last)
        return Status(self.name, level, message, "bullet", values)
