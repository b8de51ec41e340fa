"""The report: report.json (the issue's format plus details) and a readable table."""

from puzzlebot_common.effects import EFFECTS
from puzzlebot_mpc.identify import residuals
from puzzlebot_mpc.identify.core import PARAM_DIGITS


def _rmse(metric):
    return {"rmse_pos_m": round(metric.rmse_pos_m, 9), "rmse_yaw_rad": round(metric.rmse_yaw_rad, 9)}


def margin_text(settings):
    return ("an effect is added if it lowers the validation position or yaw RMSE by at least %.0f %%, raises "
            "neither by more than %.0f %%, lowers the improved RMSE on more than half of the robots, and the "
            "improvement is significant (one-sided p < %.2g over blocks of %.1f s)"
            % (100 * settings.accept_margin, 100 * settings.max_worsening, settings.accept_alpha,
               settings.horizon_s))


def report_dict(result):
    s, sel = result.settings, result.selection
    params = sel.params
    effects = [{"name": step["name"],
                "params": {k: round(params[k], PARAM_DIGITS) for k in EFFECTS[step["name"]]},
                "params_when_added": {k: round(v, PARAM_DIGITS) for k, v in step["params"].items()},
                "after": _rmse(step["after"]),
                "why": step["reason"]} for step in sel.steps]
    trace = []
    for i, rnd in enumerate(sel.rounds):
        best = rnd.candidates[0]
        trace.append({
            "round": i + 1,
            "candidates": [{"name": c.name, "explained": round(c.explained, 4),
                            "params": {k: round(c.params[k], PARAM_DIGITS) for k in EFFECTS[c.name]}}
                           for c in rnd.candidates],
            "best": rnd.chosen, "validation": _rmse(best.validation), "accepted": rnd.accepted,
            "reason": rnd.reason})
    final = residuals.summary(result.final_analysis)
    return {
        "data": result.path,
        "robots": result.dataset.robot_names(),
        "fit_fraction": s.fit_fraction,
        "horizon_s": s.horizon_s,
        "before": _rmse(sel.nominal[0]),
        "effects": effects,
        "after": _rmse(sel.final[0]),
        "residual": final,
        "residual_nominal": residuals.summary(result.nominal_analysis),
        "acceptance": margin_text(s),
        "windows": {"fit": sum(len(w[0]) for w in result.problem.windows),
                    "validation": sum(len(w[1]) for w in result.problem.windows),
                    "stride_s": s.window_stride_s},
        "trace": trace,
        "per_robot": result.per_robot,
        "warnings": result.warnings,
        "runtime_s": round(result.runtime_s, 2),
    }


def _params_text(params):
    return " ".join("%s=%.4g" % (k, v) for k, v in params.items())


def table(result):
    """Readable summary (mm and mrad) for the terminal."""
    rep = report_dict(result)
    s = result.settings
    lines = ["Model identification: %s" % rep["data"],
             "robots: %s; fit on the first %.0f %% of each robot's record, validate on the rest"
             % (", ".join(rep["robots"]), 100 * s.fit_fraction),
             "error: open-loop prediction over H = %.1f s from a measured pose every %.1f s (%d validation windows)"
             % (s.horizon_s, s.window_stride_s, rep["windows"]["validation"]),
             ""]
    rows = [("model", "pos RMSE [mm]", "yaw RMSE [mrad]"),
            ("nominal unicycle", "%.2f" % (1e3 * rep["before"]["rmse_pos_m"]),
             "%.1f" % (1e3 * rep["before"]["rmse_yaw_rad"]))]
    for e in rep["effects"]:
        rows.append(("+ %s (%s)" % (e["name"], _params_text(e["params_when_added"])),
                     "%.2f" % (1e3 * e["after"]["rmse_pos_m"]), "%.1f" % (1e3 * e["after"]["rmse_yaw_rad"])))
    b, a = rep["before"], rep["after"]
    rows.append(("final (%d effect%s)" % (len(rep["effects"]), "" if len(rep["effects"]) == 1 else "s"),
                 "%.2f (%+.0f %%)" % (1e3 * a["rmse_pos_m"], 100 * (a["rmse_pos_m"] / b["rmse_pos_m"] - 1)),
                 "%.1f (%+.0f %%)" % (1e3 * a["rmse_yaw_rad"], 100 * (a["rmse_yaw_rad"] / b["rmse_yaw_rad"] - 1))))
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows)
    w2 = max(len(r[2]) for r in rows)
    for r in rows:
        lines.append("  %-*s  %*s  %*s" % (w0, r[0], w1, r[1], w2, r[2]))
    lines.append("")
    if rep["effects"]:
        lines.append("final parameters (model.yaml): " + "; ".join(
            "%s: %s" % (e["name"], _params_text(e["params"])) for e in rep["effects"]))
    else:
        lines.append("no effect earned its place: the nominal unicycle stays")
    lines.append("acceptance: " + rep["acceptance"])
    lines.append("rounds (share of the fitting cost each candidate explains):")
    for rnd in rep["trace"]:
        lines.append("  %d: %s -> %s %s (%s)" % (
            rnd["round"], ", ".join("%s %.1f %%" % (c["name"], 100 * c["explained"]) for c in rnd["candidates"]),
            rnd["best"], "added" if rnd["accepted"] else "rejected", rnd["reason"]))
    if rep["per_robot"] and rep["effects"]:
        lines.append("per robot (own refit of the same effects; report.json per_robot):")
        for name, entry in rep["per_robot"].items():
            lines.append("  %s: %s" % (name, _params_text(entry["params"])))
    lines.append("residual: %s" % rep["residual"]["notes"])
    for w in rep["warnings"]:
        lines.append("warning: %s" % w)
    lines.append("runtime %.1f s" % rep["runtime_s"])
    return "\n".join(lines)
