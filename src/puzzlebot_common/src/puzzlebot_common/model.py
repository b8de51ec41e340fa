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


def euler_rollout(x0, u, dt):
    """States of H Euler steps from ``x0`` (n, NX) under the inputs ``u`` (n, H, NU): (n, H + 1, NX), x0
    first; numpy only. The same numbers as H calls of euler_step: each state is the running sum of its
    increments (np.cumsum adds them in turn, as the steps do), in a few array operations for all stages."""
    x0, u = np.asarray(x0, dtype=float), np.asarray(u, dtype=float)

    def run(first, increments):                 # (n,), (n, H) -> (n, H + 1)
        return np.cumsum(np.concatenate([first[:, None], increments], axis=1), axis=1)

    v = run(x0[:, 3], dt * u[:, :, 0])
    w = run(x0[:, 4], dt * u[:, :, 1])
    th = run(x0[:, 2], dt * w[:, :-1])
    step = dt * v[:, :-1]
    X = np.empty(v.shape + (NX,))
    X[:, :, 0] = run(x0[:, 0], step * np.cos(th[:, :-1]))
    X[:, :, 1] = run(x0[:, 1], step * np.sin(th[:, :-1]))
    X[:, :, 2], X[:, :, 3], X[:, :, 4] = th, v, w
    return X


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
