"""One robot pulling a coupled pair apart (puzzlebot_experiments.pull_check) and the saved states it runs from."""

from puzzlebot_experiments.pull_check import PULLS, pull_pairs
from puzzlebot_experiments.trials import MATE_GAP, _world
from puzzlebot_sim.params import AnchorParams, RobotParams, SimParams
from puzzlebot_sim.world import RobotStart

ROBOT = RobotParams()


def _chain_and_loner():
    """c0-c1-c2 mated in a row (c0 in front, its anchor in c1), and a robot 0.3 m ahead of c0 whose anchor is in no one."""
    pitch = ROBOT.body_side + MATE_GAP
    starts = [RobotStart("c%d" % k, -k * pitch, 0.0, 0.0) for k in range(3)]
    starts.append(RobotStart("far", 0.3, 0.0, 0.0))
    return _world(starts, SimParams(), ROBOT, AnchorParams())


def test_seated_pairs_of_a_chain_hold_one_robots_pull_and_the_world_comes_back():
    with _chain_and_loner() as w:
        w.run(0.5)
        before = {n: w.pose2d(n) for n in w.names}
        t0 = w.time
        out = pull_pairs(w, [("c0", "c1"), ("c1", "c2"), ("far", "c0")], seconds=2.0)
        assert [r["pair"] for r in out] == ["c0-c1", "c1-c2", "far-c0"]
        for r in out[:2]:
            assert r["before"] == "head_inserted" and r["reason"] == ""
            for driver, _ in PULLS:
                assert r[driver]["held"], r
                assert 1.0 < r[driver]["stretch_mm"] < 20.0, r      # stretched, stalled: the anchor holds
        # an anchor in no opening is not held: its robot drives away
        assert out[2]["before"] == "decoupled"
        assert not out[2]["anchor"]["held"] and out[2]["anchor"]["stretch_mm"] > 50.0
        # the world is back where the pulls started: same time, same poses, every robot at rest
        assert w.time == t0
        for n in w.names:
            assert max(abs(a - b) for a, b in zip(w.pose2d(n), before[n])) < 1e-6, n
            assert w.robots[n].command == (0.0, 0.0)
