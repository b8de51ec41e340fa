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
