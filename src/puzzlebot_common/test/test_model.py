import math

import casadi as ca
import numpy as np
import pytest

from puzzlebot_common import model
from puzzlebot_common.model import NX, euler_step, unicycle_arc


def euler_rollout(pose, v, w, t, dt):
    x = np.array([*pose, v, w])
    for _ in range(int(round(t / dt))):
        x = euler_step(x, np.zeros(2), dt)
    return x


@pytest.mark.parametrize("v, w", [(0.05, 0.0), (0.05, 1.0), (-0.03, -0.7), (0.0, 1.5)])
def test_euler_converges_to_closed_form_at_first_order(v, w):
    pose, t = (0.1, -0.2, 0.4), 1.0
    exact = unicycle_arc(pose, v, w, t)
    errors = []
    for dt in (0.1, 0.05, 0.025):
        x = euler_rollout(pose, v, w, t, dt)
        errors.append(np.hypot(*(x[:2] - exact[:2])))
        assert x[2] == pytest.approx(exact[2])
    if errors[0] > 1e-12:
        assert errors[1] == pytest.approx(errors[0] / 2, rel=0.1)
        assert errors[2] == pytest.approx(errors[1] / 2, rel=0.1)
    assert errors[0] < 0.003  # dt = 0.1 s over 1 s: within 3 mm at these speeds


def test_straight_line_closed_form():
    assert np.allclose(unicycle_arc((0, 0, math.pi / 2), 0.05, 0.0, 2.0), (0, 0.1, math.pi / 2))


def test_same_function_for_numpy_and_casadi():
    x = ca.SX.sym("x", NX)
    u = ca.SX.sym("u", 2)
    f = ca.Function("f", [x, u], [euler_step(x, u, 0.1)])
    x0, u0 = np.array([0.1, 0.2, 0.3, 0.04, -0.5]), np.array([1.0, -2.0])
    assert np.allclose(np.asarray(f(x0, u0)).ravel(), euler_step(x0, u0, 0.1))


def test_rollout_gives_the_numbers_of_the_euler_steps_in_turn():
    rng = np.random.default_rng(3)
    x0, u = rng.uniform(-2, 2, (6, NX)), rng.uniform(-3, 3, (6, 10, 2))
    X = model.euler_rollout(x0, u, 0.1)
    assert X.shape == (6, 11, NX) and np.array_equal(X[:, 0], x0)
    x = x0.T
    for k in range(10):
        x = euler_step(x, u[:, k].T, 0.1)
        assert np.array_equal(X[:, k + 1], x.T)     # the same numbers, not only close ones
