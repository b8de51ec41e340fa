"""Connection pairs: augmentation, status updates, conflict-free activation.

The paper's Algorithms 1 and 2, ROS-free. A pair couples a *point robot*
``robot_i`` with a *polygon robot* ``robot_j``:

========  =============================  ===============================
type      robot_i (point robot)          robot_j (polygon robot)
========  =============================  ===============================
ANCHOR    carries the anchor on its back  receives it in its front opening
KNOB      carries the side knob (left)    has the side hole (right)
========  =============================  ===============================

Points (body frame of their robot, metres; RobotGeometry defines them):

- ``C_i``: anchor point (-L/2, 0, pi) or knob point (0, L/2, pi/2);
- ``C_j``: opening point (L/2, 0, 0) or hole point (0, -L/2, -pi/2);
- ``head``: the anchor head H_a = C_a + (-l, 0) (paper: C'); for a knob
  pair the knob centre itself.

Status (Algorithm 2, margin ``eps``; "inside P + eps" means the signed
distance into polygon P is at least -eps). Bodies are solid, so an anchor
head can only be inside robot_j's footprint after passing its opening; the
tests state this explicitly ("through the opening": the head's lateral
offset in robot_j's frame is at most opening_width / 2 + eps and the pair's
heading error at most anchor_yaw_free), which also makes them meaningful
for a kinematic plant where bodies may overlap:

- decoupled -> head_aligned when ``head`` is inside robot_j's footprint + eps,
  through the opening;
- head_aligned -> head_inserted when ``C_i`` is inside robot_j's footprint + eps,
  through the opening and *lined up* -- C_i's lateral offset from the
  opening's axis and the pair's heading error within the seating tolerances
  (:class:`Seating`: an anchor pushed home askew leaves a barb outside its
  slit) -- on ``confirm_steps`` consecutive updates (measurement noise must
  not declare a skewed anchor seated);
- head_aligned -> decoupled when ``head`` leaves robot_j's footprint + eps, or
  when the pair has been head_aligned for ``align_timeout`` s without being
  inserted (a jammed anchor: the docking robot backs off and lines up again);
- a KNOB pair goes decoupled -> head_inserted when the knob centre is inside
  robot_j's knob region (RobotGeometry.knob_region) + eps with a heading
  error of at most knob_yaw_tolerance.

A coupled pair is kept by the point-in-polygon constraint: ``head`` inside
robot_j's *coupling polygon* -- the triangle (centre, front-right corner,
front-left corner) for anchors (paper: "projected anchor zero position"),
the knob region for knobs -- for k = 1..Hc. A coupled pair is *lost* (back to
decoupled) when ``head`` lies more than ``lost_margin`` outside that polygon,
e.g. when an external force pulled the robots apart. Coupled pairs also keep
their relative heading within the connection's freedom (yaw_limit).
"""

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import numpy as np

from puzzlebot_common.geometry import inverse_transform_point, signed_margin, transform_point
from puzzlebot_mpc.docking import APPROACH, BACKOFF, DRIVEN, NUDGE, PUSH, Docking, DockingSettings, SeatMonitor, \
    seat_measure

ANCHOR, KNOB = 0, 1                                  # = puzzlebot_msgs/ConnectionPair TYPE_*
DECOUPLED, HEAD_ALIGNED, HEAD_INSERTED = 0, 1, 2     # = puzzlebot_msgs/ConnectionPair STATUS_*
KNOB_MARGIN_STEP = 1e-4    # m: a coupled knob pair's constraint margin is rounded down to this (constraint_margin)
TYPE_NAMES = {ANCHOR: "anchor", KNOB: "knob"}
STATUS_NAMES = {DECOUPLED: "decoupled", HEAD_ALIGNED: "head_aligned", HEAD_INSERTED: "head_inserted"}

_POINT_TOL = 1e-6   # m, rad: how exactly a given connection point must match a known one


@dataclass(frozen=True)
class Seating:
    """How precisely an anchor pair must be lined up to go in (Algorithm 2's extra conditions).

    The defaults impose nothing (Algorithm 2 as in the paper); the MPC's
    settings give the values (``insert_*`` in config/mpc.yaml).
    """

    lateral: float = math.inf        # m: |lateral offset| of the head from the opening's axis
    yaw: float = math.inf            # rad: |heading error| of the pair
    confirm_steps: int = 1           # consecutive updates the head_inserted condition must hold
    align_timeout: float = math.inf  # s: head_aligned longer than this without insertion -> decoupled
    knob: float = math.inf           # m: a knob pair is coupled only with the knob point this close to the
                                     # hole point, along the side and across it (inf: the knob region)


