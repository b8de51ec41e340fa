"""Bringing a knob pair together: the mover follows a lane along its partner's side (not the MPC).

The knob and the hole sit on the wheel axle's line, where a differential
drive moves only along its heading, so a knob cannot be rolled sideways
into its hole. A sprung knob (the body's side gives, puzzlebot_sim
``knob_travel``) gets in by sliding: the mover drives along the partner's
side on a lane ``gap`` out from it, closes in on a straight line from
``standoff`` behind the hole to ``press`` inside the side ``level`` behind it,
and runs on straight into the hole: passing the side's square corner
``gap`` out, the knob meets it at a glancing angle and is pressed in (nearer
the side the corner meets it head on and pushes the partner away), slides
along the side, pressed, and springs into the hole.

The MPC's alignment cost cannot steer an assembly (a chain joining another
side by side) along such a lane: its coupling polygons let a robot back
25 mm into its partner's mouth, so the planned motion turns one robot while
its partners stand. Here the MPC tracks the twist :func:`command` gives the
mover robot (its couplings and the stage edges still hold), the rest of its
assembly the rigid-body speeds that go with it (Couple.knob_objectives):

- *back off*: a mover more than OFF_LANE off its lane that needs a longer
  run to get onto it than it has (less than ``need = min(standoff_max,
  |e| / tan(MAX_CUT) + run)`` behind the hole, ``e`` its offset from the
  lane; ``run`` is ``standoff``, or only ``level`` for a point already
  alongside the partner's side, less than ``standoff`` behind the hole,
  with no corner left to pass) backs out to ``need + lookahead`` behind: a
  chain straight, without turning (a chain that reverses while it turns
  jack-knifes), a single robot or a row turning to its partner's heading
  (the run assumes a parallel mover: one that came out askew cuts in too
  late and backs off again and again). Where a robot stands behind the
  mover (``backoff_clearance`` short of it, puzzlebot_mpc.room) the mover
  stops and its partner's assembly drives straight ahead instead, as far
  as it has room (Couple.make_room): a row forming in a column of rows
  backs into the row behind it otherwise, its anchor into that row's
  mouth. A back-off that gets nowhere (blocked by a robot behind the
  mover) is given up for a while and the mover follows the lane from where
  it is; a mover that gets no nearer the hole along the lane (jammed on
  its partner's side, or caught on the hole's edge) backs off and comes
  again (:class:`ProgressWatch`);
- *follow*: a line follower on the lane (offset and heading fed back,
  ``steer_gain``) at up to ``speed``, slowing to the hole at ``speed_gain``
  per metre left but at least ``creep``, turning at most ``turn_rate``; a
  mover already inside the lane (pressed on the side) does not follow the
  lane's slope into the side, which would press it on and drag the partner
  along by friction; at
  the hole it turns to its partner's heading about its connection point
  (on the axle's line, a pivot a differential drive can turn about); past
  the hole it backs.

Algorithm 2's knob test (``knob_seat_tolerance`` for ``insert_confirm_steps``
steps, puzzlebot_mpc.pairs) then finds the pair coupled.
"""

import math
from dataclasses import dataclass

from puzzlebot_common.geometry import wrap_angle
from puzzlebot_mpc import pairs as pr

BACKOFF, FOLLOW = "backoff", "follow"
MAX_CUT = 0.35          # rad: the steepest angle at which a mover cuts towards its lane
OFF_LANE = 0.003        # m: a mover this far off its lane is off it (and may back off to get onto it)
HOME = 0.0005           # m: a moving point this close behind the hole (or past it) is there
BACKOFF_STALL = 2.0     # s: a back-off that has not gained BACKOFF_PROGRESS in this long is blocked ...
BACKOFF_PROGRESS = 0.002  # m
BACKOFF_REST = 10.0     # s: ... and the mover does not back off again for this long
FOLLOW_STALL = 3.0      # s: a mover on the lane that has not come BACKOFF_PROGRESS nearer the hole in this long
                        # is jammed: it backs off and comes again


