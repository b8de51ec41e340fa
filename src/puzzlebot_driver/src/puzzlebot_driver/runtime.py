"""The driver at run time, without ROS: core + TCP server + fixed-rate loop.

:class:`DriverRuntime` is what the driver node runs; the node only converts
messages and publishes. Inputs may come from any thread (ROS callbacks);
the loop runs in the caller's thread on a fixed grid of monotonic time and
skips ahead (without bursts) when it falls far behind. ``clock()`` is the
time base of the pose stamps and command arrival times (ROS time in the
node, wall time in the lab).
"""

import threading
import time

from puzzlebot_common.throttle import Throttle
from puzzlebot_driver import safety
from puzzlebot_driver.diagnostics import loop_status, robot_status
from puzzlebot_driver.driver import DriverCore, LoopStats
from puzzlebot_driver.link import PwmServer


class DriverRuntime:
    def __init__(self, robots, config, clock=time.time, log=None):
        """``robots``: parsed robot list; ``config``: params.DriverConfig;
        ``log(level, text)``, level in "info", "warn", "error"."""
        p = self.params = config.params
        self.clock = clock
        self.log = log or (lambda level, text: None)
        self.core = DriverCore(robots, config)
        self.server = PwmServer({r.ip_octet: r.name for r in robots}, p.bind_address, p.port, p,
                                log=lambda level, text: self.log(level, "link: " + text))
        self.stats = LoopStats(p.period, window=max(30, int(round(10 * p.loop_rate))))
        self.lock = threading.Lock()      # the core is shared by the loop, callbacks and services
        self.stopping = False
        self.late_ticks = 0
        self._late_logged = -1e9
        self._old_logged = {}
        self.throttle = Throttle(config.pose_gate.log_period)   # per robot and kind: rejections, loop faults

    def start(self):
        """Listen for robots (raises link.LinkError if the port cannot be used)."""
        self.server.start()
        return self

    # ------------------------------------------------------------------ inputs
    def on_pose(self, name, stamp, x, y, heading, z=0.0):
        """A mocap pose (stamp = measurement time; ``heading``: yaw [rad] or quaternion (x, y, z, w)).

        Returns the pose gate's Verdict. Rejections are logged, at most one
        line per robot, kind and ``pose_gate.log_period``; re-acquisitions
        and the end of a hold at info level.
        """
        now = self.clock()
        with self.lock:
            verdict = self.core.on_pose(name, stamp, x, y, heading, now, z=z)
        if not verdict.accepted:
            line = self.throttle(("pose", name, verdict.kind), "rejected pose (%s): %s" % (verdict.kind, verdict.reason))
            if line:
                self.log("warn", line)
            return verdict
        if verdict.reacquired:
            self.log("warn", "pose %s" % verdict.reason)
        elif verdict.resumed:
            line = self.throttle(("resumed", name), "pose of %s plausible again for %d frames in a row"
                                 % (name, self.core.robots[name].gate.params.reacquire_frames))
            if line:
                self.log("info", line)
        age = now - stamp
        if age > self.params.pose_timeout and now - self._old_logged.get(name, -1e9) > 5.0:
            self._old_logged[name] = now
            self.log("warn", "pose of %s is %.3f s old on arrival (pose_timeout %.3f s): it is stale before it "
                             "is used; is the mocap clock synchronised with this machine?"
                     % (name, age, self.params.pose_timeout))
        return verdict

    def on_cmd(self, name, v, w):
        with self.lock:
            return self.core.on_cmd(name, self.clock(), v, w)

    def set_estop(self, engaged, reason=""):
        """Engage (PWM 0 to every robot at once, latched) or release; True if the state changed."""
        with self.lock:
            changed = self.core.set_estop(engaged, reason)
            if engaged and not self.stopping:
                for name in self.core.order:
                    self.server.send(name, 0, 0)
        return changed

    # -------------------------------------------------------------------- loop
    def tick(self, dt):
        """One loop step: decide and send. Returns (now, decisions, sent) or None once stopping."""
        now = self.clock()
        with self.lock:
            if self.stopping:
                return None
            decisions = self.core.tick(now, dt, set(self.server.connected_names()))
            sent = {name: self.server.send(name, d.left, d.right) for name, d in decisions.items()}
        for name, d in decisions.items():
            if d.detail:
                line = self.throttle(("loop", name, d.reason), "%s: PWM 0 (%s): %s" % (name, d.reason, d.detail))
                if line:
                    self.log("error" if d.reason == safety.INTERNAL_ERROR else "warn", line)
        return now, decisions, sent

    def run(self, should_stop, on_tick=None, on_diagnostics=None):
        """Loop until ``should_stop()``; ``on_tick(now, decisions, sent)`` after every tick and
        ``on_diagnostics(statuses)`` at the diagnostics rate (both in this thread)."""
        period = self.params.period
        diag_every = max(1, int(round(self.params.loop_rate / self.params.diagnostics_rate)))
        t_next = time.monotonic()
        last, k = None, 0
        while not should_stop():
            delay = t_next - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            if should_stop():
                break
            start = time.monotonic()
            out = self.tick(period if last is None else start - last)
            if out is None:
                break
            last = start
            if on_tick is not None:
                on_tick(*out)
            if on_diagnostics is not None and k % diag_every == 0:
                on_diagnostics(self.diagnostics())
            self.stats.record(start, time.monotonic() - start)
            k += 1
            t_next += period
            behind = time.monotonic() - t_next
            if behind > period:                   # far behind: skip the missed ticks, do not burst
                skipped = int(behind / period)
                t_next += skipped * period
                self.late_ticks += skipped
                if time.monotonic() - self._late_logged > 5.0:
                    self._late_logged = time.monotonic()
                    self.log("warn", "driver loop %d period(s) late (machine busy?); %d ticks skipped so far"
                             % (skipped, self.late_ticks))

    def diagnostics(self):
        """Per-robot and loop statuses (diagnostics.Status)."""
        now = self.clock()
        summary = self.stats.summary()
        with self.lock:
            out = [robot_status(self.core.robots[n], self.server.link_info(n), self.core.estimate(n), now,
                                self.params, summary["rate_hz"]) for n in self.core.order]
            out.append(loop_status(summary, self.params, self.core.estop, self.core.estop_reason,
                                   self.server.rejected_connections))
        return out

    def shutdown(self):
        """Zero every connected robot and close the server (idempotent)."""
        with self.lock:
            if self.stopping:
                return []
            self.stopping = True
            self.core.set_estop(True, "shutdown")
            connected = self.server.connected_names()
        self.server.stop(zero=True)
        return connected
