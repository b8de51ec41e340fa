"""Fitting effects per robot, cross-validation, trace and add, and the sharing test.

Fit: for each robot, weighted least squares on the open-loop prediction errors
of its windows (position error / sigma_p, yaw error / sigma_y, sigma the
robot's current model's RMSE, updated every round), over every continuous
parameter of the model at once (scipy ``least_squares``, bounded, finite
differences). Parameters with several local minima get a grid scan first
(delay, heading offset, acceleration limits); deadband thresholds change the
error only where they cross a commanded value and are set by a
coarse-to-fine scan over the intervals between commanded values, halfway
between the largest value the windows show zeroed and the smallest they show
passing (``scan_threshold``).

Cross-validation: each robot's record is cut into ``cv_folds`` parts in time;
part k is predicted by the parameters fitted on the windows that do not
overlap it. Every window thus has a held-out error.

Trace and add: each round fits, per robot, each candidate not yet in the
model (its own parameters only, the others kept: screening), ranks the
candidates by the share of the current cost they explain, refits the best
one with every parameter, and adds it if it is physically large enough on at
least one robot (``Candidate.size``) and earns its place on the held-out
errors (``accepts``); otherwise the next best is tried, then the loop stops.

Sharing: an effect's parameters are shared by the robots unless each robot's
own parameters predict its held-out parts clearly better (the same rule) than
the robots' common value (fitted on the same folds: the median of their fits;
for a deadband threshold, the threshold that fits all robots' windows best
together, ``joint_threshold``).
"""

import math
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Callable, Dict, List

import numpy as np
from scipy import stats
from scipy.optimize import least_squares

from puzzlebot_common.effects import EFFECTS, NOMINAL
from puzzlebot_mpc.identify import engine

SCAN_POINTS = 24          # evaluations per level of the coarse-to-fine threshold scan
FLAT_COST = 1e-9          # relative cost difference below which two thresholds fit equally well
DIFF_STEP = 1e-4          # least-squares finite-difference step (relative, at least absolute 1e-4)
WEIGHT_FLOOR = 1e-9       # lower bound of sigma_p [m] and sigma_y [rad]
SCREEN_NFEV = 3           # least-squares evaluations of a screening fit (its own parameters: about one
                          # Gauss-Newton step from the scans' best start)
SCREEN_SCAN = 2           # screening scans every SCREEN_SCAN-th value of a start grid ...
SCREEN_THRESHOLDS = 12    # ... and this many thresholds, at one level
TRIES_PER_ROUND = 2       # candidates tried per round, best first
NO_LIMIT = 0.999          # an acceleration limit fitted above this fraction of its upper bound is none
ERRORS_CACHE = 512        # parameter sets whose window errors a RobotFit keeps (about 35 kB each at lab size):
                          # the folds of a cross-validation start their scans from the same parameters, the two
                          # passes of a fit rescan thresholds, the weights re-evaluate the current model


@dataclass(frozen=True)
class Spec:
    """A continuous parameter's search range, start value and typical scale (units of EFFECTS)."""

    lower: float
    upper: float
    start: float
    scale: float


@dataclass(frozen=True)
class Context:
    """What a robot's commands say about the sizes that matter (for scans and minimum sizes)."""

    period: float      # s: the command period (10th percentile of the intervals between commands: a CSV
                       # without t_cmd shows only the changes of the command)
    v_typ: float       # m/s: median magnitude of the nonzero v commands
    w_typ: float       # rad/s: ... of w
    dv: float          # m/s: 90th percentile of the changes of v between commands
    dw: float          # rad/s: ... of w
    duration: float    # s: the robot's record

    @classmethod
    def of(cls, r):
        def typical(x, q):
            x = np.abs(x[x != 0])
            return float(np.percentile(x, q)) if x.size else 0.0

        gaps = np.diff(r.cmd_t)
        gaps = gaps[gaps > 0]
        period = float(np.percentile(gaps, 10)) if gaps.size else 0.1
        return cls(period, typical(r.cmd_v, 50), typical(r.cmd_w, 50), typical(np.diff(r.cmd_v), 90),
                   typical(np.diff(r.cmd_w), 90), r.duration)


def _ratio(value, minimum):
    return value / minimum if minimum > 0 else (math.inf if value > 0 else 0.0)


def _timing(ctx, s):
    return s.min_timing_periods * ctx.period


def _ramp(change, a):
    return change / a if math.isfinite(a) and a > 0 else 0.0


