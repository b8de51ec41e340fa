"""Behaviour requests: validation, per-step objectives, progress status.

One behaviour runs at a time; it names the robots it drives and every other
robot is brought to rest. Requests are validated completely before they
replace the running behaviour, so a bad request changes nothing (robots at
rest stay at rest). Coupled pairs are kept by the MPC's polygon constraints
whatever the behaviour.

Behaviours:

- ``go_to_goal``, ``follow_velocity``, ``stop``;
- ``couple``: the robots form a target configuration (Algorithm 3: goal
  pairs from the target and the start poses, conflict-free active pairs,
  Algorithm 2 status updates). Succeeds when every goal pair is coupled;
- ``decouple``: the named coupled anchor pair separates. Phase *wiggle*: the
  anchor robot a receives the paper's wiggle open loop,
  ``v = wiggle_v_bias, w = wiggle_w_amplitude sin(2 pi t / wiggle_period)``
  (eq. "wiggle"; outside the MPC's own limits and butterfly set, within the
  hardware limits), in attempts: when a period did not free the anchor, a
  backs into o for a moment (the anchor goes back in) and wiggles again, to
  the other side first (:func:`wiggle`); the MPC drives the robots coupled
  to a straight on at a's speed (so they neither pull on a's front nor turn
  with it), the opening robot o creeps back into its own assembly
  at ``decouple_creep`` and the rest of o's assembly holds; an o that is not
  coupled to other robots turns in place against a's swing instead
  (:func:`partner_turn`, ``wiggle_partner_turn``). Released when, from the measured poses, a's anchor point C_a is
  farther than anchor_length + ``decouple_clearance`` + eps from o's opening
  point C_o on ``decouple_confirm_steps`` steps in a row: an anchor that
  slides out of its holder and turns in it cannot reach into the opening
  from there (the head point H_a alone is not enough: when a turns against
  o, H_a leaves o's footprint sideways while the anchor, free to turn in its
  holder, is still in).
  Phase *settle* (``decouple_settle_time``): a and o push back into their own
  assemblies at ``decouple_settle_speed`` (away from each other; a robot
  without an assembly rests), which straightens and re-seats the anchors the
  wiggle bent; then it succeeds;
- ``drive_assembly``: the assembly of the named robots drives as one body
  with twist (v, w) given in the first robot's frame: the first robot
  tracks (v, w), every other member the rigid-body speed at its own position
  along its heading, turning as its couplings allow (a chain of unicycles
  turns like a train, within the anchors' yaw freedom). Succeeds after ``distance``
  metres (or after ``timeout`` seconds when no distance is given); fails if
  a coupled pair of the assembly is lost on the way.
"""

import math
from dataclasses import dataclass, field
from typing import List, Sequence, Tuple

import numpy as np

from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.controller import Objectives, PairObjective
from puzzlebot_mpc.targets import TargetError, assign, resolve_target

GO_TO_GOAL = "go_to_goal"
FOLLOW_VELOCITY = "follow_velocity"
STOP = "stop"
COUPLE = "couple"
DECOUPLE = "decouple"
DRIVE_ASSEMBLY = "drive_assembly"
BEHAVIORS = (GO_TO_GOAL, FOLLOW_VELOCITY, STOP, COUPLE, DECOUPLE, DRIVE_ASSEMBLY)

# Behaviour states; same values as puzzlebot_msgs/BehaviorStatus.
IDLE, RUNNING, SUCCEEDED, FAILED = 0, 1, 2, 3
STATE_NAMES = {IDLE: "idle", RUNNING: "running", SUCCEEDED: "succeeded", FAILED: "failed"}


class BehaviorError(ValueError):
    """A behaviour request was refused; the message says why."""


@dataclass
class BehaviorRequest:
    behavior: str
    robots: Sequence[str] = ()                     # empty: all robots
    goals: Sequence[Tuple[float, float]] = ()      # go_to_goal, world frame [m]
    velocities: Sequence[Tuple[float, float]] = ()  # follow_velocity: per robot; drive_assembly: one twist
    tolerance: float = 0.0                         # [m], 0 = default
    timeout: float = 0.0                           # [s], 0 = none; follow_velocity: duration
    target: str = ""                               # couple: target name
    slots: Sequence[Tuple[float, float, float]] = ()  # couple: explicit slots (assembly frame)
    pair: Sequence[str] = ()                       # decouple: the two robots
    distance: float = 0.0                          # drive_assembly: metres to drive (0: for timeout s)
    # Scheduling (ControlLoop.request): when the behaviour starts.
    queue: bool = False          # start once the running behaviour and those queued before it have ended
                                 # (dropped if one of them fails); False: replace the running one now
    start_time: float = 0.0      # [s] ROS time: start at the first control step at or after it; 0 = at once


