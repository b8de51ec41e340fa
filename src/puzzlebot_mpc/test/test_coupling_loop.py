"""Closed loop on the kinematic plant: couple into a line, drive as one body, decouple; bad requests.

The kinematic plant has no anchors: nothing but the controller holds a pair together. The decoupling
wiggle is an open-loop command that a coupled neighbour in *front* of the wiggling robot cannot follow
without its anchor (the Bullet tests -- puzzlebot_sim/test/test_closed_loop.py and the couple4_line
rostest -- decouple the middle pair pz2-pz3 physically), so here the front pair pz1-pz2 decouples.
"""

import math

import numpy as np
import pytest

from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.behaviors import FAILED, SUCCEEDED, BehaviorError, BehaviorRequest
from puzzlebot_mpc.config_files import load_target_file
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_common.model import unicycle_arc
from puzzlebot_mpc.settings import MPCSettings

GEO = RobotGeometry()
NAMES = ["pz1", "pz2", "pz3", "pz4"]
#: A kinematic plant has no anchor to pull against: the docking manoeuvre's pull test could never find a pair
#: seated, so these runs couple by Algorithm 2 alone (the paper's controller; docking: false).
KINEMATIC = MPCSettings(docking=False)
# the coupling demo's start poses (puzzlebot_bringup/config/scenarios/couple4_line.yaml)
START = {"pz1": (0.00, 0.00, 0.25), "pz2": (-0.11, 0.035, -0.3), "pz3": (-0.20, -0.03, 0.35),
         "pz4": (-0.30, 0.025, -0.25)}


class Plant:
    """Kinematic plant: applies each command exactly (closed-form arcs) for one period."""

    def __init__(self, loop, poses):
        self.loop, self.poses, self.t = loop, dict(poses), 0.0
        self.failures, self.min_margin = 0, math.inf
        for n, p in self.poses.items():
            loop.on_pose(n, self.t, *p)

    def run(self, req, max_time, watch=()):
        rid = self.loop.request(req, self.t)
        t0 = self.t
        while self.t - t0 < max_time:
            out = self.loop.step(self.t)
            self.failures += 0 if out.result.success else 1
            for name, (v, w) in out.commands.items():
                p = self.poses[name]
                for _ in range(10):
                    p = unicycle_arc(p, v, w, 0.01)
                self.poses[name] = tuple(p)
            self.t += 0.1
            for n, p in self.poses.items():
                self.loop.on_pose(n, self.t, *p)
            for key in watch:
                pair = self.loop.pairs.coupled[key]
                self.min_margin = min(self.min_margin, self.margin(pair))
            if out.status.request_id == rid and out.status.state in (SUCCEEDED, FAILED):
                return out.status, self.t - t0
        return out.status, self.t - t0

    def margin(self, pair):
        return pr.head_margin(pair, self.poses[pair.robot_i], self.poses[pair.robot_j],
                              pr.coupling_polygon(pair, GEO))


@pytest.fixture(scope="module")
def demo():
    """The whole demo once: couple, drive 0.3 m, decouple pz1-pz2 (results checked by the tests below)."""
    loop = ControlLoop(NAMES, KINEMATIC)
    plant = Plant(loop, START)
    res = {"couple": plant.run(BehaviorRequest("couple", NAMES, target="line", timeout=90.0), 95.0)}
    res["coupled_after_couple"] = sorted(loop.pairs.coupled)
    res["margins_after_couple"] = {k: plant.margin(p) for k, p in loop.pairs.coupled.items()}
    res["yaw_after_couple"] = {k: pr.alignment_error(p, plant.poses[p.robot_i], plant.poses[p.robot_j])[1]
                               for k, p in loop.pairs.coupled.items()}
    start_lead = np.array(plant.poses["pz1"][:2])
    res["drive"] = plant.run(BehaviorRequest("drive_assembly", ["pz1"], velocities=[(0.03, 0.0)], distance=0.3,
                                             timeout=30.0), 35.0, watch=list(loop.pairs.coupled))
    res["driven"] = float(np.linalg.norm(np.array(plant.poses["pz1"][:2]) - start_lead))
    res["drive_min_margin"] = plant.min_margin
    res["coupled_after_drive"] = sorted(loop.pairs.coupled)
    res["decouple"] = plant.run(BehaviorRequest("decouple", pair=["pz2", "pz1"], timeout=30.0), 35.0)
    res["coupled_after_decouple"] = sorted(loop.pairs.coupled)
    pz12 = pr.make_pair("pz1", "pz2", pr.ANCHOR, GEO)
    res["pz12_head_margin"] = pr.head_margin(pz12, plant.poses["pz1"], plant.poses["pz2"], GEO.footprint())
    res["failures"] = plant.failures
    return res