@dataclass(frozen=True)
class Candidate:
    """How one effect is fitted and judged: its continuous parameters (``specs``), start grids for
    those with local minima (``scans``: Context -> values), threshold parameters scanned over the
    commanded magnitudes of a command component (``thresholds``: key -> "cmd_v"/"cmd_w"), and its
    physical size relative to the minimum a finding needs (``size``: (params, Context, settings) ->
    ratio, >= 1: large enough)."""

    name: str
    specs: Dict[str, Spec]
    size: Callable
    scans: Dict[str, Callable] = field(default_factory=dict)
    thresholds: Dict[str, str] = field(default_factory=dict)


def _threshold_size(p, ctx, s, kv, kw):
    return max(_ratio(p[kv], s.min_threshold_fraction * ctx.v_typ), _ratio(p[kw], s.min_threshold_fraction * ctx.w_typ))


#: Every effect of the vocabulary as a candidate (bounds: physical plausibility for 5 cm robots, wide
#: enough not to bind on real data).
CANDIDATES = {c.name: c for c in [
    Candidate("input_delay", {"delay_s": Spec(0.0, 0.5, 0.05, 0.02)},
              size=lambda p, ctx, s: _ratio(p["delay_s"], _timing(ctx, s)),
              scans={"delay_s": lambda ctx: np.arange(0.0, 0.5 + 1e-9, 0.025)}),
    Candidate("deadband", {}, size=lambda p, ctx, s: _threshold_size(p, ctx, s, "v_min", "w_min"),
              thresholds={"v_min": "cmd_v", "w_min": "cmd_w"}),
    Candidate("friction_offset", {"v_c": Spec(0.0, 0.05, 0.0, 0.002), "w_c": Spec(0.0, 1.0, 0.0, 0.02)},
              size=lambda p, ctx, s: _threshold_size(p, ctx, s, "v_c", "w_c")),
    Candidate("velocity_scale", {"k_v": Spec(0.2, 5.0, 1.0, 0.05), "k_w": Spec(0.2, 5.0, 1.0, 0.05)},
              size=lambda p, ctx, s: _ratio(max(abs(p["k_v"] - 1), abs(p["k_w"] - 1)), s.min_scale)),
    Candidate("velocity_lag", {"tau_v_s": Spec(0.0, 1.0, 0.05, 0.02), "tau_w_s": Spec(0.0, 1.0, 0.05, 0.02)},
              size=lambda p, ctx, s: _ratio(max(p["tau_v_s"], p["tau_w_s"]), _timing(ctx, s))),
    Candidate("accel_limit", {"a_v": Spec(0.02, 20.0, 20.0, 0.05), "a_w": Spec(0.2, 200.0, 200.0, 0.5)},
              size=lambda p, ctx, s: _ratio(max(_ramp(ctx.dv, p["a_v"]), _ramp(ctx.dw, p["a_w"])), _timing(ctx, s)),
              # both limits as one multiple of the typical commanded accelerations (ramps of 0.3-30 periods),
              # or none
              scans={("a_v", "a_w"): lambda ctx: np.vstack([
                  np.outer(1.0 / np.geomspace(0.3, 30.0, 12), [max(ctx.dv, 1e-3), max(ctx.dw, 1e-2)]) / ctx.period,
                  [[20.0, 200.0]]])}),
    Candidate("gain_drift", {"rate_per_s": Spec(-0.01, 0.01, 0.0, 1e-4)},
              size=lambda p, ctx, s: _ratio(abs(p["rate_per_s"]) * ctx.duration, s.min_drift)),
    Candidate("yaw_rate_bias", {"w_per_v": Spec(-30.0, 30.0, 0.0, 0.5), "w0": Spec(-2.0, 2.0, 0.0, 0.02)},
              size=lambda p, ctx, s: _ratio(max(abs(p["w_per_v"]) * ctx.v_typ, abs(p["w0"])), s.min_turn_rate)),
    Candidate("heading_offset", {"offset_rad": Spec(-math.pi, math.pi, 0.0, 0.02)},
              size=lambda p, ctx, s: _ratio(abs(p["offset_rad"]), s.min_offset_rad),
              scans={"offset_rad": lambda ctx: np.linspace(-math.pi, math.pi, 24, endpoint=False)}),
]}
assert set(CANDIDATES) == set(EFFECTS)
#: Continuous parameters of every candidate.
PARAM_SPECS = {k: spec for c in CANDIDATES.values() for k, spec in c.specs.items()}
#: Deadband threshold parameters -> the command component they act on ("cmd_v" / "cmd_w").
THRESHOLDS = {k: attr for c in CANDIDATES.values() for k, attr in c.thresholds.items()}


