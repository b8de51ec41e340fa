"""MPC settings with units, defaults and validation.

Loaded from the ``mpc`` mapping of ``config/mpc.yaml`` (or the ROS parameter
``~mpc``). Limits are the paper's demo values (facts.md, "Control"); the
weights start from the lab's values and docs/mpc.md says where and why they
differ.
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
    butterfly: bool = True           # no turning in place: |w| <= (w_max/v_max) |v| + w_free (soft, linearised)
    w_free: float = 0.05             # rad/s: turn rate allowed at v = 0 by the butterfly set
    w_goal_terminal: float = 1.0e4   # 1/m^2: terminal weight on squared goal distance
    w_goal_stage: float = 1.0        # 1/m^2: stage weight on squared goal distance
    w_goal_lateral: float = 100.0    # 1/m^2: stage weight on the goal's squared sideways offset in the
                                     # robot frame (turns the robot towards its goal: no local minimum
                                     # beside the goal, which a unicycle cannot reach by driving straight)
    w_velocity: float = 1.0e2        # s^2/m^2: weight on squared velocity-tracking error
    w_rest: float = 1.0              # weight on squared (v, w) of goal-driven robots (no spinning at the goal)
    w_control: float = 1.0e-1        # weight on squared accelerations dv, dw
    w_pair_terminal_pos: float = 1.0e5    # 1/m^2: terminal weight on an active pair's squared position error
    w_pair_terminal_angle: float = 1.0e3  # terminal weight on tan^2(dtheta/2) of an active pair
    w_pair_stage_pos: float = 1.0         # 1/m^2: stage weight, position
    w_pair_stage_angle: float = 1.0e-2    # stage weight, tan^2(dtheta/2)
    w_pair_lateral: float = 1.0e3         # 1/m^2: stage weight on the sideways offset of an active pair's
                                          # position error in each robot's frame (turns the robots to face
                                          # each other: no local minimum beside the target)
    w_coupled_pos: float = 1.0e3          # 1/m^2: stage weight keeping coupled pairs aligned (k = 1..H)
    w_coupled_angle: float = 10.0         # stage weight on tan^2(dtheta/2) of coupled pairs
    w_slack_pip: float = 1.0e7       # 1/m: exact-penalty weight of a coupling-polygon violation
    w_slack_butterfly: float = 1.0e5  # s/rad: exact-penalty weight of a butterfly-set violation
    slack_regularisation: float = 1.0e-2  # small quadratic weight on slacks (strictly convex QP)
    pip_margin: float = 0.001        # m: coupling polygons are tightened by this much in the constraint
    solver: str = "clarabel"         # "clarabel" (real-time iteration, sparse QP) or "ipopt" (full NLP)
    sqp_iterations: int = 1          # QPs per step when warm (1 = real-time iteration)
    sqp_iterations_cold: int = 3     # QPs per step after a cold start
    butterfly_lobe_robots: int = 2   # robots at rest whose direction of travel is chosen by trying both
                                     # butterfly cones (2^k QPs in such a step); 0 = use the preference only
    max_iter: int = 100              # solver iteration cap per QP / NLP
    qp_tolerance: float = 1.0e-6     # Clarabel's gap and feasibility tolerances
    command_zero: float = 1.0e-5     # m/s, rad/s: smaller commands are sent as exact zeros (solver noise)
    goal_tolerance: float = 0.005    # m: default success radius of go_to_goal
    pose_timeout: float = 0.5        # s: a pose older than this is stale; the robot is stopped
    approach_lookahead: float = 0.04      # m: the approach target leads the opening robot by this along the axis
    approach_standoff_max: float = 0.03   # m: largest standoff of a misaligned anchor pair's approach target
    approach_gain_angle: float = 0.04     # m/rad: standoff per radian of heading error
    approach_gain_lateral: float = 2.0    # m/m: standoff per metre of lateral offset of the head
    pair_epsilon: float = 0.0015     # m: margin of the pair status tests (Algorithm 2)
    pair_lost_margin: float = 0.005  # m: a coupled pair whose head is this far outside its polygon is lost
    wiggle_v_bias: float = 0.02      # m/s: forward speed of the anchor robot while it wiggles out
    wiggle_w_amplitude: float = 1.5  # rad/s: wiggle turn rate amplitude (paper: w_max)
    wiggle_period: float = 1.0       # s: wiggle period 2 pi / B
    hold_scale: float = 100.0        # rest-weight scale of an assembly a single robot docks onto (holds still)
    follower_rest_scale: float = 0.1  # rest-cost scale (0..1) of robots dragged along by a coupled partner
    decouple_clearance: float = 0.003  # m: decoupled once the anchor head is this far outside the opening robot

    @classmethod
    def from_dict(cls, data, where="mpc"):
        """Validated settings from a mapping; unknown keys raise ConfigError."""
        return from_mapping(cls, data, where)

    def check(self, where="mpc"):
        """Range and cross-field checks; raise ConfigError."""
        require_positive(self, ["dt", "horizon", "constraint_horizon", "v_max", "w_max", "dv_max",
                                "dw_max", "max_iter", "goal_tolerance", "pose_timeout", "sqp_iterations",
                                "sqp_iterations_cold", "pair_epsilon", "pair_lost_margin", "wiggle_period",
                                "slack_regularisation", "qp_tolerance", "command_zero", "w_slack_pip",
                                "w_slack_butterfly"], where)
        for key in ("w_free", "w_goal_terminal", "w_goal_stage", "w_goal_lateral", "w_velocity", "w_rest",
                    "w_control", "w_pair_terminal_pos", "w_pair_terminal_angle", "w_pair_stage_pos",
                    "w_pair_stage_angle", "w_pair_lateral", "w_coupled_pos", "w_coupled_angle", "pip_margin",
                    "wiggle_v_bias", "wiggle_w_amplitude", "decouple_clearance", "follower_rest_scale", "hold_scale", "butterfly_lobe_robots",
                    "approach_lookahead", "approach_standoff_max", "approach_gain_angle", "approach_gain_lateral"):
            if getattr(self, key) < 0:
                raise ConfigError("%s.%s: must be >= 0" % (where, key))
        if self.constraint_horizon > self.horizon:
            raise ConfigError("%s.constraint_horizon (%d) must be <= horizon (%d)"
                              % (where, self.constraint_horizon, self.horizon))
        if self.solver not in ("clarabel", "ipopt"):
            raise ConfigError("%s.solver: unknown solver %r; known: clarabel, ipopt" % (where, self.solver))
        if self.wiggle_v_bias > self.v_max or self.wiggle_w_amplitude > self.w_max:
            raise ConfigError("%s: the wiggle (%.3f m/s, %.2f rad/s) exceeds the limits v_max, w_max"
                              % (where, self.wiggle_v_bias, self.wiggle_w_amplitude))
