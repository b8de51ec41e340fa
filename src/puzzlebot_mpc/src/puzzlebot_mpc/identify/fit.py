"""Fitting effects and the trace-and-add loop.

Fit: weighted least squares on the open-loop prediction errors of the fitting
windows (position error / sigma_p, yaw error / sigma_y, with sigma the
current model's fitting RMSE of each, updated every round, so both count
alike and the weights follow the noise as the model improves), over every
continuous parameter of the model at once (scipy ``least_squares``, bounded,
finite differences). Parameters with several local minima get a grid scan
first (the delay, the heading offset); the deadband thresholds change the
error only where they cross a commanded value, so they are set by a
coarse-to-fine scan over the midpoints between commanded values, alternated
with the least squares.

Trace and add: each round fits the current model plus each candidate not yet
in it, ranks the candidates by the fraction of the current fitting cost they
explain, and adds the best one if it earns its place on the validation
windows (``accepts``: a clear margin, on most robots, and significant);
otherwise, or when no candidate is left, it stops.
"""

import math
import time
from dataclasses import dataclass, field
from typing import Dict, List

import numpy as np
from scipy import stats
from scipy.optimize import least_squares

from puzzlebot_common.effects import EFFECTS, NOMINAL
from puzzlebot_mpc.identify import engine

#: Continuous parameters: (lower bound, upper bound, start value, typical scale), units as in EFFECTS.
#: Bounds are physical plausibility limits for 5 cm robots, wide enough not to bind on real data.
PARAM_SPECS = {
    "delay_s": (0.0, 0.5, 0.05, 0.02),      # s
    "tau_v_s": (0.0, 1.0, 0.05, 0.02),      # s
    "tau_w_s": (0.0, 1.0, 0.05, 0.02),      # s
    "k_v": (0.2, 5.0, 1.0, 0.05),           # 1
    "k_w": (0.2, 5.0, 1.0, 0.05),           # 1
    "w_per_v": (-30.0, 30.0, 0.0, 0.5),     # rad/m
    "w0": (-2.0, 2.0, 0.0, 0.02),           # rad/s
    "offset_rad": (-math.pi, math.pi, 0.0, 0.02),  # rad
}
#: Grid scans that pick the start of the least squares for parameters with local minima.
SCANS = {
    "delay_s": np.arange(0.0, 0.5 + 1e-9, 0.025),
    "offset_rad": np.linspace(-math.pi, math.pi, 24, endpoint=False),
}
#: Deadband thresholds -> the command component they act on.
THRESHOLDS = {"v_min": "cmd_v", "w_min": "cmd_w"}
SCAN_POINTS = 24          # evaluations per level of the coarse-to-fine threshold scan
FLAT_COST = 1e-9          # relative cost difference below which two thresholds fit equally well
DIFF_STEP = 1e-4          # least-squares finite-difference step (relative, at least absolute 1e-4)
WEIGHT_FLOOR = 1e-9       # lower bound of sigma_p [m] and sigma_y [rad]


@dataclass
class Candidate:
    name: str
    params: Dict[str, float]
    cost: float
    explained: float          # fraction of the current fitting cost explained
    validation: object = None
    per_robot: List[object] = field(default_factory=list)


