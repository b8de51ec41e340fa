"""The pose gate on synthetic mocap streams: what it rejects, holds, keeps and re-acquires."""

import math

import numpy as np
import pytest

from puzzlebot_common import pose_gate as pg
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import quaternion_from_yaw, wrap_angle
from puzzlebot_common.mocap_faults import FAULTS, clean
from puzzlebot_common.model import unicycle_arc
from puzzlebot_common.throttle import Throttle

V_MAX, W_MAX = 0.2, 6.0          # the robots' hardware limits (driver v_limit / w_limit)
RATE = 100.0                     # Hz, the lab's Vicon
P = pg.PoseGateParams()


def gate():
    return pg.PoseGate("p21", V_MAX, W_MAX, P)


def track(n, v=0.04, w=0.5, t0=0.0, pose=(0.3, -0.2, 3.0), noise=0.0, seed=0):
    """n frames (stamp, x, y, yaw) of a robot driving an arc at RATE, with optional mocap noise."""
    rng = np.random.default_rng(seed)
    out, p = [], np.array(pose, dtype=float)
    for k in range(n):
        out.append((t0 + k / RATE, p[0] + noise * rng.normal(), p[1] + noise * rng.normal(),
                    wrap_angle(p[2] + 10 * noise * rng.normal())))
        p = unicycle_arc(p, v, w, 1.0 / RATE)
    return out


def test_shipped_yaml_states_the_dataclass_defaults():
    assert pg.shipped_params() == pg.PoseGateParams()


@pytest.mark.parametrize("v, w", [(0.0, 0.0), (0.05, 1.5), (0.2, 0.0), (0.0, 6.0), (-0.2, -6.0), (0.2, 6.0)])
def test_driving_at_the_limits_with_lab_noise_is_never_rejected(v, w):
    g = gate()
    for f in track(3000, v, w, noise=0.0003, seed=3):       # 30 s, 0.3 mm / 3 mrad noise
        assert g.check(*f).accepted
    assert g.rejected == 0 and not g.held


def test_slow_streams_and_gaps_are_judged_by_their_stamps():
    g = gate()
    assert g.check(0.0, 0.0, 0.0, 0.0).accepted
    assert g.check(0.1, 0.02, 0.0, 0.5).accepted           # 10 Hz at 0.2 m/s, 5 rad/s
    assert g.check(5.1, 1.0, 0.0, 2.0).accepted            # after 5 s unseen: 1 m is possible
    assert not g.check(5.11, 1.1, 0.0, 2.0).accepted       # 0.1 m in 10 ms is not


def feed(g, frame):
    """Give the gate a MocapFrame."""
    return g.check(frame.stamp, frame.x, frame.y, quaternion=frame.q, z=frame.z)


@pytest.mark.parametrize("fault", sorted(FAULTS))
@pytest.mark.parametrize("burst", [1, 10])
def test_each_bad_frame_is_rejected_named_and_the_track_kept(fault, burst):
    make, kind = FAULTS[fault]
    g = gate()
    frames = track(120)
    for f in frames[:50]:
        assert feed(g, clean(*f)).accepted
    for f in frames[50:50 + burst]:
        v = feed(g, make(*f))
        assert not v.accepted and v.kind == kind, (fault, v)
        assert v.reason and math.isnan(v.yaw)
    assert g.held and g.counts[kind] == burst and g.last.stamp == frames[49][0]
    # the good frames that follow continue the old track at once; the hold ends after reacquire_frames
    resumed_at = None
    for k, f in enumerate(frames[50 + burst:]):
        v = feed(g, clean(*f))
        assert v.accepted and not v.reacquired, (fault, k, v)
        if v.resumed:
            resumed_at = k
    assert resumed_at == P.reacquire_frames - 1 and not g.held
    assert g.rejected == burst and g.reacquisitions == 0


def test_the_fault_catalogue_covers_the_issue():
    assert len(FAULTS) == 8 + 7 * 2        # 5 jumps, a flip, 2 quaternions; NaN and inf in each field
    assert all(kind in pg.KINDS for _, kind in FAULTS.values())


def test_stamps_older_than_the_track_are_rejected():
    g = gate()
    assert g.check(1.0, 0.0, 0.0, 0.0).accepted
    v = g.check(0.5, 0.0, 0.0, 0.0)
    assert not v.accepted and v.kind == pg.ORDER and "older" in v.reason


