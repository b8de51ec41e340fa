"""The unicycle model of the paper, defined once for every user.

State per robot ``x = [px, py, theta, v, w]`` (world frame; m, m, rad, m/s,
rad/s), input ``u = [dv, dw]`` (m/s^2, rad/s^2). Continuous dynamics::

    px' = v cos(theta),  py' = v sin(theta),  theta' = w,  v' = dv,  w' = dw

discretised with one explicit Euler step of ``dt`` seconds. The same function
works on numpy arrays (plants, tests, identification) and on CasADi symbols
(the MPC), so there is exactly one definition of the model.
"""

import math

import numpy as np

STATE_NAMES = ("px", "py", "theta", "v", "w")
INPUT_NAMES = ("dv", "dw")
NX = len(STATE_NAMES)
NU = len(INPUT_NAMES)


def _vstack(items, like):
    try:
        import casadi as ca

        if isinstance(like, (ca.SX, ca.MX, ca.DM)):
            return ca.vertcat(*items)
    except ImportError:  # pragma: no cover - casadi is a declared dependency
        pass
    return np.array(items, dtype=float)


def _trig(like):
    try:
        import casadi as ca

        if isinstance(like, (ca.SX, ca.MX, ca.DM)):
            return ca.cos, ca.sin
    except ImportError:  # pragma: no cover
        pass
    return np.cos, np.sin


def euler_step(x, u, dt):
    """One Euler step of the unicycle: returns x(t + dt) for state x, input u."""
    cos, sin = _trig(x)
    px, py, th, v, w = (x[i] for i in range(NX))
    dv, dw = u[0], u[1]
    return _vstack([px + dt * v * cos(th),
                    py + dt * v * sin(th),
                    th + dt * w,
                    v + dt * dv,
                    w + dt * dw], x)


def unicycle_arc(pose, v, w, t):
    """Exact pose after driving (v, w) constant for t seconds from ``pose``.

    The closed form the Euler discretisation approximates; used by tests and
    by the simple kinematic plant.
    """
    x, y, th = pose
    if abs(w) < 1e-9:
        return np.array([x + v * t * math.cos(th), y + v * t * math.sin(th), th])
    th1 = th + w * t
    r = v / w
    return np.array([x + r * (math.sin(th1) - math.sin(th)),
                     y - r * (math.cos(th1) - math.cos(th)),
                     th1])