@dataclass
class ConnectionPair:
    """One augmented connection pair (Algorithm 1); see the module docstring."""

    robot_i: str                       # point robot (anchor or knob carrier)
    robot_j: str                       # polygon robot (opening or hole)
    type: int                          # ANCHOR or KNOB
    point_i: np.ndarray                # C_i (x, y, heading) in robot_i's body frame
    point_j: np.ndarray                # C_j (x, y, heading) in robot_j's body frame
    head: np.ndarray                   # head point (x, y) in robot_i's body frame
    status: int = DECOUPLED
    since: Optional[float] = None      # time [s] of the last status change (None: unknown)
    confirmed: int = 0                 # consecutive updates the head_inserted condition held

    @property
    def key(self):
        return (self.robot_i, self.robot_j)

    @property
    def anchor_robot(self):
        """Robot carrying the anchor (empty for knob pairs), as in ConnectionPair.msg."""
        return self.robot_i if self.type == ANCHOR else ""

    @property
    def robots(self):
        return (self.robot_i, self.robot_j)

    def describe(self):
        return "%s %s->%s (%s)" % (TYPE_NAMES[self.type], self.robot_i, self.robot_j, STATUS_NAMES[self.status])


def make_pair(robot_i, robot_j, pair_type, geometry, status=DECOUPLED):
    """Pair with the standard points of ``geometry`` for its type."""
    if pair_type == ANCHOR:
        pi, pj, head = geometry.anchor_point(), geometry.opening_point(), geometry.anchor_head()
    elif pair_type == KNOB:
        pi, pj = geometry.knob_point(), geometry.hole_point()
        head = pi[:2].copy()
    else:
        raise ValueError("unknown pair type %r" % (pair_type,))
    return ConnectionPair(robot_i, robot_j, pair_type, pi, pj, head, status)


def pair_type_of_points(point_i, point_j, geometry):
    """Algorithm 1's type and anchor side from two connection points.

    Returns ``(type, swapped)``: ``swapped`` is True when ``point_j`` is the
    anchor/knob point (so the pair must be stored the other way round).
    Raises ValueError for a combination that does not couple.
    """
    a, o = geometry.anchor_point(), geometry.opening_point()
    k, h = geometry.knob_point(), geometry.hole_point()

    def same(p, q):
        d = np.asarray(p, float) - q
        return abs(d[0]) < _POINT_TOL and abs(d[1]) < _POINT_TOL and abs(math.remainder(d[2], 2 * math.pi)) < _POINT_TOL

    for pt, (first, second) in ((ANCHOR, (a, o)), (KNOB, (k, h))):
        if same(point_i, first) and same(point_j, second):
            return pt, False
        if same(point_i, second) and same(point_j, first):
            return pt, True
    raise ValueError("connection points %s and %s do not form an anchor-opening or knob-hole pair"
                     % (np.round(point_i, 4).tolist(), np.round(point_j, 4).tolist()))


def augment_pairs(goal_pairs, geometry):
    """Algorithm 1: ``goal_pairs`` is a list of (robot_i, point_i, robot_j, point_j).

    Each pair gets its type, anchor side (the point robot goes first) and
    head point, with status decoupled.
    """
    out = []
    for ri, pi, rj, pj in goal_pairs:
        pair_type, swapped = pair_type_of_points(pi, pj, geometry)
        if swapped:
            ri, rj = rj, ri
        out.append(make_pair(ri, rj, pair_type, geometry))
    return out


# ------------------------------------------------------------------ geometry
def world_point(pose, point):
    """World position of a body-frame point of a robot at ``pose``."""
    return transform_point(pose, point[:2])


def point_in_robot(pose_j, world_xy):
    """A world point expressed in robot j's body frame."""
    return inverse_transform_point(pose_j, world_xy)


def head_margin(pair, pose_i, pose_j, polygon):
    """Signed distance [m] of the pair's head into ``polygon`` (robot_j's frame)."""
    return signed_margin(polygon, point_in_robot(pose_j, world_point(pose_i, pair.head)))


def connection_margin(pair, pose_i, pose_j, polygon):
    """Signed distance [m] of C_i into ``polygon`` (robot_j's frame)."""
    return signed_margin(polygon, point_in_robot(pose_j, world_point(pose_i, pair.point_i)))


def coupling_polygon(pair, geometry):
    """Polygon in robot_j's frame in which a coupled pair keeps its head (pip constraint)."""
    return geometry.front_triangle() if pair.type == ANCHOR else geometry.knob_region()


def constraint_margin(pair, pose_i, pose_j, geometry, hold, step):
    """How much [m] the MPC's constraint tightens a coupled pair's polygon (its rows' offsets less this);
    None (pip_margin) for an anchor pair or without both poses. A knob pair's region (a square of
    half-size geometry.knob_tolerance) is tightened to keep its knob within ``hold`` (knob_hold) of the
    hole, but at most to ``step`` (knob_hold_step) further in than the knob is now (rounded down to
    KNOB_MARGIN_STEP; negative when the knob is further outside the region than that).
    The robots cannot move a knob sideways within a step (both points sit on the axle lines): a knob
    outside the whole tightened region had the exact penalty turn both robots at full rate to bring it in
    (measured: an idle row of a grid dragged 0.18 m in 80 s); asked ``step`` further in per step it comes
    in at a third of that rate. Nothing else holds a knob pair's sides together in Bullet."""
    if pair.type != KNOB or pose_i is None or pose_j is None:
        return None
    inside = head_margin(pair, pose_i, pose_j, coupling_polygon(pair, geometry))
    return min(geometry.knob_tolerance - hold, math.floor((inside + step) / KNOB_MARGIN_STEP) * KNOB_MARGIN_STEP)


