"""The sim node's command link: every robot's latest command, and the lockstep handshake.

ROS-free. The sim node feeds a ``Lockstep`` what its subscribers receive
(``on_cmd``: a robot's cmd_vel, ``on_sync``: the stamp of a controller's
sync message; from any thread), calls ``handshake`` at every sync instant
(with sync_topic set) and ``apply_commands`` before every physics step.
Wall time and waiting come from an injected clock (wall_clock.WallClock, a
fake in the unit tests), the resending of a step's messages from an
injected callback, the simulated time from ``sim_time``.

Commands: a robot drives on its latest finite command (non-finite ones are
ignored with a warning) until it is older than ``cmd_timeout`` [s, sim
time]; then it stops (0, 0).

Lockstep: at every multiple of sync_period, ``handshake`` waits (wall time,
up to sync_timeout; sync_startup_timeout the first time) for a sync message
stamped at or after the current time, then (up to sync_cmd_timeout) for the
command of that control step from every robot the controller commanded the
step before, so the controller never falls behind the simulation however
fast it runs and every command acts from the instant it was computed for.
While it waits for the sync message it calls ``resend`` every RESEND_PERIOD
[s, wall]: the node publishes that step's clock and vicon messages again,
unchanged, and a controller whose subscriptions came up after they went out
(start-up) gets them all the same, so a run does not depend on the graph's
start-up timing. A wait that runs out is warned about and the simulation
runs on.
"""

import logging
import math
import threading

from puzzlebot_sim.wall_clock import WallClock

#: s (wall): while waiting for the controller, this step's clock and poses go out again this often
RESEND_PERIOD = 0.5
#: s: a sync message stamped this little before the step's time still counts as that step's
SYNC_STAMP_TOLERANCE = 1e-6
#: s (sim time): a command received this little before the step's time counts as that step's
CMD_STAMP_TOLERANCE = 1e-9
#: s (wall): one warning per kind in this period, at most (non-finite commands, missed waits)
NONFINITE_WARN_PERIOD = 2.0
TIMEOUT_WARN_PERIOD = 5.0


class Lockstep:
    """Latest commands of the robots ``names`` and the handshake with a controller.

    ``sim`` (SimParams): cmd_timeout, sync_topic (named in warnings),
    sync_timeout, sync_startup_timeout, sync_cmd_timeout. ``sim_time()``:
    the simulated time now [s]; ``resend()``: publish this step's messages
    again; ``clock``: now / wait (default WallClock); ``warn(text)``: a warning
    (throttled here); ``is_shutdown()``: true ends every wait at once.
    """

    def __init__(self, names, sim, sim_time, resend=lambda: None, clock=None,
                 warn=logging.getLogger(__name__).warning, is_shutdown=lambda: False):
        self.sim = sim
        self._sim_time, self._resend = sim_time, resend
        self._clock = clock if clock is not None else WallClock()
        self._warn_text, self._is_shutdown = warn, is_shutdown
        self._cond = threading.Condition()     # guards _cmd and _sync_stamp (reentrant: a fake clock's wait
        #                                        may deliver messages from inside)
        self._cmd = {n: (0.0, 0.0, -math.inf) for n in names}   # v [m/s], w [rad/s], receive sim time [s]
        self._applied = {n: None for n in names}               # (v, w) last passed on to the world
        self._sync_stamp = -math.inf
        self._first = True
        self.commanded = set()      # robots that had a command of the last control step: waited for next
        self._warned = {}           # warning kind -> wall time of the last one

    # ------------------------------------------------------------ inputs
    def on_cmd(self, name, v, w):
        """A cmd_vel (m/s, rad/s) for robot ``name``, received now; non-finite ones are ignored."""
        if name not in self._cmd:
            raise KeyError("unknown robot %r" % name)
        if not (math.isfinite(v) and math.isfinite(w)):
            self._warn("nonfinite", NONFINITE_WARN_PERIOD,
                       "ignoring non-finite cmd_vel for %s: (%r, %r)" % (name, v, w))
            return
        with self._cond:
            self._cmd[name] = (v, w, self._sim_time())
            self._cond.notify_all()

    def on_sync(self, stamp):
        """A controller's sync message stamped ``stamp`` [s, sim time]."""
        with self._cond:
            self._sync_stamp = max(self._sync_stamp, stamp)
            self._cond.notify_all()

    # --------------------------------------------------------- handshake
    def handshake(self, t):
        """At the sync instant ``t`` [s]: wait for the controller's sync message, then for its commands.

        Returns whether the sync message came (False: timed out, the simulation runs on)."""
        timeout = self.sim.sync_startup_timeout if self._first else self.sim.sync_timeout
        self._first = False
        ok = self.wait_for_sync(t, timeout)
        if ok:
            self.commanded = self.wait_for_commands(t, self.commanded)
        return ok

    def wait_for_sync(self, t, timeout):
        """Wait (wall, up to ``timeout`` s) for a sync message stamped at or after ``t``, resending
        this step's messages every RESEND_PERIOD s meanwhile (see the module docstring)."""
        clock = self._clock
        end = clock.now() + timeout
        ok = False
        while not ok:
            with self._cond:
                ok = clock.wait(self._cond,
                                lambda: self._sync_stamp >= t - SYNC_STAMP_TOLERANCE or self._is_shutdown(),
                                max(0.0, min(RESEND_PERIOD, end - clock.now())))
            if ok or clock.now() >= end:
                break
            self._resend()
        if not ok:
            self._warn("sync", TIMEOUT_WARN_PERIOD, "no message on %s for t = %.2f s within %.1f s: running on"
                       % (self.sim.sync_topic, t, timeout))
        return ok

    def wait_for_commands(self, t, expected):
        """Wait (wall, up to sync_cmd_timeout) until every robot in ``expected`` has a command received at
        sim time ``t``.

        The controller publishes its commands, then its sync message, but on
        separate connections: without this wait some robots would drive one
        more period on the previous command. The world is frozen while
        waiting, so a command of this control step is stamped t on arrival.
        Returns the robots that received a command at t (the next step's
        ``expected``: robots the controller does not command are not waited for).
        """
        timeout = self.sim.sync_cmd_timeout
        with self._cond:
            self._clock.wait(self._cond, lambda: all(self._cmd[n][2] >= t - CMD_STAMP_TOLERANCE for n in expected)
                             or self._is_shutdown(), timeout)
            fresh = {n for n, c in self._cmd.items() if c[2] >= t - CMD_STAMP_TOLERANCE}
        missing = sorted(set(expected) - fresh)
        if missing:
            self._warn("cmd", TIMEOUT_WARN_PERIOD, "no cmd_vel for %s at t = %.2f s within %.1f s: running on"
                       % (", ".join(missing), t, timeout))
        return fresh

    # ------------------------------------------------------------ output
    def apply_commands(self, now, set_command):
        """Pass every robot's command in force at sim time ``now`` [s] to ``set_command(name, v, w)``,
        (0, 0) for one older than cmd_timeout; only changes (each is a new command event for the
        actuator effects)."""
        with self._cond:
            for name, (v, w, t_cmd) in self._cmd.items():
                if now - t_cmd > self.sim.cmd_timeout:
                    v = w = 0.0
                if self._applied[name] != (v, w):
                    self._applied[name] = (v, w)
                    set_command(name, v, w)

    def _warn(self, kind, period, text):
        now = self._clock.now()
        last = self._warned.get(kind)
        if last is None or now - last >= period:
            self._warned[kind] = now
            self._warn_text(text)
