"""The docking manoeuvre's phases (puzzlebot_mpc.docking), on synthetic measurements."""

import math
from dataclasses import replace

import numpy as np
import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_mpc import docking as dk
from puzzlebot_mpc.pairs import ANCHOR, make_pair

S = dk.DockingSettings(pull_test=True)       # the full manoeuvre: push, pull, push home again
DT = 0.1


def run(d, gaps, lateral=0.0, dtheta=0.0, t0=0.0):
    """Feed gaps [m] one per control step; returns the step at which the pair was proven seated (or None)."""
    for k, g in enumerate(gaps):
        if d.update(g, lateral, dtheta, t0 + k * DT):
            return k
    return None


def test_a_seated_pair_is_pushed_home_pulled_within_the_band_and_pushed_home_again():
    d = dk.Docking(S, mover="j", now=0.0)
    push = [0.015, 0.010, 0.005] + [0.001] * 3
    pull = [0.001 + 0.0095 * min(1.0, k / 5) for k in range(1, 11)]       # stretches 9.5 mm, stalls
    repush = [0.004, 0.001, 0.001, 0.001]
    seated_at = run(d, push + pull + repush)
    assert seated_at == len(push + pull + repush) - 1 and d.phase == dk.SEATED
    assert "pull held at 9.5 mm" in d.note


@pytest.mark.parametrize("growth, why", [(0.020, "came out"), (0.0075, "folded")])
def test_a_pull_outside_the_band_backs_off_and_approaches_again(growth, why):
    d = dk.Docking(S, now=0.0)
    gaps = [0.015] + [0.001] * 3 + [0.001 + growth * min(1.0, k / 5) for k in range(1, 11)]
    assert run(d, gaps) is None and d.phase == dk.BACKOFF and why in d.note
    t = len(gaps) * DT
    for k in range(int(S.backoff_time / DT) + 1):
        d.update(0.02, 0.0, 0.0, t + k * DT)
    assert d.phase == dk.APPROACH


def test_a_push_that_does_not_get_home_backs_off_after_the_timeout():
    d = dk.Docking(S, now=0.0)
    n = int(S.push_timeout / DT) + 2
    assert run(d, [0.015] + [0.011] * n) is None
    assert d.phase == dk.BACKOFF and "did not get home" in d.note and d.attempts == 1


def test_the_push_waits_for_a_lined_up_pair():
    d = dk.Docking(S, now=0.0)
    d.update(0.012, 0.004, 0.0, 0.0)                    # 4 mm off the axis: the MPC keeps aligning
    assert d.phase == dk.APPROACH
    d.update(0.012, 0.0, 0.3, 0.1)                      # askew
    assert d.phase == dk.APPROACH
    d.update(0.025, 0.0, 0.0, 0.2)                      # too far
    assert d.phase == dk.APPROACH
    d.update(0.012, 0.001, 0.05, 0.3)
    assert d.phase == dk.PUSH


@pytest.mark.parametrize("mover, sign", [("j", 1.0), ("i", -1.0)])
def test_commands_point_into_the_partner_and_hold_its_heading_at_the_start(mover, sign):
    d = dk.Docking(S, mover=mover, start=dk.PUSH, now=0.0)
    c = d.command(0.2, 0.3)                     # mover heading, partner heading
    assert c.v == pytest.approx(sign * S.push_speed) and c.w == pytest.approx(S.push_heading_gain * 0.1)
    c = d.command(0.2, 0.6)                     # the contact turns the partner: the push keeps its course
    assert c.w == pytest.approx(S.push_heading_gain * 0.1)
    d._to(dk.PULL, 1.0)
    c = d.command(0.2, 0.6)                     # a new phase takes the partner's heading again
    assert c.v == pytest.approx(-sign * S.pull_speed) and c.w == pytest.approx(S.push_heading_gain * 0.4)
    d._to(dk.APPROACH, 2.0)
    assert d.command(0.0, 0.0) is None


def test_seat_measure_reads_gap_lateral_and_heading_off_the_poses():
    g = RobotGeometry()
    pair = make_pair("a", "o", ANCHOR, g)
    pose_o = (0.1, 0.2, 0.3)
    # a in front of o, 2 mm gap, 1 mm to o's left, turned 0.05 rad
    c, s = math.cos(0.3), math.sin(0.3)
    x, y = g.body_side + 0.002, 0.001
    pose_a = (0.1 + c * x - s * y, 0.2 + s * x + c * y, 0.35)
    gap, lat, dth = dk.seat_measure(pair, pose_a, pose_o)
    # C_a is on a's back face: turning a moves it sideways by L/2 sin(0.05)
    assert gap == pytest.approx(0.002 + g.body_side / 2 * (1 - math.cos(0.05)), abs=1e-9)
    assert lat == pytest.approx(0.001 - g.body_side / 2 * math.sin(0.05), abs=1e-9)
    assert dth == pytest.approx(0.05)