def through_opening(pair, pose_i, pose_j, geometry, eps):
    """The head is laterally within the opening and the headings agree within the anchor's freedom."""
    q = point_in_robot(pose_j, world_point(pose_i, pair.head))
    dth = abs(alignment_error(pair, pose_i, pose_j)[1])
    return abs(q[1]) <= geometry.opening_width / 2.0 + eps and dth <= geometry.anchor_yaw_free


def lined_up(pair, pose_i, pose_j, seating, point=None):
    """The pair's ``point`` (default its head) lies within ``seating.lateral`` of robot_j's opening axis
    and its heading error is within ``seating.yaw``."""
    q = point_in_robot(pose_j, world_point(pose_i, pair.head if point is None else point))
    return (abs(q[1] - pair.point_j[1]) <= seating.lateral
            and abs(alignment_error(pair, pose_i, pose_j)[1]) <= seating.yaw)


def yaw_limit(pair, geometry):
    """Largest relative heading [rad] a coupled pair keeps (anchor freedom, or the knob's tolerance)."""
    return geometry.anchor_yaw_free if pair.type == ANCHOR else geometry.knob_yaw_tolerance


def knob_measure(pair, pose_i, pose_j):
    """(gap [m], along [m], dtheta [rad]) of a knob pair: how far its knob point C_i is out from the hole's
    side (> 0: the sides apart) and along the side from the hole point C_j, in robot_j's frame, and
    robot_i's heading minus robot_j's."""
    off = point_in_robot(pose_j, world_point(pose_i, pair.point_i)) - pair.point_j[:2]
    outward = math.copysign(1.0, pair.point_j[1])          # the hole's side: +y (left) or -y (right)
    return float(outward * off[1]), float(off[0]), float(alignment_error(pair, pose_i, pose_j)[1])


def knob_offset(pair, pose_i, pose_j):
    """How far [m] a knob pair's knob point C_i is from its hole point C_j, in robot_j's frame: the larger
    of the offsets along the side and across it (the knob test compares it with ``Seating.knob``)."""
    gap, along, _ = knob_measure(pair, pose_i, pose_j)
    return max(abs(gap), abs(along))


def update_status(pair, pose_i, pose_j, geometry, eps, seating=Seating(), now=None):
    """Algorithm 2 for one pair (not yet coupled): the new status.

    ``seating``: the lining-up conditions and the jam timeout (Seating);
    ``now`` [s]: the time, for the timeout (None: no timeout). Updates
    ``pair.confirmed`` (the count of consecutive inserted readings).
    """
    footprint = geometry.footprint()
    if pair.type == KNOB:
        if math.isinf(seating.knob):
            inside = head_margin(pair, pose_i, pose_j, geometry.knob_region()) >= -eps
        else:
            inside = knob_offset(pair, pose_i, pose_j) <= seating.knob
        aligned = abs(alignment_error(pair, pose_i, pose_j)[1]) <= geometry.knob_yaw_tolerance
        pair.confirmed = pair.confirmed + 1 if inside and aligned else 0
        return HEAD_INSERTED if pair.confirmed >= seating.confirm_steps else DECOUPLED
    status = pair.status
    if status == DECOUPLED:
        pair.confirmed = 0
        if head_margin(pair, pose_i, pose_j, footprint) >= -eps and through_opening(pair, pose_i, pose_j,
                                                                                     geometry, eps):
            return HEAD_ALIGNED
        return DECOUPLED
    if status == HEAD_ALIGNED:
        if (connection_margin(pair, pose_i, pose_j, footprint) >= -eps
                and through_opening(pair, pose_i, pose_j, geometry, eps)
                and lined_up(pair, pose_i, pose_j, seating, pair.point_i)):
            pair.confirmed += 1
            if pair.confirmed >= seating.confirm_steps:
                return HEAD_INSERTED
            return HEAD_ALIGNED
        pair.confirmed = 0
        if head_margin(pair, pose_i, pose_j, footprint) < -eps:
            return DECOUPLED
        if now is not None and pair.since is not None and now - pair.since > seating.align_timeout:
            return DECOUPLED
        return HEAD_ALIGNED
    return status


