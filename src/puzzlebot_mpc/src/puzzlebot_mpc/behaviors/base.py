"""The behaviour interface, and what every behaviour and the manager share.

A behaviour is one class (a subclass of :class:`Behavior`), registered under
its request name in :mod:`puzzlebot_mpc.behaviors.registry`. The manager
(:class:`~puzzlebot_mpc.behaviors.manager.BehaviorManager`) makes one object
per request and calls, in this order:

1. ``validate(poses)``: the request's own checks, raising
   :class:`BehaviorError`. With ``poses`` None only the checks that do not
   depend on the robots' state (a request queued for later); with poses
   (name -> (x, y, theta) [m, m, rad], world frame, or None) all of them,
   just before it starts. The manager has already checked what every request
   shares (robot names, tolerance / timeout / distance).
2. ``start(now, poses, static)``: the request was accepted and replaces the
   running behaviour (whose ``done`` ran first); take over the pair
   bookkeeping and write the objectives that stay fixed while it runs into
   ``static`` (every robot at rest). Returns the first status message.
3. every control step while it runs: ``status(now, poses, newly, lost,
   elapsed)`` -> :class:`Progress`; then, if still running ``timeout`` [s]
   after the start (the request's; 0: never), ``timed_out(...)`` ->
   :class:`Progress`; then ``completion(errors, elapsed)``, the fraction done
   (BehaviorStatus.progress: the action's feedback); then, if it still runs,
   ``objectives(obj, now, poses)`` adds this step's objectives to ``obj`` (a
   copy of ``static``).
4. ``done(poses)`` when another behaviour starts: give back what it holds
   (the decouple's pair).

When a behaviour ends (SUCCEEDED or FAILED) the manager brings every robot to
rest and clears the goal pairs; its status errors are then ``errors(poses)``.
"""

import math
from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple

from puzzlebot_mpc import pairs as pr

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
    groups: Sequence[int] = ()                     # couple: robots per group (consecutive in robots), each
                                                   # forming its own copy of the target; empty: one group
    cross_edges: bool = False                      # its robots may leave their stage (MPCSettings.edges):
                                                   # down a step, over a gap
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
    progress: float = float("nan")                      # 0..1 done (Behavior.completion); NaN: not measurable


@dataclass
class DisplayObjectives:
    request_id: int
    behavior: str
    state: int
    goals: List[Tuple[str, Tuple[float, float]]]               # go_to_goal: (robot, (x, y)) world [m]
    target: str                                                # couple: target name
    slots: List[Tuple[str, Tuple[float, float, float]]]        # couple: (robot, slot (x, y, heading)) world


@dataclass
class Progress:
    """A behaviour's answer to a status update: its state, its message (None: unchanged) and its
    errors (per robot or pair, the behaviour says what; BehaviorStatus.errors)."""

    state: int = RUNNING
    message: Optional[str] = None
    errors: List[float] = field(default_factory=list)


def finite(values):
    """True when every value is a finite int or float (not a bool)."""
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values)


class Context:
    """What the behaviours share with the manager: the robots, settings, geometry, pair book and targets.

    ``names``: the robots in the MPC's order; ``index``: name -> that index;
    ``settings``: MPCSettings; ``geometry``: RobotGeometry; ``pairs``:
    pairs.PairBook (the coupled pairs, the goal pairs, the active ones);
    ``targets``: name -> targets.Target.
    """

    def __init__(self, names, index, settings, geometry, pairs, targets):
        self.names, self.index = names, index
        self.settings = settings
        self.geometry = geometry
        self.pairs = pairs
        self.targets = targets

    def assembly_of(self, robot):
        """The robots coupled to ``robot`` (directly or through others), itself included, in ``names`` order."""
        return self.pairs.assemblies(self.names).get(robot, [robot])

    def mover(self, pair):
        """"i", "j" or None: the robot of a pair that docks (pairs.PairBook.mover: the smaller assembly; the
        opening robot on a tie; None for a pair inside one assembly, where both hold)."""
        return self.pairs.mover(pair)


