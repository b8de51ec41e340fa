"""PI velocity loop and PWM mapping, on an analytic first-order motor model."""

import math

import pytest

from puzzlebot_driver.controller import WheelController
from puzzlebot_driver.params import ControlGains


def first_order_run(gains, v_cmd, w_cmd, plant_gain=(0.85, 0.95), tau=0.1, seconds=3.0, dt=1.0 / 30, sub=10,
                    wheel_base=0.04, mps_per_pwm=0.0007):
    """Controller at 30 Hz on wheels with speed' = (k pwm - speed) / tau; returns (t, v, w) samples."""
    ctrl = WheelController(gains)
    sl = sr = 0.0
    out = []
    for k in range(int(round(seconds / dt))):
        v, w = 0.5 * (sl + sr), (sr - sl) / wheel_base
        out.append((k * dt, v, w))
        cmd = ctrl.step(v_cmd, w_cmd, (v, w), dt)
        for _ in range(sub):
            h = dt / sub
            sl += h * (plant_gain[0] * mps_per_pwm * cmd.left - sl) / tau
            sr += h * (plant_gain[1] * mps_per_pwm * cmd.right - sr) / tau
    return out


def test_pi_converges_on_a_first_order_motor_model():
    # Motors 15 % and 5 % weaker than nominal: open loop, v is 10 % low and w 25 % high.
    out = first_order_run(ControlGains(), 0.05, 0.5)
    t, v, w = out[-1]
    assert v == pytest.approx(0.05, rel=0.01)
    assert w == pytest.approx(0.5, rel=0.01)
    after_1s = [(v, w) for t, v, w in out if t >= 1.0]
    assert all(abs(v - 0.05) < 0.005 and abs(w - 0.5) < 0.05 for v, w in after_1s)


def test_without_integral_action_an_error_remains():
    """The same plant with P only: the integrator is what removes the error."""
    out = first_order_run(ControlGains(ki_v=0.0, ki_w=0.0), 0.05, 0.5)
    _, v, w = out[-1]
    assert abs(v - 0.05) > 0.001 and abs(w - 0.5) > 0.02


def test_feed_forward_and_trims():
    g = ControlGains(pwm_per_v=1000.0, pwm_per_w=20.0, trim_left=2.0, trim_right=-1.0)
    cmd = WheelController(g).step(0.05, 1.0, None, 1 / 30)        # no estimate: feed-forward only
    assert (cmd.left, cmd.right) == (50 - 20 + 2, 50 + 20 - 1)


def test_deadband_compensation_pushes_moving_wheels_out():
    g = ControlGains(pwm_per_v=1000.0, pwm_per_w=20.0, pwm_deadband=10.0)
    assert WheelController(g).pwm(0.02, 0.0) == (30.0, 30.0)
    assert WheelController(g).pwm(-0.02, 0.0) == (-30.0, -30.0)
    assert WheelController(g).pwm(0.0, 0.0) == (0.0, 0.0)


def test_saturation_keeps_the_turn_ratio_and_the_cap():
    g = ControlGains(pwm_per_v=1428.6, pwm_per_w=28.6, pwm_max=180)
    cmd = WheelController(g).step(0.2, 6.0, None, 1 / 30)
    assert cmd.saturated
    assert max(abs(cmd.left), abs(cmd.right)) == 180
    raw = WheelController(g).pwm(0.2, 6.0)
    assert cmd.left / cmd.right == pytest.approx(raw[0] / raw[1], rel=0.02)


def test_anti_windup_bounds_the_integrator():
    g = ControlGains()
    ctrl = WheelController(g)
    for _ in range(300):                      # 10 s of a robot held in place (stalled)
        ctrl.step(0.2, 0.0, (0.0, 0.0), 1 / 30)
    assert abs(ctrl.i_v) <= g.i_max_v + 1e-12
    # Released: the stalled history does not make it overshoot for long.
    ctrl2 = WheelController(g)
    for _ in range(300):
        ctrl2.step(0.05, 0.0, (0.0, 0.0), 1 / 30)
    assert ctrl2.i_v == pytest.approx(g.i_max_v)
    ctrl2.reset()
    assert ctrl2.i_v == 0.0 and ctrl2.i_w == 0.0


def test_output_is_integer_and_within_the_cap():
    ctrl = WheelController(ControlGains(pwm_max=120))
    for v, w in [(0.2, 0.0), (-0.2, 0.0), (0.0, 6.0), (0.1, -6.0), (0.01, 0.1)]:
        cmd = ctrl.step(v, w, (0.0, 0.0), 1 / 30)
        assert isinstance(cmd.left, int) and isinstance(cmd.right, int)
        assert abs(cmd.left) <= 120 and abs(cmd.right) <= 120
        assert not math.isnan(cmd.left)