def alignment_points(pair, pose_i=None, pose_j=None, approach=None, mover="j", aim=0.0):
    """Points the alignment cost brings together in the pair's current phase.

    Anchor pairs first bring the anchor head H_a to the opening C_o
    (decoupled), then push in: C_a to C_o (head_aligned). Knob pairs align
    C_i with C_j.

    While an anchor pair is decoupled, the target on the *holding* robot
    (the one that is not ``mover``: "i" = the anchor robot docks backwards,
    "j" = the opening robot docks forwards) is a *carrot* on its axis, ``c``
    metres out from its connection point. With ``approach`` = (lookahead [m],
    standoff max [m], standoff per rad of heading error [m/rad], standoff per
    metre of lateral offset [m/m]) and the mover's point at distance ``e_x``
    along that axis and ``e_y`` beside it::

        c = max(standoff, e_x - lookahead),  standoff = min(max, k_th |dtheta| + k_y |e_y|)

    The carrot leads the mover along the axis (pure pursuit: a unicycle
    turns onto the line while it drives), and a misaligned pair lines up at
    a standoff, where there is room to turn, before it closes in. ``aim`` [m]
    puts the anchor that far across the opening's axis (robot j's +y): the
    docking manoeuvre's correction after a jam (puzzlebot_mpc.docking).
    Returns ((x, y, heading) on robot_i, (x, y, heading) on robot_j).
    """
    if pair.type == ANCHOR and pair.status == DECOUPLED:
        head = np.array([pair.head[0], pair.head[1], pair.point_i[2]])
        pj = np.array(pair.point_j, dtype=float)
        pj[1] += aim
        if approach is not None and pose_i is not None and pose_j is not None:
            lookahead, smax, k_th, k_y = approach
            dth = abs(alignment_error(pair, pose_i, pose_j)[1])
            if mover == "j":        # carrot behind the anchor head, on the anchor robot's axis
                q = inverse_transform_point(pose_i, world_point(pose_j, pj))
                e_x, e_y = head[0] - q[0], q[1] - head[1]
            else:                   # carrot in front of the opening, on the opening robot's axis
                q = inverse_transform_point(pose_j, world_point(pose_i, pair.head))
                e_x, e_y = q[0] - pj[0], q[1] - pj[1]
            c = max(min(smax, k_th * dth + k_y * abs(e_y)), e_x - lookahead)
            if mover == "j":
                head[0] -= c
            else:
                pj[0] += c
        return head, pj
    if pair.type == ANCHOR and aim:
        pj = np.array(pair.point_j, dtype=float)
        pj[1] += aim
        return pair.point_i, pj
    return pair.point_i, pair.point_j


def alignment_error(pair, pose_i, pose_j):
    """(position error [m], heading error [rad]) between the pair's connection frames."""
    pi, pj = pair.point_i, pair.point_j
    dp = world_point(pose_i, pi) - world_point(pose_j, pj)
    dth = math.remainder(pose_i[2] + pi[2] - pose_j[2] - pj[2] - math.pi, 2 * math.pi)
    return float(np.hypot(dp[0], dp[1])), dth


# ---------------------------------------------------------------- activation
class CoupledPairs(dict):
    """The coupled pairs {key: ConnectionPair}; ``version`` counts the changes (for caches of the assemblies)."""

    version = 0

    def __setitem__(self, key, value):
        self.version += 1
        super().__setitem__(key, value)

    def __delitem__(self, key):
        self.version += 1
        super().__delitem__(key)

    def pop(self, key, *default):
        self.version += 1
        return super().pop(key, *default)

    def clear(self):
        self.version += 1
        super().clear()

    def update(self, *args, **kwargs):
        self.version += 1
        super().update(*args, **kwargs)


def _hops(edges, start):
    """{robot: hops from the nearest of ``start``} over the graph ``edges`` ({robot: neighbours}): the
    robots reachable from ``start``."""
    dist, frontier = {r: 0 for r in start}, list(start)
    while frontier:
        nxt = []
        for r in frontier:
            for n in edges.get(r, ()):
                if n not in dist:
                    dist[n] = dist[r] + 1
                    nxt.append(n)
        frontier = nxt
    return dist


def _components(edges):
    """{robot: a name for its connected component} of the graph ``edges`` (its first robot by name)."""
    out = {}
    for r in sorted(edges):
        if r not in out:
            for m in _hops(edges, [r]):
                out[m] = r
    return out


