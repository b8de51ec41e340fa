"""Multi-robot MPC over the unicycle model, built once and warm-started.

Life cycle (do-mpc style)::

    mpc = MultiRobotMPC(settings, n_robots=3)
    mpc.setup()                        # builds the CasADi problem once
    result = mpc.make_step(x0, objectives)

``x0`` is an (N, 5) array of robot states ``[px, py, theta, v, w]`` in the
world frame; ``result.commands`` is (N, 2): the body velocity ``(v, w)`` to
send now (m/s, rad/s). A failed solve never returns an uncommanded motion:
the commands are zero and ``result.fallback == "stop"``.
"""

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from puzzlebot_mpc.model import NU, NX, euler_step


@dataclass
class Objectives:
    """What each robot should do this step (arrays over the N robots).

    goal: (N, 2) world position [m] for robots with goal_mask True.
    velocity: (N, 2) reference (v [m/s], w [rad/s]) for robots with
    velocity_mask True. A robot with neither mask is driven to rest.
    """

    goal: np.ndarray
    goal_mask: np.ndarray
    velocity: np.ndarray
    velocity_mask: np.ndarray

    @classmethod
    def stop_all(cls, n):
        return cls(np.zeros((n, 2)), np.zeros(n, bool), np.zeros((n, 2)), np.ones(n, bool))


@dataclass
class MPCResult:
    commands: np.ndarray            # (N, 2) body velocity to apply now
    predicted: np.ndarray           # (N, H+1, 5) predicted states (zeros after a failure)
    success: bool
    status: str
    solve_time_ms: float
    iterations: int
    cost: float
    fallback: str = ""              # "" or the safe action taken
    extra: dict = field(default_factory=dict)