def test_the_monitor_wants_a_reseat_only_after_the_pair_looked_open_for_a_while():
    m = dk.SeatMonitor(S)
    assert not m.update(0.001, 0.0, 0.0)
    assert not m.update(0.005, 0.0, 0.1)                 # open, just now
    assert not m.update(0.001, 0.0, 0.2)                 # closed again: forgiven
    times = np.arange(0.3, 0.3 + S.repair_time + 0.05, DT)
    assert [m.update(0.005, 0.0, t) for t in times][-1]       # open for repair_time
    assert not dk.SeatMonitor(S).update(0.001, 0.004, 0.0)    # off its axis alone: not a sign


def test_a_jammed_push_aims_the_next_approach_to_the_side_it_was_pushed():
    d = dk.Docking(S, start=dk.PUSH, now=0.0)
    n = int(S.push_timeout / DT) + 2
    run(d, [0.011] * n, lateral=0.006)               # pushed aside: the partner's C_a 6 mm to the left
    assert d.phase == dk.BACKOFF and d.aim == pytest.approx(-S.aim_step)
    assert not d.ready_to_push(0.012, 0.0, 0.0)       # the approach must now bring C_a across the axis ...
    assert d.ready_to_push(0.012, -S.aim_step, 0.0)   # ... to the aim
    for k in range(5):
        d._to(dk.PUSH, 10.0 + k)
        d.update(0.011, 0.006, 0.0, 10.0 + k + S.push_timeout)
    assert d.aim == pytest.approx(-S.aim_max)         # never further than aim_max


def test_bad_settings_are_clear_errors():
    with pytest.raises(ConfigError, match="dock_push_speed"):
        dk.DockingSettings(push_speed=-1.0).check()
    with pytest.raises(ConfigError, match="must be below"):
        dk.DockingSettings(seat_pull_min=0.02).check()
    with pytest.raises(ConfigError, match="must reach past"):
        dk.DockingSettings(pull_speed=0.005).check()


def test_an_approach_that_comes_no_closer_backs_off_and_one_that_closes_in_does_not():
    off = dk.Docking(dk.DockingSettings(), now=0.0)           # off by default
    assert not any(off.approach_stalled(0.010, 0.014, 1.0, k * DT) for k in range(300))
    s = dk.DockingSettings(stall_time=8.0)
    d = dk.Docking(s, mover="j", now=0.0)
    steps = int(s.stall_time / DT)
    # closing in 1 mm per second: progress, never a stall
    assert not any(d.approach_stalled(0.040 - 0.0001 * k, 0.010, 0.5, k * DT) for k in range(2 * steps))
    # stuck beside the partner (10 mm out, 14 mm aside, 1 rad askew, jittering by 1 mm): a stall after stall_time
    d = dk.Docking(s, mover="j", now=0.0)
    stalled = [d.approach_stalled(0.010 + 0.001 * (k % 2), 0.014, 1.0, k * DT) for k in range(steps + 2)]
    assert stalled.index(True) == steps and d.phase == dk.BACKOFF and "stalled" in d.note
    v, w = d.command(mover_heading=0.0, partner_heading=1.0).v, d.command(0.0, 1.0).w
    assert v < 0 and w > 0                                # backs away from the partner, turning to its heading
    t = (steps + 2) * DT
    for k in range(int(s.backoff_time / DT) + 1):
        d.update(0.03, 0.014, 1.0, t + k * DT)
    assert d.phase == dk.APPROACH                        # a fresh approach, its progress measured anew:
    assert d.approach_watch.best_at is None or d.approach_watch.best_at >= steps * DT + s.backoff_time - 1e-9


