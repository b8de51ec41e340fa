"""Multi-robot MPC over the unicycle model, built once and warm-started.

Life cycle (do-mpc style)::

    mpc = MultiRobotMPC(settings, n_robots=3)
    mpc.setup()                        # builds the problem without pairs once
    result = mpc.make_step(x0, objectives)

``x0`` is an (N, 5) array of robot states ``[px, py, theta, v, w]`` in the
world frame; ``result.commands`` is (N, 2): the body velocity ``(v, w)`` to
send now (m/s, rad/s). A failed solve never returns an uncommanded motion:
the commands are zero and ``result.fallback == "stop"``.

The problem (puzzlebot_mpc/ocp.py has the formulation) depends on the
number of robots and the set of pair slots; pair geometry and status, masks,
goals and references are numbers. Pair slots split the robots into
*independent subproblems* (connected components of the slot graph: robots
that are neither coupled nor pairing with each other): each is its own QP
with its own sparsity, built once (puzzlebot_mpc/qp.py, numpy only) and
cached, so a pair that changes status, or a robot that joins or leaves one
of the slots' pairs, only changes numbers. Small subproblems are solved
together in one QP (the result is the same: they are independent; it saves
per-solve overhead), large ones alone (``decompose``), optionally on
``solver_threads`` threads.

Solvers (``settings.solver``):

- ``active_set`` (default) and ``clarabel``: real-time iteration. Each step
  linearises the problem at the previous solution shifted by one stage
  (Gauss-Newton Hessian, linearised dynamics and constraints) and solves
  that sparse QP: ``active_set`` by the primal-dual active-set method
  (puzzlebot_mpc/active_set.py) warm-started with the working set of the
  last solution, one LDL' factorization per working set (Clarabel on a
  structure's first QP and on a QP it does not finish); ``clarabel`` by
  Clarabel's interior-point method. ``sqp_iterations`` QPs per step
  (1 = classic RTI), ``sqp_iterations_cold`` after a cold start.
  The butterfly set is two cones; each stage uses the cone of the previous
  plan's direction of travel. A robot at rest that must move (a goal, an
  active pair) has no such direction: the first QP of the step is then
  solved for both cones of up to ``butterfly_lobe_robots`` such robots and
  the lower objective wins.
- ``ipopt``: the full NLP of the same formulation, solved to convergence
  (built once, warm-started); slower, kept as the reference.
"""

import itertools
import math
import time
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import casadi as ca
import numpy as np

from puzzlebot_common.model import NU, NX, euler_rollout, euler_step
from puzzlebot_mpc import qp as qpm
from puzzlebot_mpc.ocp import Problem, Structure, param_vector

SOLVERS = ("active_set", "clarabel", "ipopt")


@dataclass
class PairObjective:
    """One pair slot of a step: robots (by index) and what to do with them.

    ``point_i``/``point_j``: points (x, y, heading) the alignment cost brings
    together (robot i's and robot j's body frames); ``head`` (x, y) in robot
    i's frame and ``polygon`` (K <= 4 counter-clockwise vertices in robot j's
    frame) define the coupling constraint, used when ``coupled``.
    """

    i: int
    j: int
    point_i: np.ndarray
    point_j: np.ndarray
    active: bool = False
    coupled: bool = False
    head: Optional[np.ndarray] = None
    polygon: Optional[np.ndarray] = None
    yaw_limit: float = math.pi          # |relative heading| allowed while coupled [rad]
    margin: Optional[float] = None      # m the polygon is tightened by in the constraint (None: pip_margin)


@dataclass
class Objectives:
    """What each robot should do this step (arrays over the N robots).

    goal: (N, 2) world position [m] for robots with goal_mask True.
    velocity: (N, 2) reference (v [m/s], w [rad/s]) for robots with
    velocity_mask True, or (N, H, 2) per prediction stage k = 1..H.
    velocity_mask: (N,) bool or weight scale, or (N, 2) per component (v, w).
    pairs: pair slots (alignment and coupling). A robot without a goal,
    velocity or active pair is driven to rest.
    open_loop: robot index -> (v [m/s], w [rad/s]) sent to that robot instead
    of the MPC's command this step (the paper's wiggle is an open-loop
    command, outside the MPC's velocity limits and butterfly set); applied by
    control_loop.ControlLoop after a successful solve only.
    edge_box: None (no edges) or (N, 4) (x_lo, x_hi, y_lo, y_hi) [m, world
    frame]: the box each robot's base_link keeps to over the horizon (soft),
    +-inf on a side without an edge (control_loop fills it from the world's
    stages).
    """

    goal: np.ndarray
    goal_mask: np.ndarray
    velocity: np.ndarray
    velocity_mask: np.ndarray
    pairs: List[PairObjective] = field(default_factory=list)
    open_loop: Dict[int, Tuple[float, float]] = field(default_factory=dict)
    edge_box: Optional[np.ndarray] = None

    @classmethod
    def stop_all(cls, n):
        return cls(np.zeros((n, 2)), np.zeros(n, bool), np.zeros((n, 2)), np.ones(n, bool))


