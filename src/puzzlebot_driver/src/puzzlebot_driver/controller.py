"""Velocity loop of one robot: commanded (v, w) and estimated (v, w) -> wheel PWM.

A PI controller per channel in velocity units around a feed-forward::

    v_out = v_cmd + kp_v (v_cmd - v_est) + I_v,   I_v' = ki_v (v_cmd - v_est)
    w_out = w_cmd + kp_w (w_cmd - w_est) + I_w,   I_w' = ki_w (w_cmd - w_est)
    left  = pwm_per_v v_out - pwm_per_w w_out + trim_left
    right = pwm_per_v v_out + pwm_per_w w_out + trim_right

then ``pwm_deadband`` is added in the direction of each moving wheel and,
if a wheel exceeds ``pwm_max``, both wheels are scaled down by the same
factor (the turn ratio is kept). Anti-windup: the integrators are clamped to
``i_max_v`` / ``i_max_w`` and do not integrate while the output is saturated
in the direction that would grow the error. Without a velocity estimate
(the first poses) only the feed-forward acts.

Nothing non-finite reaches ``round()``: a non-finite input or output gives
PWM 0 with ``invalid`` set (and the integrators reset); the caller logs it.
"""

import math
from dataclasses import dataclass


@dataclass
class WheelCommand:
    left: int                # PWM, -pwm_max..pwm_max
    right: int
    saturated: bool = False  # the output was scaled down to pwm_max
    invalid: str = ""        # why the output is zero instead (non-finite input or output), "" if valid


def _finite(*xs):
    return all(math.isfinite(x) for x in xs)


def _clamp(x, limit):
    return max(-limit, min(limit, x))


class WheelController:
    """PI velocity loop with PWM mapping for one robot (gains: params.ControlGains)."""

    def __init__(self, gains):
        self.gains = gains
        self.i_v = 0.0     # m/s, integral term of v
        self.i_w = 0.0     # rad/s, integral term of w

    def reset(self):
        self.i_v = self.i_w = 0.0

    def pwm(self, v_out, w_out):
        """Unclipped wheel PWM (floats) of body velocities through the feed-forward and trims."""
        g = self.gains
        pv, pw = g.pwm_per_v * v_out, g.pwm_per_w * w_out
        left, right = pv - pw + g.trim_left, pv + pw + g.trim_right
        if g.pwm_deadband > 0:
            left = left + math.copysign(g.pwm_deadband, left) if abs(left) >= 0.5 else 0.0
            right = right + math.copysign(g.pwm_deadband, right) if abs(right) >= 0.5 else 0.0
        return left, right

    def step(self, v_cmd, w_cmd, estimate, dt):
        """One loop step; ``estimate`` is (v_est, w_est) or None; dt [s] since the last step."""
        g = self.gains
        if not _finite(v_cmd, w_cmd, dt) or (estimate is not None and not _finite(*estimate)):
            self.reset()
            return WheelCommand(0, 0, invalid="non-finite input (cmd %r, %r, estimate %r, dt %r)"
                                % (v_cmd, w_cmd, estimate, dt))
        if estimate is None:
            e_v = e_w = 0.0
        else:
            e_v, e_w = v_cmd - estimate[0], w_cmd - estimate[1]
        v_out = v_cmd + g.kp_v * e_v + self.i_v
        w_out = w_cmd + g.kp_w * e_w + self.i_w
        left, right = self.pwm(v_out, w_out)
        if not _finite(left, right):
            self.reset()
            return WheelCommand(0, 0, invalid="non-finite PWM (%r, %r) from v_out %r, w_out %r"
                                % (left, right, v_out, w_out))
        peak = max(abs(left), abs(right))
        saturated = peak > g.pwm_max
        if saturated:
            scale = g.pwm_max / peak
            left, right = left * scale, right * scale
        if estimate is not None and dt > 0:
            # Conditional integration: while saturated, only integrate errors that shrink the output.
            if not saturated or e_v * v_out < 0:
                self.i_v = _clamp(self.i_v + g.ki_v * e_v * dt, g.i_max_v)
            if not saturated or e_w * w_out < 0:
                self.i_w = _clamp(self.i_w + g.ki_w * e_w * dt, g.i_max_w)
        cap = g.pwm_max
        return WheelCommand(int(_clamp(round(left), cap)), int(_clamp(round(right), cap)), saturated)
