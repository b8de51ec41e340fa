"""MPC settings with units, defaults and validation.

Loaded from the ``mpc`` mapping of ``config/mpc.yaml`` (or the ROS parameter
``~mpc``). Defaults are the paper's demo values (facts.md, "Control").
"""

from dataclasses import dataclass

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.params import from_mapping, require_positive


@dataclass(frozen=True)
class MPCSettings:
    dt: float = 0.1                  # s: control period and Euler step
    horizon: int = 10                # Hm: prediction steps
    constraint_horizon: int = 3      # Hc <= Hm: steps with coupling constraints
    v_max: float = 0.05              # m/s: |v| limit
    w_max: float = 1.5               # rad/s: |w| limit
    dv_max: float = 2.0              # m/s^2: |dv| limit
    dw_max: float = 5.0              # rad/s^2: |dw| limit
    butterfly: bool = False          # restrict w by v: w^2 <= (w_max/v_max)^2 v^2 + w_free^2
    w_free: float = 0.05             # rad/s: turn rate allowed at v = 0 by the butterfly set
    w_goal_terminal: float = 1.0e4   # 1/m^2: terminal weight on squared goal distance
    w_goal_stage: float = 1.0        # 1/m^2: stage weight on squared goal distance
    w_goal_lateral: float = 100.0    # 1/m^2: stage weight on the goal's squared sideways offset in the
                                     # robot frame (turns the robot towards its goal: no local minimum
                                     # beside the goal, which a unicycle cannot reach by driving straight)
    w_velocity: float = 1.0e2        # s^2/m^2: weight on squared velocity-tracking error
    w_rest: float = 1.0              # weight on squared (v, w) of goal-driven robots (no spinning at the goal)
    w_control: float = 1.0e-1        # weight on squared accelerations dv, dw
    solver: str = "ipopt"            # CasADi nlpsol plugin
    max_iter: int = 100              # solver iteration cap per step
    goal_tolerance: float = 0.005    # m: default success radius of go_to_goal
    pose_timeout: float = 0.5        # s: a pose older than this is stale; the robot is stopped

    @classmethod
    def from_dict(cls, data, where="mpc"):
        """Validated settings from a mapping; unknown keys raise ConfigError."""
        return from_mapping(cls, data, where)

    def check(self, where="mpc"):
        """Range and cross-field checks; raise ConfigError."""
        require_positive(self, ["dt", "horizon", "constraint_horizon", "v_max", "w_max", "dv_max",
                                "dw_max", "max_iter", "goal_tolerance", "pose_timeout"], where)
        for key in ("w_free", "w_goal_terminal", "w_goal_stage", "w_goal_lateral", "w_velocity", "w_rest",
                    "w_control"):
            if getattr(self, key) < 0:
                raise ConfigError("%s.%s: must be >= 0" % (where, key))
        if self.constraint_horizon > self.horizon:
            raise ConfigError("%s.constraint_horizon (%d) must be <= horizon (%d)"
                              % (where, self.constraint_horizon, self.horizon))
