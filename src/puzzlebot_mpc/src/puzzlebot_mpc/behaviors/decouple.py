"""``decouple``: the named coupled anchor pair (a, o) separates; a's anchor leaves o's opening.

Phase *wiggle*: the anchor robot a receives the paper's wiggle open loop,
``v = wiggle_v_bias, w = wiggle_w_amplitude sin(2 pi t / wiggle_period)``
(eq. "wiggle"; outside the MPC's own limits and butterfly set, within the
hardware limits), in attempts: when a period did not free the anchor, a
backs into o for a moment (the anchor goes back in) and wiggles again, to
the other side first (:func:`wiggle`); the MPC drives the robots coupled
to a straight on at a's speed (so they neither pull on a's front nor turn
with it), the opening robot o creeps back into its own assembly
at ``decouple_creep`` and the rest of o's assembly holds; an o that is not
coupled to other robots turns in place against a's swing instead
(:func:`partner_turn`, ``wiggle_partner_turn``). Released when, from the
measured poses, a's anchor point C_a is farther than anchor_length +
``decouple_clearance`` + eps from o's opening point C_o on
``decouple_confirm_steps`` steps in a row: an anchor that slides out of its
holder and turns in it cannot reach into the opening from there (the head
point H_a alone is not enough: when a turns against o, H_a leaves o's
footprint sideways while the anchor, free to turn in its holder, is still
in).

Phase *settle* (``decouple_settle_time``): a and o push back into their own
assemblies at ``decouple_settle_speed`` (away from each other; a robot
without an assembly rests), which straightens and re-seats the anchors the
wiggle bent; then it succeeds.

While it runs the pair is out of the pair book (no polygon constraint) but
keeps a slot in the MPC. Fails after ``timeout`` s (0: none); a decouple
that fails or is replaced puts the pair back among the coupled ones if it
still is coupled geometrically. Status errors: how far [m] the anchor head
is outside o's footprint (negative: inside). Progress: C_a's distance from
C_o over the release distance (1 once released, while settling).
"""

import math

import numpy as np

from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.behaviors.base import FAILED, SUCCEEDED, Behavior, BehaviorError, Progress

DECOUPLE = "decouple"


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


