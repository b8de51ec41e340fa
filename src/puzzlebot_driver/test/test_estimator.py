"""Velocity estimator on synthetic mocap poses (exact arcs, stamps, noise, faults)."""

import math

import numpy as np
import pytest

from puzzlebot_driver.estimator import VelocityEstimator
from puzzlebot_common.model import unicycle_arc


def feed(est, v, w, stamps, pose0=(0.1, -0.2, 0.5)):
    for t in stamps:
        x, y, th = unicycle_arc(pose0, v, w, t - stamps[0])
        assert est.update(t, x, y, th) is None
    return est.velocity()


@pytest.mark.parametrize("v, w", [(0.05, 0.0), (0.04, 1.0), (-0.03, -2.0), (0.0, 1.5), (0.2, 6.0)])
def test_exact_on_arcs_in_the_robot_frame(v, w):
    est = VelocityEstimator(window=0.05, tau=0.03, max_gap=0.2)
    v_est, w_est = feed(est, v, w, [0.01 * k for k in range(60)])
    assert v_est == pytest.approx(v, abs=1e-9)
    assert w_est == pytest.approx(w, abs=1e-9)
    assert abs(est.lateral) < 1e-9


def test_heading_wraps_across_pi():
    est = VelocityEstimator(0.05, 0.0, 0.2)
    v_est, w_est = feed(est, 0.03, 2.0, [0.01 * k for k in range(40)], pose0=(0.0, 0.0, math.pi - 0.2))
    assert (v_est, w_est) == pytest.approx((0.03, 2.0), abs=1e-9)


def test_uses_stamps_not_arrival_order_spacing():
    """Irregular stamps (jittery Vicon bridge): the estimate follows the stamps."""
    rng = np.random.default_rng(1)
    stamps = np.cumsum(rng.uniform(0.005, 0.015, 80))
    est = VelocityEstimator(0.05, 0.03, 0.2)
    assert feed(est, 0.05, -0.7, list(stamps)) == pytest.approx((0.05, -0.7), abs=1e-9)


def test_noise_is_averaged():
    rng = np.random.default_rng(2)
    est = VelocityEstimator(0.05, 0.03, 0.2)
    errs = []
    for k in range(300):
        t = 0.01 * k
        x, y, th = unicycle_arc((0, 0, 0), 0.04, 0.5, t)
        est.update(t, x + rng.normal(0, 2e-4), y + rng.normal(0, 2e-4), th + rng.normal(0, 2e-3))
        if k > 20:
            errs.append(np.subtract(est.velocity(), (0.04, 0.5)))
    rms = np.sqrt(np.mean(np.square(errs), axis=0))
    assert rms[0] < 0.004       # m/s: 10 % of 0.04 m/s with 0.2 mm position noise
    assert rms[1] < 0.06        # rad/s


def test_rejects_bad_samples_and_restarts_after_a_gap():
    est = VelocityEstimator(0.05, 0.0, 0.2)
    assert est.velocity() is None
    assert est.update(1.0, 0.0, 0.0, 0.0) is None
    assert est.velocity() is None                       # one pose: no velocity yet
    assert "non-finite" in est.update(1.01, float("nan"), 0.0, 0.0)
    assert "not after" in est.update(1.0, 0.001, 0.0, 0.0)      # duplicate stamp
    assert "not after" in est.update(0.99, 0.001, 0.0, 0.0)     # out of order
    for k in range(1, 5):
        assert est.update(1.0 + 0.01 * k, 0.0005 * k, 0.0, 0.0) is None
        assert est.velocity() is None                   # 10..40 ms of poses: less than the window
    assert est.update(1.05, 0.0025, 0.0, 0.0) is None
    assert est.velocity() == pytest.approx((0.05, 0.0))
    # 0.5 s hidden, then 0.05 m further: no fake 0.1 m/s averaged over the gap
    assert est.update(1.55, 0.0525, 0.0, 0.0) is None
    assert est.velocity() is None
    for k in range(1, 6):
        assert est.velocity() is None
        assert est.update(1.55 + 0.01 * k, 0.0525 + 0.0005 * k, 0.0, 0.0) is None
    assert est.velocity() == pytest.approx((0.05, 0.0))


def test_first_estimate_after_a_restart_spans_the_window():
    """Resuming after a gap, the first estimate is a full-window difference: its error from 0.3 mm
    pose noise and 2 ms stamp jitter stays that of the window, not five times it (two poses 10 ms apart)."""
    rng = np.random.default_rng(3)
    worst = 0.0
    for trial in range(200):
        est = VelocityEstimator(0.05, 0.03, 0.2)
        t = 0.0
        while est.velocity() is None:
            x, y, th = unicycle_arc((0, 0, 0), 0.04, 0.3, t)
            stamp = t + rng.uniform(-0.002, 0.002)
            est.update(stamp, x + rng.normal(0, 3e-4), y + rng.normal(0, 3e-4), th + rng.normal(0, 3e-3))
            t += 0.01
        assert t >= 0.05
        worst = max(worst, abs(est.velocity()[0] - 0.04))
    assert worst < 0.04         # m/s: 0.025 here; the first pose pair 10 ms apart gave 0.13 m/s
