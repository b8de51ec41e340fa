"""Seating an anchor pair and keeping it seated, from what the hardware has: poses, commands, time.

The MPC brings an anchor pair's head to the partner's mouth (the *approach*,
Algorithm 2's decoupled -> head_aligned). What happens from there is chosen
by two settings:

- ``insert_by_mpc`` (default): the MPC pushes the anchor home itself
  (Algorithm 2's head_aligned -> head_inserted, with its lining-up test,
  ``insert_*`` in MPCSettings). A push that stays head_aligned for
  ``insert_timeout`` has jammed: the barb sits on the lip. The pair is
  decoupled again and :meth:`Docking.jammed` aims the next approach
  ``aim_step`` to the side the mover was pushed (the anchor turns freely in
  its holder, so the head is not where the partner's pose puts it), up to
  ``aim_max``. A pair whose headings are more than ``jam_yaw`` apart is
  *askew*: the head in the mouth holds the relative heading, so such a pair
  gets no nudge, and when it jams the mover backs off first.
- ``insert_by_mpc`` false: this module drives the mover straight in (the
  ``push`` phase below) and backs it off after ``push_timeout``.

With ``pull_test`` the pair is pulled on once home: a robot cannot pull a
seated anchor out (the barbs hold 0.6 N at 4 mm, a robot pushes 0.5 N:
facts.md), so a seated pair stretches by the anchor's travel in its holder
plus the barbs' give, then stalls; an anchor not behind the lips gives way
further, or not at all when a barb is folded against the head. Off by
default: measured, the pull unseated more pairs than it caught
(docs/mpc.md, "Seating").

Whatever seated it, a coupled pair is then watched (:class:`SeatMonitor`):
faces more than ``repair_gap`` apart for ``repair_time`` (a pair pushed out
of its slits by robots docking elsewhere) -> re-seated from ``push`` while
a couple runs (a knob pair pushed off its hole goes back to the goals and
its approach: puzzlebot_mpc.pairs). The phases of one pair's manoeuvre (:class:`Docking`):

=========  ==============================================================
phase      what the mover (the robot that docks) does
=========  ==============================================================
approach   the MPC aligns the pair (alignment cost, approach carrot)
nudge      (``insert_by_mpc``, with ``insert_stall_time``) the MPC's
           insertion has stalled with the head in the mouth, the faces
           not yet home: a mover driving forwards drives straight in at
           ``push_speed`` for ``nudge_time`` (or until home), then the
           MPC again; Algorithm 2's lining-up test still decides when the
           pair is coupled. Not for a pair askew (``jam_yaw``). Meanwhile
           the anchor robot *braces*: it (and its assembly, as one body)
           drives backwards into the mover at ``brace_speed`` until the
           faces are ``brace_gap`` apart. A robot pushed at its tail
           rests nose up on its rear caster, its anchor's head below the
           mouth of a robot that drives forwards (nose up too); the
           brace's wheel torque tips it onto its front caster and lifts
           the head (:meth:`Docking.brace`)
push       drives straight into the partner at ``push_speed``, holding
           the heading the partner had when the push began (the mouth and
           the anchor's free yaw do the last millimetres; chasing a partner
           that the contact turns would turn the pair together); "home"
           when the gap between the faces is below ``home_gap`` for
           ``home_steps`` steps
pull       backs away at ``pull_speed`` for at most ``pull_time``: the gap
           must grow by ``seat_pull_min`` .. ``seat_pull_max`` (the seated
           band) and stall there (the pull ends early once it has; it fails
           early once the gap has grown past the band)
repush     drives home again at ``repush_speed`` (the pull leaves the anchor
           part way out, its barbs behind the lips: a gentle push seats it,
           a hard one can knock a barb out again)
backoff    backs away at ``backoff_speed`` for ``backoff_time``, then
           approaches again: after a push that did not get home
           (``push_timeout``), a pull outside the band, or a jam askew
           (``jam_yaw``: turning to the partner's heading). A push that jams
           leaves the mover pushed aside by the head, towards the side the
           head sits on (the anchor turns freely in its holder, so the head
           is not where the partner's pose puts it): the next approach aims
           the mouth ``aim_step`` further to that side (up to ``aim_max``)
seated     the pair is coupled (the controller's head_inserted)
=========  ==============================================================

The mover's partner (and its assembly) holds still throughout, but for the
brace during a nudge. A pair that was seated and is later found open
(:func:`seat_measure`: gap above ``repair_gap`` for ``repair_time``) is
re-seated from ``push``.

The seated band is a property of the anchor and its holder: in the Bullet
model a seated pair stretches 9.0-12.3 mm before it stalls; a barb folded
against the head 7.1-7.5 mm; an anchor not behind the lips comes out
(18-21 mm; ``rosrun puzzlebot_experiments anchor_trials seatpull`` measures
it). On the lab's robots, measure it the same way (docs/lab-measurements.md).

Geometry (robot frames, metres): the anchor robot ``i`` stands in front of
the opening robot ``j``; C_a is the centre of i's back face, C_o of j's
front face. In j's frame, C_a is at (L/2 + gap, lateral); the pair's
relative heading is theta_i - theta_j.
"""