class Problem:
    """The fitting and validation windows of every robot, and the fitting cost."""

    def __init__(self, dataset, settings, progress=None):
        self.settings = settings
        self.robots = dataset.robots
        self.progress = progress or (lambda msg: None)
        self.windows = [engine.fit_and_validation_windows(r, settings) for r in self.robots]
        self.nfev = 0
        self.set_weights(dict(NOMINAL))
        self._thresholds = {k: self._threshold_candidates(attr) for k, attr in THRESHOLDS.items()}

    def set_weights(self, params):
        """Weigh position and yaw errors by the fitting RMSE of the model ``params``."""
        m = engine.metric(self.fit_errors(params))
        self.sigma_pos = max(m.rmse_pos_m / math.sqrt(2.0), WEIGHT_FLOOR)   # per coordinate
        self.sigma_yaw = max(m.rmse_yaw_rad, WEIGHT_FLOOR)

    # ---------------------------------------------------------------- errors
    def fit_errors(self, params):
        self.nfev += 1
        return [engine.errors(params, r, w[0]) for r, w in zip(self.robots, self.windows)]

    def validation_errors(self, params):
        return [engine.errors(params, r, w[1]) for r, w in zip(self.robots, self.windows)]

    def validation(self, params):
        """(pooled Metric, [per-robot Metric]) on the validation windows."""
        errs = self.validation_errors(params)
        return engine.metric(errs), [engine.metric([e]) for e in errs]

    def residuals(self, params):
        errs = self.fit_errors(params)
        ep = np.concatenate([e[0] for e in errs])
        ey = np.concatenate([e[1] for e in errs])
        return np.concatenate([ep.real / self.sigma_pos, ep.imag / self.sigma_pos, ey / self.sigma_yaw])

    def cost(self, params):
        r = self.residuals(params)
        return float(r @ r)

    # ------------------------------------------------------------ fitting
    def _threshold_candidates(self, attr):
        """0 and the midpoints between the distinct magnitudes commanded in the fitting part,
        up to their median (a threshold anywhere between two of them fits alike: take the middle)."""
        mags = np.concatenate([np.abs(getattr(r, attr)[r.cmd_t <= engine.split_time(r, self.settings.fit_fraction)])
                               for r in self.robots])
        mags = np.unique(mags[mags > 0])
        if mags.size == 0:
            return np.zeros(1)
        mags = mags[mags <= np.median(mags)]
        mids = 0.5 * (mags[:-1] + mags[1:])
        return np.concatenate([[0.0, 0.5 * mags[0]], mids])

    def _scan(self, params, key, values):
        best, best_cost = params[key], None
        for value in values:
            trial = dict(params, **{key: float(value)})
            c = self.cost(trial)
            if best_cost is None or c < best_cost:
                best, best_cost = float(value), c
        return best, best_cost

    def _scan_threshold(self, params, key):
        """Coarse-to-fine scan: SCAN_POINTS candidates spread over the range, then the
        range between the best one's neighbours, until every candidate in it was tried.
        Neighbouring candidates that fit equally well (no window sees a command between
        them) form one flat stretch: its middle is returned."""
        cands = self._thresholds[key]
        lo, hi = 0, cands.size - 1
        while True:
            idx = np.unique(np.round(np.linspace(lo, hi, min(SCAN_POINTS, hi - lo + 1))).astype(int))
            costs = np.array([self.cost(dict(params, **{key: float(cands[i])})) for i in idx])
            b = int(np.argmin(costs))
            if idx.size == hi - lo + 1:
                flat = costs <= costs[b] + FLAT_COST * max(abs(costs[b]), 1.0)
                a, e = b, b
                while a > 0 and flat[a - 1]:
                    a -= 1
                while e < idx.size - 1 and flat[e + 1]:
                    e += 1
                return float(0.5 * (cands[idx[a]] + cands[idx[e]]))
            lo, hi = int(idx[max(b - 1, 0)]), int(idx[min(b + 1, idx.size - 1)])

    def _least_squares(self, params, keys):
        lower = np.array([PARAM_SPECS[k][0] for k in keys])
        upper = np.array([PARAM_SPECS[k][1] for k in keys])
        x0 = np.clip(np.array([params[k] for k in keys]), lower, upper)
        scale = np.array([PARAM_SPECS[k][3] for k in keys])

        def fun(x):
            return self.residuals(dict(params, **dict(zip(keys, map(float, x)))))

        sol = least_squares(fun, x0, bounds=(lower, upper), x_scale=scale, diff_step=DIFF_STEP,
                            max_nfev=self.settings.max_nfev, method="trf")
        return dict(params, **dict(zip(keys, map(float, sol.x))))

    def fit(self, names, start, new=None):
        """Fit every parameter of the effects ``names`` from ``start`` (parameter dict);
        ``new``: the effect just added, whose parameters are initialised here."""
        p = dict(start)
        if new is not None:
            for key in EFFECTS[new]:
                p[key] = PARAM_SPECS[key][2] if key in PARAM_SPECS else 0.0
            for key in EFFECTS[new]:
                if key in SCANS:
                    p[key], _ = self._scan(p, key, SCANS[key])
        keys = [k for n in names for k in EFFECTS[n] if k in PARAM_SPECS]
        thresholds = [k for n in names for k in EFFECTS[n] if k in THRESHOLDS]
        for _ in range(2 if thresholds else 1):
            for key in thresholds:
                p[key] = self._scan_threshold(p, key)
            if keys:
                p = self._least_squares(p, keys)
        return p


def improvement_p_value(settings, cur_errs, new_errs, what):
    """One-sided p-value that ``new`` predicts better than ``cur`` (position or yaw).

    Windows overlap (a 1 s horizon every 0.1 s), so the per-window differences of
    squared errors are averaged over blocks of one horizon (independent enough);
    the block means get a one-sided Wilcoxon signed-rank test: do most blocks
    improve? (Robust to a few blocks with large errors either way, which a t test
    on the mean is not.) Returns (p, number of blocks)."""
    per_block = max(1, int(round(settings.horizon_s / settings.window_stride_s)))
    blocks = []
    for (cp, cy), (np_, ny) in zip(cur_errs, new_errs):
        d = np.abs(cp) ** 2 - np.abs(np_) ** 2 if what == "position" else cy ** 2 - ny ** 2
        n = d.size // per_block
        if n:
            blocks.append(d[:n * per_block].reshape(n, per_block).mean(axis=1))
    b = np.concatenate(blocks) if blocks else np.zeros(0)
    b = b[b != 0.0]
    if b.size < 1:
        return 1.0, 0
    return float(stats.wilcoxon(b, alternative="greater").pvalue), int(b.size)