class Decouple(Behavior):
    name = DECOUPLE
    needs_poses = True

    def validate(self, poses=None):
        """State-free: two known robots. With poses: they are a coupled anchor pair that can separate
        on its own, with fresh poses (``self.pair``)."""
        req, ctx = self.req, self.ctx
        if len(req.pair) != 2:
            raise BehaviorError("decouple needs the pair's two robots, got %r" % (list(req.pair),))
        unknown = [r for r in req.pair if r not in ctx.index]
        if unknown:
            raise BehaviorError("decouple: unknown robot(s) %s" % ", ".join(map(repr, unknown)))
        self.pair = None
        if poses is None:               # whether they are coupled is checked when it starts
            return
        book = ctx.pairs
        pair = book.find(*req.pair)
        if pair is None or pair.key not in book.coupled:
            raise BehaviorError("decouple: %s and %s are not coupled; coupled pairs: %s"
                                % (req.pair[0], req.pair[1],
                                   ", ".join("%s-%s" % p.robots for p in book.coupled.values()) or "none"))
        if pair.type != pr.ANCHOR:
            raise BehaviorError("decouple: %s-%s is a knob-hole coupling (rigid); only anchor pairs are "
                                "decoupled by wiggling" % pair.robots)
        others = [p for p in book.coupled.values() if p.key != pair.key]
        if pair.robot_j in pr.assembly_of(pair.robot_i, ctx.names, others):
            raise BehaviorError("decouple: %s and %s are also coupled through other robots; the pair cannot "
                                "separate on its own" % pair.robots)
        self.need_poses(list(req.pair), poses)
        self.pair = pair

    def start(self, now, poses, static):
        """The pair leaves the pair book (held here until released); a's assembly (``self.a_side``) and
        o's (``self.o_side``) as they are without it."""
        message = super().start(now, poses, static)
        d = self.pair
        self.ctx.pairs.remove_coupled(d.key)
        d.status = pr.HEAD_INSERTED
        self.released_at = None          # time the pair separated (settle phase from then on)
        self.released_share = float("nan")  # C_a's distance from C_o over the release distance (progress)
        self.release_count = 0           # consecutive steps the release was seen
        self.release_message = ""
        self.robots = list(d.robots)
        self.a_side = self.ctx.assembly_of(d.robot_i)
        self.o_side = self.ctx.assembly_of(d.robot_j)
        return message

    def pair_slots(self):
        return [] if self.pair is None else [self.pair]

    def done(self, poses):
        """A decouple that ends (or is replaced) leaves its pair coupled if it still is geometrically."""
        d = self.pair
        if d is None:
            return
        self.pair = None
        if poses is not None and self.decoupled(d, poses) is False:
            self.ctx.pairs.add_coupled(d)

    # ------------------------------------------------------------------ release
    @staticmethod
    def separation(pair, poses):
        """Distance [m] between a's anchor point C_a and o's opening point C_o (None: no pose)."""
        pi, pj = poses.get(pair.robot_i), poses.get(pair.robot_j)
        if pi is None or pj is None:
            return None
        return pr.alignment_error(pair, pi, pj)[0]

    def decoupled(self, pair, poses):
        """True when C_a is farther than anchor_length + decouple_clearance + eps from C_o (None: no pose)."""
        d = self.separation(pair, poses)
        if d is None:
            return None
        s = self.settings
        return d > self.ctx.geometry.anchor_length + s.decouple_clearance + s.pair_epsilon

    def status(self, now, poses, newly, lost, elapsed):
        d = self.pair
        pi, pj = poses.get(d.robot_i), poses.get(d.robot_j)
        if pi is None or pj is None:
            return Progress(errors=[float("nan")])
        margin = pr.head_margin(d, pi, pj, self.ctx.geometry.footprint())
        sep = self.separation(d, poses)
        s = self.settings
        self.released_share = min(1.0, sep / (self.ctx.geometry.anchor_length + s.decouple_clearance +
                                              s.pair_epsilon))
        if self.released_at is None:
            self.release_count = self.release_count + 1 if self.decoupled(d, poses) else 0
            if self.release_count >= self.settings.decouple_confirm_steps:
                self.released_at = now
                d.status = pr.DECOUPLED
                self.release_message = "%s-%s decoupled after %.2f s (C_a %.1f mm from C_o, anchor head " \
                    "%.1f mm outside %s)" % (d.robot_i, d.robot_j, elapsed, 1e3 * sep, -1e3 * margin, d.robot_j)
        if self.released_at is None:
            return Progress(message="wiggling %s out of %s (C_a %.1f mm from C_o)" % (d.robot_i, d.robot_j,
                                                                                        1e3 * sep),
                            errors=[-margin])
        if now - self.released_at >= self.settings.decouple_settle_time - 1e-9:
            self.pair = None             # released: it stays out of the pair book
            return Progress(SUCCEEDED, self.release_message + "; assemblies settled", [-margin])
        return Progress(message=self.release_message + "; settling", errors=[-margin])

    def completion(self, errors, elapsed):
        return 1.0 if self.released_at is not None else self.released_share

    def timed_out(self, now, poses, errors, elapsed):
        message = "timeout after %.2f s; %s-%s still coupled" % ((elapsed,) + tuple(self.robots))
        self.done(poses)
        return Progress(FAILED, message, errors)

    # --------------------------------------------------------------- objectives
    def objectives(self, obj, now, poses):
        """Wiggle phase: a wiggles open loop, its assembly drives straight on at v_bias, o creeps back into
        its assembly, which holds. Settle phase: a and o push back into their assemblies, which hold."""
        s, d, index = self.settings, self.pair, self.ctx.index
        a, o = index[d.robot_i], index[d.robot_j]
        hold = self.hold()
        for m in self.a_side + self.o_side:
            obj.velocity_mask[index[m]] = hold
        # a robot pushes back into its own assembly only when it has one (alone, it would only drag its partner)
        a_push = s.decouple_settle_speed if len(self.a_side) > 1 else 0.0
        o_push = s.decouple_settle_speed if len(self.o_side) > 1 else 0.0
        if self.released_at is None:
            obj.velocity = self.wiggle_profile(now)
            v, w, phase = self._wiggle(now, poses)
            obj.open_loop[a] = (v, w)
            for m in self.a_side:         # a's partners in front go along straight (back in while it reseats)
                if m != d.robot_i:
                    obj.velocity[index[m]] = (v, 0.0)
                    obj.velocity_mask[index[m]] = 1.0
            obj.velocity[o] = (-s.decouple_creep if o_push else 0.0, 0.0)
            w_o = partner_turn(s, w, phase, len(self.o_side))
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
        d = self.pair
        pi, pj = (poses.get(d.robot_i), poses.get(d.robot_j)) if poses else (None, None)
        rel = None if pi is None or pj is None else math.remainder(pi[2] - pj[2], 2 * math.pi)
        return wiggle(self.settings, self._since_start(now), rel)

    def _since_start(self, now):
        """[s] since the decouple started (``now`` None: 0)."""
        return (now if now is not None else self.start_time) - self.start_time

    def wiggle_profile(self, now):
        """The wiggle over the horizon, within the MPC's own limits: the MPC's prediction of the anchor
        robot (its partners react to it), while the robot itself receives :meth:`wiggle_command`."""
        s, index = self.settings, self.ctx.index
        vel = np.zeros((len(self.ctx.names), s.horizon, 2))
        d = self.pair
        i, j = index[d.robot_i], index[d.robot_j]
        t = self._since_start(now)
        for k in range(s.horizon):
            v, w, phase = wiggle(s, t + s.dt * (k + 1))
            vel[i, k] = (float(np.clip(v, -s.v_max, s.v_max)), float(np.clip(w, -s.w_max, s.w_max)))
            w_o = partner_turn(s, w, phase, len(self.o_side))
            if w_o is not None:
                vel[j, k] = (0.0, float(np.clip(w_o, -s.w_max, s.w_max)))
        return vel
