"""FaultPlan: which fault replaces a robot's frames when (the rostests' schedule of every fault)."""

import pytest

from puzzlebot_common.mocap_faults import FAULTS, SILENCE, FaultPlan, clean


def test_a_window_replaces_the_frames_inside_it_only():
    plan = FaultPlan()
    plan.add("pz1", 1.0, 1.1, "jump 1 m")
    plan.add("pz1", 2.0, 2.5, SILENCE)
    assert plan.frame("pz1", 0.99, 0.2, 0.0, 0.3) == clean(0.99, 0.2, 0.0, 0.3)
    assert plan.frame("pz1", 1.0, 0.2, 0.0, 0.3) == FAULTS["jump 1 m"][0](1.0, 0.2, 0.0, 0.3)
    assert plan.frame("pz1", 1.0, 0.2, 0.0, 0.3).x == pytest.approx(1.2)
    assert plan.fault("pz1", 1.1) is None                  # [t0, t1)
    assert plan.frame("pz1", 2.2, 0.2, 0.0, 0.3) is None
    assert plan.fault("pz2", 1.05) is None                 # another robot: clean


def test_an_unknown_fault_is_refused():
    with pytest.raises(ValueError, match="unknown fault 'jump 2 m'"):
        FaultPlan().add("pz1", 0.0, 1.0, "jump 2 m")


def test_every_fault_once_per_burst_spread_over_the_robots():
    plan, rate, spacing = FaultPlan(), 100.0, 0.6
    robots = ("a", "b", "c", "d")
    schedule = plan.every_fault(robots, 10.003, spacing, rate)
    assert sorted((f, b) for _, f, b, _ in schedule) == sorted((f, b) for f in FAULTS for b in (1, 10))
    for i, (robot, fault, burst, t) in enumerate(schedule):
        assert robot == robots[i % 4]
        assert t == pytest.approx(10.005 + spacing * (i // 4))              # half a period off the grid
        assert plan.fault(robot, t) == fault and plan.fault(robot, t + (burst - 0.5) / rate) == fault
        assert plan.fault(robot, t + burst / rate) is None
    for robot in robots:                                   # a robot's faults one after the other, apart
        starts = [t for r, _, _, t in schedule if r == robot]
        assert len(starts) == len(schedule) // 4
        assert all(b - a == pytest.approx(spacing) for a, b in zip(starts, starts[1:]))
