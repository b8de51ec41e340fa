"""The report: report.json (the issue's format plus details) and a readable table."""

import math

from puzzlebot_common.effects import EFFECTS
from puzzlebot_mpc.identify import residuals
from puzzlebot_mpc.identify.core import PARAM_DIGITS


def _rmse(metric):
    return {"rmse_pos_m": round(metric.rmse_pos_m, 9), "rmse_yaw_rad": round(metric.rmse_yaw_rad, 9)}


def _params(p, name):
    return {k: round(p[k], PARAM_DIGITS) if math.isfinite(p[k]) else p[k] for k in EFFECTS[name]}


def margin_text(settings):
    return ("an effect is added if it is larger than its physical minimum on at least one robot and, on held-out "
            "data (%d-part cross-validation in time), lowers the position or yaw RMSE of all robots or of one "
            "robot by at least %.0f %%, in most parts, significantly (one-sided p < %.2g over blocks of %.1f s, "
            "Bonferroni over the groups), and raises neither pooled RMSE by more than %.0f %%; an effect's "
            "parameters are shared by the robots unless their own parameters predict their held-out data "
            "better by the same rule"
            % (settings.cv_folds, 100 * settings.accept_margin, settings.accept_alpha, settings.horizon_s,
               100 * settings.max_worsening))


def report_dict(result):
    s, sel = result.settings, result.selection
    names = result.dataset.robot_names()
    effects = []
    for step in sel.steps:
        name = step["name"]
        shared = name in sel.shared
        effects.append({
            "name": name, "shared": shared,
            "params": _params(sel.params[0], name) if shared else None,
            "robots": {r: _params(sel.params[i], name) for i, r in enumerate(names)
                       if name not in sel.pruned.get(r, [])},
            "params_when_added": {r: _params(p, name) for r, p in zip(names, step["params"])},
            "after": _rmse(step["after"]), "why": step["reason"]})
    trace = []
    for i, rnd in enumerate(sel.rounds):
        trace.append({
            "round": i + 1,
            "candidates": [{"name": c.name, "explained": round(c.explained, 4)} for c in rnd.candidates],
            "tried": [{"name": t["name"], "accepted": t["accepted"], "reason": t["reason"],
                       "sizes": {r: round(x, 3) for r, x in zip(names, t["sizes"])},
                       "validation": _rmse(t["validation"]) if "validation" in t else None} for t in rnd.tried],
            "accepted": rnd.accepted})
    sharing = [{"name": d["name"], "shared": d["shared"], "reason": d["reason"],
                "held_out_shared": _rmse(d["shared_error"]), "held_out_own": _rmse(d["own_error"]),
                "per_robot": {r: {k: round(v, PARAM_DIGITS) if math.isfinite(v) else v for k, v in p.items()}
                              for r, p in d["per_robot"].items()}} for d in sel.sharing]
    return {
        "data": result.path,
        "robots": names,
        "cv_folds": s.cv_folds,
        "horizon_s": s.horizon_s,
        "before": _rmse(sel.nominal[0]),
        "effects": effects,
        "after": _rmse(sel.final[0]),
        "residual": residuals.summary(result.final_analysis),
        "residual_nominal": residuals.summary(result.nominal_analysis),
        "acceptance": margin_text(s),
        "sharing": sharing,
        "pruned": sel.pruned,
        "removed": sel.removed,
        "model": result.model.to_dict()["model"],
        "windows": {"total": sum(len(rf.windows) for rf in result.problem.fits), "stride_s": s.window_stride_s},
        "trace": trace,
        "per_robot": result.per_robot,
        "warnings": result.warnings,
        "runtime_s": round(result.runtime_s, 2),
    }


def _params_text(params):
    return " ".join("%s=%.4g" % (k, v) for k, v in params.items())


def _effect_text(e):
    if e["shared"]:
        return _params_text(e["params"])
    return "; ".join("%s %s" % (r, _params_text(p)) for r, p in e["robots"].items()) or "(pruned on every robot)"


def table(result):
    """Readable summary (mm and mrad) for the terminal."""
    rep = report_dict(result)
    s = result.settings
    lines = ["Model identification: %s" % rep["data"],
             "robots: %s; every part of each robot's record (%d in time) predicted by the model fitted on the others"
             % (", ".join(rep["robots"]), s.cv_folds),
             "error: open-loop prediction over H = %.1f s from a measured pose every %.1f s (%d windows)"
             % (s.horizon_s, s.window_stride_s, rep["windows"]["total"]),
             ""]
    rows = [("model (held-out errors)", "pos RMSE [mm]", "yaw RMSE [mrad]"),
            ("nominal unicycle", "%.2f" % (1e3 * rep["before"]["rmse_pos_m"]),
             "%.1f" % (1e3 * rep["before"]["rmse_yaw_rad"]))]
    for e in rep["effects"]:
        when = list(e["params_when_added"].values())
        median = {k: sorted(p[k] for p in when)[len(when) // 2] for k in when[0]}
        text = _params_text(median) + (" median of the robots' fits" if len(when) > 1 else "")
        rows.append(("+ %s (%s)" % (e["name"], text), "%.2f" % (1e3 * e["after"]["rmse_pos_m"]),
                     "%.1f" % (1e3 * e["after"]["rmse_yaw_rad"])))
    b, a = rep["before"], rep["after"]
    rows.append(("final (%d effect%s%s)" % (len(rep["effects"]), "" if len(rep["effects"]) == 1 else "s",
                                            ", shared where the robots agree" if len(rep["robots"]) > 1 and
                                            rep["effects"] else ""),
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
            "%s%s: %s" % (e["name"], "" if e["shared"] else " (per robot)", _effect_text(e)) for e in rep["effects"]))
    else:
        lines.append("no effect earned its place: the nominal unicycle stays")
    lines.append("acceptance: " + rep["acceptance"])
    lines.append("rounds (share of the current cost each candidate explains):")
    for rnd in rep["trace"]:
        lines.append("  %d: %s" % (rnd["round"], ", ".join("%s %.1f %%" % (c["name"], 100 * c["explained"])
                                                           for c in rnd["candidates"])))
        for t in rnd["tried"]:
            lines.append("     -> %s %s (%s)" % (t["name"], "added" if t["accepted"] else "rejected", t["reason"]))
    for d in rep["removed"]:
        lines.append("removed by the backward check: %s (%s)" % (d["name"], d["reason"]))
    for d in rep["sharing"]:
        lines.append("sharing %s: %s (%s)" % (d["name"], "shared" if d["shared"] else "per robot", d["reason"]))
    if len(rep["robots"]) > 1:
        lines.append("per robot (held-out errors, nominal -> identified; its effects):")
        for name, entry in rep["per_robot"].items():
            lines.append("  %s: pos %.2f -> %.2f mm, yaw %.1f -> %.1f mrad; %s" % (
                name, 1e3 * entry["before"]["rmse_pos_m"], 1e3 * entry["after"]["rmse_pos_m"],
                1e3 * entry["before"]["rmse_yaw_rad"], 1e3 * entry["after"]["rmse_yaw_rad"],
                _params_text(entry["params"]) or "none"))
    lines.append("residual: %s" % rep["residual"]["notes"])
    for w in rep["warnings"]:
        lines.append("warning: %s" % w)
    lines.append("runtime %.1f s" % rep["runtime_s"])
    return "\n".join(lines)
