"""The real-time iteration's QP, assembled in numpy on a sparsity built once.

The same problem as ocp.py (its docstring has the formulation; ocp.Problem
stays the symbolic reference, used by the IPOPT solver and by the tests
that compare the two), written as small blocks of fixed shape:

- residual blocks (the cost is the sum of their squares): the command's
  velocity term of every robot (stage 0), one block per robot and stage
  k = 1..H (control, goal, lateral, rest, velocity) and one per pair slot
  and stage (alignment, facing);
- row blocks: the dynamics of every robot and stage (zero cone), the
  command's rate limit, the butterfly rows of every robot and stage, the
  edge-box rows of every robot and stage k >= 1 (a structure with
  ``edges``), the coupling rows of every pair slot and stage k <= Hc, the
  variable bounds.

:class:`QPStructure` fixes, once per :class:`ocp.Structure`, where each
block entry lands in the CSC data of P (upper triangle) and A, so that a
step only computes the blocks' numbers (vectorised over robots, stages and
pairs) and scatters them: no symbolic work, no Python loop over robots.
Gauss-Newton at the linearisation point zbar: P = 2 J'J + diag(reg),
q = 2 J'(r - J zbar) + lin; A z <= b from the linearised rows
(A = J_g, b = J_g zbar - g(zbar)).

Pair slots that are neither active nor coupled carry zero weights and zero
rows (``0 - s <= 0``): a pair that changes status, or a robot that joins or
leaves a slot's pair, changes numbers, never the structure.

Clarabel takes the QP as assembled (``assemble``); the active-set solver
(active_set.py) takes it with its single-variable rows as bounds
(``bounded``: lb <= z <= ub and the general rows).
"""

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from puzzlebot_common.geometry import polygon_halfplanes
from puzzlebot_common.model import NU, NX
from puzzlebot_mpc.ocp import (EDGE_FREE, EDGE_ROWS, POLY_ROWS, YAW_ROW_SCALE, OcpLayout,
                               heading_residual_and_slope)

# local variable order of the blocks
_RS_VARS = 7     # robot stage k >= 1: u_{k-1} (dv, dw), x_k (px, py, theta, v, w)
_PS_VARS = 6     # pair stage: (px, py, theta) of robot i, then of robot j


@dataclass
class StepData:
    """Per-step numbers of one (sub)problem, in its own robot and slot order.

    x0 (n, 5) measured pose and previous command; goal (n, 2) [m]; goal_on
    (n,); vref (n, H, 2) references of stages 1..H; vel_on (n, 2) weight
    scales of the v and w terms; bsign (n, H+1) butterfly cone per stage
    (+-1). Pair slots: pt_i, pt_j (P, 3) aligned points; act, conn (P,)
    masks; head (P, 2); poly_g (P, 4, 2), poly_h (P, 4) tightened, unit-row
    coupling polygons; yaw_lim, yaw_off (P,) [rad]. edge_box (n, 4): the
    box (x_lo, x_hi, y_lo, y_hi) [m] each robot's base_link keeps to (+-EDGE_FREE:
    no edge on that side).
    """

    x0: np.ndarray
    goal: np.ndarray
    goal_on: np.ndarray
    vref: np.ndarray
    vel_on: np.ndarray
    bsign: np.ndarray
    pt_i: np.ndarray
    pt_j: np.ndarray
    act: np.ndarray
    conn: np.ndarray
    head: np.ndarray
    poly_g: np.ndarray
    poly_h: np.ndarray
    yaw_lim: np.ndarray
    yaw_off: np.ndarray
    edge_box: np.ndarray

    def subset(self, robots, slots):
        """The data of a subproblem: robots (global indices, in its order) and pair slots (indices)."""
        return StepData(self.x0[robots], self.goal[robots], self.goal_on[robots], self.vref[robots],
                        self.vel_on[robots], self.bsign[robots], self.pt_i[slots], self.pt_j[slots],
                        self.act[slots], self.conn[slots], self.head[slots], self.poly_g[slots],
                        self.poly_h[slots], self.yaw_lim[slots], self.yaw_off[slots], self.edge_box[robots])

    def has_edges(self, robots):
        """True when one of ``robots`` (indices) has an edge (a box side closer than EDGE_FREE)."""
        return bool(np.any(np.abs(self.edge_box[robots]) < EDGE_FREE))


def _matvec(M, x):
    """Batched matrix-vector products: (B, m, k) @ (B, k) -> (B, m)."""
    return np.matmul(M, x[:, :, None])[:, :, 0]


def _jtj_terms(pat):
    """The upper entries (a, b) (a <= b, local variables) of J'J for a residual block of pattern ``pat`` (m, k)
    and their products: entry e of J'J is the sum of Jf[ta] * Jf[tb] over the terms starts[e] <= t <
    starts[e + 1] (Jf: the block's (m, k) Jacobian flattened), one for each row m that holds both variables.
    Returns (a, b, (ta, tb, starts))."""
    a, b = np.nonzero(np.triu((pat.T.astype(int) @ pat.astype(int)) > 0))
    k = pat.shape[1]
    rows = [np.flatnonzero(pat[:, x] & pat[:, y]) for x, y in zip(a, b)]
    ta = np.concatenate([m * k + x for m, x in zip(rows, a)])
    tb = np.concatenate([m * k + y for m, y in zip(rows, b)])
    starts = np.cumsum([0] + [len(m) for m in rows[:-1]])
    return a, b, (ta, tb, starts)