def test_a_pair_askew_in_the_mouth_is_not_nudged_and_backs_off_when_it_jams():
    s = dk.DockingSettings(insert_stall_time=1.0, jam_yaw=0.25)
    steps = int(round(s.insert_stall_time / DT))
    askew = dk.Docking(s, mover="j", now=0.0)             # 11 mm out, 0.45 rad: no nudge (no brace either)
    assert not any(askew.insert_stalled(0.011 + 0.001 * (k % 2), k * DT, dtheta=-0.45) for k in range(3 * steps))
    straight = dk.Docking(s, mover="j", now=0.0)          # lined up within jam_yaw: nudged as before
    assert any(straight.insert_stalled(0.011 + 0.001 * (k % 2), k * DT, dtheta=0.1) for k in range(steps + 2))
    for mover, sign in (("j", 1.0), ("i", -1.0)):
        d = dk.Docking(s, mover=mover, now=0.0)
        d.jammed(0.010, -0.002, 4.0, dtheta=-0.45)
        assert d.phase == dk.BACKOFF and "askew" in d.note and d.attempts == 1
        cmd = d.command(mover_heading=0.45, partner_heading=0.0)
        assert sign * cmd.v < 0 and cmd.w < 0              # away from the partner, turning to its heading
        for k in range(int(s.backoff_time / DT) + 1):
            d.update(0.02, 0.0, -0.3, 4.0 + k * DT)
        assert d.phase == dk.APPROACH
    lined_up = dk.Docking(s, mover="i", now=0.0)          # a jam within jam_yaw: the aim alone, as before
    lined_up.jammed(0.002, 0.003, 4.0, dtheta=0.05)
    assert lined_up.phase == dk.APPROACH and lined_up.aim < 0
    off = dk.Docking(dk.DockingSettings(jam_yaw=0.0), mover="j", now=0.0)   # 0: off
    off.jammed(0.010, -0.002, 4.0, dtheta=-0.45)
    assert off.phase == dk.APPROACH


def test_a_stalled_insertion_is_nudged_straight_in_then_the_mpc_inserts_again():
    off = dk.Docking(dk.DockingSettings(insert_stall_time=0.0), mover="j", now=0.0)     # 0: off
    assert not any(off.insert_stalled(0.011, k * DT) for k in range(100))
    s = dk.DockingSettings(insert_stall_time=1.0)
    steps = int(round(s.insert_stall_time / DT))
    closing = dk.Docking(s, mover="j", now=0.0)                           # 3 mm/s deeper: progress, no nudge
    assert not any(closing.insert_stalled(0.012 - 0.0003 * k, k * DT) for k in range(30))
    backing = dk.Docking(s, mover="i", now=0.0)                           # a robot backing its anchor in: never
    assert not any(backing.insert_stalled(0.011, k * DT) for k in range(100))
    d = dk.Docking(s, mover="j", now=0.0)
    stalled = [d.insert_stalled(0.011 + 0.001 * (k % 2), k * DT) for k in range(steps + 2)]
    assert stalled.index(True) == steps and d.phase == dk.NUDGE and d.phase in dk.DRIVEN and d.nudges == 1
    cmd = d.command(mover_heading=0.0, partner_heading=0.2)
    assert cmd.v == pytest.approx(s.push_speed) and cmd.w > 0              # straight in, towards the partner's heading
    brace = d.brace()                                                     # the anchor robot backs into the mover
    assert (brace.v, brace.w) == pytest.approx((-s.brace_speed, 0.0)) and s.brace_speed > 0
    assert dk.Docking(replace(s, brace_speed=0.0), mover="j", now=0.0).brace() is None
    d.update(s.brace_gap - 0.001, 0.0, 0.0, steps * DT)                  # the head past the lips: no brace
    assert d.phase == dk.NUDGE and d.brace() is None
    t = steps * DT                                                        # the nudge began here
    assert run(d, [0.011] * (int(round(s.nudge_time / DT)) - 1), t0=t + DT) is None and d.phase == dk.NUDGE
    d.update(0.011, 0.0, 0.0, t + s.nudge_time + DT)                      # not home after nudge_time: the MPC again
    assert d.phase == dk.APPROACH and "nudged for" in d.note and d.brace() is None
    d.insert_reset()
    assert not any(d.insert_stalled(0.011, t + 2 + k * DT) for k in range(steps))   # a fresh spell
    home = dk.Docking(s, mover="j", now=0.0)                              # home, not yet lined up: no nudge
    assert not any(home.insert_stalled(0.002, k * DT) for k in range(30))
    d = dk.Docking(s, mover="j", now=0.0)
    [d.insert_stalled(0.011, k * DT) for k in range(steps + 1)]
    assert run(d, [0.002] * s.home_steps, t0=(steps + 1) * DT) is None     # home: the MPC again, not "seated":
    assert d.phase == dk.APPROACH and "nudged home" in d.note             # Algorithm 2's test decides