class Behavior:
    """One kind of behaviour request (see the module docstring for the calls and their order).

    ``req``: the BehaviorRequest; ``ctx``: the shared :class:`Context`.
    ``robots``: the robots it names (the request's, default all); ``start``
    may change it to the robots it drives (BehaviorStatus.robots).
    """

    #: the request's ``behavior`` string this class serves (its registry key)
    name = ""
    #: request() refuses the behaviour without the robots' current poses
    needs_poses = False
    #: while it runs, the pair book assigns active pairs every step (ControlLoop.step)
    assigns_active_pairs = False

    def __init__(self, req, ctx):
        self.req = req
        self.ctx = ctx
        self.settings = ctx.settings
        self.robots = list(req.robots) or list(ctx.names)
        self.start_time = None

    # ------------------------------------------------------------ the interface
    def validate(self, poses=None):
        """Raise BehaviorError if the request is bad (``poses`` None: only the state-free checks)."""

    def start(self, now, poses, static):
        """Start at ``now`` [s]: take over the pair bookkeeping and write the fixed objectives into
        ``static`` (controller.Objectives, every robot at rest, float velocity mask). Returns the status
        message."""
        self.start_time = now
        return "started"

    def status(self, now, poses, newly, lost, elapsed):
        """This step's :class:`Progress`, ``elapsed`` [s] after the start; ``newly``/``lost``: pairs just
        coupled / lost (pairs.PairBook.update)."""
        return Progress(RUNNING, None, self.errors(poses))

    def timed_out(self, now, poses, errors, elapsed):
        """The :class:`Progress` when the request's ``timeout`` has passed and it still runs (``errors``:
        this step's, from :meth:`status`). Default: FAILED."""
        return Progress(FAILED, "timeout after %.2f s" % elapsed, errors)

    def objectives(self, obj, now, poses):
        """Add this step's objectives to ``obj`` (a copy of the static ones; velocity_mask (N, 2))."""

    def done(self, poses):
        """Another behaviour starts (``poses``: the current ones, or None): give back what this one holds."""

    def errors(self, poses):
        """BehaviorStatus.errors from ``poses``; also reported after the behaviour ended. Default: none."""
        return []

    def completion(self, errors, elapsed):
        """Fraction 0..1 of the behaviour done, from this step's ``errors`` (status) and ``elapsed`` [s]:
        BehaviorStatus.progress, the action's feedback. Default: NaN (nothing to measure it by); the
        timeout, when the request has one, says nothing about progress."""
        return float("nan")

    def pair_slots(self):
        """Pairs outside the pair book that need a slot in the MPC (the pair being decoupled)."""
        return []

    def crossing(self):
        """Robots this behaviour lets off the edges of their stages (a request with ``cross_edges``)."""
        return list(self.robots) if self.req.cross_edges else []

    def driven_pairs(self):
        """Keys of active pairs whose robots this behaviour drives itself this step: the MPC leaves out
        their alignment cost (couple: the docking manoeuvre's push and pull)."""
        return set()

    def display(self, request_id, state):
        """What the behaviour was asked, for displays: DisplayObjectives."""
        return DisplayObjectives(request_id, self.req.behavior, state, [], "", [])

    # ----------------------------------------------------------------- helpers
    def check_velocity(self, name, vel):
        """Refuse a (v [m/s], w [rad/s]) for ``name`` that is not finite or exceeds v_max / w_max."""
        s = self.settings
        if len(vel) != 2 or not finite(vel):
            raise BehaviorError("velocity for %s is not a finite (v, w): %r" % (name, tuple(vel)))
        if abs(vel[0]) > s.v_max + 1e-12 or abs(vel[1]) > s.w_max + 1e-12:
            raise BehaviorError("velocity for %s (%.3f m/s, %.3f rad/s) exceeds the limits "
                                "v_max %.3f m/s, w_max %.3f rad/s" % (name, vel[0], vel[1], s.v_max, s.w_max))

    def one_per_robot(self, values, what, whats):
        """(robot, value) pairs of ``values``, one per robot, or BehaviorError ("one goal per robot":
        ``what`` "goal", ``whats`` "goal(s)")."""
        if len(values) != len(self.robots):
            raise BehaviorError("%s needs one %s per robot: %d robot(s), %d %s"
                                % (self.req.behavior, what, len(self.robots), len(values), whats))
        return list(zip(self.robots, values))

    def need_poses(self, robots, poses):
        """Refuse when ``poses`` (not None) lack a fresh, finite pose for one of ``robots``."""
        if poses is None:
            return
        missing = [r for r in robots if poses.get(r) is None or not finite(poses[r])]
        if missing:
            raise BehaviorError("%s: no fresh, finite pose for %s; the robots stay as they are"
                                % (self.req.behavior, ", ".join(missing)))

    def rigid_velocities(self, vel, lead, v, w, members, poses):
        """Write into ``vel`` (N, 2) the references of an assembly moving as one body with twist (v [m/s],
        w [rad/s]) in the frame of robot ``lead``: the lead (v, w), every other member of ``members`` the
        rigid-body speed at its own position along its heading (clipped to v_max) and w."""
        s, index = self.settings, self.ctx.index
        pl = poses.get(lead)
        if pl is None:
            return vel
        c, sn = math.cos(pl[2]), math.sin(pl[2])
        for m in members:
            pm = poses.get(m)
            if pm is None:
                continue
            rx, ry = pm[0] - pl[0], pm[1] - pl[1]
            vx, vy = v * c - w * ry, v * sn + w * rx
            vm = vx * math.cos(pm[2]) + vy * math.sin(pm[2])
            vel[index[m]] = (max(-s.v_max, min(s.v_max, vm)), w)
        return vel

    def lost_while_driving(self, lost, members):
        """A FAILED Progress naming the pairs of ``lost`` with a robot among ``members`` (an assembly that
        drives lost a coupling), or None."""
        gone = [p for p in lost if p.robot_i in members]
        if not gone:
            return None
        return Progress(FAILED, "pair(s) lost while driving: %s" % ", ".join("%s-%s" % p.robots for p in gone))

    def hold(self):
        """The velocity-mask weight of a robot that holds still: sqrt(hold_scale)."""
        return math.sqrt(self.settings.hold_scale)
