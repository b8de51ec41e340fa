"""The MPC's optimal control problem, written once in CasADi.

One formulation, two forms: this symbolic one (CasADi) is the full NLP that
IPOPT solves and the reference of puzzlebot_mpc/qp.py, which assembles the
real-time iteration's Gauss-Newton QP of the same problem in numpy (the
tests compare the two). Everything that changes per step is a parameter;
the structure depends only on the number of robots ``n``, the horizons and
the *pair slots* (which robot pairs may carry alignment costs or coupling
constraints).

State x = [px, py, theta, v, w], input u = [dv, dw], explicit Euler
(model.euler_step). The initial pose is measured (a parameter). The initial
velocity (v_0, w_0) is the command sent now: a decision variable within one
step of acceleration of the previous command. The command therefore acts on
the first prediction interval, as it does in the lockstep simulation and,
through the velocity loop, on the robots.

Decision variables, stage-major::

    (v_0, w_0) (n x 2)
    for k = 0..H-1:  u_k (n x 2),  x_{k+1} (n x 5),
                     s_pip_{k+1} (one per pair slot, if k+1 <= Hc),
                     s_bf_k (one per robot; the butterfly slack of x_k),
                     s_edge_{k+1} (one per robot, with stage edges)
    s_bf_H (one per robot)

Cost (all residuals r enter as sum r^2; weights from MPCSettings; masks are
parameters multiplying the residuals, a pair is either active or coupled)::

    sum_k  w_control |u_k|^2
         + goal robots:     w_goal(k) |p - g|^2 + w_goal_lateral lat^2 + w_rest |(v, w)|^2
         + velocity robots: w_velocity |(v, w) - ref_k|^2
         + pair slots:      (act W_pair(k) + coupled W_coupled) (|dp|^2, tan^2(dtheta / 2), linear past HEADING_KNEE)
                            + act w_pair_lateral (lat_i^2 + lat_j^2)    (k < H)
         + w_slack_pip s_pip + w_slack_butterfly s_bf + w_slack_edge s_edge   (exact L1 penalties)

Constraints::

    x_{k+1} = euler_step(x_k, u_k)                                k = 0..H-1
    |v| <= v_max, |w| <= w_max, |dv| <= dv_max, |dw| <= dw_max,
    |v_0 - v_prev| <= dv_max dt, |w_0 - w_prev| <= dw_max dt
    pip:  G_p q_p(x_k) - h_p <= s_pip      (normalised rows [m])  k = 1..Hc
          c |dtheta_p - 2 pi m_p| - c yaw_lim_p <= s_pip (c = YAW_ROW_SCALE)
    butterfly: +-w - (w_max / v_max) sigma_k v <= w_free + s_bf   k = 0..H
    edges:     x_lo <= px, px <= x_hi, y_lo <= py, py <= y_hi  (each - s_edge)  k = 1..H

``lat_i`` (``lat_j``) is the sideways offset of the pair's position error in
robot i's (j's) frame. ``q_p`` is the pair's head point expressed in the polygon robot's frame and
``G_p, h_p`` the (tightened) coupling polygon; the heading rows keep a
coupled pair within the connection's yaw freedom (``m_p`` unwraps the raw
heading difference at the measured state); ``sigma_k`` = +-1 is the
direction of travel the butterfly cone is linearised for (chosen per step
from the previous solution). ``(x_lo, x_hi, y_lo, y_hi)`` is the box the
robot's base_link keeps to stay on the stage it stands on (a parameter per
robot, +-EDGE_FREE where it has no edge); the rows exist only in a structure
with ``edges``. The soft constraints make every QP feasible:
a coupled pair that the measured state already puts outside its polygon is
pulled back instead of making the problem infeasible.
"""

import math
from dataclasses import dataclass
from typing import Dict, Tuple

import casadi as ca
import numpy as np

from puzzlebot_common.model import NU, NX, euler_step

