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

ANCHOR, KNOB = 0, 1                                  # = puzzlebot_msgs/ConnectionPair TYPE_*
DECOUPLED, HEAD_ALIGNED, HEAD_INSERTED = 0, 1, 2     # = puzzlebot_msgs/ConnectionPair STATUS_*
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


def update_status(pair, pose_i, pose_j, geometry, eps, seating=Seating(), now=None):
    """Algorithm 2 for one pair (not yet coupled): the new status.

    ``seating``: the lining-up conditions and the jam timeout (Seating);
    ``now`` [s]: the time, for the timeout (None: no timeout). Updates
    ``pair.confirmed`` (the count of consecutive inserted readings).
    """
    footprint = geometry.footprint()
    if pair.type == KNOB:
        inside = head_margin(pair, pose_i, pose_j, geometry.knob_region()) >= -eps
        aligned = abs(alignment_error(pair, pose_i, pose_j)[1]) <= geometry.knob_yaw_tolerance
        return HEAD_INSERTED if inside and aligned else DECOUPLED
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


def alignment_points(pair, pose_i=None, pose_j=None, approach=None, mover="j"):
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
    a standoff, where there is room to turn, before it closes in.
    Returns ((x, y, heading) on robot_i, (x, y, heading) on robot_j).
    """
    if pair.type == ANCHOR and pair.status == DECOUPLED:
        head = np.array([pair.head[0], pair.head[1], pair.point_i[2]])
        pj = np.array(pair.point_j, dtype=float)
        if approach is not None and pose_i is not None and pose_j is not None:
            lookahead, smax, k_th, k_y = approach
            dth = abs(alignment_error(pair, pose_i, pose_j)[1])
            if mover == "j":        # carrot behind the anchor head, on the anchor robot's axis
                q = inverse_transform_point(pose_i, world_point(pose_j, pair.point_j))
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
    return pair.point_i, pair.point_j


def alignment_error(pair, pose_i, pose_j):
    """(position error [m], heading error [rad]) between the pair's connection frames."""
    pi, pj = pair.point_i, pair.point_j
    dp = world_point(pose_i, pi) - world_point(pose_j, pj)
    dth = math.remainder(pose_i[2] + pi[2] - pose_j[2] - pj[2] - math.pi, 2 * math.pi)
    return float(np.hypot(dp[0], dp[1])), dth


# ---------------------------------------------------------------- activation
def select_active(candidates, busy=(), order=None):
    """Conflict-free choice of pairs to align now (a robot is in one active pair).

    ``candidates``: pairs not yet coupled; ``busy``: robots that may not take
    part; ``order``: optional key (pair -> sortable) giving the priority,
    default the list order. Greedy in priority order: optimal for the
    paper's rule "execute without conflict" and deterministic.
    """
    chosen, used = [], set(busy)
    for pair in sorted(candidates, key=order) if order else candidates:
        if pair.robot_i in used or pair.robot_j in used:
            continue
        chosen.append(pair)
        used.update(pair.robots)
    return chosen


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
    coupled: Dict[Tuple[str, str], ConnectionPair] = field(default_factory=dict)
    goals: List[ConnectionPair] = field(default_factory=list)
    active: List[ConnectionPair] = field(default_factory=list)
    priority: Optional[Dict[Tuple[str, str], float]] = None

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

    def clear_goals(self):
        self.goals, self.active, self.priority = [], [], None

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
        """Choose the active pairs among the goals (robots with a pose only).

        Conflict-free (a robot is in one active pair) and *growing one
        assembly*: a single robot docks onto an assembly of two or more (the
        seed: the largest that has such a pair, ties broken by priority),
        several at once where the seed has several free places. Before any
        assembly exists, the best pair alone is chosen (it becomes the seed).
        Two multi-robot assemblies are joined only when nothing else is left:
        a straight chain of unicycles can only turn through its couplings'
        freedom, so docking one chain onto another is a hard manoeuvre, while a
        single robot docks easily.
        """
        missing = {n for n, p in poses.items() if p is None}
        order = (lambda p: self.priority.get(p.key, 0.0)) if self.priority else None
        ranked = sorted(self.goals, key=order) if order else list(self.goals)
        coupled = list(self.coupled.values())
        group_of = {}
        for g in components(sorted({r for p in coupled for r in p.robots}), coupled):
            for r in g:
                group_of[r] = tuple(g)
        grow, single, join = [], [], []
        for p in ranked:
            gi, gj = group_of.get(p.robot_i), group_of.get(p.robot_j)
            (single if gi is None and gj is None else grow if (gi is None) != (gj is None) else join).append(p)
        if grow:
            def seed_key(g):
                return (len(g), -min(k for k, p in enumerate(grow) if set(p.robots) & set(g)))
            seeds = {group_of.get(p.robot_i) or group_of.get(p.robot_j) for p in grow}
            seed = set(max(seeds, key=seed_key))
            eligible = [p for p in grow if set(p.robots) & seed]
        else:
            eligible = (single or join)[:1]
        # Pairs already being aligned keep their place: switching partners mid-way wastes the approach.
        keep = [p for p in self.active if p in eligible and not (set(p.robots) & missing)]
        busy = {r for p in keep for r in p.robots} | missing
        rest = [p for p in eligible if p not in keep]
        self.active = keep + select_active(rest, busy)
        return self.active

    def update(self, poses, now=None):
        """Algorithm 2 on the active pairs, then the coupled-pair watchdog (``now`` [s]: the time).

        Returns (newly coupled pairs, lost pairs).
        """
        newly, lost = [], []
        for pair in list(self.active):
            pi, pj = poses.get(pair.robot_i), poses.get(pair.robot_j)
            if pi is None or pj is None:
                continue
            status = update_status(pair, pi, pj, self.geometry, self.eps, self.seating, now)
            if status != pair.status or pair.since is None:
                pair.since = now
            pair.status = status
            if pair.status == HEAD_INSERTED:
                self.active.remove(pair)
                self.goals.remove(pair)
                self.add_coupled(pair)
                newly.append(pair)
        for key, pair in list(self.coupled.items()):
            pi, pj = poses.get(pair.robot_i), poses.get(pair.robot_j)
            if pi is None or pj is None:
                continue
            if head_margin(pair, pi, pj, coupling_polygon(pair, self.geometry)) < -self.lost_margin:
                del self.coupled[key]
                pair.status = DECOUPLED
                lost.append(pair)
        return newly, lost


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
