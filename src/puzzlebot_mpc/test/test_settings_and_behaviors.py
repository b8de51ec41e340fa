import math

import pytest

from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_mpc.behaviors import (FAILED, RUNNING, SUCCEEDED, BehaviorError, BehaviorManager,
                                     BehaviorRequest)
from puzzlebot_mpc.settings import MPCSettings

import os

CONFIG = os.path.join(os.path.dirname(__file__), "..", "config", "mpc.yaml")


def test_shipped_config_loads():
    s = MPCSettings.from_dict(load_yaml(CONFIG)["mpc"])
    assert s.dt == 0.1 and s.constraint_horizon <= s.horizon


@pytest.mark.parametrize("data, fragment", [
    ({"horizon": 0}, "horizon"),
    ({"horizon": 3, "constraint_horizon": 5}, "constraint_horizon"),
    ({"v_max": "fast"}, "v_max"),
    ({"dt": float("nan")}, "dt"),
    ({"horizn": 3}, "unknown key"),
    ({"butterfly": 1}, "true or false"),
])
def test_bad_settings_raise_config_error(data, fragment):
    with pytest.raises(ConfigError) as e:
        MPCSettings.from_dict(data)
    assert fragment in str(e.value)


def manager():
    return BehaviorManager(["pz1", "pz2", "pz3"], MPCSettings())


@pytest.mark.parametrize("req, fragment", [
    (BehaviorRequest("go_to_goal", ["pz9"], [(0, 0)]), "unknown robot"),
    (BehaviorRequest("fly"), "unknown behaviour"),
    (BehaviorRequest("go_to_goal", ["pz1", "pz2"], [(0, 0)]), "one goal per robot"),
    (BehaviorRequest("go_to_goal", ["pz1"], [(math.nan, 0)]), "not a finite"),
    (BehaviorRequest("go_to_goal", ["pz1", "pz1"], [(0, 0), (1, 1)]), "named twice"),
    (BehaviorRequest("follow_velocity", ["pz1"], velocities=[(1.0, 0.0)]), "exceeds the limits"),
    (BehaviorRequest("stop", timeout=-1.0), "timeout"),
])
def test_bad_requests_are_refused_and_change_nothing(req, fragment):
    m = manager()
    good = m.request(BehaviorRequest("go_to_goal", ["pz1"], [(0.1, 0.0)]), now=0.0)
    with pytest.raises(BehaviorError) as e:
        m.request(req, now=1.0)
    assert fragment in str(e.value)
    status = m.update(1.0, {"pz1": (0.0, 0.0, 0.0)})
    assert status.request_id == good and status.state == RUNNING
    assert m.objectives().goal_mask[0]


def test_go_to_goal_succeeds_within_tolerance_and_fails_on_timeout():
    m = manager()
    m.request(BehaviorRequest("go_to_goal", ["pz1", "pz2"], [(0.1, 0.0), (0.0, 0.1)], timeout=10.0), now=0.0)
    s = m.update(1.0, {"pz1": (0.1, 0.004, 0), "pz2": (0.0, 0.09, 0)})
    assert s.state == RUNNING and s.errors == pytest.approx([0.004, 0.01])
    s = m.update(2.0, {"pz1": (0.1, 0.004, 0), "pz2": (0.0, 0.097, 0)})
    assert s.state == SUCCEEDED
    m.request(BehaviorRequest("go_to_goal", ["pz3"], [(1.0, 1.0)], timeout=5.0), now=3.0)
    s = m.update(8.5, {"pz3": (0.0, 0.0, 0.0)})
    assert s.state == FAILED and "pz3" in s.message
    assert not m.objectives().goal_mask.any()  # stopped after the failure


def test_unrequested_robots_are_stopped():
    m = manager()
    m.request(BehaviorRequest("follow_velocity", ["pz2"], velocities=[(0.03, 0.2)]), now=0.0)
    o = m.objectives()
    assert (o.velocity_mask > 0).all()
    assert o.velocity[1] == pytest.approx([0.03, 0.2])
    assert o.velocity[0] == pytest.approx([0, 0]) and o.velocity[2] == pytest.approx([0, 0])


def test_seed_pair_partner_holds_while_the_mover_pushes_the_anchor_home():
    settings = MPCSettings()
    m = BehaviorManager(["pz1", "pz2"], settings)

    def step(now, poses):              # as control_loop.ControlLoop.step does
        m.pairs.update(poses, now)
        m.update(now, poses)
        m.pairs.assign_active(poses)
        return m.objectives(now, poses).velocity_mask

    far = {"pz1": (0.0, 0.0, 0.0), "pz2": (-0.15, 0.0, 0.0)}
    m.request(BehaviorRequest("couple", ["pz1", "pz2"], target="line", timeout=60.0), now=0.0, poses=far)
    assert (step(0.1, far) == 0.0).all()                               # lining up: both move
    (pair,) = m.pairs.active
    a, o = pair.robot_i, pair.robot_j                                  # o docks (the opening robot)
    inside = {a: (0.0, 0.0, 0.0), o: (-m.geometry.body_side - 0.008, 0.0, 0.0)}   # head 8 mm in
    mask = step(0.2, inside)
    assert pair.status == 1                                            # head_aligned
    assert mask[m.index[a]] == pytest.approx([math.sqrt(settings.hold_scale)] * 2)   # a holds still
    assert mask[m.index[o]] == pytest.approx([0.0, 0.0])                              # o pushes