POLY_ROWS = 4          # rows per coupling polygon (triangles get one inactive row)
YAW_ROW_SCALE = 0.025  # m/rad: heading rows of coupled pairs share the polygon rows' slack (metres)
EDGE_ROWS = 4          # rows per robot and stage of the edge box: x_hi, -x_lo, y_hi, -y_lo
EDGE_FREE = 1.0e3      # m: the box bound of a side without an edge (a row that never binds)
HEADING_KNEE = 2.0     # rad: beyond this heading error a pair's tan(dtheta / 2) residual goes on as its tangent
#                        line (slope and value bounded: a robot facing away from its partner does not make the
#                        Gauss-Newton step spin the partner's whole assembly; :func:`heading_residual`)


class ParamLayout:
    """Offsets of named blocks in the flat parameter vector."""

    def __init__(self):
        self.blocks: Dict[str, Tuple[int, tuple]] = {}
        self.size = 0

    def add(self, name, shape):
        self.blocks[name] = (self.size, shape)
        self.size += int(np.prod(shape))

    def sym(self, p, name):
        off, shape = self.blocks[name]
        n = int(np.prod(shape))
        flat = p[off:off + n]
        if len(shape) == 1:
            return flat
        return ca.reshape(flat, shape[1], shape[0]).T if len(shape) == 2 else flat

    def put(self, vec, name, value):
        off, shape = self.blocks[name]
        vec[off:off + int(np.prod(shape))] = np.asarray(value, dtype=float).reshape(-1)


@dataclass(frozen=True)
class Structure:
    """What fixes the problem's sparsity."""

    n: int
    horizon: int
    constraint_horizon: int
    pairs: Tuple[Tuple[int, int], ...]     # (point robot index, polygon robot index) per slot
    edges: bool = False                    # edge-box rows (and their slacks) for every robot, k = 1..H


class OcpLayout:
    """Variable indices of a :class:`Structure`."""

    def __init__(self, st: Structure):
        self.st = st
        n, h, hc, P = st.n, st.horizon, st.constraint_horizon, len(st.pairs)
        self.u_idx = np.zeros((h, n, NU), dtype=int)
        self.x_idx = np.zeros((h + 1, n, NX), dtype=int)   # x_idx[0, :, :3] unused (measured pose)
        self.sp_idx = np.full((h + 1, P), -1, dtype=int)
        self.sb_idx = np.full((h + 1, n), -1, dtype=int)
        self.se_idx = np.full((h + 1, n), -1, dtype=int)   # edge slacks of x_1..x_H (with st.edges)
        self.x_idx[0, :, 3:] = np.arange(0, n * 2).reshape(n, 2)
        self.x_idx[0, :, :3] = -1
        i = n * 2
        for k in range(h):
            self.u_idx[k] = np.arange(i, i + n * NU).reshape(n, NU)
            i += n * NU
            self.x_idx[k + 1] = np.arange(i, i + n * NX).reshape(n, NX)
            i += n * NX
            if k + 1 <= hc and P:
                self.sp_idx[k + 1] = np.arange(i, i + P)
                i += P
            self.sb_idx[k] = np.arange(i, i + n)
            i += n
            if st.edges:
                self.se_idx[k + 1] = np.arange(i, i + n)
                i += n
        self.sb_idx[h] = np.arange(i, i + n)
        i += n
        self.nz = i
        self.slack = np.zeros(i, dtype=bool)
        self.slack[self.sp_idx[self.sp_idx >= 0]] = True
        self.slack[self.sb_idx[self.sb_idx >= 0]] = True
        self.slack[self.se_idx[self.se_idx >= 0]] = True

    def states(self, z, x0):
        """(n, H+1, 5) states: the measured pose at k = 0, the variables elsewhere."""
        X = np.zeros((self.st.n, self.st.horizon + 1, NX))
        X[:, 0, :3] = x0[:, :3]
        X[:, 0, 3:] = z[self.x_idx[0, :, 3:]]
        X[:, 1:] = z[self.x_idx[1:]].transpose(1, 0, 2)
        return X

    def inputs(self, z):
        return z[self.u_idx].transpose(1, 0, 2)

    def bounds(self, settings):
        """(lb, ub) [nz] of the variables under ``settings`` (settings.MPCSettings), the one definition
        of the box both forms share (Problem, qp.QPStructure): the inputs within dv_max, dw_max
        [m/s^2, rad/s^2] (left out where the velocity box implies it: |dv| dt <= 2 v_max), the
        velocities within v_max, w_max, the slacks >= 0, the butterfly slacks 0 without the butterfly
        cones; -inf / inf elsewhere."""
        s = settings
        lb, ub = np.full(self.nz, -np.inf), np.full(self.nz, np.inf)
        if s.dv_max * s.dt < 2 * s.v_max:
            lb[self.u_idx[..., 0]], ub[self.u_idx[..., 0]] = -s.dv_max, s.dv_max
        if s.dw_max * s.dt < 2 * s.w_max:
            lb[self.u_idx[..., 1]], ub[self.u_idx[..., 1]] = -s.dw_max, s.dw_max
        lb[self.x_idx[:, :, 3]], ub[self.x_idx[:, :, 3]] = -s.v_max, s.v_max
        lb[self.x_idx[:, :, 4]], ub[self.x_idx[:, :, 4]] = -s.w_max, s.w_max
        lb[self.slack] = 0.0
        if not s.butterfly:
            ub[self.sb_idx[self.sb_idx >= 0]] = 0.0
        return lb, ub