def _normalise(p):
    """An acceleration limit at its upper bound is no limit."""
    for key in ("a_v", "a_w"):
        if p[key] >= NO_LIMIT * PARAM_SPECS[key].upper:
            p[key] = math.inf
    return p


def size(name, params, ctx, settings):
    return CANDIDATES[name].size(params, ctx, settings)


def threshold_bounds(commands, up_to_median=False):
    """0 and the distinct nonzero magnitudes of ``commands``, ascending (only those up to their
    median with ``up_to_median``): a threshold anywhere between two consecutive ones zeroes the same
    commands, so the intervals between them are the thresholds worth telling apart."""
    mags = np.unique(np.abs(np.asarray(commands, dtype=float)))
    mags = mags[mags > 0]
    if up_to_median and mags.size:
        mags = mags[mags <= np.median(mags)]
    return np.concatenate([[0.0], mags])


def scan_threshold(cost, bounds, coarse=False, start=None):
    """The threshold that fits best, ``cost(value)`` evaluated at the middle of the intervals between
    consecutive ``bounds`` (ascending, ``threshold_bounds``).

    Coarse to fine: SCAN_POINTS intervals spread over the range (``start``: (first, last) interval;
    default: all), then the range between the best one's neighbours, until every interval in it was
    tried. The best interval is then grown into its flat stretch, beyond the range too (neighbours
    that fit equally well: no window sees a command between them), and the middle between the
    stretch's ends is returned: halfway between the largest magnitude the windows show zeroed and
    the smallest they show passing (a command that none of the cost's windows sees, one in a
    held-out part, does not move it). ``coarse``: the middle of the best of SCREEN_THRESHOLDS
    intervals spread over all."""
    mids = 0.5 * (bounds[:-1] + bounds[1:])
    n = mids.size
    if n == 0:
        return 0.0
    costs = {}

    def at(i):
        if i not in costs:
            costs[i] = cost(float(mids[i]))
        return costs[i]

    if coarse:
        idx = np.unique(np.round(np.linspace(0, n - 1, min(SCREEN_THRESHOLDS, n))).astype(int))
        return float(mids[min(idx, key=at)])
    lo, hi = start if start is not None else (0, n - 1)
    while True:
        idx = np.unique(np.round(np.linspace(lo, hi, min(SCAN_POINTS, hi - lo + 1))).astype(int))
        j = min(range(idx.size), key=lambda m: at(idx[m]))
        if idx.size == hi - lo + 1:
            break
        lo, hi = int(idx[max(j - 1, 0)]), int(idx[min(j + 1, idx.size - 1)])
    a = e = int(idx[j])
    flat = at(a) + FLAT_COST * max(abs(at(a)), 1.0)
    while a > 0 and at(a - 1) <= flat:
        a -= 1
    while e < n - 1 and at(e + 1) <= flat:
        e += 1
    return float(0.5 * (bounds[a] + bounds[e + 1]))


