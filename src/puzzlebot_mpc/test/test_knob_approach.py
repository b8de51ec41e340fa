"""The knob pairs' lane follower (puzzlebot_mpc.knob_approach), on the kinematic model."""

import pytest

from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_common.model import unicycle_arc
from puzzlebot_mpc import knob_approach as ka
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.settings import MPCSettings

GEO = RobotGeometry()
LANE = MPCSettings().knob_lane()
HOLE_ROBOT = (0.0, 0.0, 0.0)


def knob_pair():
    return pr.make_pair("k", "h", pr.KNOB, GEO)


def drive(pose, seconds, pair=None, mover="i"):
    """The knob robot k (the mover) from ``pose`` under the follower for ``seconds``; returns its pose and
    the phases it went through."""
    pair, phase, phases = pair or knob_pair(), ka.FOLLOW, []
    for _ in range(int(seconds / 0.1)):
        cmd = ka.command(pair, mover, pose, HOLE_ROBOT, LANE, phase)
        phase = cmd.phase
        if not phases or phases[-1] != phase:
            phases.append(phase)
        for _ in range(10):
            pose = unicycle_arc(pose, cmd.v, cmd.w, 0.01)
    return pose, phases


def test_the_lane_runs_out_from_the_side_then_closes_in_to_press_on_it():
    assert LANE.offset(0.1) == pytest.approx(LANE.gap)
    assert LANE.offset(LANE.standoff) == pytest.approx(LANE.gap)
    assert LANE.offset(LANE.level) == pytest.approx(-LANE.press)
    assert LANE.offset(0.0) == pytest.approx(-LANE.press)


def test_a_mover_beside_the_hole_but_off_its_lane_backs_straight_out():
    beside = (0.0, -GEO.body_side - 0.02, 0.0)           # k 20 mm out from h's right side, level with it
    cmd = ka.command(knob_pair(), "i", beside, HOLE_ROBOT, LANE)
    assert cmd.phase == ka.BACKOFF and cmd.v < 0.0 and cmd.w == 0.0


def test_a_single_robot_backing_off_askew_turns_to_its_partners_heading_and_then_follows_in():
    """The run a back-off gives assumes a parallel mover: this one, backing straight (as an assembly does),
    never gets onto its lane."""
    askew = (0.0, -GEO.body_side - 0.02, 0.3)
    assert ka.command(knob_pair(), "i", askew, HOLE_ROBOT, LANE).w == 0.0            # an assembly: straight
    cmd = ka.command(knob_pair(), "i", askew, HOLE_ROBOT, LANE, turn_back=True)
    assert cmd.phase == ka.BACKOFF and cmd.v < 0.0 and cmd.w < 0.0                   # towards heading 0
    pose, phase = askew, ka.FOLLOW
    for _ in range(400):
        cmd = ka.command(knob_pair(), "i", pose, HOLE_ROBOT, LANE, phase, turn_back=True)
        phase = cmd.phase
        for _ in range(10):
            pose = unicycle_arc(pose, cmd.v, cmd.w, 0.01)
    behind, off, dtheta, _ = ka.lane_state(knob_pair(), "i", pose, HOLE_ROBOT, LANE)
    assert abs(behind) < ka.HOME + 0.0005 and -LANE.press - 0.001 < off + LANE.offset(behind) < 0.001
    assert abs(dtheta) < GEO.knob_yaw_tolerance and phase == ka.FOLLOW


@pytest.mark.parametrize("start", [(-0.12, -GEO.body_side - 0.02, 0.2), (0.0, -GEO.body_side - 0.02, 0.0),
                                   (-0.15, -GEO.body_side - 0.001, -0.1)])
def test_the_knob_arrives_at_the_hole_pressed_on_the_side_and_parallel(start):
    pose, phases = drive(start, 40.0)
    behind, off, dtheta, _ = ka.lane_state(knob_pair(), "i", pose, HOLE_ROBOT, LANE)
    assert abs(behind) < ka.HOME + 0.0005              # at the hole (within HOME of it)
    out = off + LANE.offset(behind)                       # the knob's distance out from the side
    assert -LANE.press - 0.001 < out < 0.001              # on the side (the seat test's 1 mm)
    assert abs(dtheta) < GEO.knob_yaw_tolerance
    assert phases[-1] == ka.FOLLOW