@dataclass(frozen=True)
class KnobLane:
    """The lane a knob pair's mover follows, in the holding robot's frame (lengths [m])."""

    standoff: float = 0.028        # the lane closes in from this far behind the hole ...
    gap: float = 0.003             # ... and this far out from the side ...
    press: float = 0.0005          # ... to this far inside the side ...
    level: float = 0.005           # ... this far behind the hole, and runs straight on into it
    lookahead: float = 0.04        # a mover that backs off goes this far beyond its run
    standoff_max: float = 0.15     # longest run a mover off its lane backs off for
    speed: float = 0.02            # m/s: largest speed along the lane
    speed_gain: float = 0.5        # 1/s: speed per metre left to the hole ...
    creep: float = 0.003           # m/s: ... but at least this up to the hole (and the scale of the turn there)
    steer_gain: float = 80.0       # 1/m: the line follower's gain (about 2/gain of travel onto the lane)
    turn_rate: float = 0.4         # rad/s: largest turn rate

    def offset(self, behind):
        """How far out from the side [m] the lane runs ``behind`` [m] behind the hole (< 0 inside)."""
        f = min(1.0, max(behind - self.level, 0.0) / (self.standoff - self.level))
        return self.gap * f - self.press * (1.0 - f)


@dataclass(frozen=True)
class KnobCommand:
    """The mover robot's command (v [m/s], w [rad/s]) and the phase that gave it."""

    v: float
    w: float
    phase: str


def lane_state(pair, mover, pose_i, pose_j, lane):
    """(behind [m], off the lane [m, + outwards], heading difference [rad], the holding point's side: +1 for
    +y, -1 for -y) of the moving connection point (the knob, or the hole when the hole robot moves) in the
    holding robot's frame."""
    if mover == "i":
        hold_pose, hold_pt, move_pose, move_pt = pose_j, pair.point_j, pose_i, pair.point_i
    else:
        hold_pose, hold_pt, move_pose, move_pt = pose_i, pair.point_i, pose_j, pair.point_j
    q = pr.point_in_robot(hold_pose, pr.world_point(move_pose, move_pt))
    behind = float(hold_pt[0] - q[0])
    out = math.copysign(1.0, hold_pt[1])            # the holding point's side: +y (knob) or -y (hole)
    off = out * float(q[1] - hold_pt[1]) - lane.offset(behind)
    dtheta = wrap_angle(move_pose[2] - hold_pose[2])
    return behind, off, dtheta, out


class ProgressWatch:
    """Watches a lane follower's mover for progress (see the module): one per active pair, a knob pair's or
    an assembly's on its partner's axis (puzzlebot_mpc.axis_approach).

    A back-off that has not gained BACKOFF_PROGRESS in BACKOFF_STALL s is
    blocked (a robot behind the mover): the mover does not back off again for
    BACKOFF_REST s and follows the lane from where it is. A mover following
    the lane that has not come BACKOFF_PROGRESS nearer in FOLLOW_STALL s
    where the caller says a stall is a jam (a knob pair's mover alongside
    its partner's side, :func:`alongside`: pushing along it, it drags its
    partner round with it by friction) backs off and comes again.
    """

    def __init__(self):
        self.start = None           # (phase, time [s], behind [m]) when the current stretch started
        self.blocked_at = None      # time [s] the last back-off was found blocked

    def advise(self, phase, behind, now, alongside):
        """(may back off, back off now) for the mover; ``phase``: its last command's, ``behind`` [m]: how far
        its point is from where it is going (lane_state's, axis_approach's ``along``), ``now`` [s],
        ``alongside``: it is where a stall while following is a jam (:func:`alongside`; False: never)."""
        if self.start is None or self.start[0] != phase:
            self.start = (phase, now, behind)
        resting = self.blocked_at is not None and now - self.blocked_at < BACKOFF_REST
        _, t0, b0 = self.start
        if phase == BACKOFF:
            if now - t0 >= BACKOFF_STALL:
                if behind - b0 < BACKOFF_PROGRESS:
                    self.blocked_at, self.start = now, None
                    return False, False
                self.start = (phase, now, behind)
            return not resting, False
        if not alongside:
            self.start = (phase, now, behind)
            return not resting, False
        if now - t0 >= FOLLOW_STALL:
            self.start = (phase, now, behind)
            if b0 - behind < BACKOFF_PROGRESS and not resting:
                return True, True
        return not resting, False