def params_layout(st: Structure):
    n, h, P = st.n, st.horizon, len(st.pairs)
    lay = ParamLayout()
    lay.add("x0", (n, NX))
    lay.add("goal", (n, 2))
    lay.add("goal_on", (n,))
    lay.add("vref", (n * h, 2))         # robot-major: row i*h + (k-1) is robot i's reference at stage k
    lay.add("vel_on", (n, 2))        # weight scale of the v and w tracking terms
    lay.add("bsign", (n * (h + 1),))    # butterfly direction of robot i at stage k = 0..H: row i*(h+1) + k
    if st.edges:
        lay.add("edge_box", (n, EDGE_ROWS))   # (x_lo, x_hi, y_lo, y_hi) of robot i's base_link [m]
    if P:
        lay.add("pt_i", (P, 3))         # aligned point on the point robot (x, y, heading)
        lay.add("pt_j", (P, 3))         # aligned point on the polygon robot
        lay.add("act", (P,))            # 1: pair being aligned (active)
        lay.add("conn", (P,))           # 1: coupled pair (small alignment cost + pip)
        lay.add("head", (P, 2))         # pip point on the point robot
        lay.add("poly_g", (P * POLY_ROWS, 2))   # coupling polygon rows (robot j frame), unit norm
        lay.add("poly_h", (P * POLY_ROWS,))
        lay.add("yaw_lim", (P,))        # |relative heading| limit of a coupled pair [rad]
        lay.add("yaw_off", (P,))        # multiple of 2 pi removed from the pair's raw heading difference
    return lay


def param_vector(par, d):
    """The flat parameter vector of layout ``par`` from a qp.StepData (the symbolic problem's numbers)."""
    p = np.zeros(par.size)
    n, h = d.x0.shape[0], d.vref.shape[1]
    par.put(p, "x0", d.x0)
    par.put(p, "goal", d.goal)
    par.put(p, "goal_on", d.goal_on)
    par.put(p, "vref", d.vref.reshape(n * h, 2))
    par.put(p, "vel_on", d.vel_on)
    par.put(p, "bsign", d.bsign.reshape(-1))
    if "edge_box" in par.blocks:
        par.put(p, "edge_box", d.edge_box)
    if len(d.act):
        for name in ("pt_i", "pt_j", "act", "conn", "head", "yaw_lim", "yaw_off"):
            par.put(p, name, getattr(d, name))
        par.put(p, "poly_g", d.poly_g.reshape(-1, 2))
        par.put(p, "poly_h", d.poly_h.reshape(-1))
    return p


