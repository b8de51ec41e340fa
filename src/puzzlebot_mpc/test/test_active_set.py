"""The active-set QP solver (active_set.py) against Clarabel: random sparse QPs, the MPC's QPs, and the
MPC's closed-loop steps with either solver."""

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from puzzlebot_common.model import unicycle_arc
from puzzlebot_mpc.active_set import AT_LOWER, AT_UPPER, ActiveSetQP
from puzzlebot_mpc import controller
from puzzlebot_mpc.controller import MultiRobotMPC
from puzzlebot_mpc.settings import MPCSettings

from test_qp import CASES, case_problem, chain_scene, random_step_data

clarabel = pytest.importorskip("clarabel")


def clarabel_solve(P, q, A, b, n_eq, lb, ub, tol=1e-10):
    """Reference: Clarabel on the same QP, bounds as rows."""
    nz = P.shape[0]
    I = sp.identity(nz, format="csc")
    up, lo = np.isfinite(ub), np.isfinite(lb)
    AA = sp.vstack([A, I[up], -I[lo]], format="csc")
    bb = np.concatenate([b, ub[up], -lb[lo]])
    o = clarabel.DefaultSettings()
    o.verbose = False
    o.tol_gap_abs = o.tol_gap_rel = o.tol_feas = tol
    o.tol_ktratio = 10 * tol
    sol = clarabel.DefaultSolver(sp.triu(P, format="csc"), q, AA, bb,
                                 [clarabel.ZeroConeT(n_eq), clarabel.NonnegativeConeT(AA.shape[0] - n_eq)],
                                 o).solve()
    assert str(sol.status) == "Solved"
    return np.asarray(sol.x)


