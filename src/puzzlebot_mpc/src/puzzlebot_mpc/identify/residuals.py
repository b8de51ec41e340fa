"""Residual analysis: what is left between a model and the measurements.

Residual windows: short open-loop predictions (``residual_horizon_s``) that
start every ``residual_stride_s`` over each robot's whole usable record; the
stride exceeds the horizon, so no two windows share a pose sample and the
mocap noise in consecutive residuals is independent. Each residual (measured
minus predicted end pose) is split into along-track and cross-track parts in
the model's body frame at the window start, and the yaw part.

For a correct model these residuals are white noise: no autocorrelation
(portmanteau test on the autocorrelations, heteroskedasticity-robust like
the correlation tests, because the residual's size varies with the motion),
zero mean (t test) and no correlation with anything the
model should have used (the commands during the window: mean, change,
magnitude, product; the commands up to ``max_command_lag_s`` before it; the
measured speed and turn rate; the heading; time). The three families of tests share the level ``residual_alpha``
equally, Bonferroni-corrected within each family, so a correct model is
called structured with probability at most ``residual_alpha``.
Windows whose commands are not known in time (a CSV's command change inside
a gap of the pose rows) are left out of this analysis.
A structured residual is reported with its strongest significant
correlations: where to look for an effect the model lacks.
"""

import math
from dataclasses import dataclass
from typing import Dict, List

import numpy as np
from scipy import stats

from puzzlebot_common.geometry import wrap_angle
from puzzlebot_mpc.identify import engine

COMPONENTS = ("along", "cross", "yaw")
UNITS = {"along": "m", "cross": "m", "yaw": "rad"}
COMMAND_LAG_STEP_S = 0.1   # s: spacing of the lagged-command regressors (the command period)
WINDOW_SAMPLES = 11        # samples of the commands within a window (for their mean and change)
FAMILIES = 3              # test families sharing residual_alpha: autocorrelation, mean, correlations
TOP_CORRELATIONS = 5       # strongest correlations listed in the report
SATURATION_LEAD_S = 0.3    # s: command changes this long before a window still act on it (a ramp in progress)


@dataclass
class RobotResiduals:
    robot: str
    t: np.ndarray
    res: Dict[str, np.ndarray]       # component -> residuals
    reg: Dict[str, np.ndarray]       # regressor name -> values


@dataclass
class Analysis:
    robots: List[RobotResiduals]
    autocorr: Dict[str, dict]        # component -> {"q", "dof", "p"} of the robust portmanteau test
    mean_test: Dict[str, dict]       # component -> {"mean", "p"}
    correlations: List[dict]         # every (component, regressor): r, n, significant; strongest first
    r_critical: float
    white: bool
    notes: str
    time_dependence: dict = None     # diagnose(): gains fitted on early versus late parts
    saturation: dict = None          # diagnose(): residual against the commanded acceleration

    def pooled(self, component):
        return np.concatenate([r.res[component] for r in self.robots])


def residual_windows(r, settings):
    """Residual windows of a robot, without those whose commands (from ``max_command_lag_s``
    before the start to the end) overlap an interval of unknown command timing."""
    start = engine.usable_start(r, settings.history_s)
    w = engine.make_windows(r, start, float(r.t[-1]), settings.residual_horizon_s, settings.residual_stride_s,
                            settings)
    if len(r.cmd_unknown) and len(w):
        a, b = r.cmd_unknown[:, 0], r.cmd_unknown[:, 1]
        lo = w.ts - settings.max_command_lag_s
        overlap = (lo[:, None] < b[None, :]) & (w.te[:, None] > a[None, :])
        w = engine.subset(w, ~overlap.any(axis=1))
    return w