def _rot(th, v):
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1])


def _rot_t(th, v):
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(c * v[0] + s * v[1], -s * v[0] + c * v[1])


def pair_residual_terms(xi, xj, pt_i, pt_j):
    """(dp (2), heading residual (:func:`heading_residual`)) between the aligned points of two robots."""
    ci = xi[0:2] + _rot(xi[2], pt_i[0:2])
    cj = xj[0:2] + _rot(xj[2], pt_j[0:2])
    dth = xi[2] + pt_i[2] - xj[2] - pt_j[2] - math.pi
    return ci - cj, heading_residual(dth)


def heading_residual(dth):
    """The pair's heading residual (casadi) of the error ``dth`` [rad] (any multiple of 2 pi off): tan(e / 2)
    of the wrapped error e while |e| <= HEADING_KNEE, its tangent line at the knee beyond."""
    e = ca.atan2(ca.sin(dth), ca.cos(dth))
    t_knee = math.tan(HEADING_KNEE / 2)
    beyond = ca.sign(e) * (t_knee + 0.5 * (1.0 + t_knee * t_knee) * (ca.fabs(e) - HEADING_KNEE))
    return ca.if_else(ca.fabs(e) <= HEADING_KNEE, ca.tan(e / 2), beyond)


def heading_residual_and_slope(dth):
    """(:func:`heading_residual`, its derivative in dth) of numpy arrays, in one pass."""
    e = np.arctan2(np.sin(dth), np.cos(dth))
    inside = np.clip(e, -HEADING_KNEE, HEADING_KNEE)
    t = np.tan(inside / 2)
    slope = 0.5 * (1.0 + t * t)
    return t + slope * (e - inside), slope


def pip_rows(xi, xj, head, g, h):
    """Linear point-in-polygon rows G q - h (<= 0 inside) for the head of i in j's polygon."""
    world = xi[0:2] + _rot(xi[2], head)
    q = _rot_t(xj[2], world - xj[0:2])
    return ca.mtimes(g, q) - h


