"""The numpy QP (qp.py) against the symbolic reference (ocp.py), decomposition against the joint problem,
and pair changes that must not rebuild anything."""

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_common.model import NX, unicycle_arc
from puzzlebot_mpc import controller
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.controller import MultiRobotMPC, Objectives, PairObjective, components
from puzzlebot_mpc.ocp import Problem, Structure, param_vector
from puzzlebot_mpc.qp import QPStructure, pack
from puzzlebot_mpc.settings import MPCSettings

GEO = RobotGeometry()


def anchor_pair(i, j, active=False, coupled=False):
    return PairObjective(i, j, GEO.anchor_point(), GEO.opening_point(), active=active, coupled=coupled,
                         head=GEO.anchor_head(), polygon=GEO.front_triangle(), yaw_limit=0.5)


def knob_pair(i, j, coupled=False):
    return PairObjective(i, j, GEO.knob_point(), GEO.hole_point(), coupled=coupled, head=GEO.knob_point()[:2],
                         polygon=GEO.knob_region(), yaw_limit=0.1)


def random_case(rng, n, pairs, settings):
    """Random states and objectives (goals, references of every kind, masks) for n robots."""
    x0 = np.c_[rng.normal(size=(n, 2)) * 0.05, rng.uniform(-3.5, 3.5, n), rng.uniform(-0.05, 0.05, n),
               rng.uniform(-1.5, 1.5, n)]
    vel = rng.normal(size=(n, settings.horizon, 2)) * 0.03 if rng.random() < 0.5 else rng.normal(size=(n, 2)) * 0.03
    mask = rng.uniform(0, 3, (n, 2)) * (rng.random((n, 2)) < 0.7)
    obj = Objectives(rng.normal(size=(n, 2)) * 0.1, rng.random(n) < 0.5, vel, mask, pairs)
    return x0, obj


def reference_qp(settings, st, zbar, d):
    """Dense P (symmetric), q, (A | b) rows of the zero cone and of the nonnegative cone, cost at zbar: ocp.py."""
    prob = Problem(settings, st)
    f, dims = prob.qp_function()
    p = param_vector(prob.par, d)
    data = np.asarray(f(zbar, p)).ravel()
    nz, nP, nA = prob.lay.nz, dims["P"].nnz(), dims["A"].nnz()
    P = sp.csc_matrix((data[:nP], dims["P"].row(), dims["P"].colind()), shape=(nz, nz)).toarray()
    q = data[nP:nP + nz]
    A = sp.csc_matrix((data[nP + nz:nP + nz + nA], dims["A"].row(), dims["A"].colind()),
                      shape=(dims["n_eq"] + dims["n_in"], nz)).toarray()
    b = data[nP + nz + nA:]
    return P, q, A, b, dims["n_eq"], float(prob.cost_function()(zbar, p))


def sorted_rows(A, b):
    M = np.c_[A, b]
    return M[np.lexsort(np.round(M, 9).T[::-1])]


CASES = [
    # (settings overrides, robots, pair slots)
    ({}, 3, [anchor_pair(0, 1, coupled=True), anchor_pair(1, 2, active=True)]),
    ({"butterfly": False, "horizon": 3, "constraint_horizon": 3}, 3, [anchor_pair(2, 0, coupled=True)]),
    ({"dv_max": 0.3, "dw_max": 2.0}, 4, [anchor_pair(0, 1), knob_pair(1, 3, coupled=True),
                                          anchor_pair(2, 3, active=True)]),
    ({"horizon": 1, "constraint_horizon": 1}, 2, [anchor_pair(0, 1, coupled=True)]),
    ({}, 2, []),
]


def case_problem(case, edges=False):
    """Settings (horizon 4, constraint horizon 2 unless the case overrides them) and Structure of CASES[case]
    (with the edge-box rows: ``edges``)."""
    over, n, pairs = CASES[case]
    s = replace(MPCSettings(horizon=4, constraint_horizon=2), **over)
    return s, Structure(n, s.horizon, s.constraint_horizon, tuple((p.i, p.j) for p in pairs), edges)


def random_edge_boxes(rng, n):
    """(n, 4) edge boxes around the origin, some sides without an edge (inf)."""
    box = np.c_[-rng.uniform(0.0, 0.1, n), rng.uniform(0.0, 0.1, n), -rng.uniform(0.0, 0.1, n),
                rng.uniform(0.0, 0.1, n)]
    box = np.where(rng.random((n, 4)) < 0.3, np.array([-1, 1, -1, 1]) * np.inf, box)   # sides without an edge
    return box