@dataclass
class BehaviorStatus:
    request_id: int
    behavior: str
    state: int
    message: str
    robots: List[str] = field(default_factory=list)
    errors: List[float] = field(default_factory=list)   # per robot; go_to_goal: distance [m]


def wiggle(settings, t, relative_heading=None):
    """The anchor robot's command (v [m/s], w [rad/s], phase) ``t`` seconds into a decouple.

    Attempts follow each other: ``wiggle_cycles`` periods of wiggling (phase
    "wiggle"; the sign flips every period with ``wiggle_alternate``: the
    heading swings to both sides in turn; with less than one period per
    attempt, e.g. 0.5: one swing, the sign flips every attempt), then ``decouple_reseat_time`` s
    backing into the partner at ``decouple_reseat_speed`` (phase "reseat": an
    anchor caught half out with both barbs flared goes back in, and the next
    attempt starts afresh). ``decouple_reseat_time`` 0: one endless wiggle.

    The wiggle is the paper's ``(v_bias, +-w_max sin(B tau))`` (B = 2 pi /
    wiggle_period) when ``wiggle_heading_amplitude`` is 0 or the relative
    heading is unknown. Otherwise it swings the *relative* heading of the pair
    (``relative_heading`` [rad], anchor robot minus partner, from the poses)
    along ``A sin(B tau)``, A = wiggle_heading_amplitude: ``w = A B cos(B tau)
    + k (A sin(B tau) - relative_heading)`` limited to +-w_max, k =
    wiggle_heading_gain. The open-loop wiggle keeps turning when the anchor
    blocks the turn and then over-rotates on the way back (in the simulation
    the anchor flips round in its holder); the closed-loop one turns the
    anchor just past its holder's play, where one barb takes the pull.
    """
    s = settings
    wiggling = s.wiggle_period * s.wiggle_cycles
    attempt = wiggling + s.decouple_reseat_time
    k = int(math.floor(t / attempt)) if s.decouple_reseat_time > 0 else 0
    tau = t - k * attempt
    if tau >= wiggling:
        return -s.decouple_reseat_speed, 0.0, "reseat"
    if s.wiggle_cycles < 1.0:       # part of a period per attempt: the side alternates from attempt to attempt
        cycle = k
    else:
        cycle = int(round(k * s.wiggle_cycles)) + int(math.floor(tau / s.wiggle_period))
    sign = -1.0 if s.wiggle_alternate and cycle % 2 else 1.0
    b = 2 * math.pi / s.wiggle_period
    if s.wiggle_heading_amplitude > 0 and relative_heading is not None:
        a = sign * s.wiggle_heading_amplitude
        w = a * b * math.cos(b * tau) + s.wiggle_heading_gain * (a * math.sin(b * tau) - relative_heading)
        return s.wiggle_v_bias, max(-s.wiggle_w_amplitude, min(s.wiggle_w_amplitude, w)), "wiggle"
    return s.wiggle_v_bias, sign * s.wiggle_w_amplitude * math.sin(b * tau), "wiggle"


def partner_turn(settings, w, phase, partner_assembly_size):
    """The partner's (opening robot's) turn rate [rad/s] while the anchor robot wiggles at ``w``, or None.

    During a swing (phase "wiggle") a partner that is not coupled to other
    robots turns the other way at ``wiggle_partner_turn`` times the anchor
    robot's rate, in place: the pair's relative heading then swings on the
    torque of both robots' wheels, not on the anchor robot's alone, and the
    barb caught behind its lip is loaded past its snap-through instead of
    dragging the partner round (docs/mpc.md, "decouple"). None (the MPC
    drives the partner as before) between swings, with the setting at 0 and
    for a partner in an assembly: turning it in place would twist its other
    couplings.
    """
    if phase != "wiggle" or settings.wiggle_partner_turn <= 0 or partner_assembly_size > 1:
        return None
    return -settings.wiggle_partner_turn * w


def _finite(values):
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values)


