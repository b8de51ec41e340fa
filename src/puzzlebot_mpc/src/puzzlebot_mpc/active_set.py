"""A primal-dual active-set QP solver on a KKT sparsity fixed once (numpy + QDLDL).

Solves::

    min  1/2 z' P z + q' z
    s.t. A_E z  = b_E          (the first ``n_eq`` rows of A)
         A_I z <= b_I          (the other rows)
         lb <= z <= ub         (per variable; -inf / +inf where unbounded)

for a sequence of problems that share P's and A's sparsity, as the real-time
iteration's QPs do (puzzlebot_mpc/qp.py). The *working set* is the
inequality rows held as equalities and the variables held at a bound. Each
iteration solves the equality-constrained QP of the working set, i.e. the
quasi-definite KKT system::

    [ P_FF + delta I    A_WF'      ] [ z_F ]   [ -q_F - P_FX z_X ]
    [ A_WF              -delta I   ] [ l_W ] = [  b_W - A_WX z_X ]

(F: free variables, X: variables at their bounds, W: equality rows and the
inequality rows in the working set), by one numeric LDL' refactorization of a
matrix whose sparsity never changes -- rows outside the working set have a
zero row and -1 on the diagonal, variables at a bound a zero row and column
and 1 on the diagonal -- followed by iterative refinement against the
unregularised system. The working set is then updated by the signs of the
multipliers and the violations (the primal-dual active-set method,
Hintermueller, Ito and Kunisch, SIAM J. Optim. 13(3), 2002): a row leaves
when its multiplier is negative, enters when it is violated; a variable
leaves its bound when the bound's multiplier is negative, is put on a bound
it violates. After FULL_STEPS iterations without convergence it changes
only the most violated indices (half as many each iteration, down to one; a
working set seen before drops it to one at once), which converges from most
starts, slowly; of two ``exclusive`` rows (a butterfly cone's two halves:
both hold only at its vertex) one enters at a time. When no index changes,
the KKT conditions hold to the tolerances below: the result is the QP's
solution, not an approximation of it. Started from the previous step's working set, a real-time iteration's
QP usually needs one factorization (Clarabel's interior point takes 11-12);
the method is not guaranteed to converge from any start, so the caller
falls back to an interior-point solver after ``max_iter`` iterations.

The factorization is QDLDL's (``qdldl`` on PyPI: its AMD ordering and
symbolic analysis once, in the first solve; a numeric refactorization per
iteration).
"""

import numpy as np
import scipy.sparse as sp

try:
    import qdldl
except ImportError as e:       # an environment set up before the dependency: say what to do
    raise ImportError("puzzlebot_mpc.active_set needs the qdldl package (requirements.txt; scripts/setup.sh "
                      "installs it), or set mpc.solver: clarabel") from e

DELTA = 1e-9          # regularisation of the KKT diagonal (primal +, dual -); refinement removes its effect
REFINE_MAX = 4        # iterative refinement steps at most per factorization
REFINE_TOL = 1e-13    # ... until the gradient's and the rows' residuals are below this, relative to
                      # their right-hand sides' scales (1 + max |.|)
PRIMAL_TOL = 1e-9     # violation of a row or bound (relative to 1 + |b|) that puts it into the working set
DUAL_TOL = 1e-12      # negative multiplier (relative to 1 + max |q|) that takes a row or bound out of it

FULL_STEPS = 3        # iterations that change every violated index; then fewer at a time (halving)

FREE, AT_LOWER, AT_UPPER = 0, -1, 1


def _largest(row_score, bound_score, k):
    """Masks of the k largest scores over both arrays."""
    both = np.concatenate([row_score, bound_score])
    k = min(k, both.size)
    top = np.argpartition(-both, k - 1)[:k]
    mask = np.zeros(both.size, bool)
    mask[top] = True
    return mask[:row_score.size], mask[row_score.size:]


