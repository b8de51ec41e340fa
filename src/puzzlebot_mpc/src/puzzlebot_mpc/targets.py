"""Target configurations and the goal pairs that build them (Algorithm 3's
``assignConnectionPairs``).

A target configuration is a list of *slots*: robot poses (x, y, heading) in
the assembly frame. Which slots connect follows from the geometry: slot s's
anchor point meeting slot t's opening point (equal headings) is an anchor
pair s -> t; s's knob meeting t's hole is a knob pair. The slots must form
one connected assembly without overlapping bodies.

Generators: ``line`` = a chain of N (slot k at (-k L, 0, 0): every robot
faces +x and its opening is behind the robot in front, whose anchor it
receives); ``row`` = N side by side (slot k at (0, k L, 0)), knob pairs;
``grid`` = 2 x N/2: two lines side by side (slot (r, k) at (-k L, r L, 0)),
anchor pairs along each line and knob pairs across them (N even, >= 4; a
bridge is the 2 x 2 grid).
Any other shape is a list of slots in YAML (config/targets.yaml).

Assignment of robots to slots (documented in docs/mpc.md):

1. distance-induced graph of the start positions and its minimum spanning
   tree (MST); the assembly frame is placed at the centroid of the robots,
   its heading candidates are the directions of the MST's longest path
   (both ways) and the circular mean of the robots' headings, each also
   turned by multiples of 90 degrees;
2. for each candidate, a minimum-cost assignment (Hungarian method) of
   robots to slots with cost |p_robot - p_slot|^2 + w_heading L^2 (1 - cos(theta_robot - theta_slot));
3. the candidate of least total cost wins; its slots' connections become
   the goal pairs, prioritised by the MST path length between their robots
   (robots close in the start configuration couple first).
"""

import math
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import minimum_spanning_tree, shortest_path

from puzzlebot_common.errors import ConfigError
from puzzlebot_mpc.pairs import ANCHOR, KNOB, make_pair

GENERATORS = ("line", "row", "grid")
_JOIN_TOL = 1e-4      # m: two connection points closer than this meet
_ANGLE_TOL = 1e-3     # rad


class TargetError(ValueError):
    """A target configuration or couple request cannot be used; the message says why."""


@dataclass
class Target:
    name: str
    slots: np.ndarray                       # (S, 3): x, y, heading in the assembly frame
    connections: List[Tuple[int, int, int]]  # (point slot, polygon slot, ANCHOR/KNOB)