class RobotFit:
    """One robot's windows (every window of its record, labelled with its part), its weights and
    the cost of a parameter set on a subset of the windows."""

    def __init__(self, r, settings):
        self.r = r
        self.settings = settings
        self.windows = engine.robot_windows(r, settings)
        self.ctx = Context.of(r)
        self.all = np.ones(len(self.windows), bool)
        self.nfev = 0                      # model evaluations (cache misses of ``errors``)
        self._errors = OrderedDict()       # parameter values -> errors, least recently used first
        self._thresholds = {k: threshold_bounds(getattr(r, attr), up_to_median=True)
                            for k, attr in THRESHOLDS.items()}
        self.set_weights(dict(NOMINAL))

    @property
    def name(self):
        return self.r.name

    def errors(self, params):
        """(position errors, yaw errors) of every window (read-only arrays: the last ERRORS_CACHE
        parameter sets are remembered, a repeated one costs a look-up)."""
        key = tuple(params[k] for k in NOMINAL)
        cached = self._errors.get(key)
        if cached is not None:
            self._errors.move_to_end(key)
            return cached
        self.nfev += 1
        cached = engine.errors(params, self.r, self.windows)
        for a in cached:
            a.flags.writeable = False
        self._errors[key] = cached
        if len(self._errors) > ERRORS_CACHE:
            self._errors.popitem(last=False)
        return cached

    def set_weights(self, params):
        """Weigh position and yaw errors by the RMSE of the model ``params``."""
        m = engine.metric([self.errors(params)])
        self.sigma_pos = max(m.rmse_pos_m / math.sqrt(2.0), WEIGHT_FLOOR)   # per coordinate
        self.sigma_yaw = max(m.rmse_yaw_rad, WEIGHT_FLOOR)

    def residuals(self, params, mask):
        ep, ey = self.errors(params)
        ep, ey = ep[mask], ey[mask]
        return np.concatenate([ep.real / self.sigma_pos, ep.imag / self.sigma_pos, ey / self.sigma_yaw])

    def cost(self, params, mask=None):
        r = self.residuals(params, self.all if mask is None else mask)
        return float(r @ r)

    # ------------------------------------------------------------ fitting
    def _scan(self, params, keys, values, mask):
        """The best of ``values`` for the parameter ``keys`` (a name, or a tuple of names with rows of
        values); returns the updated parameters."""
        keys = keys if isinstance(keys, tuple) else (keys,)
        best, best_cost = params, None
        for value in values:
            trial = dict(params, **dict(zip(keys, map(float, np.atleast_1d(value)))))
            c = self.cost(trial, mask)
            if best_cost is None or c < best_cost:
                best, best_cost = trial, c
        return best

    def _scan_threshold(self, params, key, mask, coarse=False):
        return scan_threshold(lambda value: self.cost(dict(params, **{key: value}), mask), self._thresholds[key],
                              coarse)

    def _least_squares(self, params, keys, mask, max_nfev):
        lower = np.array([PARAM_SPECS[k].lower for k in keys])
        upper = np.array([PARAM_SPECS[k].upper for k in keys])
        x0 = np.clip(np.array([params[k] for k in keys]), lower, upper)
        scale = np.array([PARAM_SPECS[k].scale for k in keys])

        def fun(x):
            return self.residuals(dict(params, **dict(zip(keys, map(float, x)))), mask)

        sol = least_squares(fun, x0, bounds=(lower, upper), x_scale=scale, diff_step=DIFF_STEP,
                            max_nfev=max_nfev, method="trf")
        return dict(params, **dict(zip(keys, map(float, sol.x))))

    def fit(self, names, start, mask=None, max_nfev=None, new=None):
        """Fit every parameter of the effects ``names`` from ``start`` on the windows of ``mask``;
        ``new``: an effect just added, whose parameters are initialised here (scans)."""
        mask = self.all if mask is None else mask
        max_nfev = max_nfev or self.settings.max_nfev
        p = dict(start)
        if new is not None:
            p = self._initial(p, new, mask, step=1)
        keys = [k for n in names for k in CANDIDATES[n].specs]
        thresholds = [k for n in names for k in CANDIDATES[n].thresholds]
        for _ in range(2 if thresholds else 1):
            for key in thresholds:
                p[key] = self._scan_threshold(p, key, mask)
            if keys:
                p = self._least_squares(p, keys, mask, max_nfev)
        return _normalise(p)

    def _initial(self, p, new, mask, step):
        cand = CANDIDATES[new]
        for key, spec in cand.specs.items():
            p[key] = spec.start
        for key in cand.thresholds:
            p[key] = 0.0
        for keys, grid in cand.scans.items():
            p = self._scan(p, keys, grid(self.ctx)[::step], mask)
        return p

    def screen(self, names, new, start):
        """A quick fit of the model ``names`` + ``new``: coarse scans and thresholds for the new effect,
        then about one Gauss-Newton step of every continuous parameter. For ranking the candidates."""
        p = self._initial(dict(start), new, self.all, step=SCREEN_SCAN)
        for key in CANDIDATES[new].thresholds:
            p[key] = self._scan_threshold(p, key, self.all, coarse=True)
        keys = [k for n in names + [new] for k in CANDIDATES[n].specs]
        if keys:
            p = self._least_squares(p, keys, self.all, SCREEN_NFEV)
        return _normalise(p)


# ---------------------------------------------------------- cross-validation
@dataclass
class CrossValidation:
    """Held-out errors of a model: ``errors[i]`` = (position, yaw) errors of every window of robot i,
    each predicted with ``fold_params[i][k]``, the parameters fitted without its part k."""

    errors: List[tuple]
    fold_params: List[List[dict]]