@dataclass
class MPCResult:
    commands: np.ndarray            # (N, 2) body velocity to apply now (= predicted[:, 0, 3:5])
    predicted: np.ndarray           # (N, H+1, 5) predicted states (zeros after a failure)
    success: bool
    status: str
    solve_time_ms: float
    iterations: int
    cost: float
    fallback: str = ""              # "" or the safe action taken
    extra: dict = field(default_factory=dict)


GROUP_ROBOTS = 16    # subproblems with fewer robots are solved together in one QP (saves per-solve overhead;
                     # the solution is the same: they are independent). 128 robots in 32 chains of 4, one run at
                     # load 3-4: 8 -> 184 ms, 16 -> 154 ms, 32 -> 152 ms, all in one QP -> 172 ms per step (runs
                     # differ by about as much)
CACHE_SIZE = 64      # built QPs kept (least recently used dropped)


def components(n, pairs):
    """Connected components of the pair-slot graph over robots 0..n-1.

    Returns a list of (robots, slots): sorted robot indices and the indices
    of the slots (into ``pairs``) within each component, ordered by first robot.
    """
    parent = list(range(n))

    def root(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for i, j in pairs:
        ri, rj = root(i), root(j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)
    roots = np.array([root(a) for a in range(n)])
    slot_roots = np.array([roots[i] for i, _ in pairs], dtype=int)
    out = []
    for r in np.unique(roots):
        out.append((np.flatnonzero(roots == r), np.flatnonzero(slot_roots == r)))
    return out


def _clarabel_settings(settings):
    import clarabel

    opts = clarabel.DefaultSettings()
    opts.verbose = False
    opts.presolve_enable = False
    opts.input_sparse_dropzeros = False
    opts.max_iter = settings.max_iter
    # The real-time iteration takes one QP per step: 1e-6 relative accuracy is plenty, and
    # iterative refinement of the KKT solves (a third of the solve time) is not needed there.
    opts.tol_gap_abs = opts.tol_gap_rel = opts.tol_feas = settings.qp_tolerance
    opts.tol_ktratio = 10 * settings.qp_tolerance
    opts.iterative_refinement_enable = False
    return opts


def _finite(*arrays):
    return all(np.all(np.isfinite(a)) for a in arrays)


class _ClarabelQP:
    """One QP of the real-time iteration (a subproblem, or several solved together): its structure
    (qp.QPStructure, built once) and its Clarabel instance (set up at the first solve, then updated)."""

    def __init__(self, settings, st, qs=None):
        self.qs = qs or qpm.QPStructure(settings, st)
        self.lay = self.qs.lay
        self.solver = None
        self.last = None             # Clarabel's last solution (primal, slacks s and duals z of the rows)
        self.solver_s = 0.0          # time spent in the solver (set-up, update, solve) [s], summed

    def solve(self, settings, zbar, d):
        Px, q, Ax, b = self.qs.assemble(zbar, d)
        if not _finite(Px, q, Ax, b):
            return None, "non-finite QP data", 0, math.inf
        return self.solve_data(settings, Px, q, Ax, b)

    def solve_data(self, settings, Px, q, Ax, b):
        """Solve the assembled QP (solver order); returns (z in the layout's order or None, status,
        iterations, objective)."""
        import clarabel

        t0 = time.perf_counter()
        if self.solver is None:
            P, A = self.qs.matrices(Px, Ax)
            cones = [clarabel.ZeroConeT(self.qs.n_eq), clarabel.NonnegativeConeT(self.qs.n_in)]
            self.solver = clarabel.DefaultSolver(P, q, A, b, cones, _clarabel_settings(settings))
        else:       # lists: the binding converts them ~4x faster than numpy arrays (5 ms at 128 robots)
            self.solver.update(P=Px.tolist(), q=q.tolist(), A=Ax.tolist(), b=b.tolist())
        sol = self.solver.solve()
        self.solver_s += time.perf_counter() - t0
        self.last = sol
        status = str(sol.status)
        ok = status in ("Solved", "AlmostSolved")
        z = self.qs.from_solver(sol.x)
        if ok and not np.all(np.isfinite(z)):
            ok, status = False, status + " (non-finite solution)"
        return (z if ok else None), status, int(sol.iterations), float(sol.obj_val)

    def keep(self, z):
        """The step chose the solution ``z`` (of the lobe search's tries): nothing to remember."""

    def cost(self, z, d):
        return self.qs.cost(z, d)


class _ActiveSetQP:
    """One QP of the real-time iteration solved by the primal-dual active-set method
    (puzzlebot_mpc/active_set.py) on its KKT sparsity, started from the working set of the solution the
    last step chose. Clarabel solves the QP when there is no such working set yet (its first QP: a cold start from rest
    changes too many rows at once) and when the active set does not converge within
    ``active_set_iterations`` working sets (status "... (Clarabel fallback)"); the rows whose dual
    exceeds their slack in its solution are the next working set."""

    def __init__(self, settings, st):
        from puzzlebot_mpc.active_set import ActiveSetQP

        self.qs = qs = qpm.QPStructure(settings, st)
        self.lay = qs.lay
        self.solver = ActiveSetQP(qs.lay.nz, qs.P_indices, qs.P_indptr, qs.m_general, qs.G_indices, qs.G_indptr,
                                  qs.n_eq, max_iter=settings.active_set_iterations)
        if qs.bf_rows.size:          # the two rows of a butterfly cone: both active only at its vertex
            self.solver.exclusive = qs.bf_rows.reshape(-1, 2)
        self.fallback = None
        self.fallbacks = 0
        self.working = None          # the WorkingSet the next QP starts from
        self._tried = []             # (z, working set) of this step's solves, for keep()
        self.solver_s = 0.0

    def solve(self, settings, zbar, d):
        Px, q, Ax, b = self.qs.assemble(zbar, d)
        if not _finite(Px, q, Ax, b):
            return None, "non-finite QP data", 0, math.inf
        t0 = time.perf_counter()
        Ag, bg, lb, ub = self.qs.bounded(Ax, b)
        res = None
        if self.working is not None:         # cold (no solution yet): the interior point gives the first one
            res = self.solver.solve(Px, q, Ag, bg, lb, ub, self.working)
            self.solver_s += time.perf_counter() - t0
            if res.solved:
                z = self.qs.from_solver(res.z)
                self._tried.append((z, res.working))
                return z, "Solved", res.iterations, res.obj
            self.fallbacks += 1
        # not converged: the interior point solves the same QP, its solution gives the working set
        if self.fallback is None:
            self.fallback = _ClarabelQP(settings, None, qs=self.qs)
        before = self.fallback.solver_s
        z, status, it, obj = self.fallback.solve_data(settings, Px, q, Ax, b)
        self.solver_s += self.fallback.solver_s - before
        if z is not None:
            zs = z[self.qs.vorder]
            zs[self.qs.slack_solver] = np.maximum(zs[self.qs.slack_solver], 0.0)
            z = self.qs.from_solver(zs)
            obj = self.solver.objective(Px, q, zs)     # comparable with the active set's (lobe search)
            self._tried.append((z, self._working_set_of(self.fallback.last, Ax)))
        if res is None:
            return z, status, it, obj
        return z, status + " (Clarabel fallback)", res.iterations + it, obj

    def _working_set_of(self, sol, Ax):
        """The working set of an interior-point solution: the rows whose dual exceeds their slack."""
        from puzzlebot_mpc.active_set import AT_LOWER, AT_UPPER, FREE, WorkingSet

        qs = self.qs
        on = np.asarray(sol.z) > np.asarray(sol.s)                      # rows in the solver's order
        bounds = np.full(qs.lay.nz, FREE, np.int8)
        up = Ax[qs.bound_entry] > 0
        hit = on[qs.bound_rows]
        bounds[qs.bound_var[hit & ~up]] = AT_LOWER
        bounds[qs.bound_var[hit & up]] = AT_UPPER
        return WorkingSet(on[qs.general[qs.n_eq:]], bounds)

    def keep(self, z):
        """The step chose the solution ``z`` (None: the step failed): its working set starts the next QP."""
        for zt, ws in self._tried:
            if zt is z:
                self.working = ws
        self._tried = []

    def cost(self, z, d):
        return self.qs.cost(z, d)


class _IpoptNLP:
    """The full NLP of ocp.Problem, solved to convergence by IPOPT (built once, warm-started): the reference."""

    def __init__(self, settings, st):
        self.prob = Problem(settings, st)
        self.lay = self.prob.lay
        self.cost_fn = self.prob.cost_function()
        nlp = {"x": self.prob.z, "p": self.prob.p, "f": self.prob.cost,
               "g": ca.vertcat(self.prob.eq, self.prob.ineq)}
        opts = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                "ipopt.max_iter": settings.max_iter, "ipopt.tol": 1e-6}
        self.nlp = ca.nlpsol("mpc", "ipopt", nlp, opts)
        ne, ni = self.prob.eq.numel(), self.prob.ineq.numel()
        self.lbg = np.concatenate([np.zeros(ne), np.full(ni, -np.inf)])
        self.ubg = np.zeros(ne + ni)
        self.solver_s = 0.0

    def solve(self, settings, zbar, d):
        p = param_vector(self.prob.par, d)
        t0 = time.perf_counter()
        sol = self.nlp(x0=zbar, p=p, lbx=self.prob.lb, ubx=self.prob.ub, lbg=self.lbg, ubg=self.ubg)
        self.solver_s += time.perf_counter() - t0
        stats = self.nlp.stats()
        ok = bool(stats.get("success", False))
        status = str(stats.get("return_status", "unknown"))
        z = np.asarray(sol["x"]).ravel()
        return (z if ok else None), status, int(stats.get("iter_count", 0)), \
            (float(self.cost_fn(z, p)) if ok else math.inf)

    def keep(self, z):
        """The step chose the solution ``z``: nothing to remember."""

    def cost(self, z, d):
        return float(self.cost_fn(z, param_vector(self.prob.par, d)))