def regressors(r, w, settings):
    """Named regressors of each window, from the commands and the measured poses."""
    out = {}
    # commands during the window (what the prediction integrated): their mean and change
    frac = np.linspace(0.0, 1.0, WINDOW_SAMPLES)
    inside = [engine.command_at(r, w.ts + f * (w.te - w.ts)) for f in frac]
    v_in = np.array([c[0] for c in inside])
    om_in = np.array([c[1] for c in inside])
    out["v_cmd mean in window"] = v_in.mean(axis=0)
    out["w_cmd mean in window"] = om_in.mean(axis=0)
    out["v_cmd change in window"] = v_in[-1] - v_in[0]
    out["w_cmd change in window"] = om_in[-1] - om_in[0]
    out["|v_cmd| mean in window"] = np.abs(v_in).mean(axis=0)
    out["|w_cmd| mean in window"] = np.abs(om_in).mean(axis=0)
    out["v_cmd*w_cmd mean in window"] = (v_in * om_in).mean(axis=0)
    # commands before the window (the actuator state it started from)
    n_lags = int(round(settings.max_command_lag_s / COMMAND_LAG_STEP_S))
    for k in range(n_lags + 1):
        v, om = engine.command_at(r, w.ts - k * COMMAND_LAG_STEP_S)
        out["v_cmd(ts-%.1fs)" % (k * COMMAND_LAG_STEP_S)] = v
        out["w_cmd(ts-%.1fs)" % (k * COMMAND_LAG_STEP_S)] = om
    # the command changes acting on the window (from SATURATION_LEAD_S before it): their sum and the sum of
    # their signed squares (a saturation grows with the square of a change, a timing error linearly)
    for attr, label in (("cmd_v", "v_cmd"), ("cmd_w", "w_cmd")):
        d = np.diff(getattr(r, attr))
        t = r.cmd_t[1:]
        lin = np.concatenate([[0.0], np.cumsum(d)])
        sq = np.concatenate([[0.0], np.cumsum(d * np.abs(d))])
        a = np.searchsorted(t, w.ts - SATURATION_LEAD_S, side="right")
        b = np.searchsorted(t, w.te, side="right")
        out["%s changes near window" % label] = lin[b] - lin[a]
        out["%s changes^2 near window" % label] = sq[b] - sq[a]
    # the measured motion, the heading in the world, time
    dur = w.te - w.ts
    out["measured speed"] = ((w.p_end - w.p_start) * np.exp(-1j * w.yaw_start)).real / dur
    out["measured turn rate"] = wrap_angle(w.yaw_end - w.yaw_start) / dur
    out["cos(yaw)"] = np.cos(w.yaw_start)
    out["sin(yaw)"] = np.sin(w.yaw_start)
    out["time"] = w.ts
    return out


def robot_residuals(params, r, w, settings):
    ep, ey = engine.errors(params, r, w)
    body = ep * np.exp(-1j * (w.yaw_start - params["offset_rad"]))
    return RobotResiduals(r.name, w.ts, {"along": body.real, "cross": body.imag, "yaw": ey},
                          regressors(r, w, settings))


def portmanteau(x, lags):
    """Heteroskedasticity-robust Box-Pierce statistic of a series (after removing its mean):
    Q = sum over lags k of t_k^2, t_k = sum(x_t x_t-k) / sqrt(sum(x_t^2 x_t-k^2)).

    Q is chi-square with ``lags`` degrees of freedom for uncorrelated residuals even when
    their variance changes (the cross-track residual grows with speed, for instance),
    where the plain Ljung-Box test rejects too often. Returns (Q, lags used).
    """
    x = np.asarray(x, dtype=float) - np.mean(x)
    lags = min(lags, x.size - 2)
    if lags < 1:
        return 0.0, 0
    q = 0.0
    for k in range(1, lags + 1):
        prod = x[k:] * x[:-k]
        den = float(prod @ prod)
        if den > 0:
            q += float(prod.sum()) ** 2 / den
    return q, lags


