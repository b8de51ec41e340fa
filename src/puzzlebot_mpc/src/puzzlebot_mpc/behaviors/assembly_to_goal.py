"""``assembly_to_goal``: every named robot leads its assembly to its own goal (x, y) [m], world frame.

Each named robot (a *lead*) belongs to a different assembly (a coupled
line, say, or a single robot); the assemblies drive at once, each as one
body. Each assembly is steered by its *driver*: the member furthest ahead
towards the goal at the start (an assembly steered from behind is pushed
like a reversing trailer and folds). The rest of the assembly trails the
driver along its path, so the driver makes for the point that lies, seen
from the lead's start, beyond the lead's goal by the driver's distance from
the lead: it follows the straight segment from where it stood at the start
to that point by pure pursuit, until the lead is at its goal: it steers towards a carrot LOOKAHEAD ahead of
its projection on the segment (the goal itself at the end), at
``assembly_speed`` times the cosine of the carrot's bearing (never
backwards), slowing down inside SLOW_RADIUS of the goal, with its turn rate
clipped to ``assembly_turn_rate``; it keeps at least MIN_SPEED_SHARE of
that speed away from the goal, as an assembly cannot turn on the spot. The
other members follow like the cars of a train: each drives at the
rigid-body speed at its own position along its heading and turns towards
the heading of the member one coupling nearer the driver (FOLLOW_GAIN); a
member whose mouth holds that member's anchor also drives CLOSE_GAIN times
the gap between their faces beyond the setting ``dock_repair_gap`` faster,
so an opening pair closes up (a line pulled open by its front while it
turns levers the anchor out sideways; closing every gap would push the line
from behind, and a line pushed so does not turn).
These commands are sent as they are, not through the MPC's plan (see
:meth:`AssemblyToGoal.objectives`). Robots outside the led assemblies
hold still.

Succeeds when every lead is within ``tolerance`` (default the setting
``goal_tolerance``) of its goal; fails if a coupled pair of a led assembly
is lost on the way, or once a lead has passed its goal (beyond the goal
on its segment by more than ``tolerance``, still outside it: an assembly
that did not turn enough does not drive on), or after ``timeout`` s (0:
none), naming the leads not there. Status errors and progress: as go_to_goal, per lead.
"""

import math

import numpy as np

from puzzlebot_common.kinematics import pursuit_curvature
from puzzlebot_mpc.behaviors.base import FAILED, BehaviorError, Progress
from puzzlebot_mpc.behaviors.go_to_goal import GoToGoal
from puzzlebot_mpc.docking import seat_measure
from puzzlebot_mpc.pairs import ANCHOR

ASSEMBLY_TO_GOAL = "assembly_to_goal"
LOOKAHEAD = 0.1         # m: the pursuit's carrot leads the lead's projection on its segment by this
SLOW_RADIUS = 0.05      # m: inside this distance of its goal a lead slows down in proportion
FOLLOW_GAIN = 1.0       # 1/s: a follower turns at this times its heading error to the member it follows
CLOSE_GAIN = 1.0        # 1/s: a follower holding an anchor drives faster by this times the gap beyond dock_repair_gap
MIN_SPEED_SHARE = 0.5   # of assembly_speed: the least a driver drives (outside SLOW_RADIUS) while it turns


