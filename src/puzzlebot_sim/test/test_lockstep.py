"""The sim node's command link and lockstep handshake (puzzlebot_sim.lockstep) and its loop timing
(puzzlebot_sim.stepper), on a fake wall clock: no roscore, no threads, no sleeping."""

import heapq
import math
from dataclasses import replace

import pytest

from puzzlebot_sim.lockstep import RESEND_PERIOD, Lockstep
from puzzlebot_sim.params import SimParams
from puzzlebot_sim.stepper import Stepper

SIM = SimParams(sync_topic="/mpc/stats", cmd_timeout=0.5, sync_timeout=10.0, sync_startup_timeout=60.0,
                sync_cmd_timeout=1.0)


class FakeClock:
    """Wall time that moves only in ``wait`` and ``sleep``; ``at(t, f)`` calls f when wall time reaches t
    during a wait (a message arriving from another thread)."""

    def __init__(self):
        self.t = 0.0
        self._events = []      # heap of (wall time, order, callback)
        self.slept = []

    def at(self, t, callback):
        heapq.heappush(self._events, (t, len(self._events), callback))

    def now(self):
        return self.t

    def sleep(self, seconds):
        self.slept.append(seconds)
        self.t += seconds

    def wait(self, condition, predicate, timeout):
        end = self.t + timeout
        while not predicate():
            if not self._events or self._events[0][0] > end:
                self.t = end
                return predicate()
            t, _, callback = heapq.heappop(self._events)
            self.t = max(self.t, t)
            callback()
        return True


class Rig:
    """A Lockstep over robots a, b, c with a fake clock, a settable sim time and recorded outputs."""

    def __init__(self, sim=SIM, names=("a", "b", "c")):
        self.clock = FakeClock()
        self.sim_time = 0.0
        self.resends = []            # wall times of the resend calls
        self.warnings = []
        self.commands = []           # (name, v, w) passed on to the world
        self.lockstep = Lockstep(list(names), sim, lambda: self.sim_time, resend=self.on_resend,
                                 clock=self.clock, warn=self.warnings.append)

    def on_resend(self):
        self.resends.append(self.clock.t)

    def apply(self):
        self.lockstep.apply_commands(self.sim_time, lambda *c: self.commands.append(c))


def test_sync_on_time_does_not_wait_or_resend():
    rig = Rig()
    rig.lockstep.on_sync(0.0)
    assert rig.lockstep.handshake(0.0)
    assert rig.clock.t == 0.0 and rig.resends == [] and rig.warnings == []


def test_late_sync_resends_the_step_every_resend_period_until_it_arrives():
    rig = Rig()
    rig.clock.at(1.2, lambda: rig.lockstep.on_sync(0.0))
    assert rig.lockstep.handshake(0.0)
    assert rig.clock.t == pytest.approx(1.2)
    assert rig.resends == pytest.approx([RESEND_PERIOD, 2 * RESEND_PERIOD])
    assert rig.warnings == []


def test_stale_sync_does_not_count_and_a_missing_one_times_out():
    rig = Rig()
    rig.lockstep.on_sync(0.0)
    assert rig.lockstep.handshake(0.0)                   # first handshake: start-up timeout
    rig.lockstep.on_sync(0.05)                           # stamped before the step at 0.1 s
    assert not rig.lockstep.handshake(0.1)
    assert rig.clock.t == pytest.approx(SIM.sync_timeout)
    assert len(rig.resends) == 19                        # at 0.5, 1.0, ... 9.5 s: none at the timeout itself
    assert rig.warnings == ["no message on /mpc/stats for t = 0.10 s within 10.0 s: running on"]


def test_the_first_handshake_waits_the_startup_timeout():
    rig = Rig()
    assert not rig.lockstep.handshake(0.0)
    assert rig.clock.t == pytest.approx(SIM.sync_startup_timeout)
    rig.clock.t = 0.0
    assert not rig.lockstep.handshake(0.1)
    assert rig.clock.t == pytest.approx(SIM.sync_timeout)


def test_shutdown_ends_the_waits():
    rig = Rig()
    rig.lockstep = Lockstep(["a"], SIM, lambda: 0.0, clock=rig.clock, is_shutdown=lambda: True)
    assert rig.lockstep.handshake(0.0) and rig.clock.t == 0.0


