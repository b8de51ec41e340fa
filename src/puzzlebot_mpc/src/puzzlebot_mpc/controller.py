"""Multi-robot MPC over the unicycle model, built once and warm-started.

Life cycle (do-mpc style)::

    mpc = MultiRobotMPC(settings, n_robots=3)
    mpc.setup()                        # builds the problem without pairs once
    result = mpc.make_step(x0, objectives)

``x0`` is an (N, 5) array of robot states ``[px, py, theta, v, w]`` in the
world frame; ``result.commands`` is (N, 2): the body velocity ``(v, w)`` to
send now (m/s, rad/s). A failed solve never returns an uncommanded motion:
the commands are zero and ``result.fallback == "stop"``.

The problem (puzzlebot_mpc/ocp.py) is built once per *structure*: the
number of robots and the set of pair slots. Pair geometry, masks, goals and
references are parameters. Structures are cached, so a behaviour that keeps
its pair set never rebuilds.

Solvers (``settings.solver``):

- ``clarabel`` (default): real-time iteration. Each step linearises the
  problem at the previous solution shifted by one stage (Gauss-Newton
  Hessian, linearised dynamics and constraints) and solves that sparse QP
  with Clarabel's interior-point method. ``sqp_iterations`` QPs per step
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
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import casadi as ca
import numpy as np
import scipy.sparse as sp

from puzzlebot_common.geometry import polygon_halfplanes
from puzzlebot_common.model import NU, NX, euler_step
from puzzlebot_mpc.ocp import POLY_ROWS, Problem, Structure

SOLVERS = ("clarabel", "ipopt")


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
    """

    goal: np.ndarray
    goal_mask: np.ndarray
    velocity: np.ndarray
    velocity_mask: np.ndarray
    pairs: List[PairObjective] = field(default_factory=list)
    open_loop: Dict[int, Tuple[float, float]] = field(default_factory=dict)

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


class _Built:
    """A built structure: problem, QP function and solver instance."""

    def __init__(self, settings, st):
        t0 = time.perf_counter()
        self.st = st
        self.prob = Problem(settings, st)
        self.lay, self.par = self.prob.lay, self.prob.par
        self.cost_fn = self.prob.cost_function()
        self.solver = None
        if settings.solver == "clarabel":
            self.qp_fn, dims = self.prob.qp_function()
            self.P_sp, self.A_sp = dims["P"], dims["A"]
            self.n_eq, self.n_in = dims["n_eq"], dims["n_in"]
            self.nP, self.nA = self.P_sp.nnz(), self.A_sp.nnz()
        else:
            nlp = {"x": self.prob.z, "p": self.prob.p, "f": self.prob.cost,
                   "g": ca.vertcat(self.prob.eq, self.prob.ineq)}
            opts = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                    "ipopt.max_iter": settings.max_iter, "ipopt.tol": 1e-6}
            self.nlp = ca.nlpsol("mpc", "ipopt", nlp, opts)
            ne, ni = self.prob.eq.numel(), self.prob.ineq.numel()
            self.lbg = np.concatenate([np.zeros(ne), np.full(ni, -np.inf)])
            self.ubg = np.zeros(ne + ni)
        self.build_s = time.perf_counter() - t0

    def clarabel_solve(self, settings, zbar, p):
        import clarabel

        data = np.asarray(self.qp_fn(zbar, p)).ravel()
        nz = self.lay.nz
        o = 0
        Px = data[o:o + self.nP]
        o += self.nP
        q = data[o:o + nz]
        o += nz
        Ax = data[o:o + self.nA]
        o += self.nA
        b = data[o:]
        if not (np.all(np.isfinite(Px)) and np.all(np.isfinite(q)) and np.all(np.isfinite(Ax))
                and np.all(np.isfinite(b))):
            return None, "non-finite QP data", 0
        if self.solver is None:
            P = sp.csc_matrix((Px, np.array(self.P_sp.row()), np.array(self.P_sp.colind())), shape=(nz, nz))
            A = sp.csc_matrix((Ax, np.array(self.A_sp.row()), np.array(self.A_sp.colind())),
                              shape=(self.n_eq + self.n_in, nz))
            cones = [clarabel.ZeroConeT(self.n_eq), clarabel.NonnegativeConeT(self.n_in)]
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
            self.solver = clarabel.DefaultSolver(P, q, A, b, cones, opts)
        else:
            self.solver.update(P=Px, q=q, A=Ax, b=b)
        sol = self.solver.solve()
        status = str(sol.status)
        ok = status in ("Solved", "AlmostSolved")
        z = np.asarray(sol.x, dtype=float)
        if ok and not np.all(np.isfinite(z)):
            ok, status = False, status + " (non-finite solution)"
        return (z if ok else None), status, int(sol.iterations), float(sol.obj_val)