import math
from dataclasses import dataclass
from typing import Optional, Tuple

from puzzlebot_common.geometry import inverse_transform_point, transform_point

APPROACH, PUSH, PULL, REPUSH, BACKOFF, SEATED = "approach", "push", "pull", "repush", "backoff", "seated"
NUDGE = "nudge"
PHASES = (APPROACH, NUDGE, PUSH, PULL, REPUSH, BACKOFF, SEATED)
#: phases in which the docking manoeuvre, not the MPC's alignment cost, drives the mover
DRIVEN = (NUDGE, PUSH, PULL, REPUSH, BACKOFF)


@dataclass(frozen=True)
class DockingSettings:
    """How a pair is pushed home, tested and re-seated (MPCSettings ``dock_*``; units m, s, rad)."""

    push_speed: float = 0.05          # m/s: straight push into the partner (faster folds the barbs surer: 40/40 vs 38/40)
    push_heading_gain: float = 2.0    # 1/s: w = gain x (partner heading - mover heading) while pushing/pulling
    push_start_gap: float = 0.016     # m: the push starts once the faces are this close ...
    push_lateral: float = 0.0015      # m: ... with C_a this close to the opening's axis (or the aim) ...
    push_yaw: float = 0.12            # rad: ... and the headings this close
    push_timeout: float = 2.5         # s: not home after this long: back off
    home_gap: float = 0.003           # m: faces closer than this: pushed home
    home_steps: int = 3               # control steps the pair must be home in a row
    insert_by_mpc: bool = True        # the MPC pushes the anchor in (Algorithm 2 and its lining-up test) and a
    #                                   jam aims the next approach; false: the straight push of this module
    pull_test: bool = False           # prove a pair pushed home seated by pulling on it (false: home is seated;
    #                                   off by default: measured, it unseats more pairs than it catches)
    pull_speed: float = 0.02          # m/s: the pull test
    pull_time: float = 1.0            # s
    seat_pull_min: float = 0.0085     # m: a seated pair stretches at least this much under the pull ...
    seat_pull_max: float = 0.0135     # m: ... and at most this much
    pull_stall: float = 0.0005        # m: the pull has stalled when the gap grew less than this in a step
    repush_speed: float = 0.02        # m/s: the push home after the pull ...
    repush_gap: float = 0.003         # m: ... until the faces are this close (0: no push after the pull)
    repush_timeout: float = 1.5       # s: back home after the pull within this
    backoff_speed: float = 0.03       # m/s
    backoff_time: float = 0.8         # s
    aim_step: float = 0.002           # m: after a jammed push, aim the mouth this much further to the side
    aim_max: float = 0.004            # m: ... up to this far off the partner's axis
    jam_yaw: float = 0.25             # rad: (insert_by_mpc) a pair whose headings are more than this apart while
    #                                   the head is in the mouth is not nudged, and when it jams the mover
    #                                   backs off (backoff_*), turning to its partner's heading, before it
    #                                   approaches again (0: off; the head askew in the mouth holds the pair's
    #                                   relative heading, measured in docs/mpc.md "Seating")
    stall_time: float = 0.0           # s: an approach (head not yet in the mouth) that has not come
    #                                   stall_progress closer in this long has stalled: back off, then again
    #                                   (0: off; measured with 8 s, line8 seed 11: 1 of 8 either way)
    stall_progress: float = 0.005     # m: ... (distance of C_a from the mouth plus 20 mm per rad of heading error)
    insert_stall_time: float = 1.0    # s: the MPC's insertion (insert_by_mpc, the head in the mouth) that has not
    #                                   closed the gap by insert_stall_progress in this long has stalled: a
    #                                   robot driving forwards into the anchor then drives straight in (nudge;
    #                                   0: off; measured, docs/mpc.md "Seating")
    insert_stall_progress: float = 0.002  # m: ...
    nudge_time: float = 1.0           # s: the nudge drives in at push_speed for at most this long, then the MPC
    #                                   again
    brace_speed: float = 0.04         # m/s: during a nudge the anchor robot (and its assembly) drives backwards
    #                                   into the mover at this speed (brace; 0: off): the wheels' torque tips
    #                                   it towards its front caster and lifts its anchor's head to the mouth
    #                                   (measured, docs/mpc.md)
    brace_gap: float = 0.009          # m: ... while the faces are farther apart than this (the head not yet past
    #                                   the lips)
    repair_gap: float = 0.003         # m: a coupled pair with its faces this far apart ...
    repair_time: float = 1.0          # s: ... for this long is re-seated
    loop_gap: float = 0.001           # m: an anchor pair closing a loop (no mover to push and pull it) is
    #                                   seated with its faces this close, the head through the opening ...
    loop_time: float = 1.0            # s: ... for this long

    def check(self, where="mpc"):
        from puzzlebot_common.errors import ConfigError

        for name in self.__dataclass_fields__:
            if name in ("pull_test", "insert_by_mpc"):
                continue
            zero_ok = name in ("repush_gap", "stall_time", "jam_yaw", "insert_stall_time", "brace_speed")
            value, least = getattr(self, name), 0.0 if zero_ok else 1e-12
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= least):
                raise ConfigError("%s.dock_%s: must be a number > 0, got %r" % (where, name, value))
        if not self.seat_pull_min < self.seat_pull_max:
            raise ConfigError("%s: dock_seat_pull_min (%g) must be below dock_seat_pull_max (%g)"
                              % (where, self.seat_pull_min, self.seat_pull_max))
        if self.pull_speed * self.pull_time <= self.seat_pull_max:
            raise ConfigError("%s: the pull (dock_pull_speed x dock_pull_time = %.1f mm) must reach past "
                              "dock_seat_pull_max (%.1f mm), or an anchor that comes out would look seated"
                              % (where, 1e3 * self.pull_speed * self.pull_time, 1e3 * self.seat_pull_max))