class BehaviorManager:
    """Holds the running behaviour and turns it into MPC objectives each step.

    ``pairbook`` (pairs.PairBook) holds the coupled pairs; ``targets`` maps
    names to targets.Target (from config/targets.yaml).
    """

    def __init__(self, robot_names, settings, geometry=None, pairbook=None, targets=None):
        from puzzlebot_common.geometry import RobotGeometry

        self.names = list(robot_names)
        self.index = {name: i for i, name in enumerate(self.names)}
        self.settings = settings
        self.geometry = geometry or RobotGeometry()
        self.pairs = pairbook or pr.PairBook(self.geometry, settings.pair_epsilon, settings.pair_lost_margin,
                                             settings.seating())
        self.targets = dict(targets or {})
        self._request_id = 0             # id of the current behaviour
        self._last_id = 0                # last id handed out (requests queued in ControlLoop get theirs early)
        self._req = BehaviorRequest(STOP)
        self._robots = []
        self._start = None
        self._state = IDLE
        self._message = "no behaviour requested yet"
        self._static = Objectives.stop_all(len(self.names))
        self._decoupling = None          # pair being decoupled
        self._released_at = None         # decouple: time the pair separated (settle phase from then on)
        self._release_count = 0          # decouple: consecutive steps the release was seen
        self._o_side = []                # decouple: the opening robot's assembly
        self._assembly = []              # drive_assembly / decouple followers
        self._start_pose = None
        self._assignment = None
        self._last_progress = ""

    # ------------------------------------------------------------- requests
    def validate(self, req):
        """The checks that do not depend on the robots' state (names, numbers, targets, limits): the
        robots the request applies to, or BehaviorError. A request queued for later passes these when
        queued and the rest when it starts."""
        return self._check(req, None)[0]

    def new_id(self):
        """A fresh request id (ids increase by one per accepted or queued request)."""
        self._last_id += 1
        return self._last_id

    @property
    def state(self):
        """IDLE, RUNNING, SUCCEEDED or FAILED: the current behaviour's state."""
        return self._state

    @property
    def request_id(self):
        """The current behaviour's request id (0 before the first request)."""
        return self._request_id

    def refuse(self, request_id, req, message):
        """Report request ``request_id`` (queued, now due) as FAILED with ``message``; the robots rest."""
        self._req, self._robots, self._request_id = req, list(req.robots), request_id
        self._state, self._message = FAILED, message
        self._rest()

    def note(self, text):
        """Append ``text`` to the current status message (e.g. queued requests dropped)."""
        self._message += text

    def _check(self, req, poses):
        """(robots, couple assignment or decouple pair or None), or raise BehaviorError."""
        extra = None
        if req.behavior not in BEHAVIORS:
            raise BehaviorError("unknown behaviour %r; known: %s" % (req.behavior, ", ".join(BEHAVIORS)))
        robots = list(req.robots) or list(self.names)
        unknown = [r for r in robots if r not in self.index]
        if unknown:
            raise BehaviorError("unknown robot(s) %s; known: %s"
                                % (", ".join(map(repr, unknown)), ", ".join(self.names)))
        if len(set(robots)) != len(robots):
            raise BehaviorError("a robot is named twice in %s" % robots)
        if not _finite([req.tolerance, req.timeout, req.distance]) or min(req.tolerance, req.timeout,
                                                                           req.distance) < 0:
            raise BehaviorError("tolerance, timeout and distance must be finite and >= 0 (got %r, %r, %r)"
                                % (req.tolerance, req.timeout, req.distance))
        if req.behavior == GO_TO_GOAL:
            if len(req.goals) != len(robots):
                raise BehaviorError("go_to_goal needs one goal per robot: %d robot(s), %d goal(s)"
                                    % (len(robots), len(req.goals)))
            for name, goal in zip(robots, req.goals):
                if len(goal) != 2 or not _finite(goal):
                    raise BehaviorError("goal for %s is not a finite (x, y): %r" % (name, tuple(goal)))
        if req.behavior == FOLLOW_VELOCITY:
            if len(req.velocities) != len(robots):
                raise BehaviorError("follow_velocity needs one velocity per robot: %d robot(s), %d velocity(ies)"
                                    % (len(robots), len(req.velocities)))
            for name, vel in zip(robots, req.velocities):
                self._check_velocity(name, vel)
        if req.behavior == COUPLE:
            extra = self._validate_couple(req, robots, poses)[1]
        if req.behavior == DECOUPLE:
            extra = self._validate_decouple(req, poses)
        if req.behavior == DRIVE_ASSEMBLY:
            if len(req.velocities) != 1:
                raise BehaviorError("drive_assembly needs exactly one velocity (the assembly's twist in the "
                                    "first robot's frame), got %d" % len(req.velocities))
            self._check_velocity(robots[0], req.velocities[0])
            if req.distance <= 0 and req.timeout <= 0:
                raise BehaviorError("drive_assembly needs a distance or a timeout (duration) > 0")
            if req.distance > 0 and abs(req.velocities[0][0]) < 1e-6:
                raise BehaviorError("drive_assembly: a distance needs a non-zero linear velocity")
            self._need_poses(robots[:1], poses, "drive_assembly")
        return robots, extra

    def _check_velocity(self, name, vel):
        s = self.settings
        if len(vel) != 2 or not _finite(vel):
            raise BehaviorError("velocity for %s is not a finite (v, w): %r" % (name, tuple(vel)))
        if abs(vel[0]) > s.v_max + 1e-12 or abs(vel[1]) > s.w_max + 1e-12:
            raise BehaviorError("velocity for %s (%.3f m/s, %.3f rad/s) exceeds the limits "
                                "v_max %.3f m/s, w_max %.3f rad/s" % (name, vel[0], vel[1], s.v_max, s.w_max))

    def _need_poses(self, robots, poses, what):
        if poses is None:
            return
        missing = [r for r in robots if poses.get(r) is None or not _finite(poses[r])]
        if missing:
            raise BehaviorError("%s: no fresh, finite pose for %s; the robots stay as they are"
                                % (what, ", ".join(missing)))

    def _validate_couple(self, req, robots, poses):
        if req.slots and not all(len(sl) == 3 and _finite(sl) for sl in req.slots):
            raise BehaviorError("couple: every slot must be a finite (x, y, heading)")
        try:
            target = resolve_target(req.target, [tuple(sl) for sl in req.slots], len(robots), self.targets,
                                    self.geometry)
        except TargetError as e:
            raise BehaviorError("couple: %s" % e)
        if len(target.slots) > len(robots):
            raise BehaviorError("couple: target %r has %d slots but only %d robot(s) were given"
                                % (target.name, len(target.slots), len(robots)))
        if len(target.slots) < len(robots):
            raise BehaviorError("couple: target %r has %d slots for %d robots; name the robots to use"
                                % (target.name, len(target.slots), len(robots)))
        self._need_poses(robots, poses, "couple")
        if poses is None:
            return target, None
        for p in self.pairs.coupled.values():
            inside = [r in robots for r in p.robots]
            if any(inside) and not all(inside):
                raise BehaviorError("couple: %s is coupled to %s, which is not in the request; decouple it first "
                                    "or include it" % tuple(p.robots if inside[0] else p.robots[::-1]))
        try:
            assignment = assign(target, robots, np.array([poses[r] for r in robots], float), self.geometry)
        except TargetError as e:
            raise BehaviorError("couple: %s" % e)
        goal_keys = {p.key for p in assignment.pairs}
        for p in self.pairs.coupled.values():
            if p.robot_i in robots and p.key not in goal_keys:
                raise BehaviorError("couple: %s and %s are coupled but the target assignment does not join "
                                    "them that way; decouple them first" % p.robots)
        return target, assignment

    def _validate_decouple(self, req, poses):
        if len(req.pair) != 2:
            raise BehaviorError("decouple needs the pair's two robots, got %r" % (list(req.pair),))
        unknown = [r for r in req.pair if r not in self.index]
        if unknown:
            raise BehaviorError("decouple: unknown robot(s) %s" % ", ".join(map(repr, unknown)))
        if poses is None:               # validate(): whether they are coupled is checked when it starts
            return None
        pair = self.pairs.find(*req.pair)
        if pair is None or pair.key not in self.pairs.coupled:
            raise BehaviorError("decouple: %s and %s are not coupled; coupled pairs: %s"
                                % (req.pair[0], req.pair[1],
                                   ", ".join("%s-%s" % p.robots for p in self.pairs.coupled.values()) or "none"))
        if pair.type != pr.ANCHOR:
            raise BehaviorError("decouple: %s-%s is a knob-hole coupling (rigid); only anchor pairs are "
                                "decoupled by wiggling" % pair.robots)
        others = [p for p in self.pairs.coupled.values() if p.key != pair.key]
        if pair.robot_j in pr.assembly_of(pair.robot_i, self.names, others):
            raise BehaviorError("decouple: %s and %s are also coupled through other robots; the pair cannot "
                                "separate on its own" % pair.robots)
        self._need_poses(list(req.pair), poses, "decouple")
        return pair

    def request(self, req, now, poses=None, request_id=None):
        """Validate and start a behaviour at time ``now`` [s]; return its id.

        ``poses``: name -> (x, y, theta) or None; needed by couple, decouple
        and drive_assembly (a missing pose refuses those requests).
        ``request_id``: the id handed out when the request was queued (None: a new one).
        """
        if req.behavior in (COUPLE, DECOUPLE, DRIVE_ASSEMBLY) and poses is None:
            raise BehaviorError("%s needs the robots' current poses" % req.behavior)
        robots, extra = self._check(req, poses)
        n = len(self.names)
        obj = Objectives.stop_all(n)
        obj.velocity_mask = obj.velocity_mask.astype(float)
        assignment = extra if req.behavior == COUPLE else None
        decoupling = extra if req.behavior == DECOUPLE else None
        if req.behavior == GO_TO_GOAL:
            for k, name in enumerate(robots):
                i = self.index[name]
                obj.goal[i] = req.goals[k]
                obj.goal_mask[i] = True
                obj.velocity_mask[i] = False
        elif req.behavior == FOLLOW_VELOCITY:
            for k, name in enumerate(robots):
                obj.velocity[self.index[name]] = req.velocities[k]
        # accepted: replace the running behaviour
        self._finish_decouple(poses)
        self.pairs.clear_goals()
        self._request_id = self.new_id() if request_id is None else request_id
        self._req, self._robots, self._start = req, robots, now
        self._static = obj
        self._assignment = assignment
        self._decoupling = None
        self._assembly = []
        self._start_pose = None
        self._state, self._message = RUNNING, "started"
        if assignment is not None:
            self.pairs.set_goals(assignment.pairs, assignment.priority)
            self._message = "goal pairs: " + ", ".join("%s->%s" % p.key for p in assignment.pairs)
        if decoupling is not None:
            self.pairs.remove_coupled(decoupling.key)
            decoupling.status = pr.HEAD_INSERTED
            self._decoupling = decoupling
            self._released_at = None
            self._release_count = 0
            self._robots = list(decoupling.robots)
            coupled = self.pairs.coupled.values()
            self._assembly = pr.assembly_of(decoupling.robot_i, self.names, coupled)
            self._o_side = pr.assembly_of(decoupling.robot_j, self.names, coupled)
        if req.behavior == DRIVE_ASSEMBLY:
            group = set()
            for r in robots:
                group.update(pr.assembly_of(r, self.names, self.pairs.coupled.values()))
            self._assembly = [n for n in self.names if n in group]
            self._robots = self._assembly
            lead = poses[robots[0]]
            self._start_pose = (robots[0], np.array(lead, float))
        return self._request_id

    def _finish_decouple(self, poses=None):
        """A decouple that ends (or is replaced) leaves its pair coupled if it still is geometrically."""
        d = self._decoupling
        if d is None:
            return
        self._decoupling = None
        if poses is not None and self._decoupled(d, poses) is False:
            self.pairs.add_coupled(d)

    def _separation(self, pair, poses):
        """Distance [m] between a's anchor point C_a and o's opening point C_o (None: no pose)."""
        pi, pj = poses.get(pair.robot_i), poses.get(pair.robot_j)
        if pi is None or pj is None:
            return None
        return pr.alignment_error(pair, pi, pj)[0]

    def _decoupled(self, pair, poses):
        """True when C_a is farther than anchor_length + decouple_clearance + eps from C_o (None: no pose)."""
        d = self._separation(pair, poses)
        if d is None:
            return None
        s = self.settings
        return d > self.geometry.anchor_length + s.decouple_clearance + s.pair_epsilon

    def coupling(self):
        """True while a couple behaviour runs (active pairs are assigned every step)."""
        return self._state == RUNNING and self._req.behavior == COUPLE

    # ----------------------------------------------------------- objectives
    def pair_slots(self):
        """Pairs that get a slot in the MPC this step: coupled, goals, the one being decoupled."""
        slots = self.pairs.all_pairs()
        if self._decoupling is not None:
            slots.append(self._decoupling)
        return slots

    def objectives(self, now=None, poses=None):
        """Objectives for this step (poses: name -> (x, y, theta) or None)."""
        s, n = self.settings, len(self.names)
        base = self._static
        mask = np.asarray(base.velocity_mask, float)
        obj = Objectives(base.goal.copy(), base.goal_mask.copy(), base.velocity.copy(),
                         np.repeat(mask[:, None], 2, axis=1) if mask.ndim == 1 else mask.copy())
        if self._state == RUNNING and self._req.behavior == COUPLE:
            self._couple_objectives(obj)
        elif self._state == RUNNING and self._req.behavior == DECOUPLE and self._decoupling is not None:
            self._decouple_objectives(obj, now, poses)
        elif self._state == RUNNING and self._req.behavior == DRIVE_ASSEMBLY and poses is not None:
            obj.velocity = self._assembly_velocities(poses)
            leads = set(self._req.robots[:1])
            for m in self._assembly:          # followers: the rigid-body speed, turn as the couplings allow
                if m not in leads:
                    obj.velocity_mask[self.index[m]] = (1.0, 0.0)
        active = {p.key for p in self.pairs.active}
        for p in self.pair_slots():
            coupled = p.key in self.pairs.coupled
            pi, pj = pr.alignment_points(p, poses.get(p.robot_i) if poses else None,
                                         poses.get(p.robot_j) if poses else None,
                                         (s.approach_lookahead, s.approach_standoff_max, s.approach_gain_angle,
                                          s.approach_gain_lateral), mover=self._mover(p))
            obj.pairs.append(PairObjective(self.index[p.robot_i], self.index[p.robot_j], pi, pj,
                                           active=p.key in active and not coupled, coupled=coupled,
                                           head=p.head, polygon=pr.coupling_polygon(p, self.geometry),
                                           yaw_limit=pr.yaw_limit(p, self.geometry)))
        return obj

    def _mover(self, pair):
        """"i" or "j": the robot of an active pair that docks (the smaller assembly; the opening robot on a tie)."""
        coupled = self.pairs.coupled.values()
        size_i = len(pr.assembly_of(pair.robot_i, self.names, coupled))
        size_j = len(pr.assembly_of(pair.robot_j, self.names, coupled))
        return "i" if size_i < size_j else "j"

    def _couple_objectives(self, obj):
        """The single robot of an active pair docks (no rest cost); the assembly it joins holds still
        (rest cost scaled by hold_scale), so the docking robot aligns with a target that does not move.

        The seed pair (two single robots) lines up with both robots moving;
        once its anchor head is in the opening (head_aligned) the robot that
        is not the mover holds still while the mover pushes the anchor home
        (otherwise the partner gives way and the pair drives off together,
        into the robots around it).
        """
        hold = math.sqrt(self.settings.hold_scale)
        for p in self.pairs.active:
            sizes = [len(pr.assembly_of(r, self.names, self.pairs.coupled.values())) for r in p.robots]
            seed_pushing = sizes == [1, 1] and p.status == pr.HEAD_ALIGNED
            holder = p.robot_j if self._mover(p) == "i" else p.robot_i
            for r, size in zip(p.robots, sizes):
                if size == 1:
                    obj.velocity_mask[self.index[r]] = hold if seed_pushing and r == holder else 0.0
                else:
                    for m in pr.assembly_of(r, self.names, self.pairs.coupled.values()):
                        obj.velocity_mask[self.index[m]] = hold

    def _decouple_objectives(self, obj, now, poses=None):
        """Wiggle phase: a wiggles open loop, its assembly drives straight on at v_bias, o creeps back into
        its assembly, which holds. Settle phase: a and o push back into their assemblies, which hold."""
        s, d = self.settings, self._decoupling
        a, o = self.index[d.robot_i], self.index[d.robot_j]
        hold = math.sqrt(s.hold_scale)
        for m in self._assembly + self._o_side:
            obj.velocity_mask[self.index[m]] = hold
        # a robot pushes back into its own assembly only when it has one (alone, it would only drag its partner)
        a_push = s.decouple_settle_speed if len(self._assembly) > 1 else 0.0
        o_push = s.decouple_settle_speed if len(self._o_side) > 1 else 0.0
        if self._released_at is None:
            obj.velocity = self._wiggle_profile(now)
            v, w, phase = self._wiggle(now, poses)
            obj.open_loop[a] = (v, w)
            for m in self._assembly:       # a's partners in front go along straight (back in while it reseats)
                if m != d.robot_i:
                    obj.velocity[self.index[m]] = (v, 0.0)
                    obj.velocity_mask[self.index[m]] = 1.0
            obj.velocity[o] = (-s.decouple_creep if o_push else 0.0, 0.0)
            w_o = partner_turn(s, w, phase, len(self._o_side))
            if w_o is not None:
                obj.open_loop[o] = (0.0, w_o)
        else:
            obj.velocity[a] = (a_push, 0.0)
            obj.velocity[o] = (-o_push, 0.0)
        obj.velocity_mask[a] = obj.velocity_mask[o] = 1.0

    def wiggle_command(self, now, poses=None):
        """The paper's wiggle (eq. "wiggle") at time ``now`` [s]: (v_bias, w_max sin(B t)), t since the
        decouple request, B = 2 pi / period. Sent open loop to the anchor robot (see :func:`wiggle`).

        With ``wiggle_alternate`` the sign flips every period (w stays continuous: sin is zero there),
        so the heading swings to both sides in turn instead of always to the same side.
        """
        return self._wiggle(now, poses)[:2]

    def _wiggle(self, now, poses):
        d = self._decoupling
        pi, pj = (poses.get(d.robot_i), poses.get(d.robot_j)) if poses else (None, None)
        rel = None if pi is None or pj is None else math.remainder(pi[2] - pj[2], 2 * math.pi)
        return wiggle(self.settings, (now if now is not None else self._start) - self._start, rel)

    def _wiggle_profile(self, now):
        """The wiggle over the horizon, within the MPC's own limits: the MPC's prediction of the anchor
        robot (its partners react to it), while the robot itself receives :meth:`wiggle_command`."""
        s, h, n = self.settings, self.settings.horizon, len(self.names)
        vel = np.zeros((n, h, 2))
        d = self._decoupling
        i = self.index[d.robot_i]
        t = (now if now is not None else self._start) - self._start
        j = self.index[d.robot_j]
        for k in range(h):
            v, w, phase = wiggle(s, t + s.dt * (k + 1))
            vel[i, k] = (float(np.clip(v, -s.v_max, s.v_max)), float(np.clip(w, -s.w_max, s.w_max)))
            w_o = partner_turn(s, w, phase, len(self._o_side))
            if w_o is not None:
                vel[j, k] = (0.0, float(np.clip(w_o, -s.w_max, s.w_max)))
        return vel

    def _assembly_velocities(self, poses):
        s, n = self.settings, len(self.names)
        vel = np.zeros((n, 2))
        lead_name = self._req.robots[0] if self._req.robots else self._assembly[0]
        lead = poses.get(lead_name)
        if lead is None:
            return vel
        v, w = self._req.velocities[0]
        c, sn = math.cos(lead[2]), math.sin(lead[2])
        for m in self._assembly:
            pm = poses.get(m)
            if pm is None:
                continue
            rx, ry = pm[0] - lead[0], pm[1] - lead[1]
            vx, vy = v * c - w * ry, v * sn + w * rx
            vm = vx * math.cos(pm[2]) + vy * math.sin(pm[2])
            vel[self.index[m]] = (float(np.clip(vm, -s.v_max, s.v_max)), w)
        return vel

    # --------------------------------------------------------------- status
    def update(self, now, poses, newly=(), lost=()):
        """Advance the behaviour's state given ``poses`` (name -> (x, y, theta) or None).

        ``newly``/``lost``: pairs that were just coupled / lost this step
        (from PairBook.update), for the couple and drive_assembly checks.
        """
        req = self._req
        errors = []
        if req.behavior == GO_TO_GOAL:
            for name in self._robots:
                pose = poses.get(name)
                goal = self._static.goal[self.index[name]]
                errors.append(float("nan") if pose is None else math.hypot(pose[0] - goal[0], pose[1] - goal[1]))
        if self._state == RUNNING:
            elapsed = now - self._start
            tol = req.tolerance or self.settings.goal_tolerance
            if req.behavior == STOP:
                self._succeed("stopped")
            elif req.behavior == GO_TO_GOAL and errors and all(e <= tol for e in errors):
                self._succeed("all %d robot(s) within %.1f mm of their goals after %.2f s"
                              % (len(errors), 1e3 * tol, elapsed))
            elif req.behavior == COUPLE:
                self._requeue_lost(lost)
                errors = self._couple_status(now, poses, newly, elapsed)
            elif req.behavior == DECOUPLE:
                errors = self._decouple_status(now, poses, elapsed)
            elif req.behavior == DRIVE_ASSEMBLY:
                errors = self._drive_status(poses, lost, elapsed)
            if self._state == RUNNING and req.timeout and elapsed >= req.timeout:
                if req.behavior == FOLLOW_VELOCITY:
                    self._succeed("followed the velocity for %.2f s" % elapsed)
                elif req.behavior == DRIVE_ASSEMBLY and req.distance <= 0:
                    self._succeed("drove the assembly %s for %.2f s with every pair coupled"
                                  % ("+".join(self._assembly), elapsed))
                else:
                    self._fail_timeout(poses, errors, elapsed)
        return BehaviorStatus(self._request_id, req.behavior, self._state, self._message,
                              list(self._robots), errors)

    def _succeed(self, message):
        self._state, self._message = SUCCEEDED, message
        self._rest()

    def _rest(self):
        self._static = Objectives.stop_all(len(self.names))
        self.pairs.clear_goals()

    def _fail_timeout(self, poses, errors, elapsed):
        req = self._req
        if req.behavior == GO_TO_GOAL:
            tol = req.tolerance or self.settings.goal_tolerance
            far = [n for n, e in zip(self._robots, errors) if not e <= tol]
            msg = "timeout after %.2f s; not at goal: %s" % (elapsed, ", ".join(far))
        elif req.behavior == COUPLE:
            msg = "timeout after %.2f s; not coupled: %s" % (
                elapsed, ", ".join(p.describe() for p in self.pairs.goals))
        elif req.behavior == DECOUPLE:
            msg = "timeout after %.2f s; %s-%s still coupled" % ((elapsed,) + tuple(self._robots))
            self._finish_decouple(poses)
        else:
            msg = "timeout after %.2f s: %s" % (elapsed, self._last_progress)
        self._state, self._message = FAILED, msg
        self._rest()

    def _requeue_lost(self, lost):
        """A goal pair lost on the way (pulled apart) is a goal again."""
        keys = {p.key for p in self._assignment.pairs} if self._assignment else set()
        for p in lost:
            if p.key in keys and p not in self.pairs.goals:
                p.status = pr.DECOUPLED
                self.pairs.goals.append(p)

    def _couple_status(self, now, poses, newly, elapsed):
        goals = self.pairs.goals
        errors = []
        for p in self._assignment.pairs if self._assignment else []:
            pi, pj = poses.get(p.robot_i), poses.get(p.robot_j)
            errors.append(float("nan") if pi is None or pj is None else pr.alignment_error(p, pi, pj)[0])
        if not goals:
            self._succeed("all %d pair(s) coupled after %.2f s: %s" % (
                len(self._assignment.pairs), elapsed, ", ".join("%s->%s" % p.key for p in self._assignment.pairs)))
        else:
            self._message = "%d of %d pair(s) coupled; active: %s" % (
                len(self._assignment.pairs) - len(goals), len(self._assignment.pairs),
                ", ".join(p.describe() for p in self.pairs.active) or "none")
        return errors

    def _decouple_status(self, now, poses, elapsed):
        d = self._decoupling
        if d is None:
            return []
        pi, pj = poses.get(d.robot_i), poses.get(d.robot_j)
        if pi is None or pj is None:
            return [float("nan")]
        margin = pr.head_margin(d, pi, pj, self.geometry.footprint())
        sep = self._separation(d, poses)
        if self._released_at is None:
            self._release_count = self._release_count + 1 if self._decoupled(d, poses) else 0
            if self._release_count >= self.settings.decouple_confirm_steps:
                self._released_at = now
                d.status = pr.DECOUPLED
                self._release_message = "%s-%s decoupled after %.2f s (C_a %.1f mm from C_o, anchor head " \
                    "%.1f mm outside %s)" % (d.robot_i, d.robot_j, elapsed, 1e3 * sep, -1e3 * margin, d.robot_j)
        if self._released_at is None:
            self._message = "wiggling %s out of %s (C_a %.1f mm from C_o)" % (d.robot_i, d.robot_j, 1e3 * sep)
        elif now - self._released_at >= self.settings.decouple_settle_time - 1e-9:
            self._decoupling = None
            self._succeed(self._release_message + "; assemblies settled")
        else:
            self._message = self._release_message + "; settling"
        return [-margin]

    def _drive_status(self, poses, lost, elapsed):
        name, start = self._start_pose
        pose = poses.get(name)
        member_lost = [p for p in lost if p.robot_i in self._assembly]
        if member_lost:
            self._state = FAILED
            self._message = "pair(s) lost while driving: %s" % ", ".join("%s-%s" % p.robots for p in member_lost)
            self._rest()
            return []
        if pose is None:
            return [float("nan")]
        moved = math.hypot(pose[0] - start[0], pose[1] - start[1])
        self._last_progress = "the assembly moved %.3f m" % moved
        if self._req.distance > 0 and moved >= self._req.distance:
            self._succeed("the assembly %s drove %.3f m in %.2f s with every pair coupled"
                          % ("+".join(self._assembly), moved, elapsed))
        else:
            self._message = "driving: %.3f m" % moved
        return [moved]

    # -------------------------------------------------------------- display
    def display_objectives(self):
        """What the current (or last) behaviour was asked, for displays (rviz) and tools.

        Kept after the behaviour ends, so a finished run still shows its goals
        and target. ``slots``: the couple assignment's slots as placed (world
        frame); the MPC aligns pairs, not slot positions, so only the slots'
        relative poses are targets.
        """
        req, a = self._req, self._assignment
        goals = [(n, tuple(g)) for n, g in zip(self._robots, req.goals)] if req.behavior == GO_TO_GOAL else []
        slots = []
        if req.behavior == COUPLE and a is not None and a.slots_world is not None:
            robot_of = {s: r for r, s in a.slot_of.items()}
            slots = [(robot_of[s], tuple(float(v) for v in a.slots_world[s])) for s in sorted(robot_of)]
        return DisplayObjectives(self._request_id, req.behavior, self._state, goals,
                                 a.target if req.behavior == COUPLE and a is not None else "", slots)


@dataclass
class DisplayObjectives:
    request_id: int
    behavior: str
    state: int
    goals: List[Tuple[str, Tuple[float, float]]]               # go_to_goal: (robot, (x, y)) world [m]
    target: str                                                # couple: target name
    slots: List[Tuple[str, Tuple[float, float, float]]]        # couple: (robot, slot (x, y, heading)) world