class AssemblyToGoal(GoToGoal):
    name = ASSEMBLY_TO_GOAL
    needs_poses = True

    def validate(self, poses=None):
        super().validate(poses)
        self.need_poses(self.robots, poses)
        if poses is None:
            return
        seen = {}
        for lead in self.robots:
            for m in self.ctx.assembly_of(lead):
                if m in seen:
                    raise BehaviorError("assembly_to_goal: %s and %s lead the same assembly; name one robot "
                                        "per assembly" % (seen[m], lead))
                seen[m] = lead

    def start(self, now, poses, static):
        self.goals = np.array([tuple(g) for g in self.req.goals], float).reshape(-1, 2)
        self.first_errors = None
        self.leads = list(self.robots)
        self.assemblies = {lead: self.ctx.assembly_of(lead) for lead in self.leads}
        self.drivers = [self.driver(lead, goal, poses) for lead, goal in zip(self.leads, self.goals)]
        self.paths = [self.path(d, lead, goal, poses) for d, lead, goal in zip(self.drivers, self.leads, self.goals)]
        self.origins = np.array([poses[lead][:2] for lead in self.leads], float).reshape(-1, 2)
        self.ahead = {}                   # member -> the member it follows, over every led assembly
        for lead, driver in zip(self.leads, self.drivers):
            self.ahead.update(self.followed(driver, self.assemblies[lead]))
        self.robots = [n for n in self.ctx.names if any(n in a for a in self.assemblies.values())]
        super(GoToGoal, self).start(now, poses, static)
        return "leading %d assemblies: %s" % (len(self.leads), ", ".join(
            "+".join(a) + " (driven by %s)" % d for a, d in zip(self.assemblies.values(), self.drivers)))

    def driver(self, lead, goal, poses):
        """The member of ``lead``'s assembly furthest ahead towards ``goal`` (the lead on a tie)."""
        start = np.array(poses[lead][:2], float)
        direction = np.asarray(goal) - start
        ahead = {m: float(np.dot(np.array(poses[m][:2]) - start, direction)) for m in self.assemblies[lead]}
        best = max(ahead.values())
        return lead if ahead[lead] >= best - 1e-9 else max(ahead, key=ahead.get)

    @staticmethod
    def path(driver, lead, goal, poses):
        """(start, end) [m] of the driver's segment: from where it stands to the point beyond ``goal`` (seen
        from the lead) by its distance from the lead."""
        start, lead_at = np.array(poses[driver][:2], float), np.array(poses[lead][:2], float)
        direction = np.asarray(goal) - lead_at
        length = float(np.linalg.norm(direction))
        if length < 1e-9:
            return start, start
        return start, np.asarray(goal) + direction / length * float(np.linalg.norm(start - lead_at))

    def goal_robots(self):
        """The leads (the goals are theirs; ``robots`` is every member of a led assembly once started)."""
        return self.leads

    def status(self, now, poses, newly, lost, elapsed):
        failed = self.lost_while_driving(lost, set(self.robots))
        if failed:
            return failed
        passed = [self.passed(k, poses) for k in range(len(self.leads))]
        if any(passed):
            return Progress(FAILED, "passed the goal: %s (an assembly turns only as its couplings allow)"
                            % ", ".join(p for p in passed if p), self.errors(poses))
        return super().status(now, poses, newly, lost, elapsed)

    def passed(self, k, poses):
        """'pz1 62 mm off' when lead ``k`` is beyond its goal (on the segment from where it started) by more
        than the tolerance and not within it; else ''."""
        lead, origin, goal = self.leads[k], self.origins[k], self.goals[k]
        pose = poses.get(lead)
        if pose is None:
            return ""
        tol = self.tolerance()
        along, length = along_segment(pose, origin, goal)
        if length < 1e-9:
            return ""
        dist = math.hypot(goal[0] - pose[0], goal[1] - pose[1])
        return "%s %.0f mm off" % (lead, 1e3 * dist) if along > length + tol and dist > tol else ""

    def followed(self, driver, members):
        """{member: the member it follows}: its neighbour one coupling nearer ``driver`` (breadth first
        over the coupled pairs among ``members``)."""
        neighbours = {}
        for p in self.ctx.pairs.coupled.values():
            neighbours.setdefault(p.robot_i, set()).add(p.robot_j)
            neighbours.setdefault(p.robot_j, set()).add(p.robot_i)
        out, frontier, seen = {}, [driver], {driver}
        while frontier:
            nxt = []
            for r in frontier:
                for n in sorted(neighbours.get(r, ())):
                    if n not in seen and n in members:
                        seen.add(n)
                        out[n] = r
                        nxt.append(n)
            frontier = nxt
        return out

    def twist(self, pose, origin, goal):
        """(v [m/s], w [rad/s]) of a driver at ``pose`` (x, y, theta) [m, m, rad] following the segment from
        ``origin`` to ``goal`` (x, y) [m], world frame."""
        s = self.settings
        p, a, b = np.asarray(pose[:2], float), np.asarray(origin, float), np.asarray(goal, float)
        along, length = along_segment(pose, a, b)
        carrot = b if along + LOOKAHEAD >= length else a + (b - a) * (along + LOOKAHEAD) / length
        dist = float(np.linalg.norm(b - p))
        to_carrot = carrot - p
        bearing = math.atan2(to_carrot[1], to_carrot[0]) - pose[2]
        v = s.assembly_speed * max(MIN_SPEED_SHARE, math.cos(bearing)) * min(1.0, dist / SLOW_RADIUS)
        w = max(-s.assembly_turn_rate, min(s.assembly_turn_rate, v * pursuit_curvature(pose, carrot)))
        return v, w

    def gap(self, member, ahead, poses):
        """[m] the gap between the faces of the anchor pair in which ``member``'s mouth holds ``ahead``'s
        anchor (:func:`puzzlebot_mpc.docking.seat_measure`; negative: pressed together); 0 when they are
        not coupled that way (``member`` carries the anchor, or a knob pair)."""
        pair = self.ctx.pairs.coupled.get((ahead, member))
        if pair is None or pair.type != ANCHOR:
            return 0.0
        return seat_measure(pair, poses[ahead], poses[member])[0]

    def objectives(self, obj, now, poses):
        """The commands of every led assembly, sent as they are (controller.Objectives.open_loop): the
        driver its steering twist, every other member the rigid-body speed along its heading (plus the
        close-up: CLOSE_GAIN times the gap beyond dock_repair_gap to the anchor it holds) and a turn
        towards the heading of the member it follows. The MPC's references are the same speeds (its plan
        is not what the robots get: planned with the coupling polygons, it drives the followers a little
        faster than the driver and turns them against it, and a chain pushed from behind that way does not
        turn in Bullet; the train's commands bend it)."""
        if poses is None:
            return
        s, vel, tol = self.settings, np.zeros((len(self.ctx.names), 2)), self.tolerance()
        for lead, driver, (origin, end), goal in zip(self.leads, self.drivers, self.paths, self.goals):
            pose, dpose, members = poses.get(lead), poses.get(driver), self.assemblies[lead]
            if pose is None or dpose is None:
                continue
            there = math.hypot(goal[0] - pose[0], goal[1] - pose[1]) <= tol
            v, w = (0.0, 0.0) if there else self.twist(dpose, origin, end)
            self.rigid_velocities(vel, driver, v, w, members, poses)
            ahead = self.ahead
            for m in members:
                i = self.ctx.index[m]
                obj.velocity_mask[i] = (1.0, 1.0) if m == driver else (1.0, 0.0)
                if m == driver:
                    obj.open_loop[i] = (float(v), float(w))
                elif poses.get(ahead.get(m)) is not None and poses.get(m) is not None:
                    error = math.remainder(poses[ahead[m]][2] - poses[m][2], 2 * math.pi)
                    opened = self.gap(m, ahead[m], poses) - s.dock_repair_gap
                    v_m = float(vel[i, 0]) + CLOSE_GAIN * max(0.0, opened)
                    obj.open_loop[i] = (max(-s.v_max, min(s.v_max, v_m)),
                                        max(-s.w_max, min(s.w_max, FOLLOW_GAIN * error)))
        obj.velocity = vel


def along_segment(pose, a, b):
    """(distance [m] of ``pose``'s (x, y) along the segment from ``a`` to ``b``, measured from ``a``; the
    segment's length [m]); the distance is 0 for a segment shorter than 1 nm."""
    d = np.asarray(b, float) - np.asarray(a, float)
    length = float(np.linalg.norm(d))
    if length < 1e-9:
        return 0.0, length
    return float(np.dot(np.asarray(pose[:2], float) - a, d)) / length, length


