"""The sim node's diagnostics (puzzlebot_sim.health.SimHealth) on a fake wall clock."""

from dataclasses import replace

import pytest

from puzzlebot_common.diagnostics import ERROR, OK, WARN
from puzzlebot_sim.health import OVERRUN_TOLERANCE, SimHealth
from puzzlebot_sim.params import SimParams


class Clock:
    def __init__(self):
        self.t = 0.0

    def now(self):
        return self.t


def values(status):
    return dict(status.values)


def run(health, clock, seconds, rtf, lag=0.0, dt=0.005):
    """Physics steps of dt for ``seconds`` of wall time at a real-time factor ``rtf``."""
    sim_time = health._sim_last or 0.0
    for _ in range(int(round(seconds / dt * rtf))):
        clock.t += dt / rtf
        sim_time += dt
        health.on_step(sim_time, 0.001, lag)


def test_lockstep_reports_the_achieved_real_time_factor():
    clock = Clock()
    health = SimHealth(SimParams(sync_topic="/stats"), clock)
    run(health, clock, 1.0, 2.5)
    health.on_handshake(True, 0.1)
    assert health.due()
    s = health.status()
    assert s.level == OK and "lockstep" in s.message
    assert float(values(s)["real-time factor"]) == pytest.approx(2.5, rel=1e-3)
    assert values(s)["lockstep handshakes"] == "1" and not health.due()


def test_overruns_counted_once_per_fall_behind_and_warned():
    clock = Clock()
    health = SimHealth(SimParams(real_time_factor=1.0), clock)
    run(health, clock, 0.5, 1.0)
    run(health, clock, 0.1, 1.0, lag=3 * OVERRUN_TOLERANCE)      # behind for 20 steps: one overrun
    run(health, clock, 0.4, 1.0)
    s = health.status()
    assert s.level == WARN and "1 step overrun" in s.message
    assert values(s)["largest lag [ms]"] == "30.0"
    run(health, clock, 1.0, 1.0)
    assert health.status().level == OK and health.total_overruns == 1


def test_slow_paced_run_timeouts_and_a_stalled_clock():
    clock = Clock()
    health = SimHealth(SimParams(real_time_factor=1.0, sync_topic="/stats"), clock)
    run(health, clock, 1.0, 0.5)
    health.on_handshake(False, 0.0)
    s = health.status()
    assert s.level == WARN and "real-time factor 0.50 of 1.00" in s.message and "timed out" in s.message
    clock.t += 1.0                                   # no step, no wait: simulated time stood still
    assert health.status().level == ERROR
    health = SimHealth(replace(SimParams(), sync_topic="/stats"), clock)
    clock.t += 1.0
    health.on_handshake(True, 0.9)                   # waiting for the controller is not a stall
    assert health.status().level == OK