class Problem:
    """Symbolic problem of a structure: residuals, constraints, bounds."""

    def __init__(self, settings, st: Structure):
        s = settings
        self.settings, self.st = s, st
        self.lay = OcpLayout(st)
        self.par = params_layout(st)
        n, h, hc, P = st.n, st.horizon, st.constraint_horizon, len(st.pairs)
        z = ca.SX.sym("z", self.lay.nz)
        p = ca.SX.sym("p", self.par.size)
        self.z, self.p = z, p
        x0 = self.par.sym(p, "x0")
        goal = self.par.sym(p, "goal")
        goal_on = self.par.sym(p, "goal_on")
        vref = self.par.sym(p, "vref")
        vel_on = self.par.sym(p, "vel_on")
        bsign = self.par.sym(p, "bsign")
        edge_box = self.par.sym(p, "edge_box") if st.edges else None
        if P:
            pt_i, pt_j = self.par.sym(p, "pt_i"), self.par.sym(p, "pt_j")
            act, conn = self.par.sym(p, "act"), self.par.sym(p, "conn")
            head = self.par.sym(p, "head")
            poly_g, poly_h = self.par.sym(p, "poly_g"), self.par.sym(p, "poly_h")
            yaw_lim, yaw_off = self.par.sym(p, "yaw_lim"), self.par.sym(p, "yaw_off")

        L = self.lay

        def X(k, i):
            if k == 0:
                return ca.vertcat(x0[i, 0:3].T, z[L.x_idx[0, i, 3:].tolist()])
            return z[L.x_idx[k, i].tolist()]

        def U(k, i):
            return z[L.u_idx[k, i].tolist()]

        res, eq, ineq = [], [], []
        ratio = s.w_max / s.v_max
        for k in range(h):
            for i in range(n):
                eq.append(X(k + 1, i) - euler_step(X(k, i), U(k, i), s.dt))
        for i in range(n):
            # the command (v_0, w_0) is one step of acceleration from the previous command (x0's v, w)
            for c, (lim, box) in enumerate(((s.dv_max, s.v_max), (s.dw_max, s.w_max))):
                if lim * s.dt < 2 * box:        # else implied by the velocity box
                    d = X(0, i)[3 + c] - x0[i, 3 + c]
                    ineq.append(ca.vertcat(d - lim * s.dt, -d - lim * s.dt))
            if s.butterfly:
                self._butterfly(ineq, X(0, i), bsign[i * (h + 1)], z[int(L.sb_idx[0, i])], ratio)
            # the command sent now tracks the reference too (its stage-1 value): without this term the
            # command is the one free velocity of the plan, and a coupled pair's keeping cost spent it
            # on a gap that the bodies' contact cannot close (a driving chain's lead stalled)
            res.append(vel_on[i, :].T * math.sqrt(s.w_velocity) * (X(0, i)[3:5] - vref[i * h, :].T))
        for k in range(1, h + 1):
            terminal = k == h
            w_goal = s.w_goal_terminal if terminal else s.w_goal_stage
            for i in range(n):
                x, u = X(k, i), U(k - 1, i)
                res.append(math.sqrt(s.w_control) * u)
                dp = x[0:2] - goal[i, :].T
                lateral = -ca.sin(x[2]) * dp[0] + ca.cos(x[2]) * dp[1]
                res.append(goal_on[i] * math.sqrt(w_goal) * dp)
                res.append(goal_on[i] * math.sqrt(s.w_goal_lateral) * lateral)
                res.append(goal_on[i] * math.sqrt(s.w_rest) * x[3:5])
                res.append(vel_on[i, :].T * math.sqrt(s.w_velocity) * (x[3:5] - vref[i * h + k - 1, :].T))
                if s.butterfly:
                    self._butterfly(ineq, x, bsign[i * (h + 1) + k], z[int(L.sb_idx[k, i])], ratio)
                if st.edges:
                    se, b = z[int(L.se_idx[k, i])], edge_box[i, :]
                    ineq.append(ca.vertcat(x[0] - b[1], b[0] - x[0], x[1] - b[3], b[2] - x[1]) - se)
            w_pos = s.w_pair_terminal_pos if terminal else s.w_pair_stage_pos
            w_ang = s.w_pair_terminal_angle if terminal else s.w_pair_stage_angle
            wc_pos, wc_ang = s.w_coupled_pos, s.w_coupled_angle
            for q, (i, j) in enumerate(st.pairs):
                xi, xj = X(k, i), X(k, j)
                dp, tang = pair_residual_terms(xi, xj, pt_i[q, :].T, pt_j[q, :].T)
                res.append((act[q] * math.sqrt(w_pos) + conn[q] * math.sqrt(wc_pos)) * dp)
                res.append((act[q] * math.sqrt(w_ang) + conn[q] * math.sqrt(wc_ang)) * tang)
                if not terminal:
                    # each robot of an active pair turns towards its partner's point (no local minimum
                    # beside the target: a unicycle cannot close a sideways offset by driving straight)
                    res.append(act[q] * math.sqrt(s.w_pair_lateral) * ca.vertcat(
                        _rot_t(xi[2], dp)[1], _rot_t(xj[2], dp)[1]))
                if k <= hc:
                    rows = slice(q * POLY_ROWS, (q + 1) * POLY_ROWS)
                    slack = z[int(L.sp_idx[k, q])]
                    ineq.append(conn[q] * pip_rows(xi, xj, head[q, :].T, poly_g[rows, :], poly_h[rows]) - slack)
                    # relative heading within the connection's freedom, in metres at the body's half side
                    dth = xi[2] + pt_i[q, 2] - xj[2] - pt_j[q, 2] - math.pi - yaw_off[q]
                    ineq.append(conn[q] * YAW_ROW_SCALE * ca.vertcat(dth - yaw_lim[q], -dth - yaw_lim[q]) - slack)
        self.res = ca.vertcat(*res)
        self.eq = ca.vertcat(*eq)
        self.ineq = ca.vertcat(*ineq) if ineq else ca.SX(0, 1)
        lin = np.zeros(L.nz)
        lin[L.sp_idx[L.sp_idx >= 0]] = s.w_slack_pip
        lin[L.sb_idx[L.sb_idx >= 0]] = s.w_slack_butterfly
        lin[L.se_idx[L.se_idx >= 0]] = s.w_slack_edge
        self.lin = lin
        self.lb, self.ub = L.bounds(s)
        self.cost = ca.sumsqr(self.res) + ca.dot(ca.DM(lin), z)

    def _butterfly(self, ineq, x, sign, slack, ratio):
        w_free = self.settings.w_free
        ineq.append(x[4] - ratio * sign * x[3] - w_free - slack)
        ineq.append(-x[4] - ratio * sign * x[3] - w_free - slack)

    # --------------------------------------------------------------- QP data
    def qp_function(self):
        """CasADi Function (zbar, p) -> [P (upper, nonzeros), q, A (nonzeros), b] and the sparsities:
        the Gauss-Newton QP of the symbolic form (the reference that qp.QPStructure is tested against).

        Clarabel form: min 1/2 z'Pz + q'z s.t. A z + s = b, s in {0}^n_eq x R+^n_in.
        Rows of A: linearised dynamics (zero cone), linearised inequalities
        and the finite variable bounds (nonnegative cone).
        """
        z, p = self.z, self.p
        J = ca.jacobian(self.res, z)
        r = self.res
        reg = np.where(self.lay.slack, self.settings.slack_regularisation, 0.0)
        Pm = 2 * ca.mtimes(J.T, J) + ca.diag(ca.DM(reg))
        Pu = ca.triu(Pm)
        q = 2 * ca.mtimes(J.T, r - ca.mtimes(J, z)) + ca.DM(self.lin)
        Je = ca.jacobian(self.eq, z)
        Ji = ca.jacobian(self.ineq, z)
        be = ca.mtimes(Je, z) - self.eq
        bi = ca.mtimes(Ji, z) - self.ineq
        ub_rows = np.where(np.isfinite(self.ub))[0]
        lb_rows = np.where(np.isfinite(self.lb))[0]
        nz = self.lay.nz
        Iu = ca.DM(ca.Sparsity.triplet(len(ub_rows), nz, list(range(len(ub_rows))), ub_rows.tolist()),
                   1.0)
        Il = ca.DM(ca.Sparsity.triplet(len(lb_rows), nz, list(range(len(lb_rows))), lb_rows.tolist()),
                   -1.0)
        A = ca.vertcat(Je, Ji, ca.SX(Iu), ca.SX(Il))
        b = ca.vertcat(be, bi, ca.DM(self.ub[ub_rows]), ca.DM(-self.lb[lb_rows]))
        Pnz = ca.vertcat(*Pu.nonzeros()) if Pu.nnz() else ca.SX(0, 1)
        Anz = ca.vertcat(*A.nonzeros())
        out = ca.vertcat(Pnz, q, Anz, b)
        f = ca.Function("mpc_qp", [z, self.p], [out], ["zbar", "p"], ["qp"])
        dims = {"P": Pu.sparsity(), "A": A.sparsity(), "n_eq": int(self.eq.numel()),
                "n_in": int(self.ineq.numel()) + len(ub_rows) + len(lb_rows)}
        return f, dims

    def cost_function(self):
        return ca.Function("mpc_cost", [self.z, self.p], [self.cost], ["z", "p"], ["cost"])

    def residual_function(self):
        """Nonlinear constraint values (dynamics defects, inequalities) for checks."""
        return ca.Function("mpc_g", [self.z, self.p], [self.eq, self.ineq], ["z", "p"], ["eq", "ineq"])