def robust_t(x, y):
    """Heteroskedasticity-consistent t statistic of the correlation of x and y."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    y = np.asarray(y, dtype=float) - np.mean(y)
    den = float(np.sum((x * y) ** 2))
    return float(x @ y) / np.sqrt(den) if den > 0 else 0.0


def autocorrelation(x, lags):
    x = np.asarray(x, dtype=float) - np.mean(x)
    denom = float(x @ x)
    if denom <= 0:
        return np.zeros(lags)
    return np.array([float(x[:-k] @ x[k:]) / denom if k < x.size else 0.0 for k in range(1, lags + 1)])


def analyse(params, robots, settings, windows=None):
    """Residual analysis of the model on every robot's record; ``params``: one parameter dict per robot."""
    windows = windows or [residual_windows(r, settings) for r in robots]
    per_robot = [robot_residuals(p, r, w, settings) for p, r, w in zip(params, robots, windows) if len(w) > 3]
    alpha = settings.residual_alpha / FAMILIES   # each family of tests gets an equal share
    lb, mean_test = {}, {}
    for c in COMPONENTS:
        q, dof = 0.0, 0
        for rr in per_robot:
            qi, di = portmanteau(rr.res[c], settings.residual_lags)
            q, dof = q + qi, dof + di
        lb[c] = {"q": q, "dof": dof, "p": float(stats.chi2.sf(q, dof)) if dof else 1.0}
        pooled = np.concatenate([rr.res[c] for rr in per_robot])
        if pooled.size > 2 and np.std(pooled) > 0:
            tstat = np.mean(pooled) / (np.std(pooled, ddof=1) / np.sqrt(pooled.size))
            p_mean = float(2 * stats.t.sf(abs(tstat), pooled.size - 1))
        else:
            p_mean = 1.0
        mean_test[c] = {"mean": float(np.mean(pooled)) if pooled.size else 0.0, "p": p_mean}
    names = list(per_robot[0].reg) if per_robot else []
    n = sum(rr.t.size for rr in per_robot)
    n_tests = max(1, len(COMPONENTS) * len(names))
    t_crit = float(stats.norm.isf(alpha / (2 * n_tests)))
    r_crit = t_crit / np.sqrt(max(n - 3, 1))      # the same bound as |r| for constant-variance noise (plots)
    corr = []
    for c in COMPONENTS:
        y = np.concatenate([rr.res[c] for rr in per_robot])
        for name in names:
            x = np.concatenate([rr.reg[name] for rr in per_robot])
            r = 0.0 if np.std(x) == 0 or np.std(y) == 0 else float(np.corrcoef(x, y)[0, 1])
            t = robust_t(x, y) if r != 0.0 else 0.0
            corr.append({"residual": c, "regressor": name, "r": r, "t": t, "significant": abs(t) > t_crit})
    corr.sort(key=lambda d: abs(d["r"]), reverse=True)
    bad_lb = [c for c in COMPONENTS if lb[c]["p"] < alpha / len(COMPONENTS)]
    bad_mean = [c for c in COMPONENTS if mean_test[c]["p"] < alpha / len(COMPONENTS)]
    sig = [d for d in corr if d["significant"]]
    white = not (bad_lb or bad_mean or sig)
    notes = _notes(white, lb, bad_lb, mean_test, bad_mean, sig, per_robot, settings, t_crit)
    return Analysis(per_robot, lb, mean_test, corr, r_crit, white, notes)


def _fmt(c, value):
    return ("%.2f mm" % (1e3 * value)) if UNITS[c] == "m" else ("%.1f mrad" % (1e3 * value))