def test_waits_for_the_commands_of_the_robots_commanded_the_step_before():
    rig = Rig()
    ls = rig.lockstep
    rig.clock.at(0.1, lambda: ls.on_cmd("a", 0.01, 0.0))
    rig.clock.at(0.2, lambda: ls.on_cmd("b", 0.02, 0.0))
    rig.clock.at(0.3, lambda: ls.on_sync(0.0))
    assert ls.handshake(0.0)
    assert ls.commanded == {"a", "b"} and rig.clock.t == pytest.approx(0.3)   # nothing expected yet
    rig.sim_time = 0.1                                   # the next control step: a and b are waited for
    rig.clock.at(0.4, lambda: ls.on_sync(0.1))
    rig.clock.at(0.6, lambda: ls.on_cmd("a", 0.03, 0.0))
    rig.clock.at(0.7, lambda: ls.on_cmd("b", 0.04, 0.0))
    rig.clock.at(0.8, lambda: ls.on_cmd("c", 0.05, 0.0))   # c was not commanded before: not waited for
    assert ls.handshake(0.1)
    assert rig.clock.t == pytest.approx(0.7) and ls.commanded == {"a", "b"}
    assert rig.warnings == []


def test_a_missing_command_is_waited_for_once_then_dropped_from_the_expected():
    rig = Rig()
    ls = rig.lockstep
    ls.on_cmd("a", 0.01, 0.0)
    ls.on_cmd("b", 0.01, 0.0)
    ls.on_sync(0.0)
    assert ls.handshake(0.0) and ls.commanded == {"a", "b"}
    rig.sim_time = 0.1
    ls.on_sync(0.1)
    ls.on_cmd("a", 0.02, 0.0)                            # b's command of this step never comes
    assert ls.handshake(0.1)
    assert rig.clock.t == pytest.approx(SIM.sync_cmd_timeout) and ls.commanded == {"a"}
    assert rig.warnings == ["no cmd_vel for b at t = 0.10 s within 1.0 s: running on"]
    rig.sim_time = 0.2
    ls.on_sync(0.2)
    ls.on_cmd("a", 0.03, 0.0)
    t0 = rig.clock.t
    assert ls.handshake(0.2) and rig.clock.t == t0      # b is no longer waited for


def test_commands_pass_on_once_each_and_time_out_to_zero():
    rig = Rig()
    ls = rig.lockstep
    rig.apply()
    assert rig.commands == [(n, 0.0, 0.0) for n in "abc"]   # the first step: every robot stands
    del rig.commands[:]
    ls.on_cmd("a", 0.05, 0.5)
    rig.apply()
    rig.sim_time = 0.3
    rig.apply()                                          # the same command: not passed on again
    assert rig.commands == [("a", 0.05, 0.5)]
    rig.sim_time = 0.5
    rig.apply()                                          # exactly cmd_timeout old: still in force
    assert rig.commands == [("a", 0.05, 0.5)]
    rig.sim_time = 0.505
    rig.apply()                                          # older: the robot stops
    assert rig.commands == [("a", 0.05, 0.5), ("a", 0.0, 0.0)]
    ls.on_cmd("b", -0.02, 0.0)
    rig.apply()
    assert rig.commands[-1] == ("b", -0.02, 0.0)


def test_non_finite_commands_are_ignored_with_a_throttled_warning():
    rig = Rig()
    ls = rig.lockstep
    ls.on_cmd("a", 0.05, 0.0)
    for bad in ((math.nan, 0.0), (0.0, math.inf), (-math.inf, math.nan)):
        ls.on_cmd("a", *bad)
    rig.apply()
    assert rig.commands[0] == ("a", 0.05, 0.0)
    assert rig.warnings == ["ignoring non-finite cmd_vel for a: (nan, 0.0)"]   # one per 2 s (wall)
    rig.clock.t = 2.0
    ls.on_cmd("b", math.nan, 0.0)
    assert len(rig.warnings) == 2
    with pytest.raises(KeyError, match="unknown robot 'z'"):
        ls.on_cmd("z", 0.0, 0.0)


def test_stepper_schedule_follows_the_rates():
    sim = replace(SIM, physics_rate=200, pose_rate=100, pairs_rate=10, sync_period=0.1)
    stepper = Stepper(sim, FakeClock())
    due = [(s, stepper.poses_due(s), stepper.pairs_due(s), stepper.sync_due(s)) for s in range(41)]
    assert [s for s, poses, _, _ in due if poses] == list(range(0, 41, 2))
    assert [s for s, _, pairs, _ in due if pairs] == [0, 20, 40]
    assert [s for s, _, _, sync in due if sync] == [0, 20, 40]
    assert not any(Stepper(replace(sim, sync_topic=""), FakeClock()).sync_due(s) for s in range(41))


def test_stepper_paces_to_the_real_time_factor():
    clock = FakeClock()
    clock.t = 100.0
    stepper = Stepper(replace(SIM, real_time_factor=0.5), clock)    # half speed: 1 s simulated in 2 s wall
    stepper.pace(1.0)
    assert clock.t == pytest.approx(102.0)
    clock.t += 3.0                                       # fell behind: no sleep until caught up
    stepper.pace(2.0)
    assert clock.slept == pytest.approx([2.0])
    fast = FakeClock()
    Stepper(replace(SIM, real_time_factor=0.0), fast).pace(5.0)
    assert fast.slept == []                              # 0: as fast as possible