def alongside(state, lane):
    """True when a mover in lane_state ``state`` runs along its partner's side on its lane, parallel: past
    the corner (less than ``standoff`` behind the hole) and up to the hole (a knob that stops there
    without seating, caught on the hole's edge, is jammed too), within OFF_LANE and MAX_CUT."""
    behind, off, dtheta, _ = state
    return -HOME < behind < lane.standoff and abs(off) <= OFF_LANE and abs(dtheta) <= MAX_CUT


def command(pair, mover, pose_i, pose_j, lane, phase=FOLLOW, may_back_off=True, retry=False, turn_back=False):
    """The mover's command for knob pair ``pair`` (robot_i the knob robot, robot_j the hole robot).

    ``mover``: "i" or "j"; ``pose_i``, ``pose_j``: (x, y, theta) [m, rad] in
    the world; ``lane``: :class:`KnobLane`; ``phase``: the phase of the last
    command (a mover backing out goes on to the end of its run);
    ``may_back_off``: False follows the lane from where the mover is;
    ``retry``: back off now, to come along the lane again (both from
    :class:`ProgressWatch`); ``turn_back``: the mover turns to its partner's
    heading while it backs off (a single robot or a row; a chain backs
    straight, see the module). The line
    follower steers the heading difference ``a`` to the lane's own heading
    ``a_lane`` less a cut towards the lane, proportional to the offset ``e``
    from it (along the holder's +y)::

        w = -v k sin(a - a_want),  a_want = a_lane - clip(k e / 4, +-MAX_CUT),  k = steer_gain

    near the lane a critically damped approach over the distance travelled.
    """
    behind, off, dtheta, out = lane_state(pair, mover, pose_i, pose_j, lane)
    run = lane.level if 0.0 <= behind < lane.standoff else lane.standoff     # alongside: no corner to pass
    need = min(lane.standoff_max, abs(off) / math.tan(MAX_CUT) + run)
    if may_back_off and (retry or phase == BACKOFF and behind < need + lane.lookahead
                         or abs(off) > OFF_LANE and behind < need):
        w = -lane.speed * lane.steer_gain * math.sin(dtheta) if turn_back else 0.0
        return KnobCommand(-lane.speed, max(-lane.turn_rate, min(lane.turn_rate, w)), BACKOFF)
    v = max(-0.5 * lane.speed, min(lane.speed, lane.speed_gain * behind))
    if behind > HOME:                                  # at least a creep up to the hole
        v = max(v, lane.creep)
    k = lane.steer_gain
    slope = -out * (lane.gap + lane.press) / (lane.standoff - lane.level) if lane.level < behind < lane.standoff \
        else 0.0
    e_left = out * off                                 # the offset along the holder's +y
    # inside the lane (pressed on the partner's side harder than the lane asks) the lane's slope is not
    # followed: heading into the side, the mover would only press on and drag its partner along
    follow_slope = min(1.0, max(0.0, 1.0 + off / lane.press)) if lane.press > 0 else float(off >= 0.0)
    want = math.atan(slope) * follow_slope - max(-MAX_CUT, min(MAX_CUT, 0.25 * k * e_left))
    if behind > HOME:
        w = -max(v, 0.0) * k * math.sin(dtheta - want)
        return KnobCommand(v, max(-lane.turn_rate, min(lane.turn_rate, w)), FOLLOW)
    if behind < -HOME:                                 # past the hole: back to it
        return KnobCommand(v, 0.0, FOLLOW)
    # at the hole: the mover turns to its partner's heading about its connection point (on the axle's
    # line: a centre speed of w times the point's y pivots there)
    w = max(-lane.turn_rate, min(lane.turn_rate, -lane.creep * k * math.sin(dtheta)))
    return KnobCommand(w * (pair.point_i if mover == "i" else pair.point_j)[1], w, FOLLOW)