def _notes(white, lb, bad_lb, mean_test, bad_mean, sig, per_robot, settings, t_crit):
    n = sum(rr.t.size for rr in per_robot)
    head = ("%d residual windows of %.1f s every %.1f s; tests at %.2g overall (Bonferroni)"
            % (n, settings.residual_horizon_s, settings.residual_stride_s, settings.residual_alpha))
    if white:
        return ("white: no autocorrelation (p = %s), zero mean, and no correlation with the commands, command "
                "changes, measured speed and turn rate, heading or time (all |t| < %.1f). %s"
                % (", ".join("%s %.2f" % (c, lb[c]["p"]) for c in COMPONENTS), t_crit, head))
    parts = []
    if bad_lb:
        parts.append("autocorrelated: %s (p = %s)"
                     % (", ".join(bad_lb), ", ".join("%.2g" % lb[c]["p"] for c in bad_lb)))
    if bad_mean:
        parts.append("nonzero mean: %s" % ", ".join("%s %s" % (c, _fmt(c, mean_test[c]["mean"])) for c in bad_mean))
    if sig:
        parts.append("correlates with: %s" % "; ".join(
            "%s residual vs %s r=%+.2f" % (d["residual"], d["regressor"], d["r"]) for d in sig[:TOP_CORRELATIONS]))
    return ("structured (an effect the model lacks may remain): %s. %s" % ("; ".join(parts), head))


def summary(analysis):
    """JSON-ready summary of an analysis."""
    return {
        "time_dependence": analysis.time_dependence,
        "saturation": analysis.saturation,
        "white": bool(analysis.white),
        "notes": analysis.notes,
        "autocorrelation_test": {c: {k: float(v) if k != "dof" else int(v) for k, v in d.items()}
                                 for c, d in analysis.autocorr.items()},
        "mean": analysis.mean_test,
        "r_critical": analysis.r_critical,
        "strongest_correlations": [dict(d, r=round(d["r"], 4), t=round(d["t"], 2), significant=bool(d["significant"]))
                                   for d in analysis.correlations[:TOP_CORRELATIONS]],
        "rms": {c: float(np.sqrt(np.mean(analysis.pooled(c) ** 2))) for c in COMPONENTS},
    }


# ------------------------------------------------------------ diagnosis
GAIN_STEP = 1e-3     # relative step of the probe gains' finite differences


def _probe_gains(rf, params, settings):
    """The velocity gains (multipliers of k_v, k_w on top of the model) that best fit each of
    ``drift_segments`` consecutive parts of a robot's windows (one Gauss-Newton step from 1):
    [(mid time [s], m_v, m_w)]."""
    def vector(p):
        ep, ey = rf.errors(p)
        return np.stack([ep.real / rf.sigma_pos, ep.imag / rf.sigma_pos, ey / rf.sigma_yaw], axis=1)

    r0 = vector(params)
    jac = []
    for key in ("k_v", "k_w"):
        jac.append((vector(dict(params, **{key: params[key] * (1.0 + GAIN_STEP)})) - r0) / GAIN_STEP)
    jac = np.stack(jac, axis=2)                      # windows x 3 x 2
    w = rf.windows
    edges = np.linspace(w.ts.min(), w.ts.max() + 1e-9, settings.drift_segments + 1)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (w.ts >= a) & (w.ts < b)
        J = jac[sel].reshape(-1, 2)
        if sel.sum() < 10 or np.linalg.cond(J.T @ J) > 1e8:
            continue
        m = -np.linalg.solve(J.T @ J, J.T @ r0[sel].reshape(-1))
        out.append((0.5 * (a + b), 1.0 + m[0], 1.0 + m[1]))
    return out


