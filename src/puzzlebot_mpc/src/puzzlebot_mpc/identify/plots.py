"""Residual plots (matplotlib, Agg): what a researcher looks at to see which effect is missing.

(a), (b) validation prediction errors over time, nominal vs identified model;
(c) correlation of the residuals with the commands before the window start
(lagged commands) and during it (mean, change); (d) autocorrelation of the
residuals with the white-noise bound; (e) the strongest correlations of the
nominal residuals with the named regressors, what remains of them, and the
strongest correlations left with the identified model (red: significant);
(f) the nominal along-track residual against the command change in the
window, the signature of timing effects (delay, lag).
"""

import numpy as np

from puzzlebot_mpc.identify import residuals

NOMINAL_STYLE = dict(color="0.6", lw=1.0)
FIGSIZE = (13.0, 12.0)   # inches
DPI = 90
BARS_NOMINAL = 7         # correlations shown in panel (e): strongest of the nominal residual ...
BARS_FINAL = 4           # ... and of the identified model's residual


def _validation_errors(result, errors):
    return [(rf.name, rf.windows.ts, np.abs(ep), ey) for rf, (ep, ey) in zip(result.problem.fits, errors)]


def _lagged_corr(analysis, component, command, lags):
    y = analysis.pooled(component)
    out = []
    for lag in lags:
        x = np.concatenate([rr.reg["%s(ts-%.1fs)" % (command, lag)] for rr in analysis.robots])
        out.append(0.0 if np.std(x) == 0 or np.std(y) == 0 else np.corrcoef(x, y)[0, 1])
    return np.array(out)


def plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nom_an, fin_an = result.nominal_analysis, result.final_analysis
    fig, ax = plt.subplots(3, 2, figsize=FIGSIZE)
    title = "identified: %s" % (", ".join(result.effect_names) or "no effect (nominal model kept)")
    fig.suptitle("%s\n%s" % (result.path, title), fontsize=11)

    # (a), (b) validation errors over time, log scale: the nominal model's (dashed, drawn first and wider)
    # stay visible beside the identified model's, which are an order of magnitude smaller
    nom = _validation_errors(result, result.selection.nominal_errors)
    fin = _validation_errors(result, result.selection.final_errors)
    for k, ((name, t, ep_n, ey_n), (_, _, ep_f, ey_f)) in enumerate(zip(nom, fin)):
        color = "C%d" % k
        for axis, nominal, final in ((ax[0, 0], ep_n, ep_f), (ax[0, 1], ey_n, ey_f)):
            axis.semilogy(t, np.maximum(1e3 * np.abs(nominal), 1e-2), ls="--", lw=1.4, color=color, alpha=0.5,
                          zorder=1, label="%s nominal" % name)
            axis.semilogy(t, np.maximum(1e3 * np.abs(final), 1e-2), lw=0.9, color=color, zorder=2,
                          label="%s identified" % name)
    h = result.settings.horizon_s
    ax[0, 0].set(title="(a) held-out position error, %.1f s open loop\n(solid: identified, dashed: nominal)" % h,
                 xlabel="window start [s]", ylabel="[mm] (log)")
    ax[0, 1].set(title="(b) held-out |yaw error|, %.1f s open loop\n(solid: identified, dashed: nominal)" % h,
                 xlabel="window start [s]", ylabel="[mrad] (log)")
    ax[0, 0].legend(fontsize=7, ncol=2)

    # (c) residual vs commands: lagged before the window, and during it
    lags = np.arange(0, result.settings.max_command_lag_s + 1e-9, residuals.COMMAND_LAG_STEP_S)
    for comp, cmd, color in (("along", "v_cmd", "C0"), ("yaw", "w_cmd", "C3"), ("cross", "v_cmd", "C2")):
        ax[1, 0].plot(lags, _lagged_corr(nom_an, comp, cmd, lags), ls="--", marker="o", ms=3, color=color,
                      alpha=0.6)
        ax[1, 0].plot(lags, _lagged_corr(fin_an, comp, cmd, lags), marker="o", ms=3, color=color,
                      label="%s residual vs %s(ts - lag)" % (comp, cmd))
    for a in (fin_an.r_critical, -fin_an.r_critical):
        ax[1, 0].axhline(a, color="k", lw=0.6, ls=":")
    ax[1, 0].set(title="(c) residual vs command before the window\n(dashed: nominal, dotted: significance)",
                 xlabel="lag before window start [s]", ylabel="correlation r", ylim=(-1, 1))
    ax[1, 0].legend(fontsize=7)

    # (d) autocorrelation
    lags_w = np.arange(1, result.settings.residual_lags + 1)
    for comp, color in zip(residuals.COMPONENTS, ("C0", "C2", "C3")):
        for an, style in ((nom_an, dict(ls="--", alpha=0.6)), (fin_an, dict())):
            acf = np.mean([residuals.autocorrelation(rr.res[comp], lags_w.size) for rr in an.robots], axis=0)
            ax[1, 1].plot(lags_w * result.settings.residual_stride_s, acf, marker="o", ms=3, color=color,
                          label=comp if an is fin_an else None, **style)
    # the band at the level the verdict tests each component's autocorrelation (Bonferroni over the
    # families, components and lags), so a point outside it is what the verdict would call structure;
    # the verdict itself (portmanteau test over all lags, mean, correlations) is written in the panel
    from scipy import stats

    n_all = sum(rr.t.size for rr in fin_an.robots) or 1
    alpha = result.settings.residual_alpha / residuals.FAMILIES / len(residuals.COMPONENTS)
    bound = float(stats.norm.isf(alpha / (2 * lags_w.size))) / np.sqrt(n_all)
    for a in (bound, -bound):
        ax[1, 1].axhline(a, color="k", lw=0.6, ls=":")
    auto_white = all(fin_an.autocorr[c]["p"] >= alpha for c in residuals.COMPONENTS)
    if fin_an.white:
        verdict = "residual verdict: white"
    elif auto_white:        # the verdict's other tests (mean, correlations: panel e) found the structure
        verdict = "autocorrelation: none;\nresidual verdict: structured (its mean or correlations, panel e)"
    else:
        verdict = "autocorrelation found;\nresidual verdict: structured"
    ax[1, 1].text(0.02, 0.04, "identified model: %s\nportmanteau p: %s (autocorrelated below %.2g)"
                  % (verdict, ", ".join("%s %.2g" % (c, fin_an.autocorr[c]["p"]) for c in residuals.COMPONENTS),
                     alpha), transform=ax[1, 1].transAxes, fontsize=8, va="bottom")
    ax[1, 1].set(title="(d) residual autocorrelation (dashed: nominal)\n(dotted: the bound at the verdict's "
                       "test level)", xlabel="lag [s]", ylabel="autocorrelation", ylim=(-1, 1))
    ax[1, 1].legend(fontsize=7)

    # (e) strongest correlations: those of the nominal residual, then what is left
    keys = [(d["residual"], d["regressor"]) for d in nom_an.correlations[:BARS_NOMINAL]]
    keys += [(d["residual"], d["regressor"]) for d in fin_an.correlations
             if (d["residual"], d["regressor"]) not in keys][:BARS_FINAL]
    nom_r = {(d["residual"], d["regressor"]): d for d in nom_an.correlations}
    fin_r = {(d["residual"], d["regressor"]): d for d in fin_an.correlations}
    y = np.arange(len(keys))
    ax[2, 0].barh(y + 0.2, [abs(nom_r[k]["r"]) for k in keys], height=0.4, color="0.6", label="nominal")
    ax[2, 0].barh(y - 0.2, [abs(fin_r[k]["r"]) for k in keys], height=0.4,
                  color=["C3" if fin_r[k]["significant"] else "C0" for k in keys],
                  label="identified (red: significant)")
    ax[2, 0].axvline(fin_an.r_critical, color="k", lw=0.6, ls=":")
    ax[2, 0].set_yticks(y)
    ax[2, 0].set_yticklabels(["%s vs %s" % k for k in keys], fontsize=7)
    ax[2, 0].invert_yaxis()
    ax[2, 0].set(title="(e) strongest residual correlations |r|, nominal and identified\n"
                       "(dotted: significance for constant-variance noise)", xlim=(0, 1))
    ax[2, 0].legend(fontsize=7)

    # (f) the timing signature
    for an, style, label in ((nom_an, dict(color="0.6", s=4), "nominal"), (fin_an, dict(color="C0", s=4),
                                                                           "identified")):
        x = np.concatenate([rr.reg["v_cmd change in window"] for rr in an.robots])
        ax[2, 1].scatter(x, 1e3 * an.pooled("along"), label=label, **style)
    ax[2, 1].set(title="(f) along-track residual vs command change in the window\n(timing effects: delay, lag)",
                 xlabel="v_cmd change in window [m/s]", ylabel="along-track residual [mm]")
    ax[2, 1].legend(fontsize=7)

    fig.tight_layout(rect=(0, 0, 1, 0.96))
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