def cross_validate(fits, names, params, settings):
    errors, folds = [], []
    for rf, p in zip(fits, params):
        ep = np.zeros(len(rf.windows), complex)
        ey = np.zeros(len(rf.windows))
        per_fold = []
        for k in range(settings.cv_folds):
            pk = rf.fit(names, p, rf.windows.fit_mask(k), settings.cv_nfev) if names else dict(p)
            e = rf.errors(pk)
            held = rf.windows.part == k
            ep[held], ey[held] = e[0][held], e[1][held]
            per_fold.append(pk)
        errors.append((ep, ey))
        folds.append(per_fold)
    return CrossValidation(errors, folds)


def with_params(fits, cv, replace):
    """Held-out errors of the fold parameters of ``cv`` with some parameters replaced:
    ``replace(i, k, params)`` -> the parameters robot i uses on its part k."""
    out = []
    for i, rf in enumerate(fits):
        ep = np.zeros(len(rf.windows), complex)
        ey = np.zeros(len(rf.windows))
        for k, pk in enumerate(cv.fold_params[i]):
            e = rf.errors(replace(i, k, pk))
            held = rf.windows.part == k
            ep[held], ey[held] = e[0][held], e[1][held]
        out.append((ep, ey))
    return out


# ------------------------------------------------------------- acceptance
def improvement_p_value(settings, fits, robots, cur_errs, new_errs, what):
    """One-sided p-value that ``new`` predicts better than ``cur`` (position or yaw) on ``robots``.

    Windows overlap (a 1 s horizon every 0.1 s), so the per-window differences of squared errors
    are averaged over blocks of one horizon within each robot's part (independent enough); the
    block means get a one-sided Wilcoxon signed-rank test: do most blocks improve? (Robust to a few
    blocks with large errors either way, which a t test on the mean is not.) Returns (p, blocks)."""
    per_block = max(1, int(round(settings.horizon_s / settings.window_stride_s)))
    blocks = []
    for i in robots:
        (cp, cy), (np_, ny) = cur_errs[i], new_errs[i]
        d = np.abs(cp) ** 2 - np.abs(np_) ** 2 if what == "position" else cy ** 2 - ny ** 2
        part = fits[i].windows.part
        for k in range(settings.cv_folds):
            dk = d[part == k]
            n = dk.size // per_block
            if n:
                blocks.append(dk[:n * per_block].reshape(n, per_block).mean(axis=1))
    b = np.concatenate(blocks) if blocks else np.zeros(0)
    b = b[b != 0.0]
    if b.size < 1:
        return 1.0, 0
    return float(stats.wilcoxon(b, alternative="greater").pvalue), int(b.size)


def _group_metric(fits, errs, robots, mask_of=None):
    sel = []
    for i in robots:
        ep, ey = errs[i]
        m = np.ones(ep.size, bool) if mask_of is None else mask_of(i)
        sel.append((ep[m], ey[m]))
    return engine.metric(sel)