def _jtj(J, terms):
    """(B, entries) upper entries of J'J (see _jtj_terms) of the Jacobians J (B, m, k): only the
    pattern's products (numpy's stacked matmul calls BLAS once per small matrix)."""
    ta, tb, starts = terms
    Jf = J.reshape(len(J), -1)
    return np.add.reduceat(Jf[:, ta] * Jf[:, tb], starts, axis=1)


def _columns(*cols):
    """(B, len(cols)) array of the 1-D columns (B,): np.stack(cols, 1) without its per-call overhead."""
    out = np.empty((len(cols[0]), len(cols)))
    for k, c in enumerate(cols):
        out[:, k] = c
    return out


_HALFPLANES = {}


def _halfplanes(polygon, margin):
    """Unit-row, tightened halfplanes of a polygon, padded to POLY_ROWS (cached by value)."""
    key = (np.asarray(polygon, float).tobytes(), margin)
    hp = _HALFPLANES.get(key)
    if hp is None:
        g = np.zeros((POLY_ROWS, 2))
        h = np.ones(POLY_ROWS)             # unused rows: 0 . q - 1 <= 0 always holds
        gq, hq = polygon_halfplanes(polygon)
        if len(gq) > POLY_ROWS:
            raise ValueError("coupling polygons have at most %d vertices" % POLY_ROWS)
        norm = np.linalg.norm(gq, axis=1)
        g[:len(gq)] = gq / norm[:, None]
        h[:len(gq)] = hq / norm - margin
        if len(_HALFPLANES) > 256:
            _HALFPLANES.clear()
        hp = _HALFPLANES[key] = (g, h)
    return hp


def finite_or_zero(a):
    """``a`` as a float array with NaN as 0 and infinities as the largest floats (np.nan_to_num); ``a``
    itself (no copy) when it is finite already, as it is in almost every step."""
    a = np.asarray(a, float)
    return a if np.isfinite(a).all() else np.nan_to_num(a)


def pack(settings, x0, objectives, pairs):
    """StepData for all robots and ``pairs`` (PairObjective, in slot order) from Objectives.

    Raises ValueError for malformed objectives (as the MPC's interface documents).
    """
    n, h = x0.shape[0], settings.horizon
    o = objectives
    vel = finite_or_zero(o.velocity)
    if vel.ndim == 2:
        vel = np.repeat(vel[:, None, :], h, axis=1)
    if vel.shape != (n, h, 2):
        raise ValueError("velocity references must be (N, 2) or (N, H, 2), got %s" % (vel.shape,))
    vm = np.asarray(o.velocity_mask, float)
    vm = vm if vm.ndim == 2 else np.repeat(vm[:, None], 2, axis=1)
    P = len(pairs)
    g = np.zeros((P, POLY_ROWS, 2))
    hh = np.ones((P, POLY_ROWS))
    heads = np.zeros((P, 2))
    for q, pr in enumerate(pairs):
        if pr.coupled and pr.active:
            raise ValueError("pair %d->%d cannot be active and coupled at once" % (pr.i, pr.j))
        if pr.coupled and (pr.polygon is None or pr.head is None):
            raise ValueError("coupled pair %d->%d needs a head point and a polygon" % (pr.i, pr.j))
        if pr.polygon is not None:
            g[q], hh[q] = _halfplanes(pr.polygon, settings.pip_margin if pr.margin is None else pr.margin)
        if pr.head is not None:
            heads[q] = pr.head
    ii = np.array([pr.i for pr in pairs], dtype=int)
    jj = np.array([pr.j for pr in pairs], dtype=int)
    pt_i = np.array([pr.point_i for pr in pairs], float).reshape(P, 3)
    pt_j = np.array([pr.point_j for pr in pairs], float).reshape(P, 3)
    raw = x0[ii, 2] + pt_i[:, 2] - x0[jj, 2] - pt_j[:, 2] - math.pi
    box = np.tile([-EDGE_FREE, EDGE_FREE, -EDGE_FREE, EDGE_FREE], (n, 1))
    if o.edge_box is not None:
        eb = np.asarray(o.edge_box, float)
        if eb.shape != (n, EDGE_ROWS) or np.isnan(eb).any():
            raise ValueError("edge_box must be (N, 4) (x_lo, x_hi, y_lo, y_hi) without NaN, got %s" % (eb.shape,))
        box = np.clip(eb, -EDGE_FREE, EDGE_FREE)
    return StepData(x0, finite_or_zero(o.goal), np.asarray(o.goal_mask, float), vel, vm,
                    np.ones((n, h + 1)), pt_i, pt_j, np.array([float(pr.active) for pr in pairs]),
                    np.array([float(pr.coupled) for pr in pairs]), heads, g, hh,
                    np.array([pr.yaw_limit for pr in pairs], float),
                    2 * math.pi * np.round(raw / (2 * math.pi)), box)


class _RowBlocks:
    """Collects row blocks (var indices, pattern) and their place in A's CSC data."""

    def __init__(self):
        self.blocks = []       # (name, V (B, k), pattern (m, k), first row)
        self.rows = 0

    def add(self, name, V, pattern):
        V = np.asarray(V, dtype=int)
        self.blocks.append((name, V, np.asarray(pattern, bool), self.rows))
        self.rows += V.shape[0] * pattern.shape[0]

    def coo(self):
        rr, cc = [], []
        for _, V, pat, r0 in self.blocks:
            B, m = V.shape[0], pat.shape[0]
            rows = r0 + np.arange(B * m).reshape(B, m)
            R = np.broadcast_to(rows[:, :, None], (B, m, V.shape[1]))
            C = np.broadcast_to(V[:, None, :], (B, m, V.shape[1]))
            rr.append(R[:, pat])
            cc.append(C[:, pat])
        return np.concatenate([r.ravel() for r in rr]), np.concatenate([c.ravel() for c in cc])