@dataclass(frozen=True)
class _Part:
    """One QP of a step's plan: its robots (global indices), its pair slots (indices into the step's
    sorted slots) and those slots in its own robot numbering."""

    robots: Tuple[int, ...]
    slots: Tuple[int, ...]
    local_pairs: Tuple[Tuple[int, int], ...]


class MultiRobotMPC:
    """Stacked MPC for N robots: go to goal, follow velocity, align and keep pairs."""

    def __init__(self, settings, n_robots):
        if n_robots < 1:
            raise ValueError("n_robots must be >= 1, got %r" % n_robots)
        if settings.solver not in SOLVERS:
            raise ValueError("unknown solver %r; known: %s" % (settings.solver, ", ".join(SOLVERS)))
        self.settings = settings
        self.n = n_robots
        self._qps = OrderedDict()     # (robots, local pairs, edges) -> _ClarabelQP, _ActiveSetQP or _IpoptNLP
        self._plans = OrderedDict()   # sorted slot tuple -> list of _Part
        self._warm = None             # (X (N, H+1, 5), U (N, H, 2)) of the last successful step
        self._pool = None
        self._ready = False
        self.build_seconds = 0.0

    # ------------------------------------------------------------------ build
    def setup(self):
        """Build the problem without pairs (the structure every robot set starts with)."""
        self.prepare(())
        self._ready = True
        return self

    def prepare(self, pairs):
        """Build (once) the QPs for a set of pair slots ((i, j) index tuples) ahead of its first step."""
        for part in self._plan(tuple(sorted(pairs))):
            self._qp(part)

    def _plan(self, key):
        """The QPs of a set of pair slots: independent subproblems, the small ones grouped (cached)."""
        plan = self._plans.get(key)
        if plan is not None:
            self._plans.move_to_end(key)
            return plan
        n = self.n
        if self.settings.solver == "ipopt" or not self.settings.decompose:
            comps = [(np.arange(n), np.arange(len(key)))]
        else:
            comps, small = [], []
            for robots, slots in components(n, key):
                (comps if len(robots) >= GROUP_ROBOTS else small).append((robots, slots))
            group_r, group_s = [], []
            for robots, slots in small:
                group_r.append(robots)
                group_s.append(slots)
                if sum(len(r) for r in group_r) >= GROUP_ROBOTS:
                    comps.append((np.concatenate(group_r), np.concatenate(group_s)))
                    group_r, group_s = [], []
            if group_r:
                comps.append((np.concatenate(group_r), np.concatenate(group_s)))
        plan = []
        for robots, slots in comps:
            robots, slots = np.sort(robots), np.sort(slots)
            local = {int(g): k for k, g in enumerate(robots)}
            plan.append(_Part(tuple(int(r) for r in robots), tuple(int(q) for q in slots),
                              tuple((local[key[q][0]], local[key[q][1]]) for q in slots)))
        self._plans[key] = plan
        if len(self._plans) > CACHE_SIZE:
            self._plans.popitem(last=False)
        return plan

    def _qp(self, part, edges=False):
        k = (part.robots, part.local_pairs, edges)
        qp = self._qps.get(k)
        if qp is None:
            t0 = time.perf_counter()
            s = self.settings
            st = Structure(len(part.robots), s.horizon, s.constraint_horizon, part.local_pairs, edges)
            qp = {"ipopt": _IpoptNLP, "clarabel": _ClarabelQP, "active_set": _ActiveSetQP}[s.solver](s, st)
            self.build_seconds += time.perf_counter() - t0
            self._qps[k] = qp
            if len(self._qps) > CACHE_SIZE:
                self._qps.popitem(last=False)
        else:
            self._qps.move_to_end(k)
        return qp

    # ------------------------------------------------------------------- step
    def make_step(self, x0, objectives):
        """Solve from states ``x0`` (N, 5) and return an :class:`MPCResult`."""
        if not self._ready:
            raise RuntimeError("MultiRobotMPC.setup() must be called before make_step()")
        s, n, h = self.settings, self.n, self.settings.horizon
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (n, NX):
            raise ValueError("x0 must have shape (%d, %d), got %s" % (n, NX, x0.shape))
        if not np.all(np.isfinite(x0)):
            raise ValueError("x0 contains non-finite values")
        x0 = x0.copy()
        x0[:, 3] = np.clip(x0[:, 3], -s.v_max, s.v_max)
        x0[:, 4] = np.clip(x0[:, 4], -s.w_max, s.w_max)
        t0 = time.perf_counter()
        pairs = sorted(objectives.pairs, key=lambda q: (q.i, q.j))
        key = tuple((q.i, q.j) for q in pairs)
        if len(set(key)) != len(key):
            raise ValueError("two pair slots for the same robots: %s" % (key,))
        bad = [k for k in key if not (0 <= k[0] < n and 0 <= k[1] < n) or k[0] == k[1]]
        if bad:
            raise ValueError("pair slots must join two different robots of 0..%d, got %s" % (n - 1, bad))
        Xbar, Ubar, cold = self._initial_guess(x0)     # unwraps x0's headings: before the pair data reads them
        data = qpm.pack(s, x0, objectives, pairs)
        parts = [(part, self._qp(part, data.has_edges(list(part.robots)))) for part in self._plan(key)]
        solver_s = sum(qp.solver_s for _, qp in parts)
        iters = s.sqp_iterations_cold if cold else s.sqp_iterations
        pref = self._preferred_direction(x0, objectives, pairs)
        ambiguous = self._ambiguous(Xbar, objectives, pairs) if s.butterfly else []
        jobs = [(part, qp, Xbar, Ubar, data, pref, ambiguous, iters) for part, qp in parts]
        try:
            if s.solver_threads > 1 and len(jobs) > 1:
                if self._pool is None:
                    self._pool = ThreadPoolExecutor(s.solver_threads, thread_name_prefix="mpc")
                outs = list(self._pool.map(lambda j: self._solve_part(*j), jobs))
            else:
                outs = [self._solve_part(*j) for j in jobs]
        except (RuntimeError, ValueError) as e:       # solver plugin errors: never crash the loop
            outs = [(None, "solver error: %s" % str(e).splitlines()[-1][:200], 0, None)]
        qp_iters = sum(o[2] for o in outs)
        solver_ms = 1e3 * (sum(qp.solver_s for _, qp in parts) - solver_s)
        failed = [o for o in outs if o[0] is None]
        solve_ms = 1e3 * (time.perf_counter() - t0)
        if failed:
            self._warm = None
            return MPCResult(np.zeros((n, 2)), np.zeros((n, h + 1, NX)), False, failed[0][1], solve_ms, qp_iters,
                             float("nan"), fallback="stop", extra={"structure_pairs": len(key),
                                                                   "subproblems": len(parts),
                                                                   "solver_ms": solver_ms})
        Xs, Us = np.zeros((n, h + 1, NX)), np.zeros((n, h, NU))
        cost, max_pip, max_bf, max_edge = 0.0, 0.0, 0.0, 0.0
        for (part, qp), (z, _, _, dpart) in zip(parts, outs):
            lay = qp.lay
            z[lay.slack] = np.maximum(z[lay.slack], 0.0)    # interior-point bound tolerance (~1e-8) x penalty
            r = list(part.robots)
            Xs[r] = lay.states(z, x0[r])
            Us[r] = lay.inputs(z)
            cost += qp.cost(z, dpart)
            sp_idx, sb_idx = lay.sp_idx[lay.sp_idx >= 0], lay.sb_idx[lay.sb_idx >= 0]
            max_pip = max(max_pip, float(z[sp_idx].max()) if sp_idx.size else 0.0)
            max_bf = max(max_bf, float(z[sb_idx].max()) if sb_idx.size else 0.0)
            se_idx = lay.se_idx[lay.se_idx >= 0]
            max_edge = max(max_edge, float(z[se_idx].max()) if se_idx.size else 0.0)
        self._warm = (Xs, Us)
        X = self._rollout(x0, Xs[:, 0, 3:], Us)
        commands = X[:, 0, 3:5].copy()
        commands[np.abs(commands) < s.command_zero] = 0.0      # interior-point noise: at rest means exactly 0
        extra = {"structure_pairs": len(key), "butterfly_lobes_tried": 2 ** len(ambiguous),
                 "max_pip_slack": max_pip, "max_butterfly_slack": max_bf, "max_edge_slack": max_edge,
                 "sqp_iterations": iters,
                 "subproblems": len(parts), "solver_ms": solver_ms}
        return MPCResult(commands, X, True, outs[0][1], solve_ms, qp_iters, cost, extra=extra)

    def _solve_part(self, part, qp, Xbar, Ubar, data, pref, ambiguous, iters):
        """SQP iterations of one QP; the first tries both butterfly cones of its ambiguous robots.

        Returns (z or None, status, QP iterations, the part's StepData)."""
        s, lay = self.settings, qp.lay
        robots = list(part.robots)
        d = data.subset(robots, list(part.slots))
        zbar = np.zeros(lay.nz)
        zbar[lay.x_idx[0, :, 3:]] = Xbar[robots, 0, 3:]
        zbar[lay.x_idx[1:]] = Xbar[robots, 1:].transpose(1, 0, 2)
        zbar[lay.u_idx] = Ubar[robots].transpose(1, 0, 2)
        where = {g: k for k, g in enumerate(robots)}
        mine = [where[a] for a in ambiguous if a in where]
        status, qp_iters = "not solved", 0
        for k in range(iters):
            tries = itertools.product((1.0, -1.0), repeat=len(mine)) if k == 0 else [()]
            best = None
            for signs in tries:
                pr = pref[robots].copy()
                if signs:
                    pr[mine] = signs
                if s.butterfly:
                    d.bsign = self._signs(lay, zbar, pr)
                z, status, it, obj = qp.solve(s, zbar, d)
                qp_iters += it
                if z is None:
                    qp.keep(None)
                    return None, status, qp_iters, d
                if best is None or obj < best[1]:
                    best = (z, obj)
            qp.keep(best[0])
            zbar = best[0]
        return zbar, status, qp_iters, d

    def reset(self):
        """Forget the warm start (next step is a cold start)."""
        self._warm = None

    # --------------------------------------------------------------- helpers
    def _rollout(self, x0, vw0, U):
        """States from the measured pose, the command (v_0, w_0) and the inputs (nonlinear model)."""
        return euler_rollout(np.concatenate([x0[:, :3], vw0], axis=1), U, self.settings.dt)

    def _initial_guess(self, x0):
        """Linearisation point (X (N, H+1, 5), U (N, H, 2), cold): the previous solution shifted by one
        stage, or a cold guess (the current velocities held).

        Also unwraps the measured headings (modifies ``x0`` in place) so they
        are continuous with the previous plan.
        """
        h, n, dt = self.settings.horizon, self.n, self.settings.dt
        if self._warm is None:
            U = np.zeros((n, h, NU))
            return euler_rollout(x0, U, dt), U, True       # keep moving at the current velocity
        Xo, Uo = self._warm
        x0[:, 2] = Xo[:, 1, 2] + np.remainder(x0[:, 2] - Xo[:, 1, 2] + math.pi, 2 * math.pi) - math.pi
        X = np.empty_like(Xo)
        U = np.empty_like(Uo)
        X[:, :-1], U[:, :-1] = Xo[:, 1:], Uo[:, 1:]
        U[:, -1] = 0.0
        X[:, -1] = euler_step(Xo[:, -1].T, U[:, -1].T, dt).T
        return X, U, False

    def _preferred_direction(self, x0, o, pairs):
        """+1 (forward) or -1 per robot: the way the robot should travel when at rest."""
        n = self.n
        pref = np.ones(n)
        c, s = np.cos(x0[:, 2]), np.sin(x0[:, 2])
        goal_on = np.asarray(o.goal_mask, bool)
        goal = qpm.finite_or_zero(o.goal)
        along = c * (goal[:, 0] - x0[:, 0]) + s * (goal[:, 1] - x0[:, 1])
        vm = np.asarray(o.velocity_mask, float).reshape(n, -1)
        v = np.asarray(o.velocity, float)[..., 0].reshape(n, -1)
        moving = np.abs(v) > 1e-9
        first = v[np.arange(n), np.argmax(moving, axis=1)]
        vel_dir = np.where(np.any(moving, axis=1) & (first < 0), -1.0, 1.0)
        pref = np.where(goal_on, np.where(along < 0, -1.0, 1.0),
                        np.where(np.any(vm != 0, axis=1), vel_dir, pref))
        act = [p for p in pairs if p.active]
        if act:
            ii = np.array([p.i for p in act])
            jj = np.array([p.j for p in act])
            pti = np.array([p.point_i[:2] for p in act], float)
            ptj = np.array([p.point_j[:2] for p in act], float)
            ci = x0[ii, :2] + np.stack([c[ii] * pti[:, 0] - s[ii] * pti[:, 1],
                                        s[ii] * pti[:, 0] + c[ii] * pti[:, 1]], 1)
            cj = x0[jj, :2] + np.stack([c[jj] * ptj[:, 0] - s[jj] * ptj[:, 1],
                                        s[jj] * ptj[:, 0] + c[jj] * ptj[:, 1]], 1)
            d = cj - ci
            di = np.where(c[ii] * d[:, 0] + s[ii] * d[:, 1] < 0, -1.0, 1.0)
            dj = np.where(-(c[jj] * d[:, 0] + s[jj] * d[:, 1]) < 0, -1.0, 1.0)
            pref[np.stack([ii, jj], 1).ravel()] = np.stack([di, dj], 1).ravel()    # in order: the last wins
        return pref

    def _lobe_threshold(self):
        s = self.settings
        return 2.0 * s.w_free * s.v_max / s.w_max     # |v| below which the plan has no direction of travel

    def _signs(self, lay, zbar, pref):
        """Butterfly cone per robot and stage (n, H+1): the plan's direction of travel, else ``pref``."""
        vbar = zbar[lay.x_idx[:, :, 3]].T
        return np.where(np.abs(vbar) > self._lobe_threshold(), np.sign(vbar), pref[:, None])

    def _ambiguous(self, Xbar, o, pairs):
        """Robots at rest in the plan that must move for their objective (a goal or an active pair,
        without a velocity reference): which way they should start is not known, so both butterfly
        lobes are tried (at most ``butterfly_lobe_robots`` robots, the first ones)."""
        at_rest = np.all(np.abs(Xbar[:, :2, 3]) <= self._lobe_threshold(), axis=1)
        movers = np.asarray(o.goal_mask, bool).copy()
        free = ~np.any(np.asarray(o.velocity_mask, float).reshape(self.n, -1) > 0, axis=1)
        for pr in pairs:
            if pr.active:
                for r in (pr.i, pr.j):
                    movers[r] |= free[r]
        return [int(i) for i in np.flatnonzero(movers & at_rest)][:self.settings.butterfly_lobe_robots]
