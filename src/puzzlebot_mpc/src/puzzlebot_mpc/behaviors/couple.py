"""``couple``: the robots form a target configuration (the paper's Algorithm 3).

The target is a name (config/targets.yaml, or a generator: ``line``,
``row``) or explicit ``slots`` (x [m], y [m], heading [rad] in the assembly
frame), one per named robot. With ``groups`` (robot counts) the named robots
are split into consecutive groups of those sizes and every group forms its
own copy of the named target, where it stands (several assemblies at once;
each group's assignment is independent). At the start the goal pairs follow
from the target and the start poses (targets.assign: MST + Hungarian); every step the
pair book picks every conflict-free pair that can go now (pairs.PairBook.
assign_active: sub-assemblies form in parallel, single robots join them,
assemblies join each other) and updates their status (Algorithm 2, and for
anchor pairs the docking manoeuvre that proves them seated:
puzzlebot_mpc.docking). In each active pair one side docks (the mover: a
single robot, or the smaller assembly driving as one body) and the other
holds still. Succeeds when every goal pair is coupled; a goal pair lost on
the way, or found open afterwards, is a goal again. Fails after ``timeout``
s (0: none), naming the pairs not coupled. Status errors: per goal pair, the
distance [m] between its connection points (NaN without poses).
"""

import math
from dataclasses import replace

import numpy as np

from puzzlebot_common.geometry import transform_point
from puzzlebot_mpc import docking as dk
from puzzlebot_mpc import axis_approach, knob_approach
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.room import assembly_room
from puzzlebot_mpc.behaviors.base import FAILED, SUCCEEDED, Behavior, BehaviorError, Progress, finite
from puzzlebot_mpc.targets import TargetError, assign, merge_assignments, resolve_target

COUPLE = "couple"