def time_dependence(fits, params, settings):
    """Do the model's velocity gains change over the record? Gains fitted on consecutive parts of
    each robot's record, a common linear trend with an intercept per robot (least squares), its
    t test (two-sided, Bonferroni over v and w)."""
    rows = [(i, t, mv, mw) for i, (rf, p) in enumerate(zip(fits, params)) for t, mv, mw in _probe_gains(rf, p, settings)]
    robots = sorted({r[0] for r in rows})
    dof = len(rows) - len(robots) - 1
    if dof < 1:
        return {"tested": False}
    t = np.array([r[1] for r in rows])
    X = np.column_stack([np.array([r[0] == i for r in rows], float) for i in robots] + [t])
    out = {"tested": True, "segments": settings.drift_segments}
    for j, comp in ((2, "v"), (3, "w")):
        y = np.array([r[j] for r in rows])
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        res = y - X @ coef
        s2 = float(res @ res) / dof
        cov = s2 * np.linalg.pinv(X.T @ X)
        se = math.sqrt(max(cov[-1, -1], 0.0))
        slope = float(coef[-1])
        tstat = slope / se if se > 0 else (math.inf if slope else 0.0)
        first = [r[j] for r in rows if r[1] == min(x[1] for x in rows if x[0] == r[0])]
        last = [r[j] for r in rows if r[1] == max(x[1] for x in rows if x[0] == r[0])]
        out[comp] = {"rate_per_s": slope, "p": float(min(1.0, 2 * 2 * stats.t.sf(abs(tstat), dof))),
                     "early": float(np.mean(first)), "late": float(np.mean(last))}
    return out


def _partial_t(y, x, control):
    """Robust t of the correlation of y and x after removing their linear dependence on ``control``."""
    A = np.column_stack([np.ones_like(control), control])
    ry = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
    rx = x - A @ np.linalg.lstsq(A, x, rcond=None)[0]
    r = 0.0 if np.std(rx) == 0 or np.std(ry) == 0 else float(np.corrcoef(rx, ry)[0, 1])
    return r, robust_t(rx, ry) if r else 0.0


def saturation(analysis):
    """Does the residual grow faster than linearly with the commanded acceleration? The along-track (yaw)
    residual against the sum of the signed squares of the v (w) command changes acting on the window,
    with their linear sum removed (a timing error is linear in it), robust t, two-sided, Bonferroni
    over v and w."""
    out = {}
    if not analysis.robots:
        return out
    for comp, cmd in (("along", "v_cmd"), ("yaw", "w_cmd")):
        y = analysis.pooled(comp)
        lin = np.concatenate([rr.reg["%s changes near window" % cmd] for rr in analysis.robots])
        sq = np.concatenate([rr.reg["%s changes^2 near window" % cmd] for rr in analysis.robots])
        r, t = _partial_t(y, sq, lin)
        out[comp] = {"regressor": "%s changes^2 near window" % cmd, "r": r,
                     "p": float(min(1.0, 2 * 2 * stats.norm.sf(abs(t))))}
    return out


def diagnose(analysis, fits, params, settings):
    """Time dependence and saturation, named in the analysis' notes whatever they find."""
    alpha = settings.residual_alpha
    td = analysis.time_dependence = time_dependence(fits, params, settings)
    sat = analysis.saturation = saturation(analysis)
    parts = []
    if td.get("tested"):
        text = ", ".join("%s %+.1f %% per 100 s (%s early %.3f, late %.3f, p = %.2g)"
                         % (c, 1e4 * td[c]["rate_per_s"], c, td[c]["early"], td[c]["late"], td[c]["p"])
                         for c in ("v", "w"))
        drift = [c for c in ("v", "w") if td[c]["p"] < alpha]
        parts.append("time dependence: %s; gains fitted on %d parts of each record: %s" % (
            ("the velocity gain changes over the record (%s): a drifting gain (gain_drift) or another slow change"
             % " and ".join(drift)) if drift else "none", td["segments"], text))
    else:
        parts.append("time dependence: not tested (too few parts with motion)")
    if sat:
        text = ", ".join("%s residual vs %s (signed) r = %+.2f (p = %.2g)"
                         % (c, d["regressor"], d["r"], d["p"]) for c, d in sat.items())
        bad = [c for c, d in sat.items() if d["p"] < alpha]
        parts.append("saturation: %s; %s" % (
            ("the residual grows faster than linearly with the commanded acceleration (%s): the robot cannot "
             "follow large command changes (accel_limit) or another saturation" % ", ".join(bad)) if bad else "none",
            text))
    analysis.notes += " Diagnosis: " + "; ".join(parts) + "."
