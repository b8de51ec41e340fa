"""The MPC formulation: coupling constraints, angle wrap, dynamics, solver agreement, fallbacks."""

import math
from dataclasses import replace

import numpy as np
import pytest

from puzzlebot_common.geometry import RobotGeometry, inverse_transform_point, point_in_polygon, transform_point
from puzzlebot_mpc.controller import MultiRobotMPC, Objectives, PairObjective
from puzzlebot_common.model import NX, euler_step, unicycle_arc
from puzzlebot_mpc.ocp import Problem, Structure, pair_residual_terms, param_vector
from puzzlebot_mpc.qp import pack
from puzzlebot_mpc.settings import MPCSettings

GEO = RobotGeometry()


def coupled_pair_objective():
    return PairObjective(0, 1, GEO.anchor_point(), GEO.opening_point(), coupled=True, head=GEO.anchor_head(),
                         polygon=GEO.front_triangle())


def test_pip_rows_of_the_problem_agree_with_ray_casting_on_random_poses():
    """The OCP's coupling rows (k = 1, slack 0, no margin) say 'inside' exactly when the anchor
    head lies in the opening robot's front triangle by an independent test."""
    s = MPCSettings(horizon=2, constraint_horizon=1, pip_margin=0.0, butterfly=False)
    prob = Problem(s, Structure(2, 2, 1, ((0, 1),)))
    g_fn = prob.residual_function()
    lay = prob.lay
    rng = np.random.default_rng(3)
    tri = GEO.front_triangle()
    agree = inside_count = 0
    for _ in range(400):
        pose_j = (rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(-math.pi, math.pi))
        # anchor robot near the coupled position, jittered so the head lands in and out of the triangle
        rel = (0.05 + rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03), rng.uniform(-0.6, 0.6))
        pose_i = (*transform_point(pose_j, rel[:2]), pose_j[2] + rel[2])
        x0 = np.array([[*pose_i, 0, 0], [*pose_j, 0, 0]])
        obj = Objectives.stop_all(2)
        obj.pairs = [coupled_pair_objective()]
        p = param_vector(prob.par, pack(s, x0, obj, obj.pairs))
        z = np.zeros(lay.nz)
        z[lay.x_idx[1]] = x0                       # stage 1 = the poses under test
        _, ineq = g_fn(z, p)
        ineq = np.asarray(ineq).ravel()
        pip = ineq[-6:-2]                          # the 4 polygon rows of the pair at k = 1
        head = inverse_transform_point(pose_j, transform_point(pose_i, GEO.anchor_head()))
        ref = point_in_polygon(tri, head)
        inside_count += ref
        agree += (pip.max() <= 0) == ref
    assert agree == 400
    assert 50 < inside_count < 350      # both cases were exercised


@pytest.mark.parametrize("delta", [1e-3, 0.05, 0.3])
def test_tan_half_angle_wraps_at_pi(delta):
    """Headings just either side of +-pi are close: the cost is small and equals the unwrapped one."""
    import casadi as ca

    xi = ca.DM([0, 0, math.pi - delta, 0, 0])
    xj = ca.DM([0, 0, -math.pi + delta, 0, 0])
    pt_i, pt_j = ca.DM(GEO.anchor_point()), ca.DM(GEO.opening_point())
    _, t_wrapped = pair_residual_terms(xi, xj, pt_i, pt_j)
    _, t_plain = pair_residual_terms(ca.DM([0, 0, -2 * delta, 0, 0]), ca.DM([0, 0, 0, 0, 0]), pt_i, pt_j)
    assert float(t_wrapped) ** 2 == pytest.approx(float(t_plain) ** 2, rel=1e-9)
    assert float(t_wrapped) ** 2 == pytest.approx(math.tan(delta) ** 2, rel=1e-9)
    # and a full turn makes no difference at all
    _, t_turn = pair_residual_terms(ca.DM([0, 0, math.pi - delta + 2 * math.pi, 0, 0]), xj, pt_i, pt_j)
    assert float(t_turn) == pytest.approx(float(t_wrapped), abs=1e-9)