class MultiRobotMPC:
    """Stacked MPC for N robots (go to goal, follow velocity, stop)."""

    def __init__(self, settings, n_robots):
        if n_robots < 1:
            raise ValueError("n_robots must be >= 1, got %r" % n_robots)
        self.settings = settings
        self.n = n_robots
        self._solver = None
        self._warm = None
        self._lbg = self._ubg = self._lbx = self._ubx = None

    # ------------------------------------------------------------------ build
    def setup(self):
        """Build the NLP once; parameters change per step, the structure does not."""
        s, n, h = self.settings, self.n, self.settings.horizon
        X = ca.SX.sym("X", NX, (h + 1) * n)
        U = ca.SX.sym("U", NU, h * n)
        P_x0 = ca.SX.sym("x0", NX, n)
        P_goal = ca.SX.sym("goal", 2, n)
        P_gmask = ca.SX.sym("gmask", 1, n)
        P_vref = ca.SX.sym("vref", 2, n)
        P_vmask = ca.SX.sym("vmask", 1, n)

        def xk(i, k):
            return X[:, i * (h + 1) + k]

        def uk(i, k):
            return U[:, i * h + k]

        cost = 0
        g, lbg, ubg = [], [], []
        ratio2 = (s.w_max / s.v_max) ** 2
        for i in range(n):
            g.append(xk(i, 0) - P_x0[:, i])
            lbg += [0.0] * NX
            ubg += [0.0] * NX
            for k in range(h):
                x, u = xk(i, k), uk(i, k)
                g.append(xk(i, k + 1) - euler_step(x, u, s.dt))
                lbg += [0.0] * NX
                ubg += [0.0] * NX
                cost += s.w_control * ca.sumsqr(u)
                x1 = xk(i, k + 1)
                dp = x1[0:2] - P_goal[:, i]
                weight = s.w_goal_terminal if k == h - 1 else s.w_goal_stage
                lateral = -ca.sin(x1[2]) * dp[0] + ca.cos(x1[2]) * dp[1]
                cost += P_gmask[i] * (weight * ca.sumsqr(dp) + s.w_goal_lateral * lateral ** 2
                                      + s.w_rest * ca.sumsqr(x1[3:5]))
                cost += P_vmask[i] * s.w_velocity * ca.sumsqr(x1[3:5] - P_vref[:, i])
                if s.butterfly:
                    g.append(x1[4] ** 2 - ratio2 * x1[3] ** 2)
                    lbg.append(-ca.inf)
                    ubg.append(s.w_free ** 2)

        w = ca.veccat(X, U)
        p = ca.veccat(P_x0, P_goal, P_gmask, P_vref, P_vmask)
        nlp = {"x": w, "f": cost, "g": ca.vertcat(*g), "p": p}
        opts = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                "ipopt.max_iter": s.max_iter, "ipopt.tol": 1e-6}
        if s.solver != "ipopt":
            opts = {"print_time": False}
        self._solver = ca.nlpsol("mpc", s.solver, nlp, opts)
        self._lbg, self._ubg = np.array(lbg), np.array(ubg)

        big = 1e9
        lbx_X = np.tile([-big, -big, -big, -s.v_max, -s.w_max], (h + 1) * n)
        ubx_X = np.tile([big, big, big, s.v_max, s.w_max], (h + 1) * n)
        lbx_U = np.tile([-s.dv_max, -s.dw_max], h * n)
        ubx_U = np.tile([s.dv_max, s.dw_max], h * n)
        self._lbx = np.concatenate([lbx_X, lbx_U])
        self._ubx = np.concatenate([ubx_X, ubx_U])
        self._nX = X.numel()
        return self

    # ------------------------------------------------------------------- step
    def make_step(self, x0, objectives):
        """Solve from states ``x0`` (N, 5) and return an :class:`MPCResult`."""
        if self._solver is None:
            raise RuntimeError("MultiRobotMPC.setup() must be called before make_step()")
        s, n, h = self.settings, self.n, self.settings.horizon
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (n, NX):
            raise ValueError("x0 must have shape (%d, %d), got %s" % (n, NX, x0.shape))
        if not np.all(np.isfinite(x0)):
            raise ValueError("x0 contains non-finite values")
        # The measured velocities may sit slightly outside the box after a
        # limit change; clip so the initial-state constraint stays feasible.
        x0 = x0.copy()
        x0[:, 3] = np.clip(x0[:, 3], -s.v_max, s.v_max)
        x0[:, 4] = np.clip(x0[:, 4], -s.w_max, s.w_max)
        o = objectives
        # Parameter layout = ca.veccat order: robot-major, as (N, k) arrays ravelled.
        p = np.concatenate([x0.ravel(), np.nan_to_num(o.goal).ravel(), o.goal_mask.astype(float),
                            np.nan_to_num(o.velocity).ravel(), o.velocity_mask.astype(float)])
        if self._warm is None:
            guess = np.concatenate([np.repeat(x0, h + 1, axis=0).ravel(), np.zeros(NU * h * n)])
        else:
            guess = self._shifted_guess(x0)
        t0 = time.perf_counter()
        sol = self._solver(x0=guess, p=p, lbx=self._lbx, ubx=self._ubx, lbg=self._lbg, ubg=self._ubg)
        solve_ms = 1e3 * (time.perf_counter() - t0)
        stats = self._solver.stats()
        success = bool(stats.get("success", False))
        status = str(stats.get("return_status", "unknown"))
        iterations = int(stats.get("iter_count", -1))
        if not success:
            self._warm = None
            return MPCResult(np.zeros((n, 2)), np.zeros((n, h + 1, NX)), False, status,
                             solve_ms, iterations, float("nan"), fallback="stop")
        wopt = np.asarray(sol["x"]).ravel()
        self._warm = wopt
        X = wopt[:self._nX].reshape(n, h + 1, NX)
        commands = X[:, 1, 3:5].copy()
        return MPCResult(commands, X, True, status, solve_ms, iterations, float(sol["f"]))

    def _shifted_guess(self, x0):
        """Previous solution shifted one step, with the new initial states."""
        n, h = self.n, self.settings.horizon
        X = self._warm[:self._nX].reshape(n, h + 1, NX).copy()
        U = self._warm[self._nX:].reshape(n, h, NU).copy()
        X[:, :-1] = X[:, 1:]
        U[:, :-1] = U[:, 1:]
        U[:, -1] = 0.0
        X[:, 0] = x0
        return np.concatenate([X.ravel(), U.ravel()])