def random_step_data(rng, case, settings, edges=False):
    """A random problem of CASES[case] (random_case) packed as step data, a random butterfly cone per stage
    (and random edge boxes: ``edges``)."""
    _, n, pairs = CASES[case]
    x0, obj = random_case(rng, n, pairs, settings)
    if edges:
        obj.edge_box = random_edge_boxes(rng, n)
    d = pack(settings, x0, obj, pairs)
    d.bsign = rng.choice([-1.0, 1.0], size=d.bsign.shape)
    return d


@pytest.mark.parametrize("case,edges", [(c, False) for c in range(len(CASES))] + [(0, True), (4, True)])
def test_qp_data_equal_the_symbolic_reference_on_random_problems(case, edges):
    """P, q, every row of A | b (as sets: the row order differs) and the cost equal the CasADi
    formulation's at random linearisation points, states, objectives, butterfly cones (and edge boxes)."""
    s, st = case_problem(case, edges)
    qs = QPStructure(s, st)
    rng = np.random.default_rng(case)
    for _ in range(3):
        d = random_step_data(rng, case, s, edges)
        zbar = rng.normal(size=qs.lay.nz) * 0.2
        Pr, qr, Ar, br, n_eq, cost = reference_qp(s, st, zbar, d)
        P, q, A, b = qs.original(*qs.assemble(zbar, d))
        Pr = Pr + np.triu(Pr, 1).T
        assert qs.n_eq == n_eq and A.shape == Ar.shape
        assert np.allclose(P, Pr, rtol=1e-10, atol=1e-9 * np.abs(Pr).max())
        assert np.allclose(q, qr, rtol=1e-10, atol=1e-9 * np.abs(qr).max())
        for rows in (slice(0, n_eq), slice(n_eq, None)):
            assert np.allclose(sorted_rows(A[rows], b[rows]), sorted_rows(Ar[rows], br[rows]), atol=1e-10)
        assert qs.cost(zbar, d) == pytest.approx(cost, rel=1e-10)


def solve_reference(mpc, x0, obj):
    """Today's step before this module: the CasADi QP solved by Clarabel, from the same linearisation point
    and butterfly cones (real-time iteration, no lobe search). Returns the solution's commands and states."""
    import clarabel

    s, n = mpc.settings, mpc.n
    pairs = sorted(obj.pairs, key=lambda q: (q.i, q.j))
    st = Structure(n, s.horizon, s.constraint_horizon, tuple((p.i, p.j) for p in pairs))
    prob = Problem(s, st)
    f, dims = prob.qp_function()
    x0 = x0.copy()
    x0[:, 3] = np.clip(x0[:, 3], -s.v_max, s.v_max)
    x0[:, 4] = np.clip(x0[:, 4], -s.w_max, s.w_max)
    Xbar, Ubar, cold = mpc._initial_guess(x0)
    d = pack(s, x0, obj, pairs)
    lay = prob.lay
    z = np.zeros(lay.nz)
    z[lay.x_idx[0, :, 3:]] = Xbar[:, 0, 3:]
    z[lay.x_idx[1:]] = Xbar[:, 1:].transpose(1, 0, 2)
    z[lay.u_idx] = Ubar.transpose(1, 0, 2)
    pref = mpc._preferred_direction(x0, obj, pairs)
    for _ in range(s.sqp_iterations_cold if cold else s.sqp_iterations):
        d.bsign = mpc._signs(lay, z, pref)
        data = np.asarray(f(z, param_vector(prob.par, d))).ravel()
        nz, nP, nA = lay.nz, dims["P"].nnz(), dims["A"].nnz()
        P = sp.csc_matrix((data[:nP], dims["P"].row(), dims["P"].colind()), shape=(nz, nz))
        A = sp.csc_matrix((data[nP + nz:nP + nz + nA], dims["A"].row(), dims["A"].colind()),
                          shape=(dims["n_eq"] + dims["n_in"], nz))
        sol = clarabel.DefaultSolver(P, data[nP:nP + nz], A, data[nP + nz + nA:],
                                     [clarabel.ZeroConeT(dims["n_eq"]), clarabel.NonnegativeConeT(dims["n_in"])],
                                     controller._clarabel_settings(s)).solve()
        assert str(sol.status) == "Solved"
        z = np.asarray(sol.x)
    return mpc._rollout(x0, lay.states(z, x0)[:, 0, 3:], lay.inputs(z))


