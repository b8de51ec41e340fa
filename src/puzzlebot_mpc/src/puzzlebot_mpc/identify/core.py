"""The whole identification: read, fit, trace and add, analyse what remains, report."""

import time
from dataclasses import dataclass
from typing import Dict, List

from puzzlebot_common.effects import EFFECTS, NOMINAL, ActuatorModel
from puzzlebot_mpc.identify import data, engine, fit, residuals
from puzzlebot_mpc.identify.settings import IdentifySettings

BOUND_TOLERANCE = 1e-4   # relative distance to a search bound counted as "at the bound"
FEW_BLOCKS = 10          # validation horizons below which significance is out of reach: warn
PARAM_DIGITS = 6     # decimals of the parameters written to the report and model.yaml


@dataclass
class Result:
    path: str
    dataset: data.Dataset
    settings: IdentifySettings
    problem: fit.Problem
    selection: fit.Selection
    model: ActuatorModel
    nominal_analysis: residuals.Analysis
    final_analysis: residuals.Analysis
    per_robot: Dict[str, dict]
    runtime_s: float
    warnings: List[str]

    @property
    def effect_names(self) -> List[str]:
        return list(self.selection.names)


def _model(names, params):
    model = ActuatorModel()
    for name in names:
        model.add(name, {k: round(params[k], PARAM_DIGITS) for k in EFFECTS[name]})
    return model


def bound_warnings(selection):
    """Fitted parameters that ended on a bound of their search range (other than a zero
    lower bound, which is a physical limit: no delay, no lag)."""
    out = []
    for name in selection.names:
        for key in EFFECTS[name]:
            if key not in fit.PARAM_SPECS:
                continue
            lo, hi = fit.PARAM_SPECS[key][:2]
            value = selection.params[key]
            for bound in (lo, hi):
                if bound != 0.0 and abs(value - bound) <= BOUND_TOLERANCE * max(abs(bound), 1.0):
                    out.append("%s.%s = %g is at the bound %g of its search range: the data may call for a "
                               "larger value or for another effect" % (name, key, value, bound))
    return out


def identify(path, settings=None, robots=None, progress=None):
    """Identify the effects in the data file ``path`` (.bag or .csv).

    ``robots``: optional robot list (RobotSpec) choosing robots and mocap
    subjects; ``progress``: callable taking one-line progress messages.
    Raises data.DataError on unusable input.
    """
    settings = settings or IdentifySettings()
    say = progress or (lambda msg: None)
    t_start = time.time()
    dataset = data.load(path, robots)
    warnings = data.drop_glitches(dataset, settings)
    for w in warnings:
        say("warning: " + w)
    say("read %s in %.1f s: %s" % (path, time.time() - t_start, "; ".join(
        "%s %.1f s, %d poses, %d commands" % (r.name, r.duration, r.t.size, r.cmd_t.size) for r in dataset.robots)))
    problem = fit.Problem(dataset, settings, say)
    n_fit = sum(len(w[0]) for w in problem.windows)
    n_val = sum(len(w[1]) for w in problem.windows)
    say("%d fitting and %d validation windows of %.1f s" % (n_fit, n_val, settings.horizon_s))
    blocks = sum(len(w[1]) for w in problem.windows) * settings.window_stride_s / settings.horizon_s
    if blocks < FEW_BLOCKS:
        warnings.append("only %.0f s of validation windows: too little to show that an effect is significant; "
                        "record longer (each robot's last %.0f %% is validation)"
                        % (blocks * settings.horizon_s, 100 * (1 - settings.fit_fraction)))
        say("warning: " + warnings[-1])
    selection = fit.trace_and_add(problem)
    say("effects: %s" % (", ".join(selection.names) or "none"))
    windows = [residuals.residual_windows(r, settings) for r in dataset.robots]
    nominal_an = residuals.analyse(dict(NOMINAL), dataset.robots, settings, windows)
    final_an = residuals.analyse(selection.params, dataset.robots, settings, windows)
    if dataset.kind == "csv":
        period = min(engine.median_period(r) for r in dataset.robots)
        for an in (nominal_an, final_an):
            if not an.white:
                an.notes += (" Note: a CSV gives command times only to within a pose period (here +/-%.1f ms), "
                             "which by itself can structure the yaw residual of fast turns; a bag has the exact "
                             "command times." % (500.0 * period))
    for w in bound_warnings(selection):
        warnings.append(w)
        say("warning: " + w)
    per_robot = {}
    if len(dataset.robots) > 1:
        for i, r in enumerate(dataset.robots):
            entry = {"before": selection.nominal[1][i].as_dict(), "after": selection.final[1][i].as_dict()}
            if selection.names:
                single = fit.Problem(data.Dataset(path, [r], dataset.t0), settings)
                p = single.fit(selection.names, selection.params)
                entry["params"] = {k: round(p[k], PARAM_DIGITS) for n in selection.names for k in EFFECTS[n]}
                entry["after_own_params"] = single.validation(p)[0].as_dict()
            per_robot[r.name] = entry
        say("per-robot refits done")
    return Result(path, dataset, settings, problem, selection, _model(selection.names, selection.params),
                  nominal_an, final_an, per_robot, time.time() - t_start, warnings)