def seat_measure(pair, pose_i, pose_j):
    """(gap between the faces [m], lateral offset of C_a from the opening's axis [m], relative heading [rad])
    of an anchor pair from the robots' poses (x, y, theta)."""
    ca = transform_point(pose_i, pair.point_i[:2])
    q = inverse_transform_point(pose_j, ca)
    return (float(q[0] - pair.point_j[0]), float(q[1] - pair.point_j[1]),
            math.remainder(pose_i[2] - pose_j[2], 2 * math.pi))


class StallWatch:
    """A distance [m] that should shrink: stalled when it has not shrunk by ``progress`` [m] in ``time`` [s]
    (measured from the smallest value so far)."""

    def __init__(self, progress, time):
        self.progress, self.time = progress, time
        self.best = None              # m: the smallest value so far ...
        self.best_at = None           # s: ... and when it was reached

    def update(self, value, now):
        """The time [s] the value has not shrunk, once that reaches ``time`` (then the watch starts afresh);
        else None."""
        if self.best is None or now is None or self.best_at is None or value < self.best - self.progress:
            self.best, self.best_at = value, now
            return None
        waited = now - self.best_at
        if waited < self.time:
            return None
        self.reset()
        return waited

    def reset(self):
        self.best = self.best_at = None


@dataclass
class Command:
    """What the docking manoeuvre asks of the mover this step: body velocity (v [m/s], w [rad/s])."""

    v: float
    w: float