def accepts(settings, current, trial, cur_errs, new_errs):
    """Does ``trial`` earn its place over ``current``? Both are (pooled, per-robot) validation
    metrics; ``*_errs`` the per-robot validation errors behind them.

    Rule: the pooled validation position or yaw RMSE drops by at least
    ``accept_margin``, neither rises by more than ``max_worsening``, the RMSE
    that dropped is lower on more than half of the robots, and the drop is
    significant (one-sided Wilcoxon p < ``accept_alpha`` over blocks of one horizon).
    Returns (accepted, reason).
    """
    (cur, cur_r), (new, new_r) = current, trial
    gains = {"position": 1.0 - new.rmse_pos_m / cur.rmse_pos_m, "yaw": 1.0 - new.rmse_yaw_rad / cur.rmse_yaw_rad}
    if min(gains.values()) < -settings.max_worsening:
        worse = min(gains, key=gains.get)
        return False, "%s RMSE rises by %.1f %% (limit %.0f %%)" % (worse, -100 * gains[worse],
                                                                     100 * settings.max_worsening)
    why_not = []
    for what in sorted(gains, key=gains.get, reverse=True):
        if gains[what] < settings.accept_margin:
            continue
        attr = "rmse_pos_m" if what == "position" else "rmse_yaw_rad"
        better = sum(getattr(n, attr) < getattr(c, attr) for c, n in zip(cur_r, new_r))
        if better * 2 <= len(cur_r):
            why_not.append("%s RMSE -%.1f %% but lower on only %d of %d robots" % (
                what, 100 * gains[what], better, len(cur_r)))
            continue
        p, blocks = improvement_p_value(settings, cur_errs, new_errs, what)
        if p >= settings.accept_alpha:
            why_not.append("%s RMSE -%.1f %% but not significant (p = %.2g over %d blocks of %.1f s)" % (
                what, 100 * gains[what], p, blocks, settings.horizon_s))
            continue
        return True, "%s RMSE -%.1f %% (margin %.0f %%), lower on %d of %d robots, p = %.1g" % (
            what, 100 * gains[what], 100 * settings.accept_margin, better, len(cur_r), p)
    if why_not:
        return False, "; ".join(why_not)
    best = max(gains, key=gains.get)
    return False, "best gain %.1f %% in %s RMSE, below the %.0f %% margin" % (
        100 * gains[best], best, 100 * settings.accept_margin)


@dataclass
class Round:
    candidates: List[Candidate]
    chosen: str
    accepted: bool
    reason: str


@dataclass
class Selection:
    names: List[str]
    params: Dict[str, float]
    steps: List[dict]               # accepted effects: name, params when added, validation after
    rounds: List[Round]
    nominal: object                 # (pooled, per-robot) validation metric of the nominal model
    final: object


def trace_and_add(problem, candidates=None):
    """Greedy forward selection of effects (module docstring)."""
    settings = problem.settings
    remaining = list(candidates or EFFECTS)
    names, params = [], dict(NOMINAL)
    current = nominal = problem.validation(params)
    current_errs = problem.validation_errors(params)
    steps, rounds = [], []
    while remaining:
        t0 = time.time()
        problem.set_weights(params)
        cost = problem.cost(params)
        cands = []
        for name in remaining:
            p = problem.fit(names + [name], params, new=name)
            c = problem.cost(p)
            cands.append(Candidate(name, p, c, 1.0 - c / cost if cost > 0 else 0.0))
        cands.sort(key=lambda c: c.explained, reverse=True)
        best = cands[0]
        best_errs = problem.validation_errors(best.params)
        best.validation = engine.metric(best_errs)
        best.per_robot = [engine.metric([e]) for e in best_errs]
        ok, reason = accepts(settings, current, (best.validation, best.per_robot), current_errs, best_errs)
        rounds.append(Round(cands, best.name, ok, reason))
        problem.progress("round %d (%.1f s): %s; best %s explains %.1f %% of the fitting cost: %s, %s"
                         % (len(rounds), time.time() - t0,
                            ", ".join("%s %.1f %%" % (c.name, 100 * c.explained) for c in cands),
                            best.name, 100 * best.explained, "added" if ok else "stop", reason))
        if not ok:
            break
        names.append(best.name)
        params, current, current_errs = best.params, (best.validation, best.per_robot), best_errs
        steps.append({"name": best.name, "params": {k: params[k] for k in EFFECTS[best.name]},
                      "after": best.validation, "per_robot": best.per_robot, "reason": reason})
        remaining.remove(best.name)
    return Selection(names, params, steps, rounds, nominal, current)