class Couple(Behavior):
    name = COUPLE
    needs_poses = True
    assigns_active_pairs = True

    def validate(self, poses=None):
        """State-free: the slots and the target. With poses: poses, existing couplings, the assignment
        (``self.assignment``)."""
        req, robots, ctx = self.req, self.robots, self.ctx
        if req.slots and not all(len(sl) == 3 and finite(sl) for sl in req.slots):
            raise BehaviorError("couple: every slot must be a finite (x, y, heading)")
        groups = self.groups()
        targets = []
        for group in groups:
            try:
                target = resolve_target(req.target, [tuple(sl) for sl in req.slots], len(group), ctx.targets,
                                        ctx.geometry)
            except TargetError as e:
                raise BehaviorError("couple: %s" % e)
            if len(target.slots) > len(group):
                raise BehaviorError("couple: target %r has %d slots but only %d robot(s) were given"
                                    % (target.name, len(target.slots), len(group)))
            if len(target.slots) < len(group):
                raise BehaviorError("couple: target %r has %d slots for %d robots; name the robots to use"
                                    % (target.name, len(target.slots), len(group)))
            targets.append(target)
        self.need_poses(robots, poses)
        self.assignment = None
        if poses is None:
            return
        for p in ctx.pairs.coupled.values():
            inside = [r in robots for r in p.robots]
            if any(inside) and not all(inside):
                raise BehaviorError("couple: %s is coupled to %s, which is not in the request; decouple it first "
                                    "or include it" % tuple(p.robots if inside[0] else p.robots[::-1]))
        try:
            assignment = merge_assignments([assign(t, g, np.array([poses[r] for r in g], float), ctx.geometry)
                                            for t, g in zip(targets, groups)])
        except TargetError as e:
            raise BehaviorError("couple: %s" % e)
        goal_keys = {p.key for p in assignment.pairs}
        for p in ctx.pairs.coupled.values():
            if p.robot_i in robots and p.key not in goal_keys:
                raise BehaviorError("couple: %s and %s are coupled but the target assignment does not join "
                                    "them that way; decouple them first" % p.robots)
        self.assignment = assignment

    def groups(self):
        """The named robots split by the request's ``groups`` (counts, in order; none: one group)."""
        req, robots = self.req, self.robots
        if not req.groups:
            return [robots]
        sizes = list(req.groups)
        if any(isinstance(k, bool) or int(k) != k or k < 2 for k in sizes) or sum(sizes) != len(robots):
            raise BehaviorError("couple: groups must be robot counts >= 2 adding up to the %d named robot(s), "
                                "got %r" % (len(robots), sizes))
        if req.slots:
            raise BehaviorError("couple: groups need a target name (each group forms its own copy), not slots")
        out, k = [], 0
        for n in sizes:
            out.append(robots[k:k + int(n)])
            k += int(n)
        return out

    def start(self, now, poses, static):
        super().start(now, poses, static)
        a = self.assignment
        self.ctx.pairs.set_goals(a.pairs, a.priority)
        self.ctx.pairs.repair = True
        self.knob_phase = {}             # knob pair key -> the phase of its mover's last command (knob_approach)
        self.watch = {}                  # knob pair or axis-lane pair key -> its knob_approach.ProgressWatch
        self.axis_phase = {}             # anchor pair key -> the phase of its assembly mover's last command
        return "goal pairs: " + ", ".join("%s->%s" % p.key for p in a.pairs)

    def status(self, now, poses, newly, lost, elapsed):
        book, a = self.ctx.pairs, self.assignment
        keys = {p.key for p in a.pairs}
        for p in lost:                    # a goal pair lost on the way (pulled apart) is a goal again
            if p.key in keys and p not in book.goals:
                p.status = pr.DECOUPLED
                book.goals.append(p)
        errors = []
        for p in a.pairs:
            pi, pj = poses.get(p.robot_i), poses.get(p.robot_j)
            errors.append(float("nan") if pi is None or pj is None else pr.alignment_error(p, pi, pj)[0])
        if not book.goals:
            still_open = self.open_pairs(poses)
            if still_open:                # the seat monitor re-seats them (dock_repair_time)
                return Progress(message="all %d pair(s) coupled; waiting for %s to close" % (
                    len(a.pairs), ", ".join(still_open)), errors=errors)
            return Progress(SUCCEEDED, "all %d pair(s) coupled after %.2f s: %s" % (
                len(a.pairs), elapsed, ", ".join("%s->%s" % p.key for p in a.pairs)), errors)
        return Progress(message="%d of %d pair(s) coupled; active: %s" % (
            len(a.pairs) - len(book.goals), len(a.pairs),
            ", ".join(p.describe() for p in book.active) or "none"), errors=errors)

    def open_pairs(self, poses):
        """The target's coupled pairs that look open now ("i-j" names; none with docking off): anchor pairs
        with their faces more than ``dock_repair_gap`` apart, knob pairs with the knob more than
        ``knob_seat_tolerance`` off its hole. The couple does not succeed while one is, since the seat
        monitor sends such a pair back after ``dock_repair_time``."""
        book = self.ctx.pairs
        if book.dock_settings is None:
            return []
        out = []
        for p in self.assignment.pairs:
            pi, pj = poses.get(p.robot_i), poses.get(p.robot_j)
            if p.key not in book.coupled or pi is None or pj is None:
                continue
            if p.type == pr.ANCHOR:
                is_open = dk.seat_measure(p, pi, pj)[0] > book.dock_settings.repair_gap
            else:
                is_open = pr.knob_offset(p, pi, pj) > book.seating.knob
            if is_open:
                out.append("%s-%s" % p.key)
        return out

    def completion(self, errors, elapsed):
        """The share of the goal pairs coupled."""
        total = len(self.assignment.pairs)
        return (total - len(self.ctx.pairs.goals)) / total if total else 1.0

    def timed_out(self, now, poses, errors, elapsed):
        return Progress(FAILED, "timeout after %.2f s; not coupled: %s" % (
            elapsed, ", ".join(p.describe() for p in self.ctx.pairs.goals)), errors)

    def objectives(self, obj, now, poses):
        """Per active pair: the mover's assembly is free (the MPC's alignment cost brings it in, its
        couplings keep it together), the other side holds still (rest cost scaled by hold_scale). While
        the docking manoeuvre drives a pair (push, pull, back off), the mover gets the manoeuvre's command
        (sent as is) and the rest of its assembly the rigid-body speeds that go with it; the pair's
        alignment cost is off (the manager marks it inactive). During a nudge the anchor robot braces
        (Docking.brace) and the rest of its assembly backs in with it as one body, all sent as is: the
        anchor robot bracing alone, against its assembly's hold, pulls its own front pair open (measured,
        docs/mpc.md "Seating").

        A seed pair (two single robots) lines up with both robots moving (the partner only turning when
        another robot stands within ``seed_holder_clearance``); once its anchor head is in the
        opening (head_aligned) the partner holds still while the mover pushes the anchor home (otherwise
        the partner gives way and the pair drives off together, into the robots around it). A pair inside
        one assembly (closing a loop) holds on both sides, except that an anchor pair that closes a loop (the
        second anchor pair between two rows of a grid or a bridge) frees the opening robot's row (its
        robots joined by knob pairs): the alignment cost turns it about the anchor pair already coupled.
        """
        ctx, hold = self.ctx, self.hold()
        book = ctx.pairs
        for p in book.active:
            mover = ctx.mover(p)
            gi, gj = ctx.assembly_of(p.robot_i), ctx.assembly_of(p.robot_j)
            if mover is None:            # a loop closure: both hold; closing an anchor pair, the opening
                row = book.row_of(p.robot_j) if p.type == pr.ANCHOR else ()   # robot's row turns onto it
                for m in set(gi) | set(gj):
                    obj.velocity_mask[ctx.index[m]] = 0.0 if m in row else hold
                continue
            mg, hg = (gi, gj) if mover == "i" else (gj, gi)
            m_robot, h_robot = (p.robot_i, p.robot_j) if mover == "i" else (p.robot_j, p.robot_i)
            if p.type == pr.KNOB:
                self.knob_objectives(obj, p, mover, m_robot, mg, hg, poses, now)
                continue
            dock = book.docking.get(p.key)
            driven = dock is not None and dock.phase in dk.DRIVEN
            if self.on_axis_lane(p):
                self.axis_objectives(obj, p, mover, m_robot, mg, hg, poses, now)
                continue
            seed = len(mg) == len(hg) == 1
            for m in hg:
                free = seed and not driven and p.status != pr.HEAD_ALIGNED
                turn_only = free and self.crowded(m, p.robots, poses)
                obj.velocity_mask[ctx.index[m]] = (hold, 0.0) if turn_only else 0.0 if free else hold
            if not driven:
                for m in mg:
                    obj.velocity_mask[ctx.index[m]] = 0.0
                continue
            pm, ph = poses.get(m_robot), poses.get(h_robot)
            if pm is None or ph is None:
                continue
            cmd = dock.command(pm[2], ph[2])
            s = self.settings
            v, w = float(np.clip(cmd.v, -s.v_max, s.v_max)), float(np.clip(cmd.w, -s.w_max, s.w_max))
            self.rigid_velocities(obj.velocity, m_robot, v, w, mg, poses)
            for m in mg:
                obj.velocity_mask[ctx.index[m]] = (1.0, 1.0) if m == m_robot else (1.0, 0.0)
            obj.open_loop[ctx.index[m_robot]] = (cmd.v, cmd.w)
            brace = dock.brace()
            if brace is not None:            # the anchor robot's whole assembly backs into the mover, as one body
                braced = self.rigid_velocities(np.zeros((len(ctx.index), 2)), h_robot, brace.v, brace.w, hg, poses)
                for m in hg:
                    obj.open_loop[ctx.index[m]] = tuple(float(x) for x in braced[ctx.index[m]])
        self.stage(obj, poses)

    def mover_tracks(self, obj, pair, m_robot, mg, hg, poses, command_of):
        """The partner's assembly ``hg`` holds still; the mover robot ``m_robot`` tracks the command
        ``command_of(pose_i, pose_j)`` gives (``v`` [m/s], ``w`` [rad/s]), the rest of its assembly ``mg`` the
        rigid-body speeds that go with it (the MPC tracks them; couplings and stage edges still hold). A knob
        mover's back-off with a robot in its way makes room instead (:meth:`make_room`; an assembly backing
        off its partner's axis does not: measured, it joined less often, docs/mpc.md)."""
        ctx = self.ctx
        for m in hg:
            obj.velocity_mask[ctx.index[m]] = self.hold()
        pi, pj = poses.get(pair.robot_i), poses.get(pair.robot_j)
        if pi is None or pj is None:
            return
        cmd = command_of(pi, pj)
        self.rigid_velocities(obj.velocity, m_robot, cmd.v, cmd.w, mg, poses)
        for m in mg:
            obj.velocity_mask[ctx.index[m]] = (1.0, 1.0) if m == m_robot else (1.0, 0.0)
        if cmd.phase == knob_approach.BACKOFF and pair.type == pr.KNOB:
            h_robot = pair.robot_j if m_robot == pair.robot_i else pair.robot_i
            self.make_room(obj, h_robot, mg, hg, poses, speed=abs(cmd.v))

    def knob_objectives(self, obj, pair, mover, m_robot, mg, hg, poses, now):
        """A knob pair's mover robot follows :mod:`puzzlebot_mpc.knob_approach`'s lane along its partner's
        side (:meth:`mover_tracks`; an assembly turning at most assembly_turn_rate)."""
        s = self.settings
        lane = s.knob_lane()
        if len(mg) > 1:                  # an assembly turns like a train
            lane = replace(lane, turn_rate=min(lane.turn_rate, s.assembly_turn_rate))

        def knob_command(pi, pj):
            phase = self.knob_phase.get(pair.key, knob_approach.FOLLOW)
            state = knob_approach.lane_state(pair, mover, pi, pj, lane)
            watch = self.watch.setdefault(pair.key, knob_approach.ProgressWatch())
            free, retry = watch.advise(phase, state[0], now, knob_approach.alongside(state, lane))
            cmd = knob_approach.command(pair, mover, pi, pj, lane, phase, may_back_off=free, retry=retry,
                                        turn_back=self.rigid(m_robot, mg))
            self.knob_phase[pair.key] = cmd.phase
            return cmd
        self.mover_tracks(obj, pair, m_robot, mg, hg, poses, knob_command)

    def make_room(self, obj, h_robot, mg, hg, poses, speed):
        """A knob mover's assembly ``mg`` backing off with another robot ``backoff_clearance`` [m] or nearer
        behind it stops; its partner's assembly ``hg`` drives straight ahead instead (rigid-body speeds of
        ``speed`` [m/s] at ``h_robot``) while it has that much room in front (room.assembly_room)."""
        geo, index, clearance = self.ctx.geometry, self.ctx.index, self.settings.backoff_clearance
        exclude = set(mg) | set(hg)
        if assembly_room(poses, mg, False, geo, exclude) > clearance:
            return
        for m in mg:
            obj.velocity[index[m]] = (0.0, 0.0)
            obj.velocity_mask[index[m]] = (1.0, 1.0)
        if assembly_room(poses, hg, True, geo, exclude) > clearance:
            self.rigid_velocities(obj.velocity, h_robot, speed, 0.0, hg, poses)
            for m in hg:
                obj.velocity_mask[index[m]] = (1.0, 1.0) if m == h_robot else (1.0, 0.0)

    def rigid(self, robot, members):
        """True when the assembly ``members`` of ``robot`` is one rigid body: a single robot, or a row (its
        robots side by side on knob pairs, no anchor pair among them). It may turn while it backs off; a
        chain that does jack-knifes."""
        return set(self.ctx.pairs.row_of(robot)) == set(members)

    def on_axis_lane(self, pair):
        """True for an active anchor pair whose mover is an assembly approaching (:mod:`axis_approach`)."""
        ctx = self.ctx
        mover = ctx.mover(pair)
        dock = ctx.pairs.docking.get(pair.key)
        if pair.type != pr.ANCHOR or mover is None or dock is None or dock.phase != dk.APPROACH:
            return False
        return len(ctx.assembly_of(pair.robot_i if mover == "i" else pair.robot_j)) > 1

    def axis_objectives(self, obj, pair, mover, m_robot, mg, hg, poses, now):
        """An assembly docking an anchor pair: its mover robot follows :mod:`puzzlebot_mpc.axis_approach`
        along its partner's axis (:meth:`mover_tracks`)."""
        s = self.settings
        lane = axis_approach.AxisLane(lookahead=s.approach_lookahead, turn_rate=s.assembly_turn_rate)

        def axis_command(pi, pj):
            phase = self.axis_phase.get(pair.key, axis_approach.FOLLOW)
            along = axis_approach.axis_state(pair, mover, pi, pj)[0]
            free, _ = self.watch.setdefault(pair.key, knob_approach.ProgressWatch()).advise(phase, along, now, False)
            cmd = axis_approach.command(pair, mover, pi, pj, lane, phase, may_back_off=free)
            self.axis_phase[pair.key] = cmd.phase
            return cmd
        self.mover_tracks(obj, pair, m_robot, mg, hg, poses, axis_command)

    def staging(self, poses):
        """{robot: (x, y) [m, world]}: where the robots that wait for a busy partner stand ready.

        A goal pair that is not active because its partner is busy (in an
        active pair, or part of an assembly) makes its other robot, when that
        one is a single robot with no active pair, drive to the pose from which
        the pair's approach is short: both headings the partner's, the
        connection points ``stage_standoff`` apart along the partner point's
        outward direction. A line that grows from its tail then has its next
        robot lined up in front of the robot docking now. None with
        ``stage_standoff`` 0.
        """
        s, ctx, book = self.settings, self.ctx, self.ctx.pairs
        if s.stage_standoff <= 0:
            return {}
        busy = {r for q in book.active for end in q.robots for r in ctx.assembly_of(end)}
        out = {}
        for q in book.goals:
            if q in book.active:
                continue
            for r, partner, pt_r, pt_p in ((q.robot_i, q.robot_j, q.point_i, q.point_j),
                                           (q.robot_j, q.robot_i, q.point_j, q.point_i)):
                if r in busy or r in out or len(ctx.assembly_of(r)) > 1:
                    continue
                if partner not in busy and len(ctx.assembly_of(partner)) == 1:
                    continue
                pose = poses.get(partner) if poses else None
                if pose is None:
                    continue
                a, b = np.asarray(pt_p[:2], float), np.asarray(pt_r[:2], float)
                norm = float(np.hypot(*a))
                if norm <= 0:
                    continue
                d = a - b + s.stage_standoff * a / norm          # r's centre in the partner's frame
                out[r] = tuple(float(v) for v in transform_point(pose, d))
        return out

    def stage(self, obj, poses):
        """Send the waiting robots to their staging points (:meth:`staging`) as goals."""
        for r, point in self.staging(poses).items():
            i = self.ctx.index[r]
            obj.goal[i] = point
            obj.goal_mask[i] = True
            obj.velocity_mask[i] = 0.0

    def crowded(self, robot, pair_robots, poses):
        """True when a robot outside ``pair_robots`` stands within ``seed_holder_clearance`` [m] of ``robot``
        (centre to centre): a seed pair's holder then only turns, since the MPC keeps no robots apart."""
        clearance, here = self.settings.seed_holder_clearance, poses.get(robot)
        if here is None or clearance <= 0:
            return False
        return any(q is not None and n not in pair_robots and math.hypot(q[0] - here[0], q[1] - here[1]) < clearance
                   for n, q in poses.items())

    def driven_pairs(self):
        """Keys of the active pairs the docking manoeuvre drives this step (their alignment cost is off). A
        pair with no mover (closing a loop; also an anchor pair re-seated inside one, whose docking stands in
        its push phase) is not driven: nobody pushes it, and its alignment cost brings it in."""
        book = self.ctx.pairs
        knobs = {q.key for q in book.active if q.type == pr.KNOB and self.ctx.mover(q) is not None}
        axis = {q.key for q in book.active if self.on_axis_lane(q)}
        return knobs | axis | book.pushed()

    def display(self, request_id, state):
        """The target's name and its slots as placed (world frame); the MPC aligns pairs, not slot
        positions, so only the slots' relative poses are targets."""
        view, a = super().display(request_id, state), self.assignment
        view.target = a.target
        if a.slots_world is not None:
            robot_of = {s: r for r, s in a.slot_of.items()}
            view.slots = [(robot_of[s], tuple(float(v) for v in a.slots_world[s])) for s in sorted(robot_of)]
        return view