def accepts(settings, fits, cur_errs, new_errs):
    """Does the model behind ``new_errs`` earn its place over the one behind ``cur_errs`` (held-out
    errors per robot)?

    Rule: pooled over all robots neither the position nor the yaw RMSE rises by more than
    ``max_worsening``; and for all robots together, or for one robot alone, the position or yaw
    RMSE drops by at least ``accept_margin``, is lower in most parts (folds), and the drop is
    significant (one-sided Wilcoxon p < ``accept_alpha`` / number of groups tested, over blocks of
    one horizon). Returns (accepted, reason)."""
    everyone = list(range(len(fits)))
    groups = [("all robots", everyone)]
    if len(fits) > 1:
        groups += [("robot %s" % rf.name, [i]) for i, rf in enumerate(fits)]
    alpha = settings.accept_alpha / len(groups)
    attrs = {"position": "rmse_pos_m", "yaw": "rmse_yaw_rad"}

    def gains(robots, mask_of=None):
        c, n = _group_metric(fits, cur_errs, robots, mask_of), _group_metric(fits, new_errs, robots, mask_of)
        return {w: 1.0 - getattr(n, a) / getattr(c, a) if getattr(c, a) > 0 else 0.0 for w, a in attrs.items()}

    pooled = gains(everyone)
    worst = min(pooled, key=pooled.get)
    if pooled[worst] < -settings.max_worsening:
        return False, "%s RMSE rises by %.1f %% (limit %.0f %%)" % (worst, -100 * pooled[worst],
                                                                     100 * settings.max_worsening)
    why_not, best = [], (-math.inf, "", "")
    for label, robots in groups:
        g = gains(robots)
        for what in sorted(g, key=g.get, reverse=True):
            if g[what] > best[0]:
                best = (g[what], what, label)
            if g[what] < settings.accept_margin:
                continue
            folds = [gains(robots, lambda i, k=k: fits[i].windows.part == k)[what] for k in range(settings.cv_folds)]
            better = sum(f > 0 for f in folds)
            if better * 2 <= len(folds):
                why_not.append("%s: %s RMSE -%.1f %% but lower in only %d of %d parts"
                               % (label, what, 100 * g[what], better, len(folds)))
                continue
            p, blocks = improvement_p_value(settings, fits, robots, cur_errs, new_errs, what)
            if p >= alpha:
                why_not.append("%s: %s RMSE -%.1f %% but not significant (p = %.2g >= %.2g over %d blocks of "
                               "%.1f s)" % (label, what, 100 * g[what], p, alpha, blocks, settings.horizon_s))
                continue
            return True, "%s: held-out %s RMSE -%.1f %% (margin %.0f %%), lower in %d of %d parts, p = %.1g" % (
                label, what, 100 * g[what], 100 * settings.accept_margin, better, len(folds), p)
    if why_not:
        return False, "; ".join(why_not)
    return False, "best held-out gain %.1f %% (%s RMSE, %s), below the %.0f %% margin" % (
        100 * best[0], best[1], best[2], 100 * settings.accept_margin)


def in_sample_gain(fits, cur_errs, new_errs):
    """The largest fractional drop of the position or yaw RMSE, for all robots or one robot."""
    groups = [list(range(len(fits)))] + ([[i] for i in range(len(fits))] if len(fits) > 1 else [])
    best = -math.inf
    for robots in groups:
        c, n = _group_metric(fits, cur_errs, robots), _group_metric(fits, new_errs, robots)
        for attr in ("rmse_pos_m", "rmse_yaw_rad"):
            if getattr(c, attr) > 0:
                best = max(best, 1.0 - getattr(n, attr) / getattr(c, attr))
    return best


# ---------------------------------------------------------- trace and add
@dataclass
class Screened:
    name: str
    params: List[dict]        # per robot
    cost: float
    explained: float          # fraction of the current cost explained (all robots)


@dataclass
class Round:
    candidates: List[Screened]
    tried: List[dict]         # name, accepted, reason, sizes (per robot), validation (Metric)
    accepted: bool


@dataclass
class Selection:
    names: List[str]
    params: List[dict]              # per robot (the final model: shared values, own values, pruned)
    steps: List[dict]               # accepted effects: name, params per robot, held-out metric after
    rounds: List[Round]
    nominal_errors: List[tuple]     # per robot, every window
    final_errors: List[tuple]       # held-out errors of the final model
    shared: List[str] = field(default_factory=list)   # effects whose parameters all robots share
    sharing: List[dict] = field(default_factory=list)  # the sharing test of each effect
    pruned: Dict[str, List[str]] = field(default_factory=dict)  # robot -> per-robot effects too small there
    removed: List[dict] = field(default_factory=list)   # effects removed by the backward check, and why

    @property
    def nominal(self):
        return engine.metric(self.nominal_errors), [engine.metric([e]) for e in self.nominal_errors]

    @property
    def final(self):
        return engine.metric(self.final_errors), [engine.metric([e]) for e in self.final_errors]


def _sizes(fits, name, params, settings):
    return [size(name, p, rf.ctx, settings) for rf, p in zip(fits, params)]


