"""BehaviorManager: holds the running behaviour and turns it into MPC objectives each step.

One behaviour runs at a time; it names the robots it drives and every other
robot is brought to rest. Requests are validated completely before they
replace the running behaviour, so a bad request changes nothing (robots at
rest stay at rest). Coupled pairs are kept by the MPC's polygon constraints
whatever the behaviour: every pair slot (coupled pairs, goal pairs, the
pair being decoupled) gets its alignment points and coupling polygon here.

What a behaviour does is its class's business (base.Behavior, one module
per behaviour, registry.REGISTRY); the manager only keeps the request ids,
the status, the rest state between behaviours and the requests queued
behaviours report on (refused, dropped).
"""

import numpy as np

from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.behaviors.base import (FAILED, IDLE, RUNNING, SUCCEEDED, BehaviorError, BehaviorRequest,
                                          BehaviorStatus, Context, DisplayObjectives, finite)
from puzzlebot_mpc.behaviors.registry import REGISTRY
from puzzlebot_mpc.behaviors.stop import STOP
from puzzlebot_mpc.controller import Objectives, PairObjective


class BehaviorManager:
    """Holds the running behaviour and turns it into MPC objectives each step.

    ``pairbook`` (pairs.PairBook) holds the coupled pairs; ``targets`` maps
    names to targets.Target (from config/targets.yaml); ``behaviors``: the
    behaviours it knows, request name -> base.Behavior subclass (default
    registry.REGISTRY).
    """

    def __init__(self, robot_names, settings, geometry=None, pairbook=None, targets=None, behaviors=None):
        self.names = list(robot_names)
        self.index = {name: i for i, name in enumerate(self.names)}
        self.settings = settings
        self.geometry = geometry or RobotGeometry()
        self.pairs = pairbook or pr.PairBook.from_settings(self.geometry, settings)
        self.targets = dict(targets or {})
        self.kinds = dict(REGISTRY if behaviors is None else behaviors)
        self._ctx = Context(self.names, self.index, settings, self.geometry, self.pairs, self.targets)
        self._request_id = 0             # id of the current behaviour
        self._last_id = 0                # last id handed out (requests queued in ControlLoop get theirs early)
        self._req = BehaviorRequest(STOP)
        self._robots = []
        self._start = None
        self._state = IDLE
        self._message = "no behaviour requested yet"
        self._static = Objectives.stop_all(len(self.names))
        self._behavior = None            # the behaviour started last (its done() runs when the next one starts)
        self._refused = False            # the current request was refused when due: it never started

    # ------------------------------------------------------------- requests
    def validate(self, req):
        """The checks that do not depend on the robots' state (names, numbers, targets, limits): the
        robots the request applies to, or BehaviorError. A request queued for later passes these when
        queued and the rest when it starts."""
        return self._check(req, None).robots

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

    @property
    def last_id(self):
        """The last request id handed out (queued requests included)."""
        return self._last_id

    def refuse(self, request_id, req, message):
        """Report request ``request_id`` (queued, now due) as FAILED with ``message``; the robots rest."""
        self._req, self._robots, self._request_id = req, list(req.robots), request_id
        self._refused = True
        self._state, self._message = FAILED, message
        self._rest()

    def set_settings(self, settings):
        """Use ``settings`` (MPCSettings, live tuning: puzzlebot_mpc.tuning) for new requests and the running
        behaviour from now on."""
        self.settings = settings
        self._ctx.settings = settings
        if self._behavior is not None:
            self._behavior.settings = settings

    def note(self, text):
        """Append ``text`` to the current status message (e.g. queued requests dropped)."""
        self._message += text

    def _check(self, req, poses):
        """The request's behaviour object, validated (``poses`` None: the state-free checks), or raise
        BehaviorError."""
        kind = self.kinds.get(req.behavior)
        if kind is None:
            raise BehaviorError("unknown behaviour %r; known: %s" % (req.behavior, ", ".join(self.kinds)))
        behavior = kind(req, self._ctx)
        robots = behavior.robots
        unknown = [r for r in robots if r not in self.index]
        if unknown:
            raise BehaviorError("unknown robot(s) %s; known: %s"
                                % (", ".join(map(repr, unknown)), ", ".join(self.names)))
        if len(set(robots)) != len(robots):
            raise BehaviorError("a robot is named twice in %s" % robots)
        if not finite([req.tolerance, req.timeout, req.distance]) or min(req.tolerance, req.timeout,
                                                                          req.distance) < 0:
            raise BehaviorError("tolerance, timeout and distance must be finite and >= 0 (got %r, %r, %r)"
                                % (req.tolerance, req.timeout, req.distance))
        behavior.validate(poses)
        return behavior

    def request(self, req, now, poses=None, request_id=None):
        """Validate and start a behaviour at time ``now`` [s]; return its id.

        ``poses``: name -> (x, y, theta) or None; needed by couple, decouple
        and drive_assembly (a missing pose refuses those requests).
        ``request_id``: the id handed out when the request was queued (None: a new one).
        """
        kind = self.kinds.get(req.behavior)
        if kind is not None and kind.needs_poses and poses is None:
            raise BehaviorError("%s needs the robots' current poses" % req.behavior)
        behavior = self._check(req, poses)
        # accepted: replace the running behaviour
        if self._behavior is not None:
            self._behavior.done(poses)
        self.pairs.clear_goals()
        self._request_id = self.new_id() if request_id is None else request_id
        self._req, self._start = req, now
        self._behavior, self._refused = behavior, False
        static = Objectives.stop_all(len(self.names))
        static.velocity_mask = static.velocity_mask.astype(float)
        self._state = RUNNING
        self._message = behavior.start(now, poses, static)
        self._static = static
        self._robots = behavior.robots
        return self._request_id

    def coupling(self):
        """True while a behaviour runs that has the pair book assign active pairs every step (couple)."""
        return self._state == RUNNING and self._behavior.assigns_active_pairs

    def crossing(self):
        """Robots the running behaviour lets off their stages' edges (its request's ``cross_edges``)."""
        return set(self._behavior.crossing()) if self._state == RUNNING else set()

    # ----------------------------------------------------------- objectives
    def pair_slots(self):
        """Pairs that get a slot in the MPC this step: coupled, goals, the one being decoupled."""
        slots = self.pairs.all_pairs()
        if self._behavior is not None:
            slots.extend(self._behavior.pair_slots())
        return slots

    def objectives(self, now=None, poses=None):
        """Objectives for this step (``now`` [s]; poses: name -> (x, y, theta) or None)."""
        s = self.settings
        base = self._static
        mask = np.asarray(base.velocity_mask, float)
        obj = Objectives(base.goal.copy(), base.goal_mask.copy(), base.velocity.copy(),
                         np.repeat(mask[:, None], 2, axis=1) if mask.ndim == 1 else mask.copy())
        if self._state == RUNNING:
            self._behavior.objectives(obj, now, poses)
        active = {p.key for p in self.pairs.active}
        if self._state == RUNNING:
            active -= self._behavior.driven_pairs()
        for p in self.pair_slots():
            coupled = p.key in self.pairs.coupled
            pose_i, pose_j = (poses.get(p.robot_i), poses.get(p.robot_j)) if poses else (None, None)
            pi, pj = pr.alignment_points(p, pose_i, pose_j,
                                         (s.approach_lookahead, s.approach_standoff_max, s.approach_gain_angle,
                                          s.approach_gain_lateral),
                                         mover="j" if coupled else self._ctx.mover(p) or "j",
                                         aim=self.pairs.docking[p.key].aim if p.key in self.pairs.docking else 0.0)
            obj.pairs.append(PairObjective(self.index[p.robot_i], self.index[p.robot_j], pi, pj,
                                           active=p.key in active and not coupled, coupled=coupled,
                                           head=p.head, polygon=pr.coupling_polygon(p, self.geometry),
                                           yaw_limit=pr.yaw_limit(p, self.geometry),
                                           margin=pr.constraint_margin(p, pose_i, pose_j, self.geometry, s.knob_hold,
                                                                       s.knob_hold_step) if coupled else None))
        return obj

    # --------------------------------------------------------------- status
    def update(self, now, poses, newly=(), lost=()):
        """Advance the behaviour's state given ``poses`` (name -> (x, y, theta) or None) at ``now`` [s].

        ``newly``/``lost``: pairs that were just coupled / lost this step
        (from PairBook.update), for the couple and drive_assembly checks.
        """
        req, behavior = self._req, None if self._refused else self._behavior
        if self._state == RUNNING:
            elapsed = now - self._start
            progress = behavior.status(now, poses, newly, lost, elapsed)
            if progress.state == RUNNING and req.timeout and elapsed >= req.timeout:
                progress = behavior.timed_out(now, poses, progress.errors, elapsed)
            if progress.message is not None:
                self._message = progress.message
            done = 1.0 if progress.state == SUCCEEDED else behavior.completion(progress.errors, elapsed)
            if progress.state != RUNNING:
                self._state = progress.state
                self._rest()
            errors = progress.errors
        else:
            errors = behavior.errors(poses) if behavior is not None else []
            done = 1.0 if self._state == SUCCEEDED else float("nan")
        return BehaviorStatus(self._request_id, req.behavior, self._state, self._message,
                              list(self._robots), errors, done)

    def _rest(self):
        self._static = Objectives.stop_all(len(self.names))
        self.pairs.clear_goals()

    # -------------------------------------------------------------- display
    def display_objectives(self):
        """What the current (or last) behaviour was asked, for displays (rviz) and tools.

        Kept after the behaviour ends, so a finished run still shows its goals
        and target (a request refused when due shows none: it never started).
        """
        behavior = None if self._refused else self._behavior
        if behavior is None:
            return DisplayObjectives(self._request_id, self._req.behavior, self._state, [], "", [])
        return behavior.display(self._request_id, self._state)