@dataclass
class PairBook:
    """Goal, active and coupled pairs of the stack (Algorithm 3's lists).

    ``coupled`` pairs are kept by polygon constraints whatever the behaviour;
    ``goals`` are the pairs the running couple behaviour still has to form,
    ``active`` the conflict-free subset being aligned now.
    """

    geometry: object
    eps: float
    lost_margin: float
    seating: Seating = Seating()
    coupled: Dict[Tuple[str, str], ConnectionPair] = field(default_factory=CoupledPairs)
    goals: List[ConnectionPair] = field(default_factory=list)
    active: List[ConnectionPair] = field(default_factory=list)
    priority: Optional[Dict[Tuple[str, str], float]] = None
    movers: Dict[Tuple[str, str], Optional[str]] = field(default_factory=dict)   # active pair -> "i" / "j" / None
    dock_settings: Optional[DockingSettings] = None    # None: Algorithm 2 alone couples a pair (the paper)
    docking: Dict[Tuple[str, str], Docking] = field(default_factory=dict)   # goal pair -> its manoeuvre
    monitors: Dict[Tuple[str, str], SeatMonitor] = field(default_factory=dict)  # coupled pair -> its watch
    repair: bool = False                 # re-seat coupled pairs found open (a couple behaviour runs)
    max_seeds: int = 0                   # sub-assemblies that may form at once per target (0: no limit)
    seed_at: str = "middle"              # where a seed starts in its target: "middle" or "tail" (_seed_rank)
    first: int = ANCHOR                  # the pair type a target forms first (ANCHOR: chains, then knob pairs
                                         # join them side by side; KNOB: rows, then anchor pairs join them)
    reseats: int = 0                     # pairs sent back to be re-seated so far
    loop_seated: Dict[Tuple[str, str], float] = field(default_factory=dict)  # loop-closing anchor pair -> time
                                         # [s] since which it has looked seated (_loop_closed)

    @classmethod
    def from_settings(cls, geometry, settings):
        """The pair book of an MPC's settings (MPCSettings: status margins, seating, docking)."""
        return cls(geometry, settings.pair_epsilon, settings.pair_lost_margin, settings.seating(),
                   dock_settings=settings.docking_settings(), max_seeds=settings.assembly_seeds,
                   seed_at=settings.assembly_seed_at,
                   first=KNOB if settings.assembly_first == "knob" else ANCHOR)

    def assemblies(self, names):
        """{robot: its assembly (robots in ``names`` order)} over the coupled pairs, computed once per change
        of the coupled pairs (the behaviours ask for it for every pair, every step)."""
        version, names = getattr(self.coupled, "version", None), tuple(names)
        cache = getattr(self, "_assemblies", None)
        if version is None or cache is None or cache[0] != version:
            cache = self._assemblies = (version, {})
        if names not in cache[1]:
            out = {}
            for g in components(list(names), list(self.coupled.values())):
                for r in g:
                    out[r] = g
            cache[1][names] = out
        return cache[1][names]

    def all_pairs(self):
        """Every known pair, each once: coupled first, then goals not yet coupled."""
        seen = dict(self.coupled)
        for p in self.goals:
            seen.setdefault(p.key, p)
        return list(seen.values())

    def set_goals(self, pairs, priority=None):
        self.goals = [p for p in pairs if p.key not in self.coupled]
        self.priority = priority
        self.active = []
        self.movers, self.docking = {}, {}

    def clear_goals(self):
        self.goals, self.active, self.priority, self.movers, self.docking = [], [], None, {}, {}
        self.loop_seated.clear()
        self.repair = False

    def remove_coupled(self, key):
        return self.coupled.pop(key, None)

    def add_coupled(self, pair):
        pair.status = HEAD_INSERTED
        self.coupled[pair.key] = pair

    def find(self, robot_a, robot_b):
        """The coupled or goal pair between two robots (either order), or None."""
        for p in self.all_pairs():
            if set(p.robots) == {robot_a, robot_b}:
                return p
        return None

    def assign_active(self, poses):
        """Choose the active pairs among the goals (robots with a pose only): every pair that can go now.

        Algorithm 3 executes every non-conflicting pair at once; here a pair
        conflicts with another when they share a robot, or when an assembly
        would have two jobs at once. In every active pair one side *moves*
        (docks) and the other *holds* (:func:`mover_of`); an assembly moves
        for at most one pair and, while it moves, is docked onto by none; an
        assembly that holds may be docked onto at several free places at
        once. Sub-assemblies therefore form in parallel (seeds of two single
        robots), single robots join them (grow), and assemblies join each
        other, the smaller one moving. At most ``max_seeds`` sub-assemblies
        exist or form at once in each target (a connected part of the graph of
        coupled and goal pairs; a couple with groups forms several targets at
        once; 0: no limit); a seed then starts where its target's graph has its
        middle, so the assembly grows outwards at both ends. Pairs already
        being aligned keep their place (switching partners mid-way wastes the
        approach), pairs whose manoeuvre is under way (a
        pair being re-seated) first; the rest are taken in priority order,
        growing first, then seeding, then joining.
        A goal pair between two robots of the same assembly (closing a loop,
        e.g. the last knob pair of a grid) holds on both sides.
        A target with both kinds of pair forms those of type ``first`` first:
        the parts they make (its chains for ANCHOR, its rows for KNOB) are the
        targets the seed limit counts, and a pair of the other type waits
        until none of type ``first`` is left among the goals. With ANCHOR a
        grid or a bridge forms its lines in parallel and then joins them side
        by side; with KNOB it forms its rows (knob pairs of single robots) and
        then joins them front to back.
        """
        missing = {n for n, p in poses.items() if p is None}
        order = (lambda q: self.priority.get(q.key, 0.0)) if self.priority else None
        ranked = sorted(self.goals, key=order) if order else list(self.goals)
        group_of = self.groups()
        kinds = {"grow": 0, "seed": 1, "join": 2, "close": 3}

        def kind(q):
            gi, gj = group_of[q.robot_i], group_of[q.robot_j]
            if gi == gj:
                return "close"
            si, sj = len(gi), len(gj)
            return "seed" if si == sj == 1 else "grow" if min(si, sj) == 1 else "join"

        def underway(q):                  # its manoeuvre is past the approach (e.g. a pair being re-seated)
            return q.key in self.docking and self.docking[q.key].phase != APPROACH

        keep = [q for q in ranked if (q in self.active or underway(q)) and not set(q.robots) & missing]
        keep.sort(key=lambda q: not underway(q))
        parts_left = any(q.type == self.first for q in self.goals)
        graph = self._goal_graph(only=self.first if parts_left else None) if self.max_seeds else {}
        eccentricity = self._seed_rank(graph) if self.max_seeds else {}
        rest = sorted((q for q in ranked if q not in keep and not set(q.robots) & missing),
                      key=lambda q: (kinds[kind(q)], eccentricity.get(q.key, 0)))
        component, assemblies = {}, {}   # robot -> its target; target -> sub-assemblies in it (formed, forming)
        if self.max_seeds:
            component = _components(graph)
            for g in {g for g in group_of.values() if len(g) > 1}:
                c = component.get(g[0], g[0])
                assemblies[c] = assemblies.get(c, 0) + 1
        used, moving, holding, chosen = set(), set(), set(), []
        for q in keep + rest:
            if q.robot_i in used or q.robot_j in used:
                continue
            if q.type != self.first and parts_left and q not in keep:
                continue
            gi, gj = group_of[q.robot_i], group_of[q.robot_j]
            mover = mover_of(q, len(gi), len(gj)) if gi != gj else None
            mg = None if mover is None else (gi if mover == "i" else gj)
            hg = [g for g in {gi, gj} if g != mg]
            if mg is not None and (mg in moving or mg in holding):
                continue
            if any(g in moving for g in hg):
                continue
            c = component.get(q.robot_i, q.robot_i)
            if q not in keep and kind(q) == "seed" and self.max_seeds and assemblies.get(c, 0) >= self.max_seeds:
                continue
            if kind(q) == "seed":
                assemblies[c] = assemblies.get(c, 0) + 1
            chosen.append(q)
            if q not in self.active and q.key in self.docking:
                self.docking[q.key].since = None     # its turn now: the phase's clock starts at the next update
            self.movers[q.key] = mover
            used.update(q.robots)
            if mg is not None:
                moving.add(mg)
            holding.update(hg)
        self.active = chosen
        return self.active

    def _goal_graph(self, only=None):
        """{robot: set of neighbours} over the coupled and the goal pairs: the targets being formed (one
        connected component per target; a couple request with groups has several). ``only``: over the
        pairs of that type alone (ANCHOR: one component per chain of a target; KNOB: per row)."""
        edges = {}
        for q in list(self.coupled.values()) + self.goals:
            if only is not None and q.type != only:
                continue
            edges.setdefault(q.robot_i, set()).add(q.robot_j)
            edges.setdefault(q.robot_j, set()).add(q.robot_i)
        return edges

    def _seed_rank(self, edges):
        """{goal pair key: rank} of the goal pairs as seeds, the smallest first: by eccentricity
        (:meth:`_seed_eccentricity`) with ``seed_at`` "middle"; with "tail", by the anchor pairs that follow
        the pair's opening robot along its chain (0: the chain's last pair, so every robot that joins the
        chain after it is an anchor robot backing in), then by eccentricity."""
        ecc = self._seed_eccentricity(edges)
        if self.seed_at == "middle":
            return ecc
        behind = {}                      # robot -> the robot whose opening takes its anchor, along the chain
        for q in list(self.coupled.values()) + self.goals:
            if q.type == ANCHOR:
                behind[q.robot_i] = q.robot_j
        rank = {}
        for q in self.goals:
            steps, r, seen = 0, q.robot_j, {q.robot_i}
            while r in behind and r not in seen:
                seen.add(r)
                r, steps = behind[r], steps + 1
            rank[q.key] = (steps if q.type == ANCHOR else len(behind), ecc[q.key])
        return rank

    def _seed_eccentricity(self, edges):
        """{goal pair key: hops from the pair to the farthest robot of its component of the goal graph
        ``edges``}: a seed with a small one sits in the middle of its target, and the assembly grows
        outwards at several places at once."""
        return {q.key: max(_hops(edges, q.robots).values()) for q in self.goals}

    def groups(self):
        """{robot: its assembly as a sorted tuple of names} over the coupled pairs (single robots: (name,)),
        for the robots of the coupled and goal pairs."""
        robots = sorted({r for q in self.coupled.values() for r in q.robots} | {r for q in self.goals for r in q.robots})
        return {r: tuple(sorted(g)) for r, g in self.assemblies(robots).items()}

    def row_of(self, robot):
        """The robots joined to ``robot`` by coupled knob pairs (its row, side by side), itself included."""
        knobs = [q for q in self.coupled.values() if q.type == KNOB]
        names = sorted({robot} | {r for q in knobs for r in q.robots})
        return next(c for c in components(names, knobs) if robot in c)

    def mover(self, pair):
        """"i", "j" or None (both hold: a loop closure) for an active pair (mover_of when not assigned)."""
        if pair.key in self.movers:
            return self.movers[pair.key]
        return self._mover_by_size(pair)

    def _mover_by_size(self, pair):
        """mover_of with the sizes of the pair's robots' assemblies now."""
        group_of = self.groups()
        return mover_of(pair, len(group_of.get(pair.robot_i, (pair.robot_i,))),
                        len(group_of.get(pair.robot_j, (pair.robot_j,))))

    def update(self, poses, now=None):
        """Algorithm 2 on the active pairs, then the coupled-pair watchdog (``now`` [s]: the time).

        With ``docking`` settings, an anchor pair that a robot docks is
        coupled only when the docking manoeuvre has proven it seated
        (:mod:`puzzlebot_mpc.docking`); Algorithm 2's status then only guides
        the approach. While ``repair`` is on (a couple behaviour runs), a
        coupled anchor pair that looks open for a while goes back to the goals
        to be re-seated. A coupled knob pair whose knob has been off its hole
        by more than the knob test's tolerance for ``repair_time`` goes back
        to the goals while a couple runs, and is lost otherwise (its knob is
        not in the hole: the pair does not hold). Returns (newly coupled
        pairs, lost pairs).
        """
        newly, lost = [], []
        for pair in list(self.active):
            pi, pj = poses.get(pair.robot_i), poses.get(pair.robot_j)
            if pi is None or pj is None:
                continue
            dock = self._docking_of(pair, now)
            before_status, since = pair.status, pair.since
            status = update_status(pair, pi, pj, self.geometry, self.eps, self.seating, now)
            seated = False
            if dock is not None and self.dock_settings.insert_by_mpc and dock.phase in (APPROACH, NUDGE):
                gap, lateral, dtheta = seat_measure(pair, pi, pj)
                if dock.phase == NUDGE:          # driven straight in; Algorithm 2 still judges the pair
                    dock.update(gap, lateral, dtheta, now)
                    if status != HEAD_ALIGNED:
                        dock.end_nudge(now, STATUS_NAMES[status])
                jammed = (before_status == HEAD_ALIGNED and status == DECOUPLED and now is not None
                          and since is not None and now - since > self.seating.align_timeout)
                if status != HEAD_ALIGNED:       # (a jam included: it leaves the pair decoupled)
                    dock.insert_reset()
                if jammed:                       # pushed in for align_timeout without getting home
                    dock.jammed(gap, lateral, now, dtheta)
                elif status == DECOUPLED:        # a stalled approach backs off and approaches again
                    dock.approach_stalled(gap, lateral, dtheta, now)
                elif status == HEAD_ALIGNED and dock.phase == APPROACH:   # a stalled insertion: a nudge
                    dock.insert_stalled(gap, now, dtheta)
                elif status == HEAD_INSERTED and self.dock_settings.pull_test:
                    dock.start_pull(gap, now)
                    status = HEAD_ALIGNED
            elif dock is None:
                if status != HEAD_ALIGNED:
                    self.loop_seated.pop(pair.key, None)
                elif self._loop_closed(pair, pi, pj, now):
                    status = HEAD_INSERTED
            else:
                gap, lateral, dtheta = seat_measure(pair, pi, pj)
                before = dock.phase
                seated = dock.update(gap, lateral, dtheta, now)
                if seated:
                    status = HEAD_INSERTED
                elif dock.phase == BACKOFF or before == BACKOFF:
                    status = DECOUPLED           # backing off, then the approach from the standoff again
                elif dock.phase in DRIVEN or status == HEAD_INSERTED:
                    status = HEAD_ALIGNED        # the pose alone does not prove the anchor seated
            if status != pair.status or pair.since is None:
                pair.since = now
            pair.status = status
            if pair.status == HEAD_INSERTED:
                self.active.remove(pair)
                self.goals.remove(pair)
                self.docking.pop(pair.key, None)
                self.add_coupled(pair)
                newly.append(pair)
        tugged = self._tugged()
        for key, pair in list(self.coupled.items()):
            pi, pj = poses.get(pair.robot_i), poses.get(pair.robot_j)
            if pi is None or pj is None:
                continue
            if pair.robot_i in tugged:       # a neighbour pushes or pulls on this assembly: it gives a little
                self.monitors.pop(key, None)
                continue
            if head_margin(pair, pi, pj, coupling_polygon(pair, self.geometry)) < -self.lost_margin:
                self._lose(pair, lost)
            elif self.repair and self.dock_settings is not None and pair.type == ANCHOR:
                monitor = self.monitors.setdefault(key, SeatMonitor(self.dock_settings))
                gap, lateral, _ = seat_measure(pair, pi, pj)
                if monitor.update(gap, lateral, now):
                    self._reseat(pair, gap, lateral, now)
            elif pair.type == KNOB and self.dock_settings is not None and math.isfinite(self.seating.knob):
                monitor = self.monitors.setdefault(key, SeatMonitor(self.dock_settings, self.seating.knob))
                if monitor.update(knob_offset(pair, pi, pj), 0.0, now):
                    if self.repair:
                        self._reseat_knob(pair, now)
                    else:                        # no couple to close it again: the pair is lost
                        self._lose(pair, lost)
        return newly, lost

    def _loop_closed(self, pair, pose_i, pose_j, now):
        """True when an anchor pair that closes a loop (no mover: both sides hold, the docking manoeuvre
        cannot push and pull it) has looked seated for ``loop_time``: its faces within ``loop_gap`` and its
        head through the opening. Algorithm 2's lining-up test does not hold there: the rows' knob pairs
        leave the second anchor pair between two rows a few mm off its axis, seated in the opening's
        play (docs/mpc.md, "Seating")."""
        if self.dock_settings is None or pair.type != ANCHOR or self.movers.get(pair.key, "j") is not None \
                or now is None:
            return False
        gap = seat_measure(pair, pose_i, pose_j)[0]
        if gap > self.dock_settings.loop_gap or not through_opening(pair, pose_i, pose_j, self.geometry, self.eps):
            self.loop_seated.pop(pair.key, None)
            return False
        since = self.loop_seated.setdefault(pair.key, now)
        if now - since < self.dock_settings.loop_time - 1e-9:
            return False
        del self.loop_seated[pair.key]
        return True

    def pushed(self):
        """Keys of the pairs a docking manoeuvre drives now (a driven phase) with a mover to drive them. A
        pair re-seated inside a loop keeps its docking in the push phase, but has no mover: nobody pushes it."""
        return {k for k, d in self.docking.items() if d.phase in DRIVEN and self.movers.get(k, "j") is not None}

    def _tugged(self):
        """Robots of the assemblies on which a docking manoeuvre pushes or pulls right now."""
        driven = [q for q in self.active if q.key in self.docking and self.docking[q.key].phase in DRIVEN]
        if not driven:
            return set()
        group_of = self.groups()
        return {r for q in driven for end in q.robots for r in group_of.get(end, (end,))}

    def _docking_of(self, pair, now):
        """The docking manoeuvre of an active anchor pair (made on first use), or None (knob pairs, a pair
        closing a loop, docking off). Its mover follows the assignment until the manoeuvre drives it."""
        if self.dock_settings is None or pair.type != ANCHOR:
            return None
        mover = self.movers.get(pair.key, "j")
        dock = self.docking.get(pair.key)
        if mover is None:
            return None
        if dock is None:
            dock = self.docking[pair.key] = Docking(self.dock_settings, mover, now=now)
        elif dock.phase == APPROACH:
            dock.mover = mover
        return dock

    def _reseat(self, pair, gap, lateral, now):
        """A coupled pair found open goes back to the goals, to be pushed home again."""
        del self.coupled[pair.key]
        self.monitors.pop(pair.key, None)
        self.docking[pair.key] = Docking(self.dock_settings, self._mover_by_size(pair), start=PUSH, now=None)
        self.docking[pair.key].note = "re-seating: %.1f mm open, %.1f mm off the axis" % (1e3 * gap, 1e3 * lateral)
        pair.status, pair.since, pair.confirmed = HEAD_ALIGNED, now, 0
        self.goals.append(pair)
        self.reseats += 1

    def _lose(self, pair, lost):
        """A coupled pair no longer holds: decoupled, appended to ``lost``."""
        del self.coupled[pair.key]
        self.monitors.pop(pair.key, None)
        pair.status = DECOUPLED
        lost.append(pair)

    def _reseat_knob(self, pair, now):
        """A coupled knob pair found off its hole goes back to the goals: its approach closes it again."""
        del self.coupled[pair.key]
        self.monitors.pop(pair.key, None)
        pair.status, pair.since, pair.confirmed = DECOUPLED, now, 0
        self.goals.append(pair)
        self.reseats += 1


def mover_of(pair, size_i, size_j):
    """Which robot of a pair docks, given the sizes of the two robots' assemblies: "i" or "j".

    The smaller assembly moves (a single robot docks onto an assembly). Two
    equal assemblies: robot j's: for an anchor pair the opening robot, which
    docks forward with its assembly following behind it like a train, where
    the anchor robot's would have to reverse a chain.
    """
    return "i" if size_i < size_j else "j"


def components(names, pairs):
    """Connected components (lists of robot names, in ``names`` order) of the pair graph."""
    parent = {n: n for n in names}

    def root(n):
        while parent[n] != n:
            parent[n] = parent[parent[n]]
            n = parent[n]
        return n

    for p in pairs:
        if p.robot_i in parent and p.robot_j in parent:
            parent[root(p.robot_i)] = root(p.robot_j)
    groups = {}
    for n in names:
        groups.setdefault(root(n), []).append(n)
    return list(groups.values())


def assembly_of(robot, names, pairs):
    """The robots coupled (directly or through others) with ``robot``, itself included."""
    for group in components(names, pairs):
        if robot in group:
            return group
    return [robot]