def generate(name, n, geometry):
    """Slots of a generated target with ``n`` robots."""
    L = geometry.body_side
    if name == "line":
        return np.array([[-k * L, 0.0, 0.0] for k in range(n)])
    if name == "row":
        return np.array([[0.0, k * L, 0.0] for k in range(n)])
    if name == "grid":
        if n < 4 or n % 2:
            raise TargetError("target 'grid' is two lines side by side: it needs an even number of robots, at "
                              "least 4, got %d" % n)
        return np.array([[-k * L, r * L, 0.0] for r in range(2) for k in range(n // 2)])
    raise TargetError("unknown target generator %r; known: %s" % (name, ", ".join(GENERATORS)))


def _pose_point(slot, point):
    c, s = math.cos(slot[2]), math.sin(slot[2])
    return np.array([slot[0] + c * point[0] - s * point[1], slot[1] + s * point[0] + c * point[1]])


def _same_heading(a, b):
    return abs(math.remainder(a - b, 2 * math.pi)) < _ANGLE_TOL


def _overlap(a, b, side):
    """Separating-axis test of two squares (touching is not overlapping)."""
    h = side / 2.0

    def corners(p):
        c, s = math.cos(p[2]), math.sin(p[2])
        return np.array([[p[0] + c * x - s * y, p[1] + s * x + c * y] for x, y in ((-h, -h), (h, -h), (h, h), (-h, h))])

    ca, cb = corners(a), corners(b)
    for p in (a, b):
        for ang in (p[2], p[2] + math.pi / 2):
            axis = np.array([math.cos(ang), math.sin(ang)])
            pa, pb = ca @ axis, cb @ axis
            if pa.max() <= pb.min() + 1e-6 or pb.max() <= pa.min() + 1e-6:
                return False
    return True


def make_target(name, slots, geometry):
    """Check slots and derive their connections; raise TargetError."""
    slots = np.asarray(slots, dtype=float)
    if slots.ndim != 2 or slots.shape[1] != 3 or len(slots) < 2:
        raise TargetError("target %r: expected at least two slots [x, y, heading], got %s"
                          % (name, np.asarray(slots).tolist()))
    if not np.all(np.isfinite(slots)):
        raise TargetError("target %r: slots must be finite numbers" % name)
    n = len(slots)
    for a in range(n):
        for b in range(a + 1, n):
            if _overlap(slots[a], slots[b], geometry.body_side):
                raise TargetError("target %r: slots %d and %d overlap" % (name, a, b))
    conns = []
    kinds = ((ANCHOR, geometry.anchor_point(), geometry.opening_point()),
             (KNOB, geometry.knob_point(), geometry.hole_point()))
    for a in range(n):
        for b in range(n):
            if a == b or not _same_heading(slots[a][2], slots[b][2]):
                continue
            for kind, pi, pj in kinds:
                if np.linalg.norm(_pose_point(slots[a], pi) - _pose_point(slots[b], pj)) < _JOIN_TOL:
                    conns.append((a, b, kind))
    # one connected assembly
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for a, b, _ in conns:
        parent[root(a)] = root(b)
    if len({root(i) for i in range(n)}) > 1:
        raise TargetError("target %r: the slots do not form one connected assembly (no anchor-opening or "
                          "knob-hole contact joins them all)" % name)
    return Target(name, slots, conns)


def load_targets(data, geometry, where="targets"):
    """Named slot lists from YAML: {name: {slots: [[x, y, heading], ...]}}."""
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError("%s: expected a mapping name -> {slots: [...]}, got %r" % (where, data))
    out = {}
    for name, entry in data.items():
        if name in GENERATORS:
            raise ConfigError("%s.%s: the name is reserved for the generated target" % (where, name))
        if not isinstance(entry, dict) or set(entry) != {"slots"}:
            raise ConfigError("%s.%s: expected {slots: [[x, y, heading], ...]}" % (where, name))
        try:
            out[str(name)] = make_target(str(name), entry["slots"], geometry)
        except (TargetError, ValueError, TypeError) as e:
            raise ConfigError("%s.%s: %s" % (where, name, e))
    return out


# --------------------------------------------------------------- assignment
def distance_mst(positions):
    """MST of the complete distance graph of the positions: (edges (i, j, d), path lengths (n, n))."""
    p = np.asarray(positions, dtype=float)
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
    # csgraph treats zeros as missing edges: coincident robots get a tiny positive distance.
    dm = np.where(d > 0, d, 1e-12)
    np.fill_diagonal(dm, 0.0)
    tree = minimum_spanning_tree(dm).tocoo()
    edges = [(int(i), int(j), float(d[i, j])) for i, j in zip(tree.row, tree.col)]
    sym = tree + tree.T
    paths = shortest_path(sym, directed=False)
    return edges, paths


def _longest_path_direction(positions, edges, paths):
    i, j = np.unravel_index(np.argmax(np.where(np.isfinite(paths), paths, -1)), paths.shape)
    v = np.asarray(positions[j]) - np.asarray(positions[i])
    return math.atan2(v[1], v[0]) if np.linalg.norm(v) > 0 else 0.0


def assignment_cost(poses, slots_world, heading_weight, side):
    """Cost matrix (robot x slot) of the minimum-cost assignment."""
    poses = np.asarray(poses, dtype=float)
    d2 = np.sum((poses[:, None, :2] - slots_world[None, :, :2]) ** 2, axis=2)
    dth = 1.0 - np.cos(poses[:, None, 2] - slots_world[None, :, 2])
    return d2 + heading_weight * side ** 2 * dth


def place(slots, x, y, heading):
    """Slots (assembly frame) placed at world pose (x, y, heading) around their centroid."""
    c, s = math.cos(heading), math.sin(heading)
    rel = slots[:, :2] - slots[:, :2].mean(axis=0)
    out = np.empty_like(slots)
    out[:, 0] = x + c * rel[:, 0] - s * rel[:, 1]
    out[:, 1] = y + s * rel[:, 0] + c * rel[:, 1]
    out[:, 2] = slots[:, 2] + heading
    return out


@dataclass
class Assignment:
    robots: List[str]
    slot_of: Dict[str, int]        # robot -> slot index
    placement: Tuple[float, float, float]
    cost: float
    pairs: list                    # ConnectionPair goal pairs (augmented)
    priority: Dict[Tuple[str, str], float]
    mst_edges: List[Tuple[str, str, float]]
    slots_world: Optional[np.ndarray] = None   # (n, 3) slots as placed (world), for displays
    target: str = ""                           # target name


def assign(target, robots, poses, geometry, heading_weight=1.0):
    """Goal pairs for ``robots`` (names) at ``poses`` ((n, 3) array) to build ``target``."""
    n = len(robots)
    if len(target.slots) != n:
        raise TargetError("target %r has %d slots for %d robots; the numbers must match"
                          % (target.name, len(target.slots), n))
    poses = np.asarray(poses, dtype=float)
    if poses.shape != (n, 3) or not np.all(np.isfinite(poses)):
        raise TargetError("poses of %s are missing or not finite" % ", ".join(robots))
    edges, paths = distance_mst(poses[:, :2])
    centre = poses[:, :2].mean(axis=0)
    base = [_longest_path_direction(poses[:, :2], edges, paths),
            math.atan2(np.sin(poses[:, 2]).sum(), np.cos(poses[:, 2]).sum())]
    slot_axis = _longest_path_direction(target.slots[:, :2], *distance_mst(target.slots[:, :2]))
    candidates = []
    for b in base:
        for quarter in range(4):
            candidates.append(b - slot_axis + quarter * math.pi / 2)
            candidates.append(b + quarter * math.pi / 2)
    best = None
    for heading in candidates:
        world = place(target.slots, centre[0], centre[1], heading)
        cost = assignment_cost(poses, world, heading_weight, geometry.body_side)
        rows, cols = linear_sum_assignment(cost)
        total = float(cost[rows, cols].sum())
        if best is None or total < best[0] - 1e-12:
            best = (total, heading, dict(zip(rows, cols)))
    total, heading, mapping = best
    robot_of_slot = {int(s): robots[int(r)] for r, s in mapping.items()}
    index = {name: i for i, name in enumerate(robots)}
    pairs, priority = [], {}
    for a, b, kind in target.connections:
        p = make_pair(robot_of_slot[a], robot_of_slot[b], kind, geometry)
        pairs.append(p)
        priority[p.key] = float(paths[index[p.robot_i], index[p.robot_j]])
    return Assignment(list(robots), {robots[int(r)]: int(s) for r, s in mapping.items()},
                      (float(centre[0]), float(centre[1]), float(heading)), total, pairs, priority,
                      [(robots[i], robots[j], d) for i, j, d in edges],
                      place(target.slots, centre[0], centre[1], heading), target.name)


def merge_assignments(assignments):
    """One Assignment of several independent ones (a couple request with groups: each group forms its own
    copy of the target): the robots, goal pairs, priorities and MST edges side by side, the slots
    numbered on from group to group; ``placement`` is the first group's, ``cost`` the sum."""
    if len(assignments) == 1:
        return assignments[0]
    robots, slot_of, pairs, priority, edges, slots = [], {}, [], {}, [], []
    for a in assignments:
        offset = len(robots)
        robots += a.robots
        slot_of.update({r: offset + s for r, s in a.slot_of.items()})
        pairs += a.pairs
        priority.update(a.priority)
        edges += a.mst_edges
        slots.append(a.slots_world)
    return Assignment(robots, slot_of, assignments[0].placement, sum(a.cost for a in assignments), pairs,
                      priority, edges, np.vstack(slots), assignments[0].target)


def brute_force_assignment(cost):
    """Minimum total cost over all permutations (for tests on small cases)."""
    from itertools import permutations

    n = cost.shape[0]
    return min(sum(cost[r, s] for r, s in zip(range(n), perm)) for perm in permutations(range(n)))


def resolve_target(name, slots, n, named, geometry):
    """The Target of a couple request: a generator, a named YAML target or explicit slots."""
    if slots is not None and len(slots):
        if name:
            raise TargetError("give either a target name or slots, not both (got %r and %d slots)"
                              % (name, len(slots)))
        return make_target("slots", slots, geometry)
    if not name:
        raise TargetError("couple needs a target name (%s or one of config/targets.yaml: %s) or slots"
                          % ("/".join(GENERATORS), ", ".join(sorted(named)) or "none"))
    if name in GENERATORS:
        if n < 2:
            raise TargetError("target %r needs at least two robots, got %d" % (name, n))
        return make_target(name, generate(name, n, geometry), geometry)
    if name not in named:
        raise TargetError("unknown target %r; known: %s" % (name, ", ".join(list(GENERATORS) + sorted(named))))
    return named[name]
