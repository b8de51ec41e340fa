"""Plausibility gate for motion-capture poses: one bad frame must never drive a robot.

Motion capture delivers implausible frames now and then: a marker swap flips
the heading by pi, a ghost marker or a reflection moves a subject by
centimetres or metres for a frame or a few, a broken bridge sends NaN or a
zero quaternion. Every consumer of the poses (the lab driver's velocity
loop, the MPC) puts each robot's frames through one :class:`PoseGate`,
built from that robot's configured limits (top speed ``v_max`` [m/s], turn
rate ``w_max`` [rad/s]) and the margins of :class:`PoseGateParams`.

A frame ``(stamp [s], x [m], y [m], yaw [rad] or quaternion (x, y, z, w))``
in the world frame is rejected, with a kind and a reason naming the figures,
when

===================  =======================================================
kind                 rule
===================  =======================================================
``non-finite``       a field (stamp, x, y, z, yaw, a quaternion component) is NaN or inf
``quaternion``       the quaternion's norm differs from 1 by more than ``quaternion_tolerance``
``out of range``     \\|x\\|, \\|y\\| or \\|z\\| exceeds ``position_limit`` (outside any capture volume)
``order``            the stamp is older than the last accepted frame's, or equal with a pose
                     beyond the per-frame margins
``jump``             it moved farther from the last accepted frame than
                     ``speed_margin v_max dt + position_margin`` (dt: the stamps' difference)
``turn``             its heading turned more than ``speed_margin w_max dt + yaw_margin``
===================  =======================================================

A frame stamped like the last accepted one is accepted as a *duplicate* if
it lies within the per-frame margins of it (it replaces it: the simulation
re-sends frames while it waits in lockstep, the in-process harness measures
again at the same instant), else rejected (``order``).

After a rejection the gate *holds* the robot until ``reacquire_frames``
frames in a row were accepted: frames plausible from the last accepted one
are accepted meanwhile (the pose stays current), but :attr:`PoseGate.held`
tells the planner not to trust it yet. If the robot really moved (the
subject was re-identified elsewhere), the rejected frames form a new track:
once ``reacquire_frames`` of them in a row are plausible from each other,
the gate re-acquires on that track (``Verdict.reacquired``: a consumer that
differentiates poses must restart there). While frames keep being rejected,
the last accepted pose ages, and the consumers' staleness rules stop the
robot as for a lost subject.
"""

import math
import numbers
from dataclasses import dataclass
from typing import Optional

from puzzlebot_common.config import load_section, shipped_config
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import wrap_angle, yaw_from_quaternion
from puzzlebot_common.params import from_mapping, require_positive

NON_FINITE = "non-finite"
QUATERNION = "quaternion"
OUT_OF_RANGE = "out of range"
ORDER = "order"
JUMP = "jump"
TURN = "turn"
#: Every rejection kind, in the order the rules are applied.
KINDS = (NON_FINITE, QUATERNION, OUT_OF_RANGE, ORDER, JUMP, TURN)


@dataclass(frozen=True)
class PoseGateParams:
    """Margins of the pose gate (``config/pose_gate.yaml`` of puzzlebot_common, ``~pose_gate``).

    The speed and turn-rate bounds are the robot's own limits (the driver's
    ``v_limit``/``w_limit``, the MPC's ``hardware_v_max``/``hardware_w_max``)
    times ``speed_margin``; the per-frame margins cover mocap noise and
    stamp jitter.
    """

    speed_margin: float = 1.5          # -, implied speed / turn rate allowed = robot limit x this ...
    position_margin: float = 0.01      # m, ... plus this distance per frame (noise; the lab's Vicon: 0.2 mm)
    yaw_margin: float = 0.3            # rad, ... plus this heading change per frame (a flip by pi is rejected)
    quaternion_tolerance: float = 0.05  # -, | |q| - 1 | above this: rejected (a zero quaternion has norm 0)
    position_limit: float = 50.0       # m, |x|, |y|, |z| above this: rejected (no capture volume is that large)
    reacquire_frames: int = 15         # accepted frames in a row that end a hold, or rejected but mutually
                                       # plausible frames in a row that become the new track (15 = 0.15 s at
                                       # 100 Hz: longer than a burst of ghost frames)
    log_period: float = 1.0            # s, rejections are logged at most once per robot, kind and period

    @classmethod
    def from_dict(cls, data, where="pose_gate"):
        return from_mapping(cls, data, where)

    def check(self, where="pose_gate"):
        require_positive(self, ["speed_margin", "position_limit", "reacquire_frames", "log_period"], where)
        for key in ("position_margin", "yaw_margin", "quaternion_tolerance"):
            if getattr(self, key) < 0:
                raise ConfigError("%s.%s: must be >= 0, got %r" % (where, key, getattr(self, key)))
        if self.quaternion_tolerance >= 1.0:
            raise ConfigError("%s.quaternion_tolerance: must be below 1 (a zero quaternion must fail), got %r"
                              % (where, self.quaternion_tolerance))


