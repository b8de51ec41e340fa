"""Settings of the model-identification tool, with units and defaults.

The defaults are the method of docs/model-identification.md;
``config/identify.yaml`` holds the same values under ``identify:`` and a file
of that form can override them with ``--config``.
"""

from dataclasses import dataclass

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.params import from_mapping, require_positive


@dataclass(frozen=True)
class IdentifySettings:
    horizon_s: float = 1.0           # s: open-loop prediction horizon H of the error metric
    window_stride_s: float = 0.1     # s: a prediction window starts every this often
    history_s: float = 2.0           # s: commands fed to the model before a window's start
    grid_dt_s: float = 0.01          # s: time step of the vectorised model integration
    pose_tolerance: float = 1.01     # x median pose period: farthest a pose sample may be from the
                                     # wanted window start/end (a dropped sample's neighbour is used)
    cv_folds: int = 3                # each robot's record is cut into this many parts in time; each part
                                     # is predicted by the model fitted on the others (cross-validation)
    accept_margin: float = 0.10      # an effect is added only if it cuts the cross-validated position or
                                     # yaw RMSE by at least this fraction (all robots, or one robot) ...
    max_worsening: float = 0.02      # ... raises neither (all robots) by more than this fraction ...
    # ... is better in most folds ...
    accept_alpha: float = 0.01       # ... and significantly: one-sided p below this (blocks of one horizon,
                                     # Bonferroni over all robots and each robot)
    min_timing_periods: float = 0.2  # physical minimum of a delay, a lag, a ramp of the acceleration limit:
                                     # this fraction of the median command period
    min_scale: float = 0.02          # ... of a velocity scale: |k - 1|
    min_turn_rate: float = 0.01      # rad/s: ... of a yaw-rate bias at the median commanded speed, or w0
    min_offset_rad: float = 0.01     # rad: ... of a heading offset
    min_threshold_fraction: float = 0.05  # ... of a deadband or friction threshold: this fraction of the
                                     # median commanded magnitude
    min_drift: float = 0.02          # ... of a gain drift: the change of the gain over the record
    drift_segments: int = 4          # time-dependence test: gains fitted on this many parts of each record
    residual_horizon_s: float = 0.5  # s: horizon of the residual-analysis windows
    residual_stride_s: float = 0.6   # s: their spacing (> horizon: no shared pose sample, independent noise)
    residual_lags: int = 10          # autocorrelation-test lags (in windows)
    residual_alpha: float = 0.01     # significance level of the whiteness and correlation tests
    max_command_lag_s: float = 0.5   # s: regressors include the commands up to this far back
    max_nfev: int = 20               # least-squares function evaluations per fit
    cv_nfev: int = 5                 # ... per cross-validation refit (started from the fit on all data)
    glitch_speed: float = 1.0        # m/s: a pose farther from its neighbours' median than this speed allows
    #                                  (plus glitch_margin_m) is a mocap glitch and is dropped
    glitch_margin_m: float = 0.01    # m: the margin on top of what glitch_speed allows
    glitch_turn_rate: float = 20.0   # rad/s: the same for the yaw (plus glitch_margin_rad)
    glitch_margin_rad: float = 0.3   # rad: the margin on top of what glitch_turn_rate allows

    @classmethod
    def from_dict(cls, data, where="identify"):
        if isinstance(data, dict) and "identify" in data:
            data, where = data["identify"], where + ".identify"
        return from_mapping(cls, data, where)

    def check(self, where="identify"):
        require_positive(self, ["horizon_s", "window_stride_s", "history_s", "grid_dt_s", "pose_tolerance",
                                "accept_margin", "accept_alpha", "residual_horizon_s", "residual_stride_s",
                                "residual_lags", "residual_alpha", "max_nfev", "cv_nfev", "glitch_speed",
                                "glitch_margin_m", "glitch_turn_rate", "glitch_margin_rad", "min_timing_periods",
                                "min_scale", "min_turn_rate", "min_offset_rad", "min_threshold_fraction",
                                "min_drift"], where)
        if self.cv_folds < 2:
            raise ConfigError("%s.cv_folds: must be >= 2, got %r" % (where, self.cv_folds))
        if self.drift_segments < 2:
            raise ConfigError("%s.drift_segments: must be >= 2, got %r" % (where, self.drift_segments))
        if self.max_worsening < 0:
            raise ConfigError("%s.max_worsening: must be >= 0" % where)
        if self.max_command_lag_s < 0:
            raise ConfigError("%s.max_command_lag_s: must be >= 0" % where)
        if self.grid_dt_s > self.window_stride_s:
            raise ConfigError("%s.grid_dt_s (%g) must be <= window_stride_s (%g)"
                              % (where, self.grid_dt_s, self.window_stride_s))
        if self.residual_alpha >= 1 or self.accept_alpha >= 1:
            raise ConfigError("%s.residual_alpha and accept_alpha: must be < 1" % where)
