"""Stage edges as MPC constraints (the edge boxes of control_loop), on a kinematic plant: a robot driven
at an edge stops on its stage; a behaviour requested with cross_edges drives over it; the floor has none."""

import math
from dataclasses import replace

import numpy as np
import pytest

from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_common.model import unicycle_arc
from puzzlebot_common.stages import WorldParams, stages
from puzzlebot_mpc.behaviors import BehaviorRequest
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_mpc.settings import MPCSettings

RADIUS = RobotGeometry().footprint_radius()
STEP = stages("step", WorldParams())          # the stage covers -0.6 <= x <= 0, |y| <= 0.3


def drive(loop, poses, seconds):
    """Run the loop on a kinematic plant for ``seconds``; returns the largest x each robot reached and the
    largest edge slack the MPC reported."""
    t, far, slack = 0.0, {n: -math.inf for n in poses}, 0.0
    for n, p in poses.items():
        loop.on_pose(n, t, *p)
    for _ in range(int(round(seconds / 0.1))):
        out = loop.step(t)
        assert out.result.success, out.result.status
        slack = max(slack, out.result.extra.get("max_edge_slack", 0.0))
        for n in poses:
            poses[n] = unicycle_arc(poses[n], *out.commands[n], 0.1)
            far[n] = max(far[n], poses[n][0])
        t += 0.1
        for n, p in poses.items():
            loop.on_pose(n, t, *p)
    return far, slack


def forward(names, cross=False):
    return BehaviorRequest("follow_velocity", names, velocities=[(0.05, 0.0)] * len(names), timeout=8.0,
                           cross_edges=cross)


def test_a_robot_driven_at_the_edge_stops_with_its_footprint_on_the_stage():
    loop = ControlLoop(["pz1"], MPCSettings(), stages=STEP)
    poses = {"pz1": (-0.15, 0.0, 0.0)}
    loop.on_pose("pz1", 0.0, *poses["pz1"])
    loop.behaviors.request(forward(["pz1"]), now=0.0)
    far, slack = drive(loop, poses, 6.0)
    assert -RADIUS - 0.004 <= far["pz1"] <= -RADIUS + 1e-3      # stopped at the box, not short of it
    assert slack < 1e-3


def test_a_robot_heading_for_the_side_edge_keeps_to_it_too():
    loop = ControlLoop(["pz1"], MPCSettings(), stages=STEP)
    poses = {"pz1": (-0.3, 0.2, math.pi / 2)}
    loop.on_pose("pz1", 0.0, *poses["pz1"])
    loop.behaviors.request(forward(["pz1"]), now=0.0)
    drive(loop, poses, 5.0)
    assert 0.3 - RADIUS - 0.004 <= poses["pz1"][1] <= 0.3 - RADIUS + 1e-3


def test_cross_edges_lets_the_behaviour_s_robots_over_and_holds_the_others():
    loop = ControlLoop(["pz1", "pz2"], MPCSettings(), stages=STEP)
    poses = {"pz1": (-0.15, 0.0, 0.0), "pz2": (-0.15, 0.15, 0.0)}
    for n, p in poses.items():
        loop.on_pose(n, 0.0, *p)
    loop.behaviors.request(BehaviorRequest("follow_velocity", ["pz1", "pz2"], velocities=[(0.05, 0.0)] * 2,
                                           timeout=8.0), now=0.0)
    loop.behaviors.request(forward(["pz1"], cross=True), now=0.0)      # replaces it: only pz1 crosses
    far, _ = drive(loop, poses, 6.0)
    assert far["pz1"] > 0.1                                          # off the stage, on the floor
    assert far["pz2"] <= 0.0


@pytest.mark.parametrize("edges,world", [(False, STEP), (True, [])])
def test_without_edges_or_stages_nothing_holds_the_robot(edges, world):
    loop = ControlLoop(["pz1"], replace(MPCSettings(), edges=edges), stages=world)
    assert loop.stage_map is None
    poses = {"pz1": (-0.15, 0.0, 0.0)}
    loop.on_pose("pz1", 0.0, *poses["pz1"])
    loop.behaviors.request(forward(["pz1"]), now=0.0)
    far, _ = drive(loop, poses, 6.0)
    assert far["pz1"] > 0.1


def test_edge_boxes_follow_the_stage_each_robot_stands_on():
    loop = ControlLoop(["a", "b", "c"], replace(MPCSettings(), edge_margin=0.01),
                       stages=stages("gap", WorldParams()))
    boxes = loop.edge_boxes({"a": (-0.2, 0.0, 0.0), "b": (0.3, 0.1, 1.0), "c": None})
    m = RADIUS + 0.01
    assert np.allclose(boxes[0], [-0.6 + m, -m, -0.3 + m, 0.3 - m])
    assert np.allclose(boxes[1], [0.04 + m, 0.64 - m, -0.3 + m, 0.3 - m])
    assert np.all(np.isinf(boxes[2]))                                 # no pose: no box
    assert np.all(np.isinf(loop.edge_boxes({"a": (0.02, 0.0, 0.0), "b": None, "c": None})[0]))   # in the gap
