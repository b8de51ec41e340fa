"""The whole identification: read, fit per robot, trace and add, share, analyse what remains, report."""

import math
import time
from dataclasses import dataclass
from typing import Dict, List

from puzzlebot_common.effects import EFFECTS, NOMINAL, ActuatorModel
from puzzlebot_mpc.identify import data, engine, fit, residuals
from puzzlebot_mpc.identify.settings import IdentifySettings

BOUND_TOLERANCE = 1e-4   # relative distance to a search bound counted as "at the bound"
FEW_BLOCKS = 10          # held-out horizons per robot below which significance is out of reach: warn
PARAM_DIGITS = 6         # decimals of the parameters written to the report and model.yaml


@dataclass
class Problem:
    """Every robot's windows and fitting state (fit.RobotFit), in the dataset's robot order."""

    fits: List[fit.RobotFit]
    settings: IdentifySettings

    @property
    def robots(self):
        return [rf.r for rf in self.fits]

    def errors(self, params):
        """Errors of every window of every robot; ``params``: one dict for all robots, a list (one per
        robot), or an ActuatorModel (each robot's ``for_robot`` model)."""
        return [rf.errors(p) for rf, p in zip(self.fits, robot_params(params, [rf.name for rf in self.fits]))]

    def metric(self, params):
        """(pooled Metric, [per-robot Metric]) of ``params`` over every window (no fitting)."""
        errs = self.errors(params)
        return engine.metric(errs), [engine.metric([e]) for e in errs]


def robot_params(params, names):
    if isinstance(params, ActuatorModel):
        return [params.for_robot(n).all_params() for n in names]
    if isinstance(params, dict):
        return [params] * len(names)
    return list(params)


@dataclass
class Result:
    path: str
    dataset: data.Dataset
    settings: IdentifySettings
    problem: Problem
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

    def robot_effects(self, name):
        """The effects robot ``name`` ends up with (shared, own, without those pruned for it)."""
        return self.model.for_robot(name).names()


def _rounded(params, names):
    return {k: round(params[k], PARAM_DIGITS) if math.isfinite(params[k]) else params[k]
            for n in names for k in EFFECTS[n]}


def build_model(sel, robot_names):
    """model.yaml: shared effects under ``effects``, each robot's own (not pruned) under ``robots``."""
    model = ActuatorModel()
    first = sel.params[0]
    for name in sel.names:
        if name in sel.shared:
            model.add(name, _rounded(first, [name]))
    for i, robot in enumerate(robot_names):
        for name in sel.names:
            if name in sel.shared or name in sel.pruned.get(robot, []):
                continue
            model.add_for_robot(robot, name, _rounded(sel.params[i], [name]))
    return model


def bound_warnings(sel, robot_names):
    """Fitted parameters that ended on a bound of their search range (other than a zero lower bound,
    a physical limit: no delay, no lag; and the acceleration limit's upper bound: no limit)."""
    out = []
    for i, robot in enumerate(robot_names):
        for name in sel.names:
            if name in sel.pruned.get(robot, []) or (name in sel.shared and i > 0):
                continue
            for key in EFFECTS[name]:
                if key not in fit.PARAM_SPECS or not math.isfinite(sel.params[i][key]):
                    continue
                spec, value = fit.PARAM_SPECS[key], sel.params[i][key]
                for bound in (spec.lower, spec.upper):
                    if bound != 0.0 and abs(value - bound) <= BOUND_TOLERANCE * max(abs(bound), 1.0):
                        who = "all robots" if name in sel.shared else "robot %s" % robot
                        out.append("%s.%s = %g (%s) is at the bound %g of its search range: the data may call "
                                   "for a larger value or for another effect" % (name, key, value, who, bound))
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
    say("read %s in %.2f s: %s" % (path, time.time() - t_start, "; ".join(
        "%s %.1f s, %d poses, %d commands" % (r.name, r.duration, r.t.size, r.cmd_t.size) for r in dataset.robots)))
    problem = Problem([fit.RobotFit(r, settings) for r in dataset.robots], settings)
    say("%d windows of %.1f s, %d parts per robot for cross-validation"
        % (sum(len(rf.windows) for rf in problem.fits), settings.horizon_s, settings.cv_folds))
    for rf in problem.fits:
        blocks = len(rf.windows) * settings.window_stride_s / settings.horizon_s
        if blocks < FEW_BLOCKS:
            warnings.append("robot %s: only %.0f s of windows: too little to show that an effect is significant; "
                            "record longer" % (rf.name, blocks * settings.horizon_s))
            say("warning: " + warnings[-1])
    selection = fit.trace_and_add(problem.fits, settings, say)
    names = dataset.robot_names()
    model = build_model(selection, names)
    say("effects: %s" % (", ".join(selection.names) or "none"))
    windows = [residuals.residual_windows(r, settings) for r in dataset.robots]
    nominal_an = residuals.analyse([dict(NOMINAL)] * len(names), dataset.robots, settings, windows)
    final_an = residuals.analyse(selection.params, dataset.robots, settings, windows)
    residuals.diagnose(final_an, problem.fits, selection.params, settings)
    residuals.diagnose(nominal_an, problem.fits, [dict(NOMINAL)] * len(names), settings)
    if dataset.kind == "csv" and not dataset.exact_command_times:
        period = min(engine.median_period(r) for r in dataset.robots)
        for an in (nominal_an, final_an):
            if not an.white:
                an.notes += (" Note: this CSV has no t_cmd column, so its command times are known only to within a "
                             "pose period (here +/-%.1f ms), which by itself can structure the yaw residual of fast "
                             "turns." % (500.0 * period))
    for w in bound_warnings(selection, names):
        warnings.append(w)
        say("warning: " + w)
    per_robot = {}
    nominal, final = selection.nominal, selection.final
    for i, name in enumerate(names):
        entry = {"before": nominal[1][i].as_dict(), "after": final[1][i].as_dict(),
                 "effects": model.for_robot(name).names(),
                 "params": _rounded(selection.params[i], model.for_robot(name).names())}
        if final[1][i].rmse_pos_m > nominal[1][i].rmse_pos_m and final[1][i].rmse_yaw_rad > nominal[1][i].rmse_yaw_rad:
            warnings.append("robot %s: the identified model predicts its held-out data worse than the nominal "
                            "model" % name)
            say("warning: " + warnings[-1])
        per_robot[name] = entry
    return Result(path, dataset, settings, problem, selection, model, nominal_an, final_an, per_robot,
                  time.time() - t_start, warnings)