def test_steps_match_the_casadi_qp_on_random_problems():
    """Closed-loop steps of the MPC (numpy QP, decomposed) and of the CasADi QP from the same warm start,
    both solved by Clarabel: the same plans within the solver's tolerance. (Random masks leave some
    commands without a cost: their optimum is a set, whose middle an interior point returns; the active
    set's solutions of these QPs are compared with Clarabel's in test_active_set.py.)"""
    s = replace(MPCSettings(horizon=6, constraint_horizon=3), butterfly_lobe_robots=0, solver="clarabel")
    rng = np.random.default_rng(11)
    for n, pairs in ((3, [anchor_pair(0, 1, coupled=True), anchor_pair(1, 2, active=True)]),
                     (4, [anchor_pair(0, 1, coupled=True), knob_pair(2, 3, coupled=True)]),
                     (3, [])):
        mpc = MultiRobotMPC(s, n).setup()
        x0, obj = random_case(rng, n, pairs, s)
        x0[:, 2] = rng.uniform(-0.3, 0.3, n)
        for _ in range(4):
            ref = solve_reference(mpc, x0, obj)
            res = mpc.make_step(x0, obj)
            assert res.success, res.status
            assert np.allclose(res.predicted, ref, atol=1e-5)
            x0 = res.predicted[:, 1].copy()


def test_components_of_the_slot_graph():
    comps = components(7, [(0, 1), (2, 1), (4, 5)])
    assert [list(r) for r, _ in comps] == [[0, 1, 2], [3], [4, 5], [6]]
    assert [list(q) for _, q in comps] == [[0, 1], [], [2], []]


def chain_scene(n_chain=3):
    """Robots: a coupled chain 0..n_chain-1, an active pair (n_chain, n_chain+1), one robot with a goal,
    one at rest: four independent subproblems."""
    n = n_chain + 4
    geo = GEO.body_side
    x0 = np.zeros((n, NX))
    x0[:n_chain, 0] = -geo * np.arange(n_chain)
    x0[n_chain] = (0.3, 0.1, 0.2, 0, 0)
    x0[n_chain + 1] = (0.22, 0.12, -0.1, 0, 0)
    x0[n_chain + 2] = (-0.3, 0.2, 1.0, 0, 0)
    x0[n_chain + 3] = (0.5, -0.4, 0.0, 0.01, 0)
    obj = Objectives.stop_all(n)
    obj.velocity[0] = (0.03, 0.15)
    obj.velocity_mask = np.ones((n, 2))
    obj.velocity_mask[1:n_chain, 1] = 0.0
    obj.velocity[1:n_chain, 0] = 0.03
    obj.velocity_mask[n_chain:n_chain + 3] = 0.0
    obj.goal[n_chain + 2] = (-0.2, 0.35)
    obj.goal_mask[n_chain + 2] = True
    obj.pairs = [anchor_pair(k, k + 1, coupled=True) for k in range(n_chain - 1)]
    obj.pairs.append(anchor_pair(n_chain, n_chain + 1, active=True))
    return x0, obj


def test_decomposed_steps_equal_the_joint_problem(monkeypatch):
    """Independent subproblems solved apart (each its own QP, two threads) give the joint QP's plan,
    step after step on the kinematic plant, the butterfly lobe search included.

    Within the solver's tolerance: the QPs are solved to 1e-9 here; the first (cold) step's commands
    agree to 1e-7; later steps linearise at each controller's own previous plan, whose weakly
    determined stages (weights from 1e-1 to 1e5) differ by up to ~1e-4, and agree to 5e-5."""
    monkeypatch.setattr(controller, "GROUP_ROBOTS", 2)       # every component of 2+ robots is its own QP
    s = MPCSettings(horizon=8, constraint_horizon=3, qp_tolerance=1e-9)
    x0, obj = chain_scene()
    n = len(x0)
    joint = MultiRobotMPC(replace(s, decompose=False), n).setup()
    parts = MultiRobotMPC(replace(s, solver_threads=2), n).setup()
    xa, xb = x0.copy(), x0.copy()
    lobes = 0
    for step in range(6):
        ra, rb = joint.make_step(xa, obj), parts.make_step(xb, obj)
        assert ra.success and rb.success, (ra.status, rb.status)
        assert ra.extra["subproblems"] == 1 and rb.extra["subproblems"] == 3   # chain, pair, the two singles
        lobes = max(lobes, rb.extra["butterfly_lobes_tried"])
        assert np.allclose(ra.commands, rb.commands, atol=1e-7 if step == 0 else 5e-5)
        assert np.allclose(ra.predicted, rb.predicted, atol=1e-3)
        assert rb.cost == pytest.approx(ra.cost, rel=1e-6)
        for x, r in ((xa, ra), (xb, rb)):
            for i in range(n):
                x[i, :3] = unicycle_arc(x[i, :3], r.commands[i, 0], r.commands[i, 1], s.dt)
                x[i, 3:] = r.commands[i]
    assert lobes > 1                    # robots at rest with a goal or a partner: both cones were tried