class WorkingSet:
    """Inequality rows held as equalities (``rows``: bool, one per inequality row) and the variables held
    at a bound (``bounds``: int8 per variable, FREE, AT_LOWER or AT_UPPER)."""

    def __init__(self, rows, bounds):
        self.rows = np.asarray(rows, bool)
        self.bounds = np.asarray(bounds, np.int8)

    def copy(self):
        return WorkingSet(self.rows.copy(), self.bounds.copy())

    def __eq__(self, other):
        return np.array_equal(self.rows, other.rows) and np.array_equal(self.bounds, other.bounds)


class Result:
    """``z`` (nz,), ``y`` (m,) row multipliers (>= 0 on inequality rows), ``bound_duals`` (nz,)
    (>= 0 at a lower bound, <= 0 at an upper one), the final ``working`` set, ``iterations``
    (factorizations), ``solved`` and ``obj`` (1/2 z'Pz + q'z)."""

    def __init__(self, z, y, bound_duals, working, iterations, solved, obj):
        self.z, self.y, self.bound_duals = z, y, bound_duals
        self.working, self.iterations, self.solved, self.obj = working, iterations, solved, obj


class ActiveSetQP:
    """The solver for one sparsity: P's upper triangle and A in CSC form (indices, indptr), n_eq
    equality rows first. ``solve`` takes the numbers (P and A's CSC data, q, b, lb, ub)."""

    def __init__(self, nz, P_indices, P_indptr, m, A_indices, A_indptr, n_eq, max_iter=10):
        if n_eq > m:
            raise ValueError("n_eq (%d) exceeds the number of rows (%d)" % (n_eq, m))
        self.nz, self.m, self.n_eq, self.max_iter = nz, m, n_eq, max_iter
        P_indices, P_indptr = np.asarray(P_indices, np.int64), np.asarray(P_indptr, np.int64)
        A_indices, A_indptr = np.asarray(A_indices, np.int64), np.asarray(A_indptr, np.int64)
        p_col = np.repeat(np.arange(nz), np.diff(P_indptr))
        if np.any(P_indices > p_col):
            raise ValueError("P must be given as its upper triangle")
        a_col = np.repeat(np.arange(nz), np.diff(A_indptr))
        self.p_row, self.p_col, self.a_row, self.a_col = P_indices, p_col, A_indices, a_col
        self.p_diag = np.flatnonzero(P_indices == p_col)
        # the KKT's upper triangle, CSC: column j < nz = P's column j and the diagonal (var j), column
        # nz + i = row i of A and the diagonal (row i)
        N = self.N = nz + m
        missing = np.setdiff1d(np.arange(nz), P_indices[self.p_diag])
        rows = np.concatenate([P_indices, missing, a_col, nz + np.arange(m)])
        cols = np.concatenate([p_col, missing, nz + A_indices, nz + np.arange(m)])
        kind = np.repeat([0, 1, 2, 3], [len(P_indices), len(missing), len(A_indices), m])
        src = np.concatenate([np.arange(len(P_indices)), missing, np.arange(len(A_indices)), np.arange(m)])
        order = np.lexsort((rows, cols))
        rows, cols, kind, src = rows[order], cols[order], kind[order], src[order]
        self.K = sp.csc_matrix((np.zeros(len(rows)), rows, np.searchsorted(cols, np.arange(N + 1))),
                               shape=(N, N))
        self.k_p = np.empty(len(P_indices), np.int64)
        self.k_p[src[kind == 0]] = np.flatnonzero(kind == 0)
        self.k_a = np.empty(len(A_indices), np.int64)
        self.k_a[src[kind == 2]] = np.flatnonzero(kind == 2)
        self.k_row = np.empty(m, np.int64)
        self.k_row[src[kind == 3]] = np.flatnonzero(kind == 3)
        self.k_var = np.empty(nz, np.int64)                       # diagonal of each variable
        self.k_var[rows[(kind <= 1) & (rows == cols)]] = np.flatnonzero((kind <= 1) & (rows == cols))
        # P (both triangles) and A, A' for the products: matrices made once, their data replaced per QP
        off = P_indices != p_col
        f_row = np.concatenate([P_indices, p_col[off]])
        f_col = np.concatenate([p_col, P_indices[off]])
        f_src = np.concatenate([np.arange(len(P_indices)), np.flatnonzero(off)])
        order = np.lexsort((f_row, f_col))
        self.pf_src = f_src[order]
        self.Pf = sp.csc_matrix((np.zeros(len(order)), f_row[order], np.searchsorted(f_col[order], np.arange(nz + 1))),
                                shape=(nz, nz))
        self.A = sp.csc_matrix((np.zeros(len(A_indices)), A_indices, A_indptr), shape=(m, nz))
        self.AT = sp.csr_matrix((self.A.data, A_indices, A_indptr), shape=(nz, m))
        self.factor = None
        self.factorizations = 0
        self.exclusive = None        # (k, 2) inequality rows of which one enters at a time (set by the caller)

    def cold_working_set(self):
        return WorkingSet(np.zeros(self.m - self.n_eq, bool), np.zeros(self.nz, np.int8))

    def objective(self, Px, q, z):
        """1/2 z'Pz + q'z of P's upper-triangle data Px."""
        self._set(Px, None)
        return float(0.5 * z @ (self.Pf @ z) + q @ z)

    # ------------------------------------------------------------------ numbers
    def _set(self, Px, Ax):
        self.Pf.data = np.asarray(Px, float)[self.pf_src]
        if Ax is not None:
            self.A.data = np.asarray(Ax, float)
            self.AT.data = self.A.data

    def _factor(self, Kx):
        self.K.data = Kx
        if self.factor is None:
            self.factor = qdldl.Solver(self.K, upper=True)
        else:
            self.factor.update(self.K, upper=True)
        self.factorizations += 1

    def solve(self, Px, q, Ax, b, lb, ub, working=None):
        """Solve one QP from ``working`` (a WorkingSet; default: no row, no bound). Returns a Result;
        ``solved`` False after ``max_iter`` iterations without a repeated working set, or on
        non-finite numbers (``z`` is then the last iterate, not a solution)."""
        nz, m, ne = self.nz, self.m, self.n_eq
        Px = np.asarray(Px, float)
        self._set(Px, Ax)
        pd = Px[self.p_diag]
        q, b = np.asarray(q, float), np.asarray(b, float)
        lb, ub = np.asarray(lb, float), np.asarray(ub, float)
        fixed_always = lb == ub
        ws = (working or self.cold_working_set()).copy()
        ws.bounds[fixed_always] = AT_LOWER
        ws.bounds[(ws.bounds == AT_LOWER) & ~np.isfinite(lb)] = FREE
        ws.bounds[(ws.bounds == AT_UPPER) & ~np.isfinite(ub)] = FREE
        tol_p_rows = PRIMAL_TOL * (1.0 + np.abs(b[ne:]))
        tol_lb = PRIMAL_TOL * (1.0 + np.abs(np.where(np.isfinite(lb), lb, 0.0)))
        tol_ub = PRIMAL_TOL * (1.0 + np.abs(np.where(np.isfinite(ub), ub, 0.0)))
        tol_d = DUAL_TOL * (1.0 + np.abs(q).max(initial=0.0))
        Kx = np.empty(self.K.nnz)
        seen = []
        best, limit = np.inf, None
        z = np.zeros(nz)
        y = np.zeros(m)
        g = np.zeros(nz)
        for it in range(1, self.max_iter + 1):
            on = np.concatenate([np.ones(ne, bool), ws.rows])               # rows held as equalities
            fx = ws.bounds != FREE
            zx = np.where(ws.bounds == AT_LOWER, lb, np.where(ws.bounds == AT_UPPER, ub, 0.0))
            Kx[self.k_p] = np.where(fx[self.p_row] | fx[self.p_col], 0.0, Px)
            Kx[self.k_var] = np.where(fx, 1.0, DELTA)
            Kx[self.k_p[self.p_diag]] = np.where(fx[self.p_row[self.p_diag]], 1.0, pd + DELTA)
            Kx[self.k_a] = np.where(on[self.a_row] & ~fx[self.a_col], self.A.data, 0.0)
            Kx[self.k_row] = np.where(on, -DELTA, -1.0)
            if not np.all(np.isfinite(Kx)):
                return Result(z, y, g, ws, it - 1, False, np.inf)
            self._factor(Kx)
            rv = np.where(fx, zx, -q - (self.Pf @ zx))
            rr = np.where(on, b - self.A @ zx, 0.0)
            tol_v = REFINE_TOL * (1.0 + np.abs(rv).max(initial=0.0))     # gradient residual
            tol_r = REFINE_TOL * (1.0 + np.abs(rr).max(initial=0.0))     # row residual
            x = self.factor.solve(np.concatenate([rv, rr]))
            for k in range(REFINE_MAX + 1):
                z, y = x[:nz].copy(), np.where(on, x[nz:], 0.0)
                z[fx] = zx[fx]
                Az = self.A @ z
                g = (self.Pf @ z) + q + self.AT @ y                        # gradient of the Lagrangian
                r_v, r_r = np.where(fx, 0.0, -g), np.where(on, b - Az, 0.0)
                if k == REFINE_MAX or (np.abs(r_v).max(initial=0.0) <= tol_v
                                       and np.abs(r_r).max(initial=0.0) <= tol_r):
                    break
                x = np.concatenate([z, y]) + self.factor.solve(np.concatenate([r_v, r_r]))
            if not (np.all(np.isfinite(z)) and np.all(np.isfinite(y))):
                return Result(z, y, np.where(fx, g, 0.0), ws, it, False, np.inf)
            # the next working set: the signs of the multipliers (held) and of the violations (not held);
            # each change scored by its violation in units of its tolerance
            viol = Az[ne:] - b[ne:]
            row_score = np.where(ws.rows, -y[ne:] / tol_d, viol / tol_p_rows)
            at_lb, at_ub = ws.bounds == AT_LOWER, ws.bounds == AT_UPPER
            bound_score = np.where(at_lb, -g / tol_d, np.where(at_ub, g / tol_d, 0.0))
            free = ~(at_lb | at_ub)
            below, above = free & (z < lb - tol_lb), free & (z > ub + tol_ub)
            bound_score[below] = (lb[below] - z[below]) / tol_lb[below]
            bound_score[above] = (z[above] - ub[above]) / tol_ub[above]
            bound_score[fixed_always] = 0.0
            change_rows, change_bounds = row_score > 1.0, bound_score > 1.0
            if self.exclusive is not None:             # of two rows that cannot both be needed, enter one
                e = self.exclusive
                both = change_rows[e[:, 0]] & change_rows[e[:, 1]] & ~ws.rows[e[:, 0]] & ~ws.rows[e[:, 1]]
                lose = np.where(row_score[e[:, 0]] >= row_score[e[:, 1]], e[:, 1], e[:, 0])
                change_rows[lose[both]] = False
            n_change = int(change_rows.sum() + change_bounds.sum())
            if n_change == 0:
                obj = 0.5 * z @ (self.Pf @ z) + q @ z
                return Result(z, y, np.where(fx, g, 0.0), ws, it, True, float(obj))
            best = min(best, n_change)
            if limit is None and (it > FULL_STEPS or n_change > best):
                limit = max(1, n_change // 2)            # no progress: change fewer indices at a time
            if limit is not None and n_change > limit:
                keep_r, keep_b = _largest(row_score, bound_score, limit)
                change_rows &= keep_r
                change_bounds &= keep_b
                limit = max(1, limit // 2)
            nxt = ws.copy()
            nxt.rows[change_rows] = ~ws.rows[change_rows]
            nb = nxt.bounds
            nb[change_bounds & ~free] = FREE
            nb[change_bounds & below] = AT_LOWER
            nb[change_bounds & above] = AT_UPPER
            if any(nxt == w for w in seen):            # a cycle: from now on one change at a time
                if limit == 1:
                    return Result(z, y, np.where(fx, g, 0.0), nxt, it, False, np.inf)
                limit = 1
            seen.append(ws)
            ws = nxt
        return Result(z, y, np.where(ws.bounds != FREE, g, 0.0), ws, self.max_iter, False, np.inf)
