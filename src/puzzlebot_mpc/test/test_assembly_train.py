"""assembly_to_goal's train on the kinematic plant: unicycles that nothing holds together stay coupled only by
their own commands, so what the followers are told is what these tests see."""

import pytest

from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.behaviors import SUCCEEDED, BehaviorRequest
from puzzlebot_mpc.behaviors.assembly_to_goal import CLOSE_GAIN
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_mpc.docking import seat_measure

from test_coupling_loop import GEO, KINEMATIC, Plant

LINE = ["pz1", "pz2", "pz3", "pz4"]      # pz1 in front, each robot's anchor in the mouth of the one behind


def coupled_line(poses=None):
    """A control loop holding the line coupled, and the line's poses (its faces touching, heading +x)."""
    loop = ControlLoop(LINE, KINEMATIC)
    for a, b in zip(LINE[:-1], LINE[1:]):
        loop.pairs.add_coupled(pr.make_pair(a, b, pr.ANCHOR, GEO))
    line = {r: (-k * GEO.body_side, 0.0, 0.0) for k, r in enumerate(LINE)}
    line.update(poses or {})
    for n, p in line.items():
        loop.on_pose(n, 0.0, *p)
    return loop, line


def test_a_follower_whose_partners_anchor_is_pulled_open_drives_faster_by_the_close_gain_times_the_opening():
    open_by = KINEMATIC.dock_repair_gap + 0.002                  # the faces 2 mm further apart than "open"
    loop, _ = coupled_line({"pz2": (-GEO.body_side - open_by, 0.0, 0.0)})
    loop.request(BehaviorRequest("assembly_to_goal", ["pz1"], goals=[(0.4, 0.0)], tolerance=0.01), 0.0)
    commands = loop.step(0.0).commands
    v1, v2, v3, v4 = (commands[r][0] for r in LINE)
    assert CLOSE_GAIN > 0 and v1 > 0
    assert v2 == pytest.approx(v1 + CLOSE_GAIN * 0.002)
    assert v3 == pytest.approx(v1) and v4 == pytest.approx(v1)   # pressed together (pz3) or shut: as before


def test_a_line_opened_at_the_start_closes_up_while_it_drives_to_a_goal_to_the_side():
    open_by = 2 * KINEMATIC.dock_repair_gap
    loop, line = coupled_line({"pz3": (-2 * GEO.body_side - open_by, 0.0, 0.0),
                               "pz4": (-3 * GEO.body_side - 2 * open_by, 0.0, 0.0)})
    plant = Plant(loop, line)
    status, _ = plant.run(BehaviorRequest("assembly_to_goal", ["pz1"], goals=[(0.4, 0.1)], tolerance=0.01,
                                          timeout=60.0), 61.0)
    assert status.state == SUCCEEDED, status.message
    gaps = [seat_measure(p, plant.poses[p.robot_i], plant.poses[p.robot_j])[0] for p in loop.pairs.coupled.values()]
    # with the heading chase alone (CLOSE_GAIN 0) the two gaps end 4.0 and 4.4 mm open
    assert max(gaps) < KINEMATIC.dock_repair_gap + 0.5e-3, gaps