def test_a_pair_that_changes_status_changes_numbers_not_the_structure():
    """Goal pair off -> active -> coupled -> off again (decoupled): one QP built, one solver set up."""
    s = MPCSettings(horizon=5, constraint_horizon=2)
    mpc = MultiRobotMPC(s, 3).setup()
    x0 = np.zeros((3, NX))
    x0[:, 0] = (0.0, -0.05, -0.12)
    x0[2, 1] = 0.01
    obj = Objectives.stop_all(3)
    mpc.make_step(x0, Objectives.stop_all(3))            # no slots: the structure without pairs
    base = len(mpc._qps)
    seen = set()
    for pair_a, pair_b in ((anchor_pair(0, 1), anchor_pair(1, 2)),
                           (anchor_pair(0, 1, coupled=True), anchor_pair(1, 2, active=True)),
                           (anchor_pair(0, 1, coupled=True), anchor_pair(1, 2, coupled=True)),
                           (anchor_pair(0, 1), anchor_pair(1, 2, coupled=True))):
        obj.pairs = [pair_a, pair_b]
        res = mpc.make_step(x0, obj)
        assert res.success, res.status
        seen.update(id(qp.solver) for qp in mpc._qps.values())
    assert len(mpc._qps) == base + 1      # one QP for the slots (0, 1), (1, 2), whatever their status
    assert len(seen) == base + 1          # and its solver was set up once, then updated


def test_a_coupled_pair_whose_headings_straddle_pi_is_not_twisted_back_by_a_turn():
    """A coupled pair facing -x: one robot's measured heading wraps from +pi to -pi between two steps.
    The warm start unwraps it next to its plan; the pair's yaw rows must measure the same difference
    (2 degrees, not 2 pi minus that), so the held pair stays at rest instead of spinning its robots
    apart at w_max."""
    s = MPCSettings(horizon=8, constraint_horizon=3)
    x0 = np.zeros((2, NX))
    x0[0, :3] = (0.0, 0.0, np.pi - 0.01)
    x0[1, :3] = (GEO.body_side, 0.0, np.pi - 0.02)      # behind robot 0 (it faces -x), the anchor in its mouth
    obj = Objectives.stop_all(2)
    obj.pairs = [anchor_pair(0, 1, coupled=True)]
    mpc = MultiRobotMPC(s, 2).setup()
    first = mpc.make_step(x0.copy(), obj)
    assert first.success and first.extra["max_pip_slack"] < 1e-4
    x0[1, 2] = -np.pi + 0.015                           # robot 1 turned 0.035 rad: across the wrap
    second = mpc.make_step(x0.copy(), obj)
    assert second.success
    assert second.extra["max_pip_slack"] < 1e-4
    assert np.abs(second.commands[:, 1]).max() < 0.2 * s.w_max


@pytest.mark.parametrize("gently", [False, True])
def test_a_coupled_knob_pair_open_within_its_play_is_pulled_in_gently(gently):
    """Two robots side by side, their sides 1.5 mm apart (the knob inside the 2 mm knob region), run in
    closed loop on the kinematic model for 2 s. Tightened by the whole pip_margin (1 mm) the region
    excludes the knob; the robots cannot move it sideways within a step, and the exact penalty has the
    MPC turn them at full rate. With the margin pairs.constraint_margin gives (the knob asked
    knob_hold_step further in per step, as the manager sets it for coupled knob pairs) they turn at a
    fraction of that, and the gap still closes to within the tightened region."""
    s = MPCSettings(horizon=10, constraint_horizon=3)
    x = np.zeros((2, NX))
    x[1, :3] = (0.0, GEO.body_side + 0.0015, 0.0)       # robot 0's knob in robot 1's hole, 1.5 mm out
    pair = pr.make_pair("a", "b", pr.KNOB, GEO)
    mpc, obj, w_peak = MultiRobotMPC(s, 2).setup(), Objectives.stop_all(2), 0.0
    for _ in range(20):
        margin = pr.constraint_margin(pair, x[0, :3], x[1, :3], GEO, s.knob_hold, s.knob_hold_step) \
            if gently else None
        obj.pairs = [replace(knob_pair(0, 1, coupled=True), margin=margin)]
        res = mpc.make_step(x, obj)
        assert res.success
        w_peak = max(w_peak, float(np.abs(res.commands[:, 1]).max()))
        x = res.predicted[:, 1].copy()                  # the plant does what the model predicts
    gap = pr.knob_measure(pair, x[0, :3], x[1, :3])[0]
    if gently:
        assert w_peak < 0.25 * s.w_max and gap < s.knob_hold + 1e-4
    else:
        assert w_peak > 0.3 * s.w_max