def test_a_persistent_offset_is_reacquired_after_n_consistent_frames():
    g = gate()
    frames = track(200)
    for f in frames[:50]:
        assert g.check(*f).accepted
    moved = [(t, x + 0.3, y, yaw) for t, x, y, yaw in frames[50:]]     # the subject re-identified 0.3 m off
    verdicts = [g.check(*f) for f in moved]
    n = P.reacquire_frames
    assert [v.accepted for v in verdicts[:n - 1]] == [False] * (n - 1)
    assert verdicts[n - 1].accepted and verdicts[n - 1].reacquired and "0.300 m" in verdicts[n - 1].reason
    assert all(v.accepted and not v.reacquired for v in verdicts[n:])
    assert not g.held and g.reacquisitions == 1 and g.counts[pg.JUMP] == n - 1


def test_alternating_ghost_frames_never_become_the_track():
    g = gate()
    frames = track(300)
    for k, (t, x, y, yaw) in enumerate(frames):
        v = g.check(t, x + (0.5 if k % 2 else 0.0), y, yaw)
        assert v.accepted == (k % 2 == 0), k
    assert g.reacquisitions == 0 and g.held         # every other frame bad: the robot stays held


def test_inconsistent_garbage_never_becomes_the_track():
    g = gate()
    frames = track(100)
    for f in frames[:20]:
        g.check(*f)
    rng = np.random.default_rng(1)
    for t, _, _, _ in frames[20:]:
        assert not g.check(t, rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-3, 3)).accepted
    assert g.reacquisitions == 0 and g.last.stamp == frames[19][0]


def test_repeated_stamps_replace_within_the_margins_and_are_rejected_beyond():
    g = gate()
    assert g.check(1.0, 0.1, 0.2, 0.3).accepted
    v = g.check(1.0, 0.1, 0.2, 0.3)
    assert v.accepted and v.duplicate and g.rejected == 0
    v = g.check(1.0, 0.1003, 0.2, 0.31)                 # a re-measurement of the instant: replaces it
    assert v.accepted and v.duplicate and g.last.x == 0.1003
    v = g.check(1.0, 0.1, 0.25, 0.3)                    # 5 cm away at the same instant
    assert not v.accepted and v.kind == pg.ORDER and "repeats" in v.reason and g.last.x == 0.1003


def test_first_frame_is_checked_too():
    g = gate()
    assert g.check(0.0, 1e300, 0.0, 0.0).kind == pg.OUT_OF_RANGE
    assert g.check(0.0, 0.0, 0.0, quaternion=(0, 0, 0, 0)).kind == pg.QUATERNION
    assert g.check(0.0, 0.0, 0.0, None).kind == pg.NON_FINITE         # no heading at all
    assert g.check(0.0, 0.0, 0.0, True).kind == pg.NON_FINITE
    assert g.last is None
    v = g.check(0.0, 0.1, 0.2, quaternion=quaternion_from_yaw(1.0))
    assert v.accepted and v.yaw == pytest.approx(1.0)


def test_reasons_carry_the_figures():
    g = gate()
    g.check(0.0, 0.0, 0.0, 0.0)
    assert "jumped 1 m in 0.010 s (allowed 0.0130 m" in g.check(0.01, 1.0, 0.0, 0.0).reason
    assert "heading turned 3.142 rad" in g.check(0.02, 0.0, 0.0, math.pi).reason
    assert "non-finite x (x=nan)" in g.check(0.03, math.nan, 0.0, 0.0).reason
    assert "norm 0," in g.check(0.04, 0.0, 0.0, quaternion=(0, 0, 0, 0)).reason


def test_bad_parameters_are_clear_errors():
    with pytest.raises(ConfigError, match="reacquire_frames"):
        pg.PoseGateParams.from_dict({"reacquire_frames": 0})
    with pytest.raises(ConfigError, match="quaternion_tolerance"):
        pg.PoseGateParams.from_dict({"quaternion_tolerance": 1.0})
    with pytest.raises(ConfigError, match="unknown key"):
        pg.PoseGateParams.from_dict({"speed": 1.0})
    with pytest.raises(ConfigError, match="v_max"):
        pg.PoseGate("p21", 0.0, 6.0)


def test_throttle_one_line_per_key_and_period_with_the_count_held_back():
    t = [0.0]
    th = Throttle(1.0, clock=lambda: t[0])
    assert th("a", "x") == "x"
    assert th("a", "x") is None and th("a", "x") is None
    assert th("b", "y") == "y"                      # another key is not held back
    t[0] = 1.0
    assert th("a", "x") == "x (2 similar message(s) suppressed)"