def trace_and_add(fits, settings, progress=None, candidates=None):
    """Greedy forward selection of effects with per-robot parameters (module docstring)."""
    say = progress or (lambda msg: None)
    remaining = list(candidates or EFFECTS)
    names, params = [], [dict(NOMINAL) for _ in fits]
    nominal = [rf.errors(p) for rf, p in zip(fits, params)]
    cv = CrossValidation(nominal, [[dict(NOMINAL)] * settings.cv_folds for _ in fits])
    steps, rounds = [], []
    while remaining:
        t0 = time.time()
        for rf, p in zip(fits, params):
            rf.set_weights(p)
        base = sum(rf.cost(p) for rf, p in zip(fits, params))
        screened = []
        for name in remaining:
            ps = [rf.screen(names, name, p) for rf, p in zip(fits, params)]
            c = sum(rf.cost(p) for rf, p in zip(fits, ps))
            screened.append(Screened(name, ps, c, 1.0 - c / base if base > 0 else 0.0))
        screened.sort(key=lambda c: c.explained, reverse=True)
        tried, chosen = [], None
        for cand in screened[:TRIES_PER_ROUND]:
            if cand.explained <= 0.0:
                break
            full = [rf.fit(names + [cand.name], p) for rf, p in zip(fits, cand.params)]
            sizes = _sizes(fits, cand.name, full, settings)
            entry = {"name": cand.name, "sizes": sizes, "params": full}
            if max(sizes) < 1.0:
                entry.update(accepted=False, reason="too small to be a finding on every robot (size %s of the "
                             "physical minimum)" % ", ".join("%.2g" % x for x in sizes))
                tried.append(entry)
                continue
            fitted = [rf.errors(p) for rf, p in zip(fits, full)]
            current = [rf.errors(p) for rf, p in zip(fits, params)]
            gain = in_sample_gain(fits, current, fitted)
            if gain < settings.accept_margin:
                entry.update(accepted=False, reason="in-sample gain %.1f %% (best of position and yaw RMSE, all robots "
                             "or one), below the %.0f %% margin: held-out data cannot reach it"
                             % (100 * gain, 100 * settings.accept_margin))
                tried.append(entry)
                continue
            new_cv = cross_validate(fits, names + [cand.name], full, settings)
            ok, reason = accepts(settings, fits, cv.errors, new_cv.errors)
            entry.update(accepted=ok, reason=reason, validation=engine.metric(new_cv.errors),
                         per_robot=[engine.metric([e]) for e in new_cv.errors])
            tried.append(entry)
            if ok:
                chosen = (cand, full, new_cv)
                break
        rounds.append(Round(screened, tried, chosen is not None))
        say("round %d (%.1f s): %s; %s" % (
            len(rounds), time.time() - t0, ", ".join("%s %.1f %%" % (c.name, 100 * c.explained) for c in screened),
            "; ".join("%s %s: %s" % (t["name"], "added" if t["accepted"] else "rejected", t["reason"])
                      for t in tried) or "nothing explains more: stop"))
        if chosen is None:
            break
        cand, params, cv = chosen
        names.append(cand.name)
        remaining.remove(cand.name)
        steps.append({"name": cand.name, "params": [{k: p[k] for k in EFFECTS[cand.name]} for p in params],
                      "after": engine.metric(cv.errors), "per_robot": [engine.metric([e]) for e in cv.errors],
                      "reason": tried[-1]["reason"]})
    names, params, cv, removed = eliminate(fits, names, params, cv, settings, say)
    steps = [st for st in steps if st["name"] in names]
    sel = Selection(names, params, steps, rounds, nominal, cv.errors, removed=removed)
    finish(fits, sel, cv, settings, say)
    return sel


def eliminate(fits, names, params, cv, settings, say=lambda msg: None):
    """Backward check of the forward selection: an effect added before others may have been
    superseded by them (an acceleration limit standing in for a lag found later). Each earlier
    effect must still earn its place over the model without it (refitted, held out, the same rule);
    the first that does not is removed, and the check starts again."""
    removed = []
    again = True
    while again and len(names) > 1:
        again = False
        for name in names[:-1]:     # the last one was just tested against the model without it
            rest = [n for n in names if n != name]
            start = [dict(p, **{k: NOMINAL[k] for k in EFFECTS[name]}) for p in params]
            refit = [rf.fit(rest, q, max_nfev=2 * settings.cv_nfev) for rf, q in zip(fits, start)]
            rest_cv = cross_validate(fits, rest, refit, settings)
            ok, reason = accepts(settings, fits, rest_cv.errors, cv.errors)
            if not ok:
                say("%s removed: the effects found after it explain what it did (%s)" % (name, reason))
                removed.append({"name": name, "reason": reason})
                names, params, cv, again = rest, refit, rest_cv, True
                break
    return names, params, cv, removed


# ---------------------------------------------------------------- sharing
def _common(values):
    """The robots' common value of a continuous parameter: their median (an absent limit counts as
    infinite)."""
    return float(np.median(np.asarray(values, dtype=float)))


