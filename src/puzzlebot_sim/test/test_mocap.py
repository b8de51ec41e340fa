"""The mocap sensor model (puzzlebot_sim.mocap) on its own: no world, a seeded RNG."""

import numpy as np
import pybullet as pb
import pytest

from puzzlebot_sim.mocap import MocapModel
from puzzlebot_sim.params import SimParams

POSE = ((0.1, -0.2, 0.025), tuple(pb.getQuaternionFromEuler([0.0, 0.0, 0.4])))


def _yaw(orn):
    return pb.getEulerFromQuaternion(orn)[2]


def test_off_by_default_returns_the_true_pose_without_drawing():
    rng = np.random.default_rng(3)
    assert MocapModel().measure(POSE, rng, 0) == POSE
    assert rng.random() == np.random.default_rng(3).random()          # nothing drawn


def test_draws_dropout_then_position_then_yaw_from_the_rng():
    m = MocapModel(position_std=0.002, yaw_std=0.01, dropout=0.3, heading_offset=0.1)
    rng, ref = np.random.default_rng(5), np.random.default_rng(5)
    for _ in range(50):
        got = m.measure(POSE, rng, 0, extra_heading_offset=0.05)
        if ref.random() < m.dropout:
            assert got is None
            continue
        dx, dy = ref.normal(0.0, m.position_std, 2)
        dyaw = ref.normal(0.0, m.yaw_std)
        assert got[0] == (POSE[0][0] + dx, POSE[0][1] + dy, POSE[0][2])
        assert _yaw(got[1]) == pytest.approx(0.4 + 0.15 + dyaw, abs=1e-6)   # PyBullet: single precision


def test_heading_offset_alone_turns_the_marker_frame():
    got = MocapModel(heading_offset=-0.2).measure(POSE, np.random.default_rng(0), 0)
    assert got[0] == POSE[0] and _yaw(got[1]) == pytest.approx(0.2, abs=1e-6)   # PyBullet: single precision
    assert sum(q * q for q in got[1]) == pytest.approx(1.0, abs=1e-6)


def test_from_sim_reads_the_mocap_fields():
    sim = SimParams(mocap_position_std=0.001, mocap_yaw_std=0.02, mocap_dropout=0.1, mocap_heading_offset=0.3)
    assert MocapModel.from_sim(sim) == MocapModel(0.001, 0.02, 0.1, 0.3)