def test_dynamics_rows_vanish_on_an_euler_rollout_and_prediction_is_euler():
    s = MPCSettings(horizon=5, constraint_horizon=2)
    mpc = MultiRobotMPC(s, 2).setup()
    x0 = np.array([[0.0, 0.0, 0.3, 0.02, 0.1], [0.1, 0.05, -1.0, 0.0, 0.0]])
    obj = Objectives.stop_all(2)
    obj.velocity[:] = [(0.03, 0.4), (-0.02, -0.3)]
    res = mpc.make_step(x0, obj)
    assert res.success
    X = res.predicted
    for i in range(2):
        for k in range(s.horizon):
            u = (X[i, k + 1, 3:] - X[i, k, 3:]) / s.dt
            assert np.allclose(euler_step(X[i, k], u, s.dt), X[i, k + 1], atol=1e-9)
    # the Euler prediction of the first step is close to the closed form of the same command
    v, w = res.commands[0]
    exact = unicycle_arc(x0[0, :3], v, w, s.dt)
    assert np.allclose(X[0, 1, :3], exact, atol=abs(v) * abs(w) * s.dt ** 2)


def test_rti_and_ipopt_agree_on_a_coupled_pair_driving():
    base = MPCSettings(horizon=6, constraint_horizon=3)
    x0 = np.array([[0.05, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0]])
    obj = Objectives.stop_all(2)
    obj.velocity[:] = [(0.03, 0.2), (0.03, 0.0)]
    obj.velocity_mask = np.array([[1.0, 1.0], [1.0, 0.0]])
    obj.pairs = [coupled_pair_objective()]
    out = {}
    for solver in ("active_set", "clarabel", "ipopt"):
        mpc = MultiRobotMPC(replace(base, solver=solver, sqp_iterations_cold=8), 2).setup()
        out[solver] = mpc.make_step(x0, obj)
        assert out[solver].success, out[solver].status
    for rti in ("active_set", "clarabel"):
        assert out[rti].cost == pytest.approx(out["ipopt"].cost, rel=0.02, abs=1e-4)
        assert np.allclose(out[rti].commands, out["ipopt"].commands, atol=2e-3)
    assert np.allclose(out["active_set"].commands, out["clarabel"].commands, atol=1e-5)


def test_coupled_pair_never_infeasible_even_when_already_outside():
    """A measured state with the head outside the polygon is pulled back, not reported infeasible."""
    s = MPCSettings(horizon=5, constraint_horizon=3)
    mpc = MultiRobotMPC(s, 2).setup()
    x0 = np.array([[0.075, 0.02, 0.4, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0]])   # head 12 mm out of the triangle
    obj = Objectives.stop_all(2)
    obj.pairs = [coupled_pair_objective()]
    res = mpc.make_step(x0, obj)
    assert res.success and res.fallback == ""
    assert res.extra["max_pip_slack"] > 1e-3           # the violation is reported through the slack ...
    tri = GEO.front_triangle()
    h0 = inverse_transform_point(x0[1, :3], transform_point(x0[0, :3], GEO.anchor_head()))
    hk = inverse_transform_point(res.predicted[1, -1, :3], transform_point(res.predicted[0, -1, :3],
                                                                          GEO.anchor_head()))
    from puzzlebot_common.geometry import signed_margin
    assert signed_margin(tri, hk) > signed_margin(tri, h0)   # ... and the plan moves the head back in


def test_failed_solve_stops_every_robot_and_is_reported():
    s = MPCSettings(horizon=5, max_iter=1)          # one interior-point iteration cannot converge
    mpc = MultiRobotMPC(s, 2).setup()
    obj = Objectives.stop_all(2)
    obj.goal[:] = [(0.3, 0.0), (0.0, 0.3)]
    obj.goal_mask[:] = True
    obj.velocity_mask[:] = False
    res = mpc.make_step(np.zeros((2, NX)), obj)
    assert not res.success and res.fallback == "stop"
    assert np.all(res.commands == 0.0)
    assert "MaxIterations" in res.status


def test_butterfly_no_turning_in_place():
    """Commanded turn rates respect |w| <= (w_max / v_max) |v| + w_free along the whole plan."""
    s = MPCSettings()
    mpc = MultiRobotMPC(s, 1).setup()
    obj = Objectives.stop_all(1)
    obj.velocity[:] = [(0.0, 1.0)]                  # ask for a pure rotation
    x = np.zeros((1, NX))
    for _ in range(10):
        res = mpc.make_step(x, obj)
        assert res.success
        V = res.predicted[0, :, 3:]
        assert np.all(np.abs(V[:, 1]) <= s.w_max / s.v_max * np.abs(V[:, 0]) + s.w_free + 1e-6)
        x = res.predicted[:, 1].copy()
