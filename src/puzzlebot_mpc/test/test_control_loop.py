"""Closed loop on a kinematic plant: the controller core without ROS or Bullet."""

import math

import numpy as np
import pytest

from puzzlebot_mpc.behaviors import SUCCEEDED, BehaviorRequest
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_common.model import unicycle_arc
from puzzlebot_mpc.settings import MPCSettings

NAMES = ["pz1", "pz2", "pz3"]


def run(loop, poses, steps, plant_dt=0.01, on_step=None):
    t, out = 0.0, None
    for k in range(steps):
        out = loop.step(t)
        if on_step:
            on_step(k, out)
        for name in NAMES:
            v, w = out.commands[name]
            for _ in range(int(round(0.1 / plant_dt))):
                poses[name] = unicycle_arc(poses[name], v, w, plant_dt)
        t += 0.1
        for name, p in poses.items():
            loop.on_pose(name, t, *p)
        if out.status.state == SUCCEEDED:
            break
    return t, out


def test_three_robots_reach_goals_within_5mm():
    loop = ControlLoop(NAMES, MPCSettings())
    poses = {"pz1": (0.0, 0.0, 0.0), "pz2": (0.0, 0.12, 1.0), "pz3": (0.1, -0.12, 3.0)}
    for n, p in poses.items():
        loop.on_pose(n, 0.0, *p)
    goals = [(0.3, 0.0), (-0.1, 0.25), (0.2, 0.2)]
    loop.behaviors.request(BehaviorRequest("go_to_goal", NAMES, goals, tolerance=0.005), now=0.0)
    failures = []
    t, out = run(loop, poses, 400, on_step=lambda k, o: failures.append(k) if not o.result.success else None)
    assert out.status.state == SUCCEEDED, out.status.message
    for name, g in zip(NAMES, goals):
        assert math.hypot(poses[name][0] - g[0], poses[name][1] - g[1]) <= 0.005
    assert t < 20.0
    assert failures == []


def test_velocity_limits_hold():
    s = MPCSettings()
    loop = ControlLoop(NAMES, s)
    poses = {n: (0.0, 0.1 * i, 0.0) for i, n in enumerate(NAMES)}
    for n, p in poses.items():
        loop.on_pose(n, 0.0, *p)
    loop.behaviors.request(BehaviorRequest("go_to_goal", NAMES, [(1.0, 0.0), (-1.0, 0.1), (0.0, 1.0)]), now=0.0)

    def check(k, out):
        for v, w in out.commands.values():
            assert abs(v) <= s.v_max + 1e-6 and abs(w) <= s.w_max + 1e-6

    run(loop, poses, 30, on_step=check)


def test_stale_and_missing_poses_give_zero_commands():
    loop = ControlLoop(NAMES, MPCSettings())
    loop.on_pose("pz1", 0.0, 0.0, 0.0, 0.0)
    loop.on_pose("pz2", 0.0, 0.0, 0.2, 0.0)
    loop.behaviors.request(BehaviorRequest("go_to_goal", NAMES, [(0.3, 0.0), (0.3, 0.2), (0.3, -0.2)]), now=0.0)
    out = loop.step(0.0)
    assert out.stale == ["pz3"] and out.commands["pz3"] == (0.0, 0.0)
    assert out.commands["pz1"][0] > 0  # the others still move
    out = loop.step(1.0)                # all poses now 1 s old (> pose_timeout)
    assert set(out.stale) == set(NAMES)
    assert all(c == (0.0, 0.0) for c in out.commands.values())
    assert out.result.fallback == "stop"


@pytest.mark.parametrize("bad", [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (0.0, 0.0, math.nan)])
def test_non_finite_pose_rejected_and_last_good_pose_kept(bad):
    loop = ControlLoop(NAMES, MPCSettings())
    assert loop.on_pose("pz1", 0.0, 0.1, 0.2, 0.3) is None
    reason = loop.on_pose("pz1", 0.05, *bad)
    assert reason and "non-finite" in reason
    assert (loop.poses.latest("pz1").x, loop.poses.latest("pz1").stamp) == (0.1, 0.0)
    assert "unknown robot" in loop.on_pose("zz", 0.0, 0, 0, 0)
    assert "older" in loop.on_pose("pz1", -1.0, 0, 0, 0)


def test_mpc_rejects_wrong_state_shape():
    loop = ControlLoop(NAMES, MPCSettings())
    with pytest.raises(ValueError, match="shape"):
        loop.mpc.make_step(np.zeros((2, 5)), None)