class Docking:
    """The docking manoeuvre of one anchor pair (see the module docstring).

    ``mover``: "i" (the anchor robot backs in) or "j" (the opening robot
    drives forward). ``start``: the first phase (``approach``; ``push`` to
    re-seat a pair that was coupled).
    """

    def __init__(self, settings, mover="j", start=APPROACH, now=None):
        self.s = settings
        self.mover = mover
        self.phase = start
        self.since = now
        self.home_count = 0
        self.attempts = 0             # pushes started
        self.pull_from = None         # gap when the pull started [m]
        self.last_growth = None       # stretch measured by the last pull [m]
        self.note = ""                # why the last phase change happened
        self.aim = 0.0                # m: where the approach puts C_a across the opening's axis (j's frame, +y)
        self.heading_ref = None       # rad: the heading a driven phase holds (the partner's at its start)
        self.last_gap = None          # m: the gap at the previous update
        self.approach_watch = StallWatch(settings.stall_progress, settings.stall_time)   # approach_stalled
        self.stalls = 0               # approaches that stalled
        self.insert_watch = StallWatch(settings.insert_stall_progress, settings.insert_stall_time)  # insert_stalled
        self.nudges = 0               # nudges started

    # ------------------------------------------------------------ helpers
    def _to(self, phase, now, note=""):
        self.phase, self.since, self.home_count, self.note = phase, now, 0, note
        self.heading_ref = None
        if phase == PUSH:
            self.attempts += 1

    def _elapsed(self, now):
        return 0.0 if self.since is None or now is None else now - self.since

    @property
    def sign(self):
        """+1 when "into the partner" is forward for the mover (the opening robot), -1 when backward."""
        return 1.0 if self.mover == "j" else -1.0

    def _aim_away(self, lateral):
        """After a jam with C_a ``lateral`` [m] across the axis: aim the next approach aim_step further to the
        other side (the side the head pushed the mover to), at most aim_max off the axis."""
        s = self.s
        self.aim = max(-s.aim_max, min(s.aim_max, self.aim - math.copysign(s.aim_step, lateral)))

    def askew(self, dtheta):
        """True when the pair's relative heading [rad] is beyond ``jam_yaw`` (0: never)."""
        return 0 < self.s.jam_yaw < abs(dtheta)

    def jammed(self, gap, lateral, now, dtheta=0.0):
        """The MPC's own insertion (``insert_by_mpc``) pushed for its timeout without getting home: aim the
        next approach to the side the mover was pushed (see the module docstring); a pair askew
        (:meth:`askew`) also backs off first."""
        self.attempts += 1
        self._aim_away(lateral)
        self.approach_watch.reset()
        self.note = "insertion %d jammed (%.1f mm out, %.1f mm aside, %.2f rad); aiming %.1f mm across" % (
            self.attempts, 1e3 * gap, 1e3 * lateral, dtheta, 1e3 * self.aim)
        if self.askew(dtheta):
            self._to(BACKOFF, now, self.note + "; askew: backing off")

    def approach_stalled(self, gap, lateral, dtheta, now):
        """During the approach (the head not yet in the mouth): True when the pair has come no closer than
        ``stall_progress`` in ``stall_time`` (the MPC stuck in a local minimum, e.g. the mover beside its
        partner at a steep angle). The mover then backs off (``backoff_*``), turning to its partner's
        heading, and approaches again from there."""
        s = self.s
        if s.stall_time <= 0:
            return False
        d = math.hypot(max(gap, 0.0), lateral - self.aim) + 0.02 * abs(dtheta)
        waited = self.approach_watch.update(d, now)
        if waited is None:
            return False
        self.stalls += 1
        self._to(BACKOFF, now, "approach %d stalled %.0f mm away for %.0f s" % (self.stalls, 1e3 * d, waited))
        return True

    def insert_stalled(self, gap, now, dtheta=0.0):
        """While the MPC inserts (the head in the mouth, ``insert_by_mpc``): True, and the ``nudge`` phase
        begins, when the gap between the faces [m], more than ``home_gap``, has not closed by
        ``insert_stall_progress`` in ``insert_stall_time``; only for a mover driving forwards ("j": a robot
        backing its anchor in pushes a link free to turn in its holder, and jams). Measured in Bullet
        (line8): the head in the mouth holds the relative heading, the MPC turns against it at a crawl;
        the straight push at ``push_speed`` takes the barbs through the lips."""
        s = self.s
        if s.insert_stall_time <= 0 or self.mover != "j" or self.askew(dtheta):
            return False
        if gap <= s.home_gap:              # home already (not yet lined up): nothing to push
            self.insert_reset()
            return False
        waited = self.insert_watch.update(gap, now)
        if waited is None:
            return False
        self.nudges += 1
        self.last_gap = gap
        self._to(NUDGE, now, "insertion stalled %.1f mm out for %.1f s: nudge %d" % (1e3 * gap, waited, self.nudges))
        return True

    def end_nudge(self, now, why):
        """The pair left head_aligned during a nudge (``why``: its status): the MPC drives it again."""
        self._to(APPROACH, now, "nudge ended: %s" % why)

    def insert_reset(self):
        """The head is not in the mouth: the next head_aligned spell starts afresh."""
        self.insert_watch.reset()

    def start_pull(self, gap, now):
        """The pair is pushed home (by the MPC): test it with the pull."""
        self._to(PULL, now, "pushed home")
        self.pull_from = gap

    def ready_to_push(self, gap, lateral, dtheta):
        """The approach has brought the pair close and lined up enough for a straight push."""
        s = self.s
        return gap <= s.push_start_gap and abs(lateral - self.aim) <= s.push_lateral and abs(dtheta) <= s.push_yaw

    # -------------------------------------------------------------- update
    def update(self, gap, lateral, dtheta, now):
        """Advance the phase from this step's measurement (seat_measure). Returns True when the pair has
        just been proven seated."""
        if self.since is None:           # the first update of this phase (the pair was waiting its turn)
            self.since = now
        try:
            return self._update(gap, lateral, dtheta, now)
        finally:
            self.last_gap = gap

    def _update(self, gap, lateral, dtheta, now):
        s, phase, t = self.s, self.phase, self._elapsed(now)
        home = gap <= s.home_gap
        self.home_count = self.home_count + 1 if home else 0
        if phase == NUDGE:
            if self.home_count >= s.home_steps or t >= s.nudge_time - 1e-9:
                self._to(APPROACH, now, "nudged %s" % ("home" if self.home_count >= s.home_steps else
                                                        "for %.1f s, %.1f mm out" % (t, 1e3 * gap)))
        elif phase == APPROACH:
            if self.ready_to_push(gap, lateral, dtheta):
                self._to(PUSH, now, "lined up %.1f mm off axis, %.1f mm out" % (1e3 * lateral, 1e3 * gap))
            else:
                self.approach_stalled(gap, lateral, dtheta, now)
        elif phase == PUSH:
            if self.home_count >= s.home_steps and not s.pull_test:
                self._to(SEATED, now, "pushed home")
                return True
            if self.home_count >= s.home_steps:
                self._to(PULL, now, "pushed home")
                self.pull_from = gap
            elif t >= s.push_timeout:
                self._aim_away(lateral)
                self._to(BACKOFF, now, "push %d did not get home (%.1f mm out, pushed %.1f mm aside after %.1f s); "
                         "aiming %.1f mm across" % (self.attempts, 1e3 * gap, 1e3 * lateral, t, 1e3 * self.aim))
        elif phase == PULL:
            growth = gap - self.pull_from
            stalled = self.last_gap is not None and gap - self.last_gap < s.pull_stall
            if growth > s.seat_pull_max or t >= s.pull_time - 1e-9 or (stalled and growth >= s.seat_pull_min):
                self.last_growth = growth
                if s.seat_pull_min <= growth <= s.seat_pull_max and s.repush_gap <= 0:
                    self._to(SEATED, now, "seated (pull held at %.1f mm)" % (1e3 * growth))
                    return True
                if s.seat_pull_min <= growth <= s.seat_pull_max:
                    self._to(REPUSH, now, "pull held at %.1f mm: seated" % (1e3 * growth))
                else:
                    why = "came out" if growth > s.seat_pull_max else "a barb folded against the head"
                    self._to(BACKOFF, now, "pull stretched the pair %.1f mm (seated: %.1f-%.1f mm): %s"
                             % (1e3 * growth, 1e3 * s.seat_pull_min, 1e3 * s.seat_pull_max, why))
        elif phase == REPUSH:
            if gap <= s.repush_gap and gap > s.home_gap:
                self.home_count = s.home_steps
            if self.home_count >= s.home_steps:
                self._to(SEATED, now, "seated (pull held at %.1f mm)" % (1e3 * self.last_growth))
                self.last_gap = gap
                return True
            if t >= s.repush_timeout:
                self._to(BACKOFF, now, "not home again after the pull (%.1f mm out)" % (1e3 * gap))
        elif phase == BACKOFF:
            if t >= s.backoff_time - 1e-9:
                self._to(APPROACH, now, self.note)
                self.approach_watch.reset()
        return False

    def command(self, mover_heading, partner_heading):
        """The mover's (v, w) in a driven phase (None in approach and seated: the MPC decides).

        Headings [rad], world frame. The mover holds the heading its partner
        had at the start of the phase (a pair pushed askew leaves a barb out).
        """
        s = self.s
        if self.heading_ref is None:
            self.heading_ref = partner_heading
        w = max(-1.0, min(1.0, s.push_heading_gain * math.remainder(self.heading_ref - mover_heading, 2 * math.pi)))
        if self.phase in (PUSH, NUDGE):
            return Command(self.sign * s.push_speed, w)
        if self.phase == REPUSH:
            return Command(self.sign * s.repush_speed, w)
        if self.phase == PULL:
            return Command(-self.sign * s.pull_speed, w)
        if self.phase == BACKOFF:
            return Command(-self.sign * s.backoff_speed, w)
        return None

    def brace(self):
        """The partner's (v, w) this step, or None (it holds): during a nudge, while the faces are more than
        ``brace_gap`` apart (the last update's gap), the anchor robot drives backwards into the mover at
        ``brace_speed``, straight (a nudge's mover drives forwards, so the partner is the anchor robot; see
        the module docstring). The couple behaviour moves the anchor robot's assembly with it. Measured
        with the anchor robot alone, bracing on once the head was past the lips pulled its own front pair
        open (a barb left on the lip, an anchor turned out of its holder)."""
        s = self.s
        if self.phase != NUDGE or self.mover != "j" or s.brace_speed <= 0:
            return None
        if self.last_gap is not None and self.last_gap < s.brace_gap:
            return None
        return Command(-s.brace_speed, 0.0)

    def describe(self):
        return "%s%s" % (self.phase, " (%s)" % self.note if self.note else "")


class SeatMonitor:
    """Watches a coupled pair: open (gap above ``limit``, default ``repair_gap``) for ``repair_time`` ->
    re-seat. For an anchor pair the gap is seat_measure's, between the faces (how far C_a is off the
    opening's axis does not tell: seated pairs were measured up to 4.5 mm off it, the anchor turned in its
    holder); for a knob pair pairs.knob_offset, with the knob test's tolerance as the limit."""

    def __init__(self, settings, limit=None):
        self.s = settings
        self.limit = settings.repair_gap if limit is None else limit
        self.bad_since = None

    def update(self, gap, lateral, now):
        """True when the pair has looked open for ``repair_time``: it needs re-seating. ``gap`` [m],
        ``lateral`` [m] (not used), ``now`` [s]."""
        if gap > self.limit:
            if self.bad_since is None:
                self.bad_since = now
            return now - self.bad_since >= self.s.repair_time - 1e-9
        self.bad_since = None
        return False
