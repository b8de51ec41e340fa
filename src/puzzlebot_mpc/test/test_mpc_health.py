"""The MPC node's diagnostics (puzzlebot_mpc.health.MpcHealth) from step results; no roscore."""

import numpy as np

from puzzlebot_common.diagnostics import ERROR, OK, WARN
from puzzlebot_mpc.behaviors import RUNNING, BehaviorStatus
from puzzlebot_mpc.controller import MPCResult
from puzzlebot_mpc.health import MpcHealth


class Clock:
    t = 0.0

    def __call__(self):
        return self.t


def result(ms, ok=True):
    return MPCResult(np.zeros((2, 2)), np.zeros((2, 11, 5)), ok, "solved" if ok else "max iterations", ms, 3, 1.0,
                     fallback="" if ok else "stop")


def test_solve_times_and_a_healthy_period():
    clock = Clock()
    health = MpcHealth("clarabel", 2, 1.0, clock)
    for k in range(10):
        clock.t += 0.11
        health.on_step(result(5.0 + k), 8.0, False, status=BehaviorStatus(3, "couple", RUNNING, "1 of 2 coupled"))
    assert health.due()
    s = health.status()
    values = dict(s.values)
    assert s.level == OK and values["solve time median [ms]"] == "9.50" and values["solve time max [ms]"] == "14.00"
    assert values["behaviour"] == "couple (request 3): running" and values["failed solves"] == "0"


def test_failures_late_steps_and_held_robots_are_reported():
    clock = Clock()
    health = MpcHealth("clarabel", 2, 1.0, clock)
    health.on_step(result(5.0), 6.0, False)
    health.on_step(result(80.0, ok=False), 90.0, True, held=["pz2"])
    s = health.status()
    assert s.level == WARN and "1 of 2 solves failed" in s.message and "1 late step" in s.message
    assert "pz2 (pose rejected)" in s.message
    health.on_step(result(80.0, ok=False), 90.0, False)
    s = health.status()
    assert s.level == ERROR and dict(s.values)["failed solves (total)"] == "2"
    clock.t += 2.0
    assert health.status().level == WARN                      # no step at all in the period