def shipped_params():
    """PoseGateParams of the shipped ``puzzlebot_common/config/pose_gate.yaml`` (what the launch files load)."""
    path = shipped_config("puzzlebot_common", "pose_gate.yaml")
    return PoseGateParams.from_dict(load_section(path, "pose_gate", required=True), where="%s: pose_gate" % path)


@dataclass(frozen=True)
class Frame:
    """One accepted pose: stamp [s], x, y [m], yaw [rad] (world frame)."""

    stamp: float
    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class Verdict:
    """What the gate made of one frame."""

    accepted: bool
    yaw: float = math.nan        # rad, the frame's heading (from the quaternion if one was given)
    kind: str = ""               # rejection kind (KINDS), "" if accepted
    reason: str = ""             # why it was rejected, with the figures
    duplicate: bool = False      # stamped like the last accepted frame (a repeat, or a re-measurement within the
                                 # margins, which replaces it): no new instant, nothing to differentiate
    reacquired: bool = False     # accepted as the start of a new track (poses jumped: restart differences)
    resumed: bool = False        # this frame ended a hold


def _finite(value):
    """True for a finite real number (numpy scalars included; bools, None, strings are not)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:       # an int too large for a float
        return False


class PoseGate:
    """Accept or reject the mocap frames of one robot (see the module docstring)."""

    def __init__(self, name, v_max, w_max, params=PoseGateParams()):
        """``v_max`` [m/s], ``w_max`` [rad/s]: the robot's configured limits."""
        if not (_finite(v_max) and _finite(w_max) and v_max > 0 and w_max > 0):
            raise ConfigError("pose gate of %s: v_max and w_max must be > 0, got %r, %r" % (name, v_max, w_max))
        self.name = name
        self.params = params
        self.max_speed = params.speed_margin * v_max      # m/s
        self.max_turn_rate = params.speed_margin * w_max  # rad/s
        self.last: Optional[Frame] = None                 # the last accepted frame
        self.held = False                                 # a rejection not yet followed by enough good frames
        self.counts = {k: 0 for k in KINDS}               # rejections by kind
        self.reacquisitions = 0
        self.last_rejection = ""                          # reason of the latest rejection
        self._good_run = 0                                # frames accepted in a row since the last rejection
        self._candidate = []                              # rejected, mutually plausible frames (a new track?)
        self._candidate_problem = ("", "")                # (kind, reason) of the candidate's first frame

    @property
    def rejected(self):
        """Frames rejected so far."""
        return sum(self.counts.values())

    def check(self, stamp, x, y, yaw=None, quaternion=None, z=0.0):
        """Judge one frame. The heading is ``yaw`` [rad] or, without it, the yaw of ``quaternion``
        (x, y, z, w); a quaternion given is checked either way (finite, unit norm), so a consumer
        that corrects the yaw (e.g. a marker offset) passes both. Never raises."""
        fields = {"stamp": stamp, "x": x, "y": y, "z": z}
        if quaternion is not None:
            fields.update(zip(("qx", "qy", "qz", "qw"), quaternion))
        if yaw is not None or quaternion is None:
            fields["yaw"] = yaw
        bad = [k for k, v in fields.items() if not _finite(v)]
        if bad:
            return self._reject(NON_FINITE, "non-finite %s (%s)"
                                % (", ".join(bad), ", ".join("%s=%r" % (k, fields[k]) for k in bad)))
        if quaternion is not None:
            norm = math.sqrt(sum(c * c for c in quaternion))
            if abs(norm - 1.0) > self.params.quaternion_tolerance:
                return self._reject(QUATERNION, "quaternion (%.4g, %.4g, %.4g, %.4g) has norm %.4g, not 1 "
                                    "(tolerance %.3g)" % (tuple(quaternion) + (norm, self.params.quaternion_tolerance)))
            if yaw is None:
                yaw = yaw_from_quaternion(*quaternion)
        limit = self.params.position_limit
        far = [("%s=%.4g m" % (k, v)) for k, v in (("x", x), ("y", y), ("z", z)) if abs(v) > limit]
        if far:
            return self._reject(OUT_OF_RANGE, "position %s beyond position_limit %.4g m" % (", ".join(far), limit))
        frame = Frame(float(stamp), float(x), float(y), float(yaw))
        last = self.last
        if last is None:
            return self._accept(frame)
        dt = frame.stamp - last.stamp
        if dt < 0:
            return self._reject(ORDER, "stamp %.6f s is older than the last accepted one (%.6f s)"
                                % (frame.stamp, last.stamp))
        if dt == 0:                    # a repeat, or a re-measurement of the same instant: replaces it
            problem = self._implausible(last, frame)
            if problem is not None:
                return self._reject(ORDER, "stamp %.6f s repeats the last accepted one with another pose: %s"
                                    % (frame.stamp, problem[1]))
            self.last = frame
            return Verdict(True, frame.yaw, duplicate=True)
        # A frame that continues the rejected frames' track (a ghost that persists) stays on that track,
        # even once the time since the last accepted frame would make it plausible from there: the jump
        # happened between two frames. Otherwise a frame plausible from the last accepted one continues
        # the robot's track, and an implausible one starts a new candidate track.
        if self._candidate and self._implausible(self._candidate[-1], frame) is None:
            self._candidate.append(frame)
            kind, reason = self._candidate_problem
            reason = "%s; %d frame(s) since continue that track (%d re-acquire it)" % (
                reason, len(self._candidate) - 1, self.params.reacquire_frames)
        else:
            problem = self._implausible(last, frame)
            if problem is None:
                return self._accept(frame)
            self._candidate, self._candidate_problem = [frame], problem
            kind, reason = problem
        if len(self._candidate) < self.params.reacquire_frames:
            return self._reject(kind, reason)
        first = self._candidate[0]
        self._candidate = []
        self.last, self.held, self._good_run = frame, False, 0
        self.reacquisitions += 1
        return Verdict(True, frame.yaw, reacquired=True, resumed=True,
                       reason="re-acquired on a new track after %d consistent frames (%.3f m, %.2f rad from the "
                              "last accepted pose)" % (self.params.reacquire_frames,
                                                       math.hypot(first.x - last.x, first.y - last.y),
                                                       abs(wrap_angle(first.yaw - last.yaw))))

    # --------------------------------------------------------------- helpers
    def _implausible(self, a, b):
        """(kind, reason) if frame ``b`` cannot follow frame ``a``, else None."""
        dt = b.stamp - a.stamp
        if dt < 0:
            return ORDER, "stamp %.6f s is older than %.6f s" % (b.stamp, a.stamp)
        p = self.params
        dist = math.hypot(b.x - a.x, b.y - a.y)
        allowed = self.max_speed * dt + p.position_margin
        if dist > allowed:
            return JUMP, ("jumped %.4g m in %.3f s (allowed %.4f m: %.2f m/s + %.3f m)"
                          % (dist, dt, allowed, self.max_speed, p.position_margin))
        turn = abs(wrap_angle(b.yaw - a.yaw))
        allowed = self.max_turn_rate * dt + p.yaw_margin
        if turn > allowed:
            return TURN, ("heading turned %.3f rad in %.3f s (allowed %.3f rad: %.1f rad/s + %.2f rad)"
                          % (turn, dt, allowed, self.max_turn_rate, p.yaw_margin))
        return None

    def _accept(self, frame):
        self.last = frame
        self._candidate = []
        resumed = False
        if self.held:
            self._good_run += 1
            if self._good_run >= self.params.reacquire_frames:
                self.held, resumed = False, True
        return Verdict(True, frame.yaw, resumed=resumed)

    def _reject(self, kind, reason):
        self.counts[kind] += 1
        self.held, self._good_run = True, 0
        self.last_rejection = reason
        return Verdict(False, kind=kind, reason=reason)