def test_four_scattered_robots_couple_into_a_line(demo):
    status, elapsed = demo["couple"]
    assert status.state == SUCCEEDED, status.message
    assert demo["coupled_after_couple"] == [("pz1", "pz2"), ("pz2", "pz3"), ("pz3", "pz4")]
    eps = MPCSettings().pair_epsilon       # Algorithm 2 declares a pair coupled within eps of its polygon
    for key, m in demo["margins_after_couple"].items():
        assert m >= -eps, "%s: anchor head %.1f mm outside the triangle" % (key, -1e3 * m)
    for key, dth in demo["yaw_after_couple"].items():
        assert abs(dth) <= GEO.anchor_yaw_free
    assert elapsed < 60.0


def test_chain_drives_0_3_m_with_every_pair_coupled(demo):
    status, elapsed = demo["drive"]
    assert status.state == SUCCEEDED, status.message
    assert demo["driven"] >= 0.3
    assert demo["coupled_after_drive"] == demo["coupled_after_couple"]
    assert demo["drive_min_margin"] >= 0.0      # every head stayed inside its triangle at every step


def test_named_pair_decouples_and_the_others_stay(demo):
    status, _ = demo["decouple"]
    assert status.state == SUCCEEDED, status.message
    assert demo["coupled_after_decouple"] == [("pz2", "pz3"), ("pz3", "pz4")]
    s = MPCSettings()
    assert demo["pz12_head_margin"] < -(s.pair_epsilon + s.decouple_clearance)


def test_no_failed_solve_in_the_demo(demo):
    assert demo["failures"] == 0


def stopped_loop(names=("pz1", "pz2", "pz3")):
    loop = ControlLoop(list(names), KINEMATIC, targets=load_target_file(GEO))
    for k, n in enumerate(names):
        loop.on_pose(n, 0.0, -0.06 * k, 0.0, 0.0)
    return loop


@pytest.mark.parametrize("req, fragment", [
    (BehaviorRequest("couple", ["pz1", "pz2"], target="line3"), "3 slots but only 2 robot"),
    (BehaviorRequest("couple", ["pz1", "pz9"], target="line"), "unknown robot"),
    (BehaviorRequest("couple", target="star"), "unknown target"),
    (BehaviorRequest("couple", ["pz1", "pz2"], slots=[(0, 0, 0), (0.01, 0, 0)]), "overlap"),
    (BehaviorRequest("couple", ["pz1", "pz2"], slots=[(0, 0, 0), (math.nan, 0, 0)]), "finite"),
    (BehaviorRequest("couple", ["pz1", "pz2"]), "needs a target"),
    (BehaviorRequest("decouple", pair=["pz1", "pz2"]), "not coupled"),
    (BehaviorRequest("decouple", pair=["pz1"]), "two robots"),
    (BehaviorRequest("drive_assembly", ["pz1"], velocities=[(0.03, 0.0)]), "distance or a timeout"),
    (BehaviorRequest("drive_assembly", ["pz1"], velocities=[(1.0, 0.0)], distance=0.1), "exceeds"),
])
def test_bad_requests_are_clear_errors_and_robots_stay_stopped(req, fragment):
    loop = stopped_loop()
    with pytest.raises(BehaviorError, match=fragment):
        loop.request(req, 0.0)
    out = loop.step(0.0)
    assert all(c == (0.0, 0.0) for c in out.commands.values())


def test_nan_or_missing_pose_refuses_couple():
    loop = ControlLoop(["pz1", "pz2", "pz3"], KINEMATIC)
    loop.on_pose("pz1", 0.0, 0.0, 0.0, 0.0)
    assert loop.on_pose("pz2", 0.0, math.nan, 0.0, 0.0) is not None      # rejected at the door
    loop.on_pose("pz3", 0.0, -0.12, 0.0, 0.0)
    with pytest.raises(BehaviorError, match="no fresh, finite pose for pz2"):
        loop.request(BehaviorRequest("couple", target="line"), 0.0)
    out = loop.step(0.0)
    assert all(c == (0.0, 0.0) for c in out.commands.values())


def test_two_robots_couple_side_by_side_with_a_knob_pair():
    loop = ControlLoop(["k1", "k2"], KINEMATIC)
    plant = Plant(loop, {"k1": (0.0, 0.0, 0.0), "k2": (-0.01, 0.085, 0.2)})
    status, elapsed = plant.run(BehaviorRequest("couple", target="row", timeout=60.0), 62.0)
    assert status.state == SUCCEEDED, status.message
    (key, pair), = loop.pairs.coupled.items()
    assert pair.type == pr.KNOB and key == ("k1", "k2")          # k1's left knob in k2's right hole
    assert plant.margin(pair) >= -MPCSettings().pair_epsilon
    assert plant.failures == 0