def joint_threshold(fits, params, key, masks=None):
    """The deadband threshold ``key`` the robots share: the value that minimises their summed cost
    (robot i with ``params[i]`` on its windows ``masks[i]``, None: all), scanned (``scan_threshold``)
    over the intervals between the distinct magnitudes any robot was commanded, starting from one
    interval below the lowest to one above the highest of the robots' own values ``params[i][key]``.

    A robot alone resolves a threshold only to the gap between its own commanded magnitudes around
    it, and the gaps differ from robot to robot: the median of the robots' own values can zero a
    command on which another robot moves. The robots' commands together bracket the threshold as
    tightly as the closest pair around it, whichever robots they come from."""
    masks = masks if masks is not None else [rf.all for rf in fits]
    bounds = threshold_bounds(np.concatenate([getattr(rf.r, THRESHOLDS[key]) for rf in fits]))
    last = max(bounds.size - 2, 0)

    def interval(value):
        return min(max(int(np.searchsorted(bounds, value, side="right")) - 1, 0), last)

    own = [p[key] for p in params]
    start = (max(interval(min(own)) - 1, 0), min(interval(max(own)) + 1, last))

    def cost(value):
        return sum(rf.cost(dict(p, **{key: value}), m) for rf, p, m in zip(fits, params, masks))

    return scan_threshold(cost, bounds, start=start)


def common_values(fits, params, keys, masks=None):
    """The robots' common values of the parameters ``keys``, from their own fits ``params`` (one dict
    per robot) on the windows ``masks`` (one mask per robot; None: all windows): the median of their
    fits for a continuous parameter (``_common``); then each deadband threshold fitted to all robots
    together (``joint_threshold``), the continuous ones at their common values."""
    out = {key: _common([p[key] for p in params]) for key in keys if key not in THRESHOLDS}
    start = [dict(p, **out) for p in params]
    for key in keys:
        if key in THRESHOLDS:
            out[key] = joint_threshold(fits, start, key, masks)
            start = [dict(p, **{key: out[key]}) for p in start]
    return out


def finish(fits, sel, cv, settings, say=lambda msg: None):
    """The sharing test of every selected effect, then the final parameters: shared effects at the
    robots' common value (the others refitted around it), per-robot effects pruned to nominal on the
    robots where they are below the physical minimum; and the held-out errors of that model."""
    if not sel.names:
        return
    if len(fits) == 1:
        sel.shared = list(sel.names)
        return

    def fold_common(keys, k):
        return common_values(fits, [cv.fold_params[i][k] for i in range(len(fits))], keys,
                             [rf.windows.fit_mask(k) for rf in fits])

    for name in sel.names:
        keys = EFFECTS[name]
        common = {k: fold_common(keys, k) for k in range(settings.cv_folds)}
        shared_errs = with_params(fits, cv, lambda i, k, p: dict(p, **common[k]))
        own_better, reason = accepts(settings, fits, shared_errs, cv.errors)
        values = {rf.name: {key: sel.params[i][key] for key in keys} for i, rf in enumerate(fits)}
        sel.sharing.append({"name": name, "shared": not own_better, "reason": reason, "per_robot": values,
                            "shared_error": engine.metric(shared_errs), "own_error": engine.metric(cv.errors)})
        if not own_better:
            sel.shared.append(name)
        say("sharing %s: %s (%s)" % (name, "per robot" if own_better else "shared", reason))
    shared_keys = [key for n in sel.shared for key in EFFECTS[n]]
    common_all = common_values(fits, sel.params, shared_keys)
    own = [n for n in sel.names if n not in sel.shared]
    params = []
    for rf, p in zip(fits, sel.params):
        q = dict(p, **common_all)
        if own and sel.shared:
            rf.set_weights(q)
            q = dict(rf.fit(own, q), **common_all)
        params.append(q)
    pruned = {}
    for i, rf in enumerate(fits):
        for n in own:
            if size(n, params[i], rf.ctx, settings) < 1.0:
                params[i].update({k: NOMINAL[k] for k in EFFECTS[n]})
                pruned.setdefault(rf.name, []).append(n)
    sel.params, sel.pruned = params, pruned
    common = {k: fold_common(shared_keys, k) for k in range(settings.cv_folds)}

    def final(i, k, p):
        q = dict(p, **common[k])
        for n in pruned.get(fits[i].name, []):
            q.update({key: NOMINAL[key] for key in EFFECTS[n]})
        return q

    sel.final_errors = with_params(fits, cv, final)