class QPStructure:
    """Sparsity and scatter maps of the QP of one :class:`ocp.Structure`, built once (numpy only)."""

    def __init__(self, settings, st):
        s = self.settings = settings
        self.st = st
        L = self.lay = OcpLayout(st)
        n, H, Hc = st.n, st.horizon, st.constraint_horizon
        self.pairs = np.array(st.pairs, dtype=int).reshape(-1, 2)
        P = len(self.pairs)
        nz = L.nz
        self._solver_order()
        vpos = self.vpos
        # ---------------------------------------------------------- residual blocks
        self.v0_idx = L.x_idx[0, :, 3:5]                                         # (n, 2)
        rs = np.concatenate([L.u_idx, L.x_idx[1:]], axis=2)                       # (H, n, 7)
        self.rs_idx = rs.reshape(H * n, _RS_VARS)
        rs_pat = np.zeros((9, _RS_VARS), bool)
        rs_pat[0, 0] = rs_pat[1, 1] = True                  # control
        rs_pat[2, 2] = rs_pat[3, 3] = True                  # goal
        rs_pat[4, 2:5] = True                               # goal lateral
        rs_pat[5, 5] = rs_pat[6, 6] = True                  # rest
        rs_pat[7, 5] = rs_pat[8, 6] = True                  # velocity
        self.rs_pat = rs_pat
        k_of = np.repeat(np.arange(1, H + 1), n)
        self.rs_wgoal = np.where(k_of == H, math.sqrt(s.w_goal_terminal), math.sqrt(s.w_goal_stage))
        res_blocks = [(self.v0_idx, np.eye(2, dtype=bool)), (self.rs_idx, rs_pat)]
        if P:
            pi, pj = self.pairs[:, 0], self.pairs[:, 1]
            ps = np.concatenate([L.x_idx[1:, pi, :3], L.x_idx[1:, pj, :3]], axis=2)   # (H, P, 6)
            self.ps_idx = ps.reshape(H * P, _PS_VARS)
            self.ps_k = np.repeat(np.arange(1, H + 1), P)
            ps_pat = np.zeros((5, _PS_VARS), bool)
            ps_pat[0, [0, 2, 3, 5]] = True                 # dp_x
            ps_pat[1, [1, 2, 4, 5]] = True                 # dp_y
            ps_pat[2, [2, 5]] = True                       # tan(dtheta / 2)
            ps_pat[3:5, :] = True                          # facing (k < H)
            stage = self.ps_k < H
            term = ~stage
            term_pat = ps_pat.copy()
            term_pat[3:5] = False
            self.ps_stage, self.ps_term = stage, term
            res_blocks += [(self.ps_idx[stage], ps_pat), (self.ps_idx[term], term_pat)]
            self.ps_pat, self.ps_term_pat = ps_pat, term_pat
        # P: upper entries (a <= b in global index) of every block's J'J pattern, plus the slack diagonal
        keys, self._p_maps = [], []
        for V, pat in res_blocks:
            a, b, terms = _jtj_terms(pat)
            ga, gb = vpos[V[:, a]], vpos[V[:, b]]
            keys.append((np.minimum(ga, gb) + nz * np.maximum(ga, gb)).ravel())     # row + nz * col
            self._p_maps.append(terms)
        slack = np.flatnonzero(L.slack)
        keys.append(vpos[slack] + nz * vpos[slack])
        allkeys = np.concatenate(keys)
        ukeys, inv = np.unique(allkeys, return_inverse=True)        # sorted by (col, row): CSC order
        self.p_inv = inv
        self.nP = len(ukeys)
        p_rows, p_cols = ukeys % nz, ukeys // nz
        self.P_indices = p_rows.astype(np.int64)
        self.P_indptr = np.searchsorted(p_cols, np.arange(nz + 1)).astype(np.int64)
        self.reg = np.full(len(slack), s.slack_regularisation)
        lin = np.zeros(nz)
        lin[L.sp_idx[L.sp_idx >= 0]] = s.w_slack_pip
        lin[L.sb_idx[L.sb_idx >= 0]] = s.w_slack_butterfly
        lin[L.se_idx[L.se_idx >= 0]] = s.w_slack_edge
        self.lin = lin
        # ---------------------------------------------------------- row blocks
        eq = _RowBlocks()
        # dynamics, k = 0 (the pose of x_0 is measured): x_1 (5), v_0, w_0, u_0 (2)
        V0 = np.concatenate([L.x_idx[1], L.x_idx[0, :, 3:5], L.u_idx[0]], axis=1)
        pat0 = np.zeros((5, 9), bool)
        pat0[np.arange(5), np.arange(5)] = True
        pat0[0, 5] = pat0[1, 5] = pat0[3, 5] = True        # v_0
        pat0[2, 6] = pat0[4, 6] = True                     # w_0
        pat0[3, 7] = pat0[4, 8] = True                     # u_0
        eq.add("dyn0", V0, pat0)
        if H > 1:
            # k = 1..H-1: x_{k+1} (5), x_k (5), u_k (2)
            Vk = np.concatenate([L.x_idx[2:], L.x_idx[1:-1], L.u_idx[1:]], axis=2).reshape((H - 1) * n, 12)
            patk = np.zeros((5, 12), bool)
            patk[np.arange(5), np.arange(5)] = True
            patk[np.arange(5), 5 + np.arange(5)] = True
            patk[0, [7, 8]] = patk[1, [7, 8]] = True       # theta, v
            patk[2, 9] = patk[3, 10] = patk[4, 11] = True  # w; dv; dw
            eq.add("dynk", Vk, patk)
        self.n_eq = eq.rows
        ineq = _RowBlocks()
        ineq.rows = eq.rows
        self.rate = [c for c, (lim, box) in enumerate(((s.dv_max, s.v_max), (s.dw_max, s.w_max)))
                     if lim * s.dt < 2 * box]
        for c in self.rate:
            ineq.add("rate%d" % c, L.x_idx[0, :, 3 + c][:, None], np.ones((2, 1), bool))
        if s.butterfly:
            Vb = np.concatenate([L.x_idx[:, :, 3:5], L.sb_idx[:, :, None]], axis=2).reshape((H + 1) * n, 3)
            ineq.add("bf", Vb, np.ones((2, 3), bool))
        if st.edges:
            Ve = np.stack([L.x_idx[1:, :, 0], L.x_idx[1:, :, 1], L.se_idx[1:]], axis=2).reshape(H * n, 3)
            pate = np.array([[1, 0, 1], [1, 0, 1], [0, 1, 1], [0, 1, 1]], bool)
            ineq.add("edge", Ve, pate)
        if P and Hc:
            ks = np.arange(1, Hc + 1)
            Vp = np.concatenate([L.x_idx[ks][:, pi, :3], L.x_idx[ks][:, pj, :3], L.sp_idx[ks][:, :, None]],
                                axis=2).reshape(Hc * P, 7)
            patp = np.ones((POLY_ROWS + 2, 7), bool)
            patp[POLY_ROWS:, [0, 1, 3, 4]] = False         # heading rows: theta_i, theta_j, slack
            ineq.add("pip", Vp, patp)
        lb, ub = L.bounds(s)
        self.ub_vars, self.lb_vars = np.flatnonzero(np.isfinite(ub)), np.flatnonzero(np.isfinite(lb))
        self.b_bounds = np.concatenate([ub[self.ub_vars], -lb[self.lb_vars]])
        ineq.add("ub", self.ub_vars[:, None], np.ones((1, 1), bool))
        ineq.add("lb", self.lb_vars[:, None], np.ones((1, 1), bool))
        self.m = ineq.rows
        self.n_in = self.m - self.n_eq
        self._row_blocks = eq.blocks + ineq.blocks
        rr = np.concatenate([eq.coo()[0], ineq.coo()[0]])
        cc = np.concatenate([eq.coo()[1], ineq.coo()[1]])
        # rows in solver order: within each cone by the robot, then the stage, of the row's first variable
        first = np.full(self.m, nz)
        np.minimum.at(first, rr, cc)
        rkey = self.var_robot[first], self.var_stage[first]
        rows = np.arange(self.m)
        zero = rows < self.n_eq
        self.rorder = np.concatenate([rows[zero][np.lexsort((rows[zero], rkey[1][zero], rkey[0][zero]))],
                                      rows[~zero][np.lexsort((rows[~zero], rkey[1][~zero], rkey[0][~zero]))]])
        rpos = np.empty(self.m, dtype=int)
        rpos[self.rorder] = rows
        rr, cc = rpos[rr], vpos[cc]
        order = np.lexsort((rr, cc))
        self.a_perm = order
        self.A_indices = rr[order].astype(np.int64)
        self.A_indptr = np.searchsorted(cc[order], np.arange(nz + 1)).astype(np.int64)
        self.nA = len(rr)
        self._ub_vals = np.ones(len(self.ub_vars))
        self._lb_vals = -np.ones(len(self.lb_vars))
        self._bound_form(rpos)
        self._step_constants()

    def _bound_form(self, rpos):
        """The same QP with its single-variable rows (the command's rate limit, the variable bounds) as
        bounds lb <= z <= ub: ``general`` (solver-order rows kept: the zero cone, butterfly and coupling
        rows), the CSC pattern of A restricted to them (``G_indices``, ``G_indptr``, ``m_general``), and
        for each single-variable row its variable and its entry in A's data (``bound_var``,
        ``bound_entry``); ``slack_solver`` marks the slacks in the solver's order, ``bf_rows`` the butterfly
        rows (stage, robot, sign) among the general inequality rows."""
        single = np.zeros(self.m, bool)
        for name, V, pat, r0 in self._row_blocks:
            if name.startswith("rate") or name in ("ub", "lb"):
                single[rpos[r0 + np.arange(V.shape[0] * pat.shape[0])]] = True
        self.general = np.flatnonzero(~single)
        keep = ~single[self.A_indices]
        newrow = np.cumsum(~single) - 1
        cols = np.repeat(np.arange(self.lay.nz), np.diff(self.A_indptr))
        self.G_entries = np.flatnonzero(keep)
        self.G_indices = newrow[self.A_indices[keep]].astype(np.int64)
        self.G_indptr = np.searchsorted(cols[keep], np.arange(self.lay.nz + 1)).astype(np.int64)
        self.m_general = len(self.general)
        srows = np.flatnonzero(single)
        entry_of_row = np.empty(self.m, np.int64)
        entry_of_row[self.A_indices] = np.arange(self.nA)      # single rows have exactly one entry
        self.bound_rows = srows
        self.bound_entry = entry_of_row[srows]
        self.bound_var = cols[self.bound_entry]
        order = np.argsort(self.bound_var, kind="stable")      # the rows of each variable together
        self._bound_order = order
        self._bound_vars, self._bound_starts = np.unique(self.bound_var[order], return_index=True)
        self.slack_solver = self.lay.slack[self.vorder]
        general_of = np.full(self.m, -1)
        general_of[self.general] = np.arange(self.m_general)
        self.bf_rows = np.zeros((0, 0, 2), int)   # (H+1, n, 2): the butterfly rows among the inequality rows
        for name, V, pat, r0 in self._row_blocks:
            if name == "bf":
                r = r0 + np.arange(V.shape[0] * 2).reshape(self.st.horizon + 1, self.st.n, 2)
                self.bf_rows = general_of[rpos[r]] - self.n_eq

    def _solver_order(self):
        """The solver's variable order (``vorder``: original indices; ``vpos``: the inverse): robot by
        robot, each robot's stages in turn (a pair's slacks with its point robot). The sparse LDL's
        ordering (AMD) starts from it; robot-major measured 7-12 % faster than the layout's stage-major
        order for a chain of 64 and 128 robots at Hm = 10 (same solution)."""
        L, st = self.lay, self.st
        nz = L.nz
        robot, stage = np.zeros(nz), np.zeros(nz)
        n = st.n
        for k in range(st.horizon + 1):
            ok = L.x_idx[k, 0] >= 0
            for c in np.flatnonzero(ok):
                robot[L.x_idx[k, :, c]], stage[L.x_idx[k, :, c]] = np.arange(n), k
            if k < st.horizon:
                robot[L.u_idx[k]], stage[L.u_idx[k]] = np.arange(n)[:, None], k + 0.5
            robot[L.sb_idx[k]], stage[L.sb_idx[k]] = np.arange(n), k
            if st.edges and k > 0:
                robot[L.se_idx[k]], stage[L.se_idx[k]] = np.arange(n), k
            if len(st.pairs) and L.sp_idx[k, 0] >= 0:
                robot[L.sp_idx[k]], stage[L.sp_idx[k]] = self.pairs[:, 0] + 0.5, k
        self.var_robot = np.append(robot, np.inf)          # [nz]: rows without a variable
        self.var_stage = np.append(stage, np.inf)
        self.vorder = np.lexsort((np.arange(nz), stage, robot))
        self.vpos = np.empty(nz, dtype=int)
        self.vpos[self.vorder] = np.arange(nz)

    # ------------------------------------------------------------------ numbers
    def _step_constants(self):
        """What every step's numbers share: the robot or slot of each block row (``rs_robot``, ``ps_slot``,
        ``pip_slot``), the pair weights by stage, and the Jacobian blocks' constant entries (templates that
        a step copies and fills), so that a step allocates and computes only what changes."""
        s, st, L = self.settings, self.st, self.lay
        n, H, Hc, P = st.n, st.horizon, st.constraint_horizon, len(self.pairs)
        dt = s.dt
        self._x_gather = np.maximum(L.x_idx, 0)
        self.rs_robot = np.tile(np.arange(n), H)                 # rows (k, i) of the robot stages
        self._blocks = {name: (V, pat) for name, V, pat, _ in self._row_blocks}
        self._block_V = [self.v0_idx, self.rs_idx]             # variables of the residual blocks (the P maps' order)
        if P:
            self._block_V += [self.ps_idx[self.ps_stage], self.ps_idx[self.ps_term]]
        J0 = np.zeros((n, 5, 9))                                 # dynamics k = 0 (see _dynamics_rows)
        J0[:, np.arange(5), np.arange(5)] = 1.0
        J0[:, 3, 5], J0[:, 2, 6], J0[:, 4, 6] = -1.0, -dt, -1.0
        J0[:, 3, 7], J0[:, 4, 8] = -dt, -dt
        Jk = np.zeros(((H - 1) * n, 5, 12))                      # dynamics k = 1..H-1
        Jk[:, np.arange(5), np.arange(5)] = 1.0
        Jk[:, np.arange(5), 5 + np.arange(5)] = -1.0
        Jk[:, 2, 9] = -dt
        Jk[:, 3, 10] = Jk[:, 4, 11] = -dt
        self._J0, self._Jk = J0, Jk
        self._rate_vals = np.tile([1.0, -1.0], (n, 1))
        B = (H + 1) * n                                          # butterfly rows (k, i): [sg, 1, -1], [sg, -1, -1]
        self._bf_vals = np.tile([0.0, 1.0, -1.0, 0.0, -1.0, -1.0], (B, 1))
        self._bf_b = np.full((B, 2), s.w_free)
        self._edge_vals = np.tile([1.0, -1.0, -1.0, -1.0, 1.0, -1.0, -1.0, -1.0], (H * n, 1))
        if not P:
            return
        self.ps_slot = np.tile(np.arange(P), H)                  # rows (k, q) of the pair stages
        self.pip_slot = np.tile(np.arange(P), Hc)                # rows (k, q), k <= Hc, of the coupling rows
        self._n_ps_stage = int(self.ps_stage.sum())              # the stage rows come first (k < H), then k = H
        term = self.ps_k == H
        self._w_pair_pos = np.where(term, math.sqrt(s.w_pair_terminal_pos), math.sqrt(s.w_pair_stage_pos))
        self._w_pair_angle = np.where(term, math.sqrt(s.w_pair_terminal_angle), math.sqrt(s.w_pair_stage_angle))
        A = np.zeros((Hc * P, POLY_ROWS + 2, 7))                 # coupling rows (see _pip_rows)
        A[:, :, 6] = -1.0
        self._A_pip = A

    def states(self, zbar, x0):
        """(H+1, n, 5) states of z (the measured pose at k = 0) and (H, n, 2) inputs."""
        X = zbar[self._x_gather]
        X[0, :, :3] = x0[:, :3]
        return X, zbar[self.lay.u_idx]

    def residuals(self, z, d, jacobians=True):
        """Residual blocks at z: list of (r (B, m), J (B, m, k) or None), in the order of the P maps."""
        X, U = self.states(z, d.x0)
        return self._residuals(X, U, d, jacobians)

    def _residuals(self, X, U, d, jacobians):
        out = [self._command_residuals(X, d, jacobians), self._robot_residuals(X, U, d, jacobians)]
        if len(self.pairs):
            out.extend(self._pair_residuals(X, d, jacobians))
        return out

    def _command_residuals(self, X, d, jacobians):
        """Stage 0: the command (v_0, w_0) tracks the stage-1 reference; rows (robot, v | w)."""
        sv = d.vel_on * math.sqrt(self.settings.w_velocity)                    # (n, 2)
        r = sv * (X[0, :, 3:5] - d.vref[:, 0])
        J = None
        if jacobians:
            J = np.zeros((len(sv), 2, 2))
            J[:, 0, 0], J[:, 1, 1] = sv[:, 0], sv[:, 1]
        return r, J

    def _robot_residuals(self, X, U, d, jacobians):
        """Robot stages k = 1..H, rows (k, i): control, goal, goal lateral, rest, velocity."""
        s, st = self.settings, self.st
        n, H = st.n, st.horizon
        x = X[1:].reshape(H * n, NX)
        u = U.reshape(H * n, NU)
        robot = self.rs_robot
        go = d.goal_on[robot]
        gl = go * math.sqrt(s.w_goal_lateral)
        gg = go * self.rs_wgoal
        gr = go * math.sqrt(s.w_rest)
        vm = d.vel_on[robot] * math.sqrt(s.w_velocity)
        vr = d.vref.transpose(1, 0, 2).reshape(H * n, 2)
        goal = d.goal[robot]
        c, sn = np.cos(x[:, 2]), np.sin(x[:, 2])
        dx, dy = x[:, 0] - goal[:, 0], x[:, 1] - goal[:, 1]
        wc = math.sqrt(s.w_control)
        r = np.empty((H * n, 9))
        r[:, 0:2] = wc * u
        r[:, 2], r[:, 3] = gg * dx, gg * dy
        r[:, 4] = gl * (-sn * dx + c * dy)
        r[:, 5:7] = gr[:, None] * x[:, 3:5]
        r[:, 7:9] = vm * (x[:, 3:5] - vr)
        J = None
        if jacobians:
            J = np.zeros((H * n, 9, _RS_VARS))
            J[:, 0, 0] = J[:, 1, 1] = wc
            J[:, 2, 2] = J[:, 3, 3] = gg
            J[:, 4, 2], J[:, 4, 3], J[:, 4, 4] = -gl * sn, gl * c, gl * (-c * dx - sn * dy)
            J[:, 5, 5] = J[:, 6, 6] = gr
            J[:, 7, 5], J[:, 8, 6] = vm[:, 0], vm[:, 1]
        return r, J

    def _pair_residuals(self, X, d, jacobians):
        """Pair stages k = 1..H, rows (k, q): alignment (dp_x, dp_y, tan(dtheta / 2)) and facing; two
        blocks: k < H, and k = H without the facing rows."""
        s, H = self.settings, self.st.horizon
        P = len(self.pairs)
        xi = X[1:, self.pairs[:, 0], :3].reshape(H * P, 3)
        xj = X[1:, self.pairs[:, 1], :3].reshape(H * P, 3)
        slot = self.ps_slot
        act, conn = d.act[slot], d.conn[slot]
        a, b = d.pt_i[slot], d.pt_j[slot]
        wpos = act * self._w_pair_pos + conn * math.sqrt(s.w_coupled_pos)
        wang = act * self._w_pair_angle + conn * math.sqrt(s.w_coupled_angle)
        wlat = act * math.sqrt(s.w_pair_lateral)
        ci, si = np.cos(xi[:, 2]), np.sin(xi[:, 2])
        cj, sj = np.cos(xj[:, 2]), np.sin(xj[:, 2])
        dpx = xi[:, 0] + ci * a[:, 0] - si * a[:, 1] - xj[:, 0] - cj * b[:, 0] + sj * b[:, 1]
        dpy = xi[:, 1] + si * a[:, 0] + ci * a[:, 1] - xj[:, 1] - sj * b[:, 0] - cj * b[:, 1]
        dth = xi[:, 2] + a[:, 2] - xj[:, 2] - b[:, 2] - math.pi
        t, slope = heading_residual_and_slope(dth)
        lat_i = -si * dpx + ci * dpy
        lat_j = -sj * dpx + cj * dpy
        r = _columns(wpos * dpx, wpos * dpy, wang * t, wlat * lat_i, wlat * lat_j)
        J = None
        if jacobians:
            Jdp = np.zeros((H * P, 2, _PS_VARS))         # d dp / d (xi, xj)
            Jdp[:, 0, 0] = Jdp[:, 1, 1] = 1.0
            Jdp[:, 0, 3] = Jdp[:, 1, 4] = -1.0
            Jdp[:, 0, 2], Jdp[:, 1, 2] = -si * a[:, 0] - ci * a[:, 1], ci * a[:, 0] - si * a[:, 1]    # dC_i / dtheta_i
            Jdp[:, 0, 5], Jdp[:, 1, 5] = -(-sj * b[:, 0] - cj * b[:, 1]), -(cj * b[:, 0] - sj * b[:, 1])
            J = np.zeros((H * P, 5, _PS_VARS))
            J[:, 0:2] = wpos[:, None, None] * Jdp
            dt = slope * wang
            J[:, 2, 2], J[:, 2, 5] = dt, -dt
            J[:, 3] = -si[:, None] * Jdp[:, 0] + ci[:, None] * Jdp[:, 1]
            J[:, 3, 2] += -ci * dpx - si * dpy
            J[:, 4] = -sj[:, None] * Jdp[:, 0] + cj[:, None] * Jdp[:, 1]
            J[:, 4, 5] += -cj * dpx - sj * dpy
            J[:, 3:5] *= wlat[:, None, None]
        ns = self._n_ps_stage
        return [(r[:ns], None if J is None else J[:ns]), (r[ns:, :3], None if J is None else J[ns:, :3])]

    def cost(self, z, d):
        """Nonlinear cost of z (sum of squared residuals + the slacks' linear penalties)."""
        return float(sum(np.sum(r * r) for r, _ in self.residuals(z, d, jacobians=False)) + self.lin @ z)

    def assemble(self, zbar, d):
        """(P data, q, A data, b) of the QP linearised at zbar, in the solver's order (``vorder``, ``rorder``;
        CSC data of P's upper triangle and of A): the solution is ``from_solver(z)``."""
        nz = self.lay.nz
        X, U = self.states(zbar, d.x0)
        pvals, q = [], np.zeros(nz)
        for (r, J), V, terms in zip(self._residuals(X, U, d, True), self._block_V, self._p_maps):
            if r.shape[0] == 0:
                pvals.append(np.zeros(0))
                continue
            pvals.append((2.0 * _jtj(J, terms)).ravel())
            t = r - _matvec(J, zbar[V])
            q += np.bincount(V.ravel(), (2.0 * np.matmul(t[:, None, :], J)[:, 0, :]).ravel(), nz)
        pvals.append(self.reg)
        Px = np.bincount(self.p_inv, np.concatenate(pvals), self.nP)
        q += self.lin
        avals, bvals = self._rows(X, U, d, zbar)
        return Px, q[self.vorder], avals[self.a_perm], bvals[self.rorder]

    def bounded(self, Ax, b):
        """(A data of the general rows (pattern ``G_indices``, ``G_indptr``), their b, lb, ub) of the QP
        assembled as (Ax, b): the same feasible set, its single-variable rows as bounds."""
        nz = self.lay.nz
        o = self._bound_order
        coef = Ax[self.bound_entry[o]]
        val = b[self.bound_rows[o]] / coef
        lb, ub = np.full(nz, -np.inf), np.full(nz, np.inf)
        if len(o):
            up = coef > 0
            ub[self._bound_vars] = np.minimum.reduceat(np.where(up, val, np.inf), self._bound_starts)
            lb[self._bound_vars] = np.maximum.reduceat(np.where(up, -np.inf, val), self._bound_starts)
        return Ax[self.G_entries], b[self.general], lb, ub

    def from_solver(self, zs):
        """Variables in the layout's order from the solver's."""
        return np.asarray(zs, float)[self.vpos]

    def _rows(self, X, U, d, zbar):
        """A entries (in row-block COO order) and b of the linearised rows at zbar (states X, inputs U)."""
        s = self.settings
        vals, bs = self._dynamics_rows(X, U, zbar)
        # the command's rate limit: |vw_0 - previous command| <= lim dt
        for cc in self.rate:
            lim = (s.dv_max, s.dw_max)[cc] * s.dt
            prev = d.x0[:, 3 + cc]
            vals.append(self._rate_vals)
            bs.append(_columns(lim + prev, lim - prev))
        if s.butterfly:
            bf = self._bf_vals.copy()
            bf[:, 0] = bf[:, 3] = -(s.w_max / s.v_max) * d.bsign.T.reshape(-1)      # rows (k, i)
            vals.append(bf)
            bs.append(self._bf_b)
        if self.st.edges:       # rows (k, i): px <= x_hi, -px <= -x_lo, py <= y_hi, -py <= -y_lo (- s_edge)
            eb = d.edge_box
            vals.append(self._edge_vals)
            bs.append(np.tile(_columns(eb[:, 1], -eb[:, 0], eb[:, 3], -eb[:, 2]), (self.st.horizon, 1)))
        if len(self.pairs) and self.st.constraint_horizon:
            Ap, bp = self._pip_rows(d, zbar)
            vals.append(Ap)
            bs.append(bp)
        vals.append(self._ub_vals)
        vals.append(self._lb_vals)
        bs.append(self.b_bounds)
        return np.concatenate([v.ravel() for v in vals]), np.concatenate([b.ravel() for b in bs])

    def _dynamics_rows(self, X, U, zbar):
        """Lists of A entries and b of the dynamics rows: eq = x_{k+1} - f(x_k, u_k); A = J, b = J zbar - eq."""
        n, H, dt = self.st.n, self.st.horizon, self.settings.dt
        th, v, w = X[:-1, :, 2], X[:-1, :, 3], X[:-1, :, 4]
        c, sn = np.cos(th), np.sin(th)
        f = np.empty((H, n, 5))
        f[:, :, 0] = X[:-1, :, 0] + dt * v * c
        f[:, :, 1] = X[:-1, :, 1] + dt * v * sn
        f[:, :, 2] = th + dt * w
        f[:, :, 3] = v + dt * U[:, :, 0]
        f[:, :, 4] = w + dt * U[:, :, 1]
        eqv = X[1:] - f
        # k = 0: [x1 (5) | v0, w0 | dv0, dw0]
        V0, pat0 = self._blocks["dyn0"]
        J0 = self._J0.copy()
        J0[:, 0, 5], J0[:, 1, 5] = -dt * c[0], -dt * sn[0]
        vals, bs = [J0[:, pat0]], [_matvec(J0, zbar[V0]) - eqv[0]]
        if H > 1:
            Vk, patk = self._blocks["dynk"]
            ck, sk, vk = c[1:].reshape(-1), sn[1:].reshape(-1), v[1:].reshape(-1)
            Jk = self._Jk.copy()
            Jk[:, 0, 7], Jk[:, 0, 8] = dt * vk * sk, -dt * ck
            Jk[:, 1, 7], Jk[:, 1, 8] = -dt * vk * ck, -dt * sk
            vals.append(Jk[:, patk])
            bs.append(_matvec(Jk, zbar[Vk]) - eqv[1:].reshape(-1, 5))
        return vals, bs

    def _pip_rows(self, d, zbar):
        """A entries and b of the coupling rows (head in the polygon, relative heading within its limit) of
        the pair stages k = 1..Hc, rows (k, q); zero rows for a slot that is not coupled."""
        Vp, patp = self._blocks["pip"]
        zb = zbar[Vp]                                            # (B, 7): pose of i, pose of j, slack
        xi, xj, sl = zb[:, :3], zb[:, 3:6], zb[:, 6]
        slot = self.pip_slot
        conn, head, G, hh = d.conn[slot], d.head[slot], d.poly_g[slot], d.poly_h[slot]
        ci, si = np.cos(xi[:, 2]), np.sin(xi[:, 2])
        cj, sj = np.cos(xj[:, 2]), np.sin(xj[:, 2])
        wx = xi[:, 0] + ci * head[:, 0] - si * head[:, 1] - xj[:, 0]
        wy = xi[:, 1] + si * head[:, 0] + ci * head[:, 1] - xj[:, 1]
        qx, qy = cj * wx + sj * wy, -sj * wx + cj * wy
        dhx, dhy = -si * head[:, 0] - ci * head[:, 1], ci * head[:, 0] - si * head[:, 1]
        Jq = np.zeros((len(slot), 2, 6))
        Jq[:, 0, 0], Jq[:, 1, 0] = cj, -sj
        Jq[:, 0, 1], Jq[:, 1, 1] = sj, cj
        Jq[:, 0, 2], Jq[:, 1, 2] = cj * dhx + sj * dhy, -sj * dhx + cj * dhy
        Jq[:, :, 3:5] = -Jq[:, :, 0:2]
        Jq[:, 0, 5], Jq[:, 1, 5] = -sj * wx + cj * wy, -cj * wx - sj * wy
        A = self._A_pip.copy()
        A[:, :POLY_ROWS, :6] = conn[:, None, None] * np.matmul(G, Jq)
        ys = YAW_ROW_SCALE * conn
        dth = xi[:, 2] + d.pt_i[slot, 2] - xj[:, 2] - d.pt_j[slot, 2] - math.pi - d.yaw_off[slot]
        yaw_lim = d.yaw_lim[slot]
        A[:, POLY_ROWS, 2], A[:, POLY_ROWS, 5] = ys, -ys
        A[:, POLY_ROWS + 1, 2], A[:, POLY_ROWS + 1, 5] = -ys, ys
        gv = np.empty((len(slot), POLY_ROWS + 2))
        gv[:, :POLY_ROWS] = conn[:, None] * (G[:, :, 0] * qx[:, None] + G[:, :, 1] * qy[:, None] - hh)
        gv[:, POLY_ROWS] = ys * (dth - yaw_lim)
        gv[:, POLY_ROWS + 1] = ys * (-dth - yaw_lim)
        b = _matvec(A, zb) - (gv - sl[:, None])
        return A[:, patp], b

    def matrices(self, Px, Ax):
        """scipy CSC matrices (P upper, A) of the data arrays, in the solver's order."""
        nz = self.lay.nz
        P = sp.csc_matrix((Px, self.P_indices, self.P_indptr), shape=(nz, nz))
        A = sp.csc_matrix((Ax, self.A_indices, self.A_indptr), shape=(self.m, nz))
        return P, A

    def original(self, Px, q, Ax, b):
        """Dense P (symmetric), q, A, b in the layout's variable order and the row blocks' row order."""
        P, A = self.matrices(Px, Ax)
        P = P.toarray()
        P = P + np.triu(P, 1).T
        bo = np.empty_like(b)
        bo[self.rorder] = b
        return P[self.vpos][:, self.vpos], q[self.vpos], A.toarray()[np.argsort(self.rorder)][:, self.vpos], bo
