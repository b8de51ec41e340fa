"""An assembly docking an anchor pair comes along its partner's axis (a line follower, not the MPC).

A single robot docks well on the MPC's alignment cost and its approach
carrot (puzzlebot_mpc.pairs.alignment_points). An assembly that docks (a
row of two joining another row, front to back: a grid's or a bridge's
rows) does not: it turns at most ``assembly_turn_rate``, and over the
MPC's one-second horizon the carrot cannot bring it sideways onto the
axis, so it swings 5-20 mm across it until the couple times out.

Here the mover's connection point (the opening robot's C_o driving
forwards, or the anchor robot's C_a backing) follows the *axis*: the line
out from the holding robot's connection point along that point's heading.
In the axis frame (origin at the holding point, x out along the axis) the
moving point is ``along`` out and ``off`` across it, and ``psi`` is its
heading error (0: moving straight at the holding point)::

    psi_want = clip(off / cut_distance, +-MAX_CUT),  w = -s steer_gain sin(psi - psi_want)

at speed ``s`` (faster far out, ``creep`` close in and on into the mouth,
where Algorithm 2 and the docking manoeuvre take over as for any pair). A
mover off the axis by more than ``off_axis`` that is too close to get onto
it (``|off| / tan(MAX_CUT) + standoff``, at most ``standoff_max``: an
askew mover drifts off the axis as it backs, and without the cap its run
grew faster than it backed) backs straight out first, without turning, to
that run plus ``lookahead``; a back-off that gets nowhere (the
assembly behind it) is given up for a while, as the knob lane's is
(puzzlebot_mpc.knob_approach.ProgressWatch).
"""

import math
from dataclasses import dataclass

from puzzlebot_common.geometry import wrap_angle
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.knob_approach import BACKOFF, FOLLOW, MAX_CUT


@dataclass(frozen=True)
class AxisLane:
    """How an assembly comes along its partner's axis (lengths [m], speeds [m/s])."""

    standoff: float = 0.03         # the run it needs on the axis before the mouth ...
    off_axis: float = 0.0015       # ... when it is more than this off the axis
    lookahead: float = 0.04        # a mover that backs off goes this far beyond its run
    speed: float = 0.02            # largest speed along the axis
    speed_gain: float = 0.5        # 1/s: speed per metre to the mouth ...
    creep: float = 0.01            # ... but at least this, on into the mouth
    cut_distance: float = 0.008    # m: the offset is cut at 1 rad per this much of it (its e-folding run) ...
    steer_gain: float = 250.0      # 1/m: ... and the heading follows at this gain per metre travelled
    turn_rate: float = 0.15        # rad/s: largest turn rate (an assembly turns like a train)
    standoff_max: float = 0.15     # longest run a mover off the axis backs off for


@dataclass(frozen=True)
class AxisCommand:
    """The mover robot's command (v [m/s], w [rad/s]) and the phase that gave it."""

    v: float
    w: float
    phase: str


def axis_state(pair, mover, pose_i, pose_j):
    """(along [m], off [m], psi [rad], direction: +1 when the mover drives forwards, -1 backwards) of the
    mover's connection point in the holding point's axis frame (see the module)."""
    if mover == "i":
        hold_pose, hold_pt, move_pose, move_pt = pose_j, pair.point_j, pose_i, pair.point_i
    else:
        hold_pose, hold_pt, move_pose, move_pt = pose_i, pair.point_i, pose_j, pair.point_j
    q = pr.point_in_robot(hold_pose, pr.world_point(move_pose, move_pt)) - hold_pt[:2]
    c, s = math.cos(hold_pt[2]), math.sin(hold_pt[2])
    along, off = c * q[0] + s * q[1], -s * q[0] + c * q[1]
    heading = move_pose[2] + move_pt[2] - hold_pose[2] - hold_pt[2]     # the moving point's, in the axis frame
    direction = 1.0 if math.cos(move_pt[2]) > 0.0 else -1.0
    return along, off, wrap_angle(heading - math.pi), direction


def command(pair, mover, pose_i, pose_j, lane, phase=FOLLOW, may_back_off=True):
    """The mover's command for anchor pair ``pair`` (robot_i the anchor robot, robot_j the opening robot).

    ``mover``: "i" or "j"; poses (x, y, theta) [m, rad] in the world;
    ``lane``: :class:`AxisLane`; ``phase``: the phase of the last command (a
    mover backing out goes on to the end of its run); ``may_back_off``:
    False follows the axis from where the mover is (a back-off found
    blocked: knob_approach.ProgressWatch)."""
    along, off, psi, direction = axis_state(pair, mover, pose_i, pose_j)
    need = min(lane.standoff_max, abs(off) / math.tan(MAX_CUT) + lane.standoff)
    if may_back_off and (phase == BACKOFF and along < need + lane.lookahead
                         or abs(off) > lane.off_axis and along < need):
        return AxisCommand(-direction * lane.speed, 0.0, BACKOFF)
    s = max(lane.creep, min(lane.speed, lane.speed_gain * along))
    k = lane.steer_gain
    want = max(-MAX_CUT, min(MAX_CUT, off / lane.cut_distance))
    w = max(-lane.turn_rate, min(lane.turn_rate, -s * k * math.sin(psi - want)))
    return AxisCommand(direction * s, w, FOLLOW)