class MultiRobotMPC:
    """Stacked MPC for N robots: go to goal, follow velocity, align and keep pairs."""

    def __init__(self, settings, n_robots):
        if n_robots < 1:
            raise ValueError("n_robots must be >= 1, got %r" % n_robots)
        if settings.solver not in SOLVERS:
            raise ValueError("unknown solver %r; known: %s" % (settings.solver, ", ".join(SOLVERS)))
        self.settings = settings
        self.n = n_robots
        self._built = {}
        self._warm = None            # (structure, z) of the last successful step
        self._ready = False
        self.build_seconds = 0.0

    # ------------------------------------------------------------------ build
    def setup(self):
        """Build the problem without pairs (the structure every robot set starts with)."""
        self._get(())
        self._ready = True
        return self

    def prepare(self, pairs):
        """Build (once) the problem for a set of pair slots ((i, j) index tuples) ahead of its first step."""
        self._get(tuple(sorted(pairs)))

    def _structure(self, pairs):
        s = self.settings
        return Structure(self.n, s.horizon, s.constraint_horizon, tuple(pairs))

    def _get(self, key):
        st = self._structure(key)
        built = self._built.get(st)
        if built is None:
            built = _Built(self.settings, st)
            self._built[st] = built
            self.build_seconds += built.build_s
        return built

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
        built = self._get(key)
        zbar, cold = self._initial_guess(built, x0)
        p = self._params(built, x0, objectives, pairs)
        iters = s.sqp_iterations_cold if cold else s.sqp_iterations
        status, qp_iters, z = "not solved", 0, None
        lobes_tried = 1
        try:
            for k in range(iters):
                pref = self._preferred_direction(x0, objectives, pairs)
                ambiguous = self._ambiguous(built, zbar, objectives, pairs) if k == 0 and s.butterfly else []
                best = None
                for signs in itertools.product((1.0, -1.0), repeat=len(ambiguous)):
                    pref[ambiguous] = signs
                    self._set_butterfly_signs(built, p, zbar, pref)
                    zk, status, it, obj = self._solve_once(built, zbar, p)
                    qp_iters += it
                    if zk is None:
                        best = None
                        break
                    if best is None or obj < best[1]:
                        best = (zk, obj)
                lobes_tried = max(lobes_tried, 2 ** len(ambiguous))
                z = best[0] if best else None
                if z is None:
                    break
                zbar = z
        except (RuntimeError, ValueError) as e:       # solver plugin errors: never crash the loop
            z, status = None, "solver error: %s" % str(e).splitlines()[-1][:200]
        solve_ms = 1e3 * (time.perf_counter() - t0)
        if z is None:
            self._warm = None
            return MPCResult(np.zeros((n, 2)), np.zeros((n, h + 1, NX)), False, status, solve_ms, qp_iters,
                             float("nan"), fallback="stop", extra={"structure_pairs": len(key)})
        lay = built.lay
        z[lay.slack] = np.maximum(z[lay.slack], 0.0)    # interior-point bound tolerance (~1e-8) x penalty
        self._warm = (built.st, z, x0)
        U = lay.inputs(z)
        X = self._rollout(x0, z[lay.x_idx[0, :, 3:]], U)
        commands = X[:, 0, 3:5].copy()
        commands[np.abs(commands) < s.command_zero] = 0.0      # interior-point noise: at rest means exactly 0
        cost = float(built.cost_fn(z, p))
        sp_idx = lay.sp_idx[lay.sp_idx >= 0]
        sb_idx = lay.sb_idx[lay.sb_idx >= 0]
        extra = {"structure_pairs": len(key), "butterfly_lobes_tried": lobes_tried,
                 "max_pip_slack": float(z[sp_idx].max()) if sp_idx.size else 0.0,
                 "max_butterfly_slack": float(z[sb_idx].max()) if sb_idx.size else 0.0,
                 "sqp_iterations": iters}
        return MPCResult(commands, X, True, status, solve_ms, qp_iters, cost, extra=extra)

    def reset(self):
        """Forget the warm start (next step is a cold start)."""
        self._warm = None

    # --------------------------------------------------------------- helpers
    def _rollout(self, x0, vw0, U):
        """States from the measured pose, the command (v_0, w_0) and the inputs (nonlinear model)."""
        X = np.zeros((self.n, U.shape[1] + 1, NX))
        X[:, 0, :3] = x0[:, :3]
        X[:, 0, 3:] = vw0
        for k in range(U.shape[1]):
            X[:, k + 1] = euler_step(X[:, k].T, U[:, k].T, self.settings.dt).T
        return X

    def _initial_guess(self, built, x0):
        """Linearisation point: the previous solution shifted by one stage, or a cold guess.

        Also unwraps the measured headings (modifies ``x0`` in place) so they
        are continuous with the previous plan.
        """
        lay, h, n = built.lay, self.settings.horizon, self.n
        if self._warm is None:
            X = np.repeat(x0[:, None, :], h + 1, axis=1)
            for k in range(1, h + 1):   # keep moving at the current velocity
                X[:, k] = euler_step(X[:, k - 1].T, np.zeros((NU, n)), self.settings.dt).T
            U = np.zeros((n, h, NU))
            cold = True
        else:
            st_old, z_old, x0_old = self._warm
            old = built.lay if st_old == built.st else self._built[st_old].lay
            Xo, Uo = old.states(z_old, x0_old), old.inputs(z_old)
            x0[:, 2] = Xo[:, 1, 2] + np.remainder(x0[:, 2] - Xo[:, 1, 2] + math.pi, 2 * math.pi) - math.pi
            X = np.empty_like(Xo)
            U = np.empty_like(Uo)
            X[:, :-1], U[:, :-1] = Xo[:, 1:], Uo[:, 1:]
            U[:, -1] = 0.0
            X[:, -1] = euler_step(Xo[:, -1].T, U[:, -1].T, self.settings.dt).T
            cold = False
        z = np.zeros(lay.nz)
        z[lay.x_idx[0, :, 3:]] = X[:, 0, 3:]
        z[lay.x_idx[1:]] = X[:, 1:].transpose(1, 0, 2)
        z[lay.u_idx] = U.transpose(1, 0, 2)
        return z, cold

    def _params(self, built, x0, o, pairs):
        par, n, h = built.par, self.n, self.settings.horizon
        p = np.zeros(par.size)
        par.put(p, "x0", x0)
        par.put(p, "goal", np.nan_to_num(np.asarray(o.goal, float)))
        par.put(p, "goal_on", np.asarray(o.goal_mask, float))
        vel = np.nan_to_num(np.asarray(o.velocity, float))
        if vel.ndim == 2:
            vel = np.repeat(vel[:, None, :], h, axis=1)
        if vel.shape != (n, h, 2):
            raise ValueError("velocity references must be (N, 2) or (N, H, 2), got %s" % (vel.shape,))
        par.put(p, "vref", vel.reshape(n * h, 2))
        vm = np.asarray(o.velocity_mask, float)
        par.put(p, "vel_on", vm if vm.ndim == 2 else np.repeat(vm[:, None], 2, axis=1))
        par.put(p, "bsign", np.ones(n * (h + 1)))
        if pairs:
            P = len(pairs)
            g = np.zeros((P * POLY_ROWS, 2))
            hh = np.zeros(P * POLY_ROWS)
            hh[:] = 1.0                      # unused rows: 0 . q - 1 <= 0 always holds
            heads = np.zeros((P, 2))
            for q, pr in enumerate(pairs):
                if pr.polygon is not None:
                    gq, hq = polygon_halfplanes(pr.polygon)
                    norm = np.linalg.norm(gq, axis=1)
                    gq, hq = gq / norm[:, None], hq / norm - self.settings.pip_margin
                    k = len(gq)
                    if k > POLY_ROWS:
                        raise ValueError("coupling polygons have at most %d vertices" % POLY_ROWS)
                    g[q * POLY_ROWS:q * POLY_ROWS + k] = gq
                    hh[q * POLY_ROWS:q * POLY_ROWS + k] = hq
                if pr.head is not None:
                    heads[q] = pr.head
                if pr.coupled and pr.active:
                    raise ValueError("pair %d->%d cannot be active and coupled at once" % (pr.i, pr.j))
                if pr.coupled and (pr.polygon is None or pr.head is None):
                    raise ValueError("coupled pair %d->%d needs a head point and a polygon" % (pr.i, pr.j))
            par.put(p, "pt_i", np.array([pr.point_i for pr in pairs], float))
            par.put(p, "pt_j", np.array([pr.point_j for pr in pairs], float))
            par.put(p, "act", np.array([float(pr.active) for pr in pairs]))
            par.put(p, "conn", np.array([float(pr.coupled) for pr in pairs]))
            par.put(p, "head", heads)
            par.put(p, "poly_g", g)
            par.put(p, "poly_h", hh)
            par.put(p, "yaw_lim", np.array([pr.yaw_limit for pr in pairs], float))
            raw = np.array([x0[pr.i, 2] + pr.point_i[2] - x0[pr.j, 2] - pr.point_j[2] - math.pi for pr in pairs])
            par.put(p, "yaw_off", 2 * math.pi * np.round(raw / (2 * math.pi)))
        return p

    def _preferred_direction(self, x0, o, pairs):
        """+1 (forward) or -1 per robot: the way the robot should travel when at rest."""
        n = self.n
        pref = np.ones(n)
        c, s = np.cos(x0[:, 2]), np.sin(x0[:, 2])
        for i in range(n):
            if o.goal_mask[i]:
                dx = o.goal[i][0] - x0[i, 0]
                dy = o.goal[i][1] - x0[i, 1]
                pref[i] = -1.0 if c[i] * dx + s[i] * dy < 0 else 1.0
            elif np.any(o.velocity_mask[i]):
                v = np.asarray(o.velocity[i], float)
                v = v[..., 0].ravel()
                vv = v[np.abs(v) > 1e-9]
                pref[i] = -1.0 if vv.size and vv[0] < 0 else 1.0
        for pr in pairs:
            if not pr.active:
                continue
            i, j = pr.i, pr.j
            ci = x0[i, :2] + _rot2(x0[i, 2], pr.point_i[:2])
            cj = x0[j, :2] + _rot2(x0[j, 2], pr.point_j[:2])
            d = cj - ci
            pref[i] = -1.0 if c[i] * d[0] + s[i] * d[1] < 0 else 1.0
            pref[j] = -1.0 if -(c[j] * d[0] + s[j] * d[1]) < 0 else 1.0
        return pref

    def _lobe_threshold(self):
        s = self.settings
        return 2.0 * s.w_free * s.v_max / s.w_max     # |v| below which the plan has no direction of travel

    def _set_butterfly_signs(self, built, p, zbar, pref):
        """Butterfly cone per stage: the previous plan's direction of travel, else ``pref``."""
        if not self.settings.butterfly:
            return
        vbar = zbar[built.lay.x_idx[:, :, 3]].T       # (n, H+1)
        sign = np.where(np.abs(vbar) > self._lobe_threshold(), np.sign(vbar), pref[:, None])
        built.par.put(p, "bsign", sign.reshape(-1))

    def _ambiguous(self, built, zbar, o, pairs):
        """Robots at rest in the plan that must move for their objective (a goal or an active pair,
        without a velocity reference): which way they should start is not known, so both butterfly
        lobes are tried (at most ``butterfly_lobe_robots`` robots, the first ones)."""
        vbar = zbar[built.lay.x_idx[:2, :, 3]]         # stages 0 and 1
        at_rest = np.all(np.abs(vbar) <= self._lobe_threshold(), axis=0)
        movers = set(np.flatnonzero(np.asarray(o.goal_mask, bool)))
        vm = np.asarray(o.velocity_mask, float)
        free = ~np.any(vm.reshape(self.n, -1) > 0, axis=1)
        for pr in pairs:
            if pr.active:
                movers.update(r for r in (pr.i, pr.j) if free[r])
        return [i for i in sorted(movers) if at_rest[i]][:self.settings.butterfly_lobe_robots]

    def _solve_once(self, built, zbar, p):
        if self.settings.solver == "clarabel":
            return built.clarabel_solve(self.settings, zbar, p)
        z, status, it = self._ipopt_solve(built, zbar, p)
        return z, status, it, (float(built.cost_fn(z, p)) if z is not None else float("inf"))

    def _ipopt_solve(self, built, zbar, p):
        b = built
        sol = b.nlp(x0=zbar, p=p, lbx=b.prob.lb, ubx=b.prob.ub, lbg=b.lbg, ubg=b.ubg)
        stats = b.nlp.stats()
        ok = bool(stats.get("success", False))
        status = str(stats.get("return_status", "unknown"))
        z = np.asarray(sol["x"]).ravel()
        return (z if ok else None), status, int(stats.get("iter_count", 0))


def _rot2(th, v):
    c, s = math.cos(th), math.sin(th)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])
