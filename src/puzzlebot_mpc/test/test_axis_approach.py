"""An assembly's docking approach along its partner's axis (puzzlebot_mpc.axis_approach), kinematic."""

import pytest

from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_common.model import unicycle_arc
from puzzlebot_mpc import axis_approach as aa
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.docking import seat_measure

GEO = RobotGeometry()
LANE = aa.AxisLane()
L = GEO.body_side


def anchor_pair():
    return pr.make_pair("a", "o", pr.ANCHOR, GEO)       # a's anchor into o's mouth (o behind a)


def drive(mover, pose, partner, seconds=30.0, stop_gap=0.0):
    """The mover ("i": a backs onto o; "j": o drives onto a) from ``pose`` under the follower, until its
    faces are ``stop_gap`` apart; returns the pair's seat measure and the phases it went through."""
    pair, phase, phases = anchor_pair(), aa.FOLLOW, []
    for _ in range(int(seconds / 0.1)):
        pi, pj = (pose, partner) if mover == "i" else (partner, pose)
        if seat_measure(pair, pi, pj)[0] <= stop_gap:
            break
        cmd = aa.command(pair, mover, pi, pj, LANE, phase)
        phase = cmd.phase
        if not phases or phases[-1] != phase:
            phases.append(phase)
        for _ in range(10):
            pose = unicycle_arc(pose, cmd.v, cmd.w, 0.01)
    pi, pj = (pose, partner) if mover == "i" else (partner, pose)
    return seat_measure(pair, pi, pj), phases


@pytest.mark.parametrize("start", [(-L - 0.08, 0.008, 0.2), (-L - 0.06, -0.006, -0.1), (-L - 0.1, 0.0, 0.0)])
def test_an_opening_robot_driving_forwards_comes_onto_the_axis_and_into_the_mouth(start):
    (gap, lateral, dtheta), phases = drive("j", start, (0.0, 0.0, 0.0))
    assert gap <= 0.0 and abs(lateral) < 0.001 and abs(dtheta) < 0.05, (gap, lateral, dtheta)
    assert phases[-1] == aa.FOLLOW and phases.count(aa.BACKOFF) <= 1      # at most one back-off for a run


@pytest.mark.parametrize("start", [(L + 0.08, 0.008, 0.2), (L + 0.06, -0.006, -0.1)])
def test_an_anchor_robot_backing_comes_onto_the_axis_the_same_way(start):
    (gap, lateral, dtheta), phases = drive("i", start, (0.0, 0.0, 0.0))
    assert gap <= 0.0 and abs(lateral) < 0.001 and abs(dtheta) < 0.05, (gap, lateral, dtheta)


def test_a_mover_close_in_and_off_the_axis_backs_straight_out_then_comes_in():
    start = (-L - 0.015, 0.008, 0.0)                       # 15 mm behind the mouth, 8 mm off the axis
    cmd = aa.command(anchor_pair(), "j", (0.0, 0.0, 0.0), start, LANE)
    assert cmd.phase == aa.BACKOFF and cmd.v < 0.0 and cmd.w == 0.0
    (gap, lateral, dtheta), phases = drive("j", start, (0.0, 0.0, 0.0), seconds=60.0)
    assert phases == [aa.BACKOFF, aa.FOLLOW]
    assert gap <= 0.0 and abs(lateral) < 0.001 and abs(dtheta) < 0.05, (gap, lateral, dtheta)


def test_a_mover_whose_back_off_is_blocked_follows_the_axis_from_where_it_is():
    start = (-L - 0.015, 0.004, 0.0)
    cmd = aa.command(anchor_pair(), "j", (0.0, 0.0, 0.0), start, LANE, aa.BACKOFF, may_back_off=False)
    assert cmd.phase == aa.FOLLOW and cmd.v > 0.0


def test_an_askew_back_off_ends_at_the_longest_run_instead_of_running_on():
    """Backing straight out 0.5 rad askew, the mover drifts off the axis faster than its run grows: without
    the cap (standoff_max) its back-off never ended."""
    pair, partner = anchor_pair(), (0.0, 0.0, 0.0)
    pose, phase = (-L - 0.01, 0.004, 0.5), aa.FOLLOW                    # o behind a, askew, near the mouth
    for k in range(400):
        cmd = aa.command(pair, "j", partner, pose, LANE, phase)
        if phase == aa.BACKOFF and cmd.phase == aa.FOLLOW:
            break
        phase = cmd.phase
        for _ in range(10):
            pose = unicycle_arc(pose, cmd.v, cmd.w, 0.01)
    along = aa.axis_state(pair, "j", partner, pose)[0]
    assert k < 399 and along == pytest.approx(LANE.standoff_max + LANE.lookahead, abs=0.003)