def random_qp(rng, nz=40, n_eq=10, n_in=25):
    """A feasible sparse convex QP: P = J'J (rank-deficient, plus a small diagonal on some variables),
    random rows, and bounds around a feasible point (some infinite, some lb == ub)."""
    J = sp.random(nz // 2, nz, density=0.15, random_state=rng, format="csc")
    P = (J.T @ J).tocsc() + sp.diags(np.where(rng.random(nz) < 0.5, 1e-2, 0.0))
    P = (P + sp.identity(nz) * 1e-6).tocsc()
    A = sp.random(n_eq + n_in, nz, density=0.12, random_state=rng, format="csc")
    A = (A + sp.hstack([sp.identity(n_eq + n_in), sp.csc_matrix((n_eq + n_in, nz - n_eq - n_in))])).tocsc()
    z0 = rng.normal(size=nz)
    b = A @ z0
    b[n_eq:] += rng.uniform(0, 1, n_in) * (rng.random(n_in) < 0.6)
    lb = z0 - rng.uniform(0, 1, nz)
    ub = z0 + rng.uniform(0, 1, nz)
    lb[rng.random(nz) < 0.2] = -np.inf
    ub[rng.random(nz) < 0.2] = np.inf
    fix = rng.random(nz) < 0.05
    lb[fix] = ub[fix] = z0[fix]
    q = rng.normal(size=nz) * 3
    return P, q, A, b, n_eq, lb, ub


def solver_for(P, A, n_eq, **kw):
    Pu = sp.triu(P, format="csc")
    Pu.sort_indices()
    A = A.tocsc()
    A.sort_indices()
    return ActiveSetQP(P.shape[0], Pu.indices, Pu.indptr, A.shape[0], A.indices, A.indptr, n_eq, **kw), Pu, A


def test_random_qps_match_clarabel_cold_and_warm():
    """From no working set (one index changed at a time once the full updates stop making progress) and
    from the working set of a perturbed problem: every QP reported solved has Clarabel's solution (to
    1e-6) and is a KKT point (multipliers of the right sign, rows and bounds held); nearly all cold
    starts get there, the warm ones in a few working sets."""
    rng = np.random.default_rng(3)
    warm_iters, cold_iters, unsolved = [], [], 0
    for trial in range(30):
        P, q, A, b, n_eq, lb, ub = random_qp(rng)
        solver, Pu, A = solver_for(P, A, n_eq, max_iter=200)
        ref = clarabel_solve(P, q, A, b, n_eq, lb, ub)
        res = solver.solve(Pu.data, q, A.data, b, lb, ub)
        if not res.solved:
            unsolved += 1
            continue
        cold_iters.append(res.iterations)
        scale = 1 + np.abs(ref).max()
        assert np.abs(res.z - ref).max() <= 1e-6 * scale
        obj_ref = 0.5 * ref @ P @ ref + q @ ref
        assert res.obj == pytest.approx(obj_ref, rel=1e-8, abs=1e-8)
        assert np.abs(A[:n_eq] @ res.z - b[:n_eq]).max() <= 1e-9
        assert (A[n_eq:] @ res.z - b[n_eq:]).max() <= 1e-8
        assert np.all(res.z >= lb - 1e-9) and np.all(res.z <= ub + 1e-9)
        assert res.y[n_eq:].min() >= -1e-6
        at_lb, at_ub = res.working.bounds == AT_LOWER, res.working.bounds == AT_UPPER
        free = ~(at_lb | at_ub | (lb == ub))
        assert res.bound_duals[at_lb & (lb < ub)].min(initial=0.0) >= -1e-6
        assert res.bound_duals[at_ub].max(initial=0.0) <= 1e-6
        assert np.all(res.bound_duals[free] == 0.0)
        # a nearby problem from the working set of this one
        q2 = q + rng.normal(size=q.size) * 0.05
        res2 = solver.solve(Pu.data, q2, A.data, b, lb, ub, res.working)
        assert res2.solved
        warm_iters.append(res2.iterations)
        assert np.abs(res2.z - clarabel_solve(P, q2, A, b, n_eq, lb, ub)).max() <= 1e-6 * scale
    assert unsolved <= 3
    assert np.mean(warm_iters) < 0.25 * np.mean(cold_iters)


def test_gives_up_after_max_iter_and_on_non_finite_data():
    rng = np.random.default_rng(5)
    P, q, A, b, n_eq, lb, ub = random_qp(rng)
    solver, Pu, A = solver_for(P, A, n_eq, max_iter=1)
    res = solver.solve(Pu.data, q, A.data, b, lb, ub)
    assert not res.solved and res.iterations == 1          # the cold start's working set changes
    bad = Pu.data.copy()
    bad[0] = np.nan
    assert not solver.solve(bad, q, A.data, b, lb, ub).solved


def test_rejects_a_lower_triangle():
    P = sp.csc_matrix(np.array([[2.0, 0.0], [1.0, 2.0]]))
    with pytest.raises(ValueError, match="upper triangle"):
        ActiveSetQP(2, P.indices, P.indptr, 0, np.zeros(0, int), np.zeros(3, int), 0)


@pytest.mark.parametrize("case", range(len(CASES)))
def test_mpc_qps_match_clarabel(case):
    """The MPC's QP (qp.py, its single-variable rows as bounds) at random linearisation points, states,
    objectives and butterfly cones (a random cone per stage: far harder than a real step's), against
    Clarabel on the QP with every row: started from the working set of Clarabel's solution it is solved,
    with Clarabel's optimal cost (to its tolerance) and a feasible point; from every slack at zero, when
    it is solved, the same. (Random masks leave some robots without any cost on their command: the
    optimum is not unique there, an interior point returns the middle of the optimal set.)"""
    s, st = case_problem(case)
    wrapper = controller._ActiveSetQP(s, st)
    qs, solver = wrapper.qs, wrapper.solver
    solver.max_iter = 200
    rng = np.random.default_rng(case)
    for _ in range(3):
        d = random_step_data(rng, case, s)
        zbar = rng.normal(size=qs.lay.nz) * 0.05
        Px, q, Ax, b = qs.assemble(zbar, d)
        Ag, bg, lb, ub = qs.bounded(Ax, b)
        P, A = qs.matrices(Px, Ax)
        ref = clarabel_solve(P + sp.triu(P, 1).T, q, A, b, qs.n_eq, np.full(qs.lay.nz, -np.inf),
                             np.full(qs.lay.nz, np.inf))
        scale = 1 + np.abs(ref).max()
        ipm = controller._ClarabelQP(replace(s, qp_tolerance=1e-10), st, qs=qs)
        ipm.solve_data(replace(s, qp_tolerance=1e-10), Px, q, Ax, b)
        ref[qs.slack_solver] = np.maximum(ref[qs.slack_solver], 0.0)
        best = solver.objective(Px, q, ref)
        ws = solver.cold_working_set()
        ws.bounds[qs.slack_solver] = AT_LOWER
        for start, one in ((wrapper._working_set_of(ipm.last, Ax), True), (ws, False)):
            res = solver.solve(Px, q, Ag, bg, lb, ub, start)
            if one:
                assert res.solved
            if res.solved:
                # never worse than Clarabel's (at 1e-10), at most its tolerance better
                assert best - 1e-6 * abs(best) <= res.obj <= best + 1e-9 * (1 + abs(best))
                assert np.abs(A @ res.z - b)[:qs.n_eq].max() <= 1e-9
                assert (A @ res.z - b)[qs.n_eq:].max() <= 1e-9


def step_plant(x, commands, dt):
    for i in range(len(x)):
        x[i, :3] = unicycle_arc(x[i, :3], commands[i, 0], commands[i, 1], dt)
        x[i, 3:] = commands[i]


def test_closed_loop_steps_equal_clarabel():
    """The MPC with either solver on the kinematic plant, from the same start (a coupled chain turning, an
    active pair docking, a robot with a goal, one at rest; lobe search included): the same commands and
    costs within the solvers' tolerance, step after step (each linearises at its own previous plan, whose
    weakly determined stages differ by ~1e-5: commands to 2e-4, costs to 1e-6), with a fraction of
    Clarabel's factorizations once warm."""
    s = MPCSettings(horizon=8, constraint_horizon=3, qp_tolerance=1e-9)
    x0, obj = chain_scene()
    n = len(x0)
    ref = MultiRobotMPC(replace(s, solver="clarabel"), n).setup()
    act = MultiRobotMPC(replace(s, solver="active_set"), n).setup()
    xa, xb = x0.copy(), x0.copy()
    iters_ref, iters_act = 0, 0
    for step in range(15):
        ra, rb = ref.make_step(xa, obj), act.make_step(xb, obj)
        assert ra.success and rb.success, (ra.status, rb.status)
        assert np.allclose(ra.commands, rb.commands, atol=1e-9 if step == 0 else 2e-4)
        assert rb.cost == pytest.approx(ra.cost, rel=1e-6)
        if step > 0:
            assert rb.status == "Solved"
            iters_ref += ra.iterations
            iters_act += rb.iterations
        step_plant(xa, ra.commands, s.dt)
        step_plant(xb, rb.commands, s.dt)
    assert iters_act < 0.25 * iters_ref


def test_falls_back_to_clarabel_with_the_same_result():
    """One working set allowed: the cold step's later QPs (its first is Clarabel's anyway) need more and
    fall back to Clarabel (the status says so), with Clarabel's plan; Clarabel's working sets then start
    the next QPs, some of which one working set solves."""
    s = MPCSettings(horizon=6, constraint_horizon=3, qp_tolerance=1e-9)
    x0, obj = chain_scene()
    obj.velocity[0] = (0.2, 0.0)                          # beyond v_max: the velocity bounds are active
    n = len(x0)
    ref = MultiRobotMPC(replace(s, solver="clarabel"), n).setup()
    one = MultiRobotMPC(replace(s, solver="active_set", active_set_iterations=1), n).setup()
    ra, rb = ref.make_step(x0, obj), one.make_step(x0, obj)
    assert rb.success and "Clarabel fallback" in rb.status
    assert np.allclose(ra.commands, rb.commands, atol=1e-6)
    xa, xb = x0.copy(), x0.copy()
    statuses = []
    for _ in range(5):
        step_plant(xa, ra.commands, s.dt)
        step_plant(xb, rb.commands, s.dt)
        ra, rb = ref.make_step(xa, obj), one.make_step(xb, obj)
        assert rb.success
        assert np.allclose(ra.commands, rb.commands, atol=5e-5)
        statuses.append(rb.status)
    assert "Solved" in statuses
