"""MPC settings with units, defaults and validation.

Loaded from the ``mpc`` mapping of ``config/mpc.yaml`` (or the ROS parameter
``~mpc``). Limits are the paper's demo values (facts.md, "Control"); the
weights start from the lab's values and docs/mpc.md says where and why they
differ.
"""

from dataclasses import dataclass
from dataclasses import fields as dc_fields

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.hardware import CONTROL_PERIOD, V_MAX, W_MAX
from puzzlebot_common.params import from_mapping, require_positive
from puzzlebot_mpc.docking import DockingSettings
from puzzlebot_mpc.knob_approach import KnobLane

_DOCK = DockingSettings()   # the docking defaults have one home: puzzlebot_mpc/docking.py
_KNOB = KnobLane()          # the knob approach's: puzzlebot_mpc/knob_approach.py


@dataclass(frozen=True)
class MPCSettings:
    dt: float = CONTROL_PERIOD       # s: control period and Euler step
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
    knob_hold: float = 0.001         # m: the constraint keeps a coupled knob pair's knob this close to its hole
                                     # (along the side and across it) ...
    knob_hold_step: float = 0.0002   # m: ... asking it at most this much further in per step than it is
                                     # (pairs.constraint_margin)
    edges: bool = True               # keep every robot's footprint on the stage it stands on (the world's
                                     # stages, puzzlebot_common.stages; none on the flat floor), except the
                                     # robots of a behaviour requested with cross_edges (soft, exact penalty)
    edge_margin: float = 0.0         # m: clearance from a stage's edge beyond the footprint's circumradius
    w_slack_edge: float = 1.0e6      # 1/m: exact-penalty weight of a robot's base_link beyond its edge box
    solver: str = "active_set"       # real-time iteration, one sparse QP per step, solved by "active_set" (the
                                     # primal-dual active-set method, warm-started) or "clarabel" (interior
                                     # point); or "ipopt" (the full NLP, the reference)
    active_set_iterations: int = 10  # working sets tried per QP by active_set before Clarabel solves it
    sqp_iterations: int = 1          # QPs per step when warm (1 = real-time iteration)
    sqp_iterations_cold: int = 3     # QPs per step after a cold start
    decompose: bool = True           # independent subproblems (robots neither coupled nor pairing with each
                                     # other) are separate QPs; the solution is that of the joint QP
    solver_threads: int = 1          # threads solving those QPs in parallel (1: in turn)
    butterfly_lobe_robots: int = 2   # robots at rest whose direction of travel is chosen by trying both
                                     # butterfly cones (2^k QPs in such a step); 0 = use the preference only
    max_iter: int = 100              # solver iteration cap per QP / NLP
    qp_tolerance: float = 1.0e-6     # Clarabel's gap and feasibility tolerances
    command_zero: float = 1.0e-5     # m/s, rad/s: smaller commands are sent as exact zeros (solver noise)
    goal_tolerance: float = 0.005    # m: default success radius of go_to_goal (and assembly_to_goal)
    assembly_speed: float = 0.03     # m/s: cruise speed of an assembly led to a goal (assembly_to_goal)
    assembly_turn_rate: float = 0.15  # rad/s: its lead's largest turn rate (a chain turns like a train)
    pose_timeout: float = 0.5        # s: a pose older than this is stale; the robot is stopped
    approach_lookahead: float = 0.04      # m: the approach target leads the opening robot by this along the axis
    approach_standoff_max: float = 0.03   # m: largest standoff of a misaligned anchor pair's approach target
    approach_gain_angle: float = 0.04     # m/rad: standoff per radian of heading error
    approach_gain_lateral: float = 2.0    # m/m: standoff per metre of lateral offset of the head
    knob_standoff: float = _KNOB.standoff    # m: a knob pair's mover comes along its partner's side on a
                                     # lane knob_lane_gap out from it, closes in from knob_standoff behind
                                     # the hole to knob_press inside the side knob_level behind it, and runs
                                     # on straight into the hole (puzzlebot_mpc.knob_approach)
    knob_lane_gap: float = _KNOB.gap         # m
    knob_press: float = _KNOB.press          # m
    knob_level: float = _KNOB.level          # m
    knob_standoff_max: float = _KNOB.standoff_max  # m: longest run a knob pair's mover off its lane backs off for
    knob_speed: float = _KNOB.speed          # m/s: largest speed of a knob pair's mover along the lane ...
    knob_speed_gain: float = _KNOB.speed_gain    # 1/s: ... slowing to the hole at this speed per metre left ...
    knob_creep: float = _KNOB.creep          # m/s: ... but at least this up to the hole ...
    knob_steer_gain: float = _KNOB.steer_gain    # 1/m: ... following the lane with this gain ...
    knob_turn_rate: float = _KNOB.turn_rate  # rad/s: ... turning at most this fast (an assembly: at most
                                     # assembly_turn_rate)
    backoff_clearance: float = 0.01  # m: a knob pair's mover backing off stops this far short of a robot in its
                                     # way; its partner then pulls away from it while this much is clear on its
                                     # side (behaviors/couple.py, Couple.make_room)
    knob_seat_tolerance: float = 0.001   # m: a knob pair is coupled when the knob point is this close to the
                                     # hole point (along the side and across it; the hole's play is
                                     # 0.5 mm) for insert_confirm_steps steps; while a couple runs, a
                                     # coupled one this far off for dock_repair_time is closed again
    pair_epsilon: float = 0.0015     # m: margin of the pair status tests (Algorithm 2)
    pair_lost_margin: float = 0.005  # m: a coupled pair whose head is this far outside its polygon is lost
    insert_lateral_tolerance: float = 0.0007  # m: an anchor pair pushed home is coupled only when C_a is this
                                     # close to the opening's axis ...
    insert_yaw_tolerance: float = 0.1    # rad: ... and the pair's headings agree this well
    insert_confirm_steps: int = 3    # consecutive control steps the head_inserted condition must hold
    insert_timeout: float = 4.0      # s: head_aligned for longer (a jammed anchor): back off, line up again
    hardware_v_max: float = V_MAX    # m/s: the robots' own speed limit (open-loop commands stay within it)
    hardware_w_max: float = W_MAX    # rad/s: the robots' own turn-rate limit
    wiggle_v_bias: float = 0.03      # m/s: forward speed of the anchor robot while it wiggles out
    wiggle_w_amplitude: float = 3.0  # rad/s: wiggle turn rate amplitude (paper: w_max), the turn rate limit of
                                     # the closed-loop swing; sent directly: within the hardware limits, not
                                     # v_max, w_max
    wiggle_period: float = 2.0       # s: wiggle period 2 pi / B
    wiggle_heading_amplitude: float = 0.55  # rad: the wiggle swings the pair's relative heading +-this
                                     # (closed loop on the poses); 0: the paper's open-loop w_max sin(B t)
    wiggle_heading_gain: float = 10.0    # 1/s: feedback gain of that relative-heading swing
    wiggle_cycles: float = 1.0       # wiggle periods per attempt (then the anchor is pushed back in: retry);
                                     # 0.5: one swing to one side per attempt, the next to the other side
    wiggle_alternate: bool = True    # flip the wiggle's sign every period: the heading swings to both sides
                                     # in turn (false: the paper's sin(B t), always to the same side first)
    wiggle_partner_turn: float = 0.0     # the partner (opening robot, when alone) turns the other way at this
                                     # fraction of the anchor robot's wiggle turn rate (0: it holds still)
    decouple_reseat_time: float = 0.5    # s: between attempts the anchor robot backs into its partner for
                                     # this long (0: one endless wiggle, the paper's controller)
    decouple_reseat_speed: float = 0.04  # m/s: ... at this speed (open loop; the anchor goes back in)
    hold_scale: float = 100.0        # rest-weight scale of an assembly a single robot docks onto (holds still)
    decouple_clearance: float = 0.007  # m: decoupled once H_a is this far outside the opening robot (+ eps);
                                     # a pulled anchor slides out of its holder: its tip is then ~6 mm behind H_a
    decouple_creep: float = 0.005    # m/s: the opening robot backs into its own assembly while its partner wiggles
    decouple_settle_speed: float = 0.01  # m/s: after the release both robots push back into their assemblies ...
    decouple_settle_time: float = 1.5    # s: ... for this long (re-seats the neighbours' anchors the wiggle bent)
    decouple_confirm_steps: int = 3  # consecutive control steps the release must be seen
    seed_holder_clearance: float = 0.15  # m: a seed pair's holder only turns (its speed held) while another robot
                                     # stands this close to it, centre to centre (0: it always drives too)
    assembly_seeds: int = 1          # sub-assemblies a couple forms at once in each target (0: every seed
                                     # that can go; pairs.PairBook)
    stage_standoff: float = 0.0      # m: a robot whose goal pair waits for a busy partner drives to where the
                                     # pair's connection points are this far apart, lined up (0: it waits in
                                     # place; behaviors/couple.py)
    assembly_first: str = "knob"     # a target with anchor and knob pairs forms these first: "anchor" (its chains,
                                     # then knob pairs join them side by side) or "knob" (its rows, then anchor
                                     # pairs join them front to back)
    assembly_seed_at: str = "middle"  # where a chain's seed starts: "middle" (it grows at both ends) or "tail"
                                     # (the last pair: every robot that joins backs its anchor in)
    # docking an anchor pair and proving it seated (puzzlebot_mpc/docking.py; dock_* = DockingSettings fields)
    docking: bool = True             # false: Algorithm 2 alone decides that a pair is coupled (the paper)
    dock_push_speed: float = _DOCK.push_speed     # m/s: the mover drives straight into its partner
    dock_push_heading_gain: float = _DOCK.push_heading_gain # 1/s: ... turning to the partner's heading at this gain
    dock_push_start_gap: float = _DOCK.push_start_gap # m: the push starts with the faces this close ...
    dock_push_lateral: float = _DOCK.push_lateral # m: ... C_a this close to the opening's axis ...
    dock_push_yaw: float = _DOCK.push_yaw         # rad: ... and the headings this close
    dock_push_timeout: float = _DOCK.push_timeout # s: not home after this long: back off, approach again
    dock_home_gap: float = _DOCK.home_gap         # m: faces this close: pushed home ...
    dock_home_steps: int = _DOCK.home_steps       # ... on this many control steps in a row
    dock_insert_by_mpc: bool = _DOCK.insert_by_mpc  # the MPC pushes the anchor in; a jam aims the next approach
    dock_pull_test: bool = _DOCK.pull_test        # prove a pair pushed home seated by pulling on it
    dock_pull_speed: float = _DOCK.pull_speed     # m/s: the pull test ...
    dock_pull_time: float = _DOCK.pull_time       # s: ... for this long
    dock_seat_pull_min: float = _DOCK.seat_pull_min # m: a seated pair stretches at least this much under the pull ...
    dock_seat_pull_max: float = _DOCK.seat_pull_max # m: ... and at most this much (anchor_trials seatpull measures it)
    dock_pull_stall: float = _DOCK.pull_stall     # m: the pull has stalled when the gap grew less in a step
    dock_repush_gap: float = _DOCK.repush_gap     # m: ... until the faces are this close (0: none)
    dock_repush_speed: float = _DOCK.repush_speed # m/s: the push home after the pull
    dock_repush_timeout: float = _DOCK.repush_timeout # s: home again after the pull within this, or back off
    dock_backoff_speed: float = _DOCK.backoff_speed # m/s
    dock_aim_step: float = _DOCK.aim_step         # m: after a jammed push, aim the mouth this much to the side ...
    dock_aim_max: float = _DOCK.aim_max           # m: ... up to this far off the partner's axis
    dock_jam_yaw: float = _DOCK.jam_yaw           # rad: the head askew in the mouth by more: no nudge; a jam backs off
    dock_backoff_time: float = _DOCK.backoff_time # s
    dock_stall_time: float = _DOCK.stall_time     # s: an approach no closer in this long: back off, again (0: off)
    dock_stall_progress: float = _DOCK.stall_progress  # m: ... by this much
    dock_insert_stall_time: float = _DOCK.insert_stall_time  # s: the MPC's insertion no deeper in this long: nudge
    dock_insert_stall_progress: float = _DOCK.insert_stall_progress  # m: ... by this much
    dock_nudge_time: float = _DOCK.nudge_time     # s: the nudge drives straight in at dock_push_speed this long
    dock_brace_speed: float = _DOCK.brace_speed   # m/s: ... while the anchor robot's assembly backs into it (0: off)
    dock_brace_gap: float = _DOCK.brace_gap       # m: ... until the faces are this close
    dock_repair_gap: float = _DOCK.repair_gap     # m: a coupled pair with its faces this far apart ...
    dock_repair_time: float = _DOCK.repair_time   # s: ... for this long is re-seated (while a couple runs)
    dock_loop_gap: float = _DOCK.loop_gap         # m: an anchor pair closing a loop is seated with its faces this
                                                  # close, its head through the opening ...
    dock_loop_time: float = _DOCK.loop_time       # s: ... for this long

    def docking_settings(self):
        """The docking manoeuvre's settings (puzzlebot_mpc.docking.DockingSettings), None when ``docking``
        is off."""
        if not self.docking:
            return None
        return DockingSettings(**{f.name: getattr(self, "dock_" + f.name) for f in dc_fields(DockingSettings)})

    def knob_lane(self):
        """The knob pairs' approach lane (puzzlebot_mpc.knob_approach.KnobLane); its look-ahead is the anchor
        approach's."""
        return KnobLane(**{f.name: getattr(self, "knob_" + f.name) for f in dc_fields(KnobLane)
                           if f.name not in ("gap", "lookahead")}, gap=self.knob_lane_gap,
                        lookahead=self.approach_lookahead)

    def seating(self):
        """The pair status tests' lining-up conditions (puzzlebot_mpc.pairs.Seating)."""
        from puzzlebot_mpc.pairs import Seating

        return Seating(self.insert_lateral_tolerance, self.insert_yaw_tolerance, self.insert_confirm_steps,
                       self.insert_timeout, self.knob_seat_tolerance)

    @classmethod
    def from_dict(cls, data, where="mpc"):
        """Validated settings from a mapping; unknown keys raise ConfigError."""
        return from_mapping(cls, data, where)

    def check(self, where="mpc"):
        """Range and cross-field checks; raise ConfigError."""
        require_positive(self, ["dt", "horizon", "constraint_horizon", "v_max", "w_max", "dv_max",
                                "dw_max", "max_iter", "goal_tolerance", "assembly_speed", "assembly_turn_rate", "pose_timeout", "sqp_iterations",
                                "sqp_iterations_cold", "solver_threads", "active_set_iterations", "pair_epsilon",
                                "pair_lost_margin", "knob_standoff", "knob_speed", "knob_speed_gain",
                                "knob_creep", "knob_steer_gain", "knob_turn_rate",
                                "wiggle_period",
                                "wiggle_cycles",
                                "hardware_v_max", "hardware_w_max", "insert_lateral_tolerance",
                                "insert_yaw_tolerance", "insert_confirm_steps", "insert_timeout",
                                "decouple_confirm_steps",
                                "slack_regularisation", "qp_tolerance", "command_zero", "w_slack_pip",
                                "w_slack_butterfly", "w_slack_edge"], where)
        for key in ("w_free", "w_goal_terminal", "w_goal_stage", "w_goal_lateral", "w_velocity", "w_rest",
                    "w_control", "w_pair_terminal_pos", "w_pair_terminal_angle", "w_pair_stage_pos",
                    "w_pair_stage_angle", "w_pair_lateral", "w_coupled_pos", "w_coupled_angle", "pip_margin", "edge_margin",
                    "knob_hold", "knob_hold_step",
                    "wiggle_v_bias", "wiggle_w_amplitude", "decouple_clearance", "decouple_creep",
                    "decouple_settle_speed", "decouple_settle_time", "decouple_reseat_time",
                    "decouple_reseat_speed", "wiggle_heading_amplitude", "wiggle_heading_gain", "wiggle_partner_turn", "hold_scale", "butterfly_lobe_robots",
                    "approach_lookahead", "approach_standoff_max", "approach_gain_angle", "approach_gain_lateral",
                    "seed_holder_clearance", "stage_standoff", "knob_standoff_max", "knob_lane_gap",
                    "knob_press", "knob_level", "knob_seat_tolerance", "backoff_clearance"):
            if getattr(self, key) < 0:
                raise ConfigError("%s.%s: must be >= 0" % (where, key))
        if self.constraint_horizon > self.horizon:
            raise ConfigError("%s.constraint_horizon (%d) must be <= horizon (%d)"
                              % (where, self.constraint_horizon, self.horizon))
        if not self.knob_level < self.knob_standoff:
            raise ConfigError("%s.knob_level (%g m) must be below knob_standoff (%g m): the lane closes in between "
                              "them" % (where, self.knob_level, self.knob_standoff))
        if self.assembly_first not in ("anchor", "knob"):
            raise ConfigError("%s.assembly_first: unknown pair type %r; known: anchor, knob"
                              % (where, self.assembly_first))
        if self.assembly_seed_at not in ("middle", "tail"):
            raise ConfigError("%s.assembly_seed_at: unknown place %r; known: middle, tail"
                              % (where, self.assembly_seed_at))
        if self.solver not in ("active_set", "clarabel", "ipopt"):
            raise ConfigError("%s.solver: unknown solver %r; known: active_set, clarabel, ipopt"
                              % (where, self.solver))
        if self.decouple_creep > self.v_max or self.decouple_settle_speed > self.v_max:
            raise ConfigError("%s: decouple_creep and decouple_settle_speed must be <= v_max (%.3f m/s)"
                              % (where, self.v_max))
        if self.v_max > self.hardware_v_max or self.w_max > self.hardware_w_max:
            raise ConfigError("%s: v_max, w_max (%.3f m/s, %.2f rad/s) exceed the hardware limits "
                              "hardware_v_max, hardware_w_max (%.3f m/s, %.2f rad/s)"
                              % (where, self.v_max, self.w_max, self.hardware_v_max, self.hardware_w_max))
        if self.wiggle_partner_turn > 1.0:
            raise ConfigError("%s.wiggle_partner_turn (%g) must be within [0, 1]: a fraction of the anchor "
                              "robot's wiggle turn rate" % (where, self.wiggle_partner_turn))
        if self.docking:
            self.docking_settings().check(where)
        if self.decouple_reseat_speed > self.hardware_v_max:
            raise ConfigError("%s.decouple_reseat_speed (%.3f m/s) exceeds hardware_v_max (%.3f m/s)"
                              % (where, self.decouple_reseat_speed, self.hardware_v_max))
        if self.wiggle_v_bias > self.hardware_v_max or self.wiggle_w_amplitude > self.hardware_w_max:
            raise ConfigError("%s: the wiggle (%.3f m/s, %.2f rad/s) exceeds the hardware limits "
                              "hardware_v_max, hardware_w_max (%.3f m/s, %.2f rad/s)"
                              % (where, self.wiggle_v_bias, self.wiggle_w_amplitude, self.hardware_v_max,
                                 self.hardware_w_max))