def test_a_moving_hole_robot_comes_to_the_knob_the_same_way():
    pair = knob_pair()
    pose = (-0.12, GEO.body_side + 0.02, -0.2)            # h (the mover) 20 mm out from k's left side
    phase = ka.FOLLOW
    for _ in range(400):
        cmd = ka.command(pair, "j", (0.0, 0.0, 0.0), pose, LANE, phase)
        phase = cmd.phase
        for _ in range(10):
            pose = unicycle_arc(pose, cmd.v, cmd.w, 0.01)
    behind, off, dtheta, _ = ka.lane_state(pair, "j", (0.0, 0.0, 0.0), pose, LANE)
    assert abs(behind) < ka.HOME + 0.0005 and abs(dtheta) < GEO.knob_yaw_tolerance
    assert -LANE.press - 0.001 < pose[1] - GEO.body_side < 0.001     # h's right side on k's left side


def test_a_mover_already_alongside_the_side_closes_in_without_backing_out_past_the_corner():
    # 4 mm out from the side, 20 mm behind the hole: past the partner's corner, it needs only the run to cut
    # onto the lane (|e| / tan(MAX_CUT) + level, 16 mm), not the corner's standoff (39 mm)
    alongside = (-0.02, -GEO.body_side - 0.004, 0.0)
    assert ka.command(knob_pair(), "i", alongside, HOLE_ROBOT, LANE).phase == ka.FOLLOW
    pose, phases = drive(alongside, 20.0)
    behind, off, dtheta, _ = ka.lane_state(knob_pair(), "i", pose, HOLE_ROBOT, LANE)
    assert phases == [ka.FOLLOW] and abs(behind) < ka.HOME + 0.0005 and abs(dtheta) < GEO.knob_yaw_tolerance
    # before the corner, 5 mm off the lane (3 mm out there), it needs the full run: it backs out first
    before = (-0.03, -GEO.body_side - 0.008, 0.0)
    assert ka.command(knob_pair(), "i", before, HOLE_ROBOT, LANE).phase == ka.BACKOFF


def test_a_blocked_back_off_is_given_up_for_a_while_and_one_that_moves_is_not():
    watch = ka.ProgressWatch()

    assert watch.advise(ka.BACKOFF, 0.002, 0.0, False) == (True, False)
    for k in range(1, int(round(ka.BACKOFF_STALL / 0.1))):   # backing, but stuck 2 mm behind the hole
        assert watch.advise(ka.BACKOFF, 0.0025, 0.1 * k, False) == (True, False)
    t = ka.BACKOFF_STALL + 0.05
    assert watch.advise(ka.BACKOFF, 0.0025, t, False) == (False, False)   # blocked: follow from here ...
    assert watch.advise(ka.FOLLOW, 0.0025, t + ka.BACKOFF_REST - 0.1, False)[0] is False
    assert watch.advise(ka.FOLLOW, 0.0025, t + ka.BACKOFF_REST + 0.1, False)[0] is True   # ... for a while
    moving = ka.ProgressWatch()
    assert all(moving.advise(ka.BACKOFF, 0.001 * k, 0.1 * k, False) == (True, False) for k in range(60))


def test_a_mover_that_gets_no_nearer_the_hole_alongside_its_partner_backs_off_and_comes_again():
    stuck = (0.015, 0.0, 0.0, -1.0)                          # 15 mm behind the hole, on the lane
    assert ka.alongside(stuck, LANE)
    watch, n = ka.ProgressWatch(), int(round(ka.FOLLOW_STALL / 0.1))
    advice = [watch.advise(ka.FOLLOW, stuck[0], 0.1 * k + 0.01, True) for k in range(n + 1)]
    assert advice[-1] == (True, True) and all(a == (True, False) for a in advice[:-1])
    cmd = ka.command(knob_pair(), "i", (-0.015, -GEO.body_side - LANE.offset(0.015), 0.0), HOLE_ROBOT, LANE,
                     retry=True)
    assert cmd.phase == ka.BACKOFF and cmd.v < 0.0
    # one that comes nearer, or is turning onto its lane far from its partner, is left alone
    closing = ka.ProgressWatch()
    assert not any(closing.advise(ka.FOLLOW, 0.025 - 0.003 * 0.1 * k, 0.1 * k, True)[1] for k in range(60))
    assert not ka.alongside((0.015, 0.0, 0.8, -1.0), LANE)                # turning onto its lane
    assert not ka.alongside((0.04, 0.0, 0.0, -1.0), LANE)                 # before the partner's corner
    assert ka.alongside((0.0, 0.002, 0.0, -1.0), LANE)                    # at the hole, not seated: jammed too
    assert not ka.alongside((0.015, 0.005, 0.0, -1.0), LANE)              # off its lane
