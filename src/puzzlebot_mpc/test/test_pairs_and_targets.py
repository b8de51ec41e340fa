"""Algorithms 1-3 without ROS: augmentation, the status machine, activation, targets, assignment."""

import math
from itertools import permutations

import numpy as np
import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.config_files import load_target_file
from puzzlebot_mpc.settings import MPCSettings
from puzzlebot_mpc.targets import (TargetError, assign, assignment_cost, brute_force_assignment, distance_mst,
                                   generate, make_target, place, resolve_target)

GEO = RobotGeometry()
L, l, EPS = GEO.body_side, GEO.anchor_length, 0.0015


# ---------------------------------------------------------------- Algorithm 1
def test_augment_sets_type_anchor_side_and_head():
    goal = [("a", GEO.opening_point(), "b", GEO.anchor_point()),    # given the other way round
            ("c", GEO.knob_point(), "d", GEO.hole_point())]
    anchor, knob = pr.augment_pairs(goal, GEO)
    assert anchor.type == pr.ANCHOR and anchor.robots == ("b", "a") and anchor.anchor_robot == "b"
    assert anchor.status == pr.DECOUPLED
    assert anchor.head == pytest.approx([-L / 2 - l, 0.0])
    assert knob.type == pr.KNOB and knob.robots == ("c", "d") and knob.anchor_robot == ""
    with pytest.raises(ValueError, match="do not form"):
        pr.augment_pairs([("a", GEO.anchor_point(), "b", GEO.knob_point())], GEO)


# ---------------------------------------------------------------- Algorithm 2
def opening_robot_behind(gap, lateral=0.0, dtheta=0.0):
    """Anchor robot a at the origin facing +x, opening robot o behind it: its front is ``gap``
    metres behind a's back, ``lateral`` to the side, turned by ``dtheta``."""
    pose_a = (0.0, 0.0, 0.0)
    pose_o = (-L - gap, lateral, dtheta)
    return pose_a, pose_o


def step_status(pair, pose_a, pose_o):
    pair.status = pr.update_status(pair, pose_a, pose_o, GEO, EPS)
    return pair.status


def test_status_machine_follows_algorithm_2_on_a_scripted_approach():
    pair = pr.make_pair("a", "o", pr.ANCHOR, GEO)
    script = [  # (gap between a's back and o's front [m], expected status)
        (0.05, pr.DECOUPLED),
        (l + EPS + 0.001, pr.DECOUPLED),      # head just outside o's footprint + eps
        (l + EPS - 0.001, pr.HEAD_ALIGNED),   # head inside (through the opening)
        (0.006, pr.HEAD_ALIGNED),             # pushing in: connection point still outside + eps
        (EPS - 0.0005, pr.HEAD_INSERTED),     # C_a inside o's footprint + eps
    ]
    for gap, expected in script:
        assert step_status(pair, *opening_robot_behind(gap)) == expected, gap


def test_head_aligned_falls_back_to_decoupled_when_the_head_leaves():
    pair = pr.make_pair("a", "o", pr.ANCHOR, GEO)
    assert step_status(pair, *opening_robot_behind(0.008)) == pr.HEAD_ALIGNED
    assert step_status(pair, *opening_robot_behind(0.010)) == pr.HEAD_ALIGNED
    assert step_status(pair, *opening_robot_behind(0.02)) == pr.DECOUPLED


def test_head_must_come_through_the_opening():
    pair = pr.make_pair("a", "o", pr.ANCHOR, GEO)
    # head inside o's footprint but beside the opening, or badly turned: not aligned
    assert step_status(pair, *opening_robot_behind(0.005, lateral=0.015)) == pr.DECOUPLED
    assert step_status(pair, *opening_robot_behind(0.005, dtheta=0.8)) == pr.DECOUPLED
    assert step_status(pair, *opening_robot_behind(0.005, lateral=0.004, dtheta=0.2)) == pr.HEAD_ALIGNED


def test_knob_pair_inserts_when_the_knob_is_in_the_hole():
    pair = pr.make_pair("k", "h", pr.KNOB, GEO)
    pose_k = (0.0, 0.0, 0.0)
    assert pr.update_status(pair, pose_k, (0.0, L + 0.01, 0.0), GEO, EPS) == pr.DECOUPLED
    assert pr.update_status(pair, pose_k, (0.001, L + 0.001, 0.02), GEO, EPS) == pr.HEAD_INSERTED
    assert pr.update_status(pair, pose_k, (0.0, L, 0.3), GEO, EPS) == pr.DECOUPLED   # turned too far


def test_pairbook_moves_inserted_pairs_to_coupled_and_watches_them():
    book = pr.PairBook(GEO, EPS, 0.005)
    pair = pr.make_pair("a", "o", pr.ANCHOR, GEO)
    book.set_goals([pair])
    poses = dict(zip(("a", "o"), opening_robot_behind(0.0)))
    poses["a"], poses["o"] = opening_robot_behind(0.008)
    book.assign_active(poses)
    assert book.active == [pair]
    assert book.update(poses) == ([], []) and pair.status == pr.HEAD_ALIGNED
    poses["a"], poses["o"] = opening_robot_behind(0.0)
    newly, lost = book.update(poses)
    assert newly == [pair] and pair.key in book.coupled and not book.goals and not book.active
    poses["a"], poses["o"] = opening_robot_behind(0.05)       # pulled apart
    newly, lost = book.update(poses)
    assert lost == [pair] and not book.coupled and pair.status == pr.DECOUPLED


def test_active_pairs_run_in_parallel_without_conflicts():
    names = ["r%d" % k for k in range(1, 9)]
    chain = [pr.make_pair(a, b, pr.ANCHOR, GEO) for a, b in zip(names[:-1], names[1:])]
    poses = {n: (0.0, 0.0, 0.0) for n in names}
    book = pr.PairBook(GEO, EPS, 0.005)
    book.set_goals(chain)
    # no assembly yet: every seed that shares no robot, at once
    assert [p.key for p in book.assign_active(poses)] == [("r1", "r2"), ("r3", "r4"), ("r5", "r6"), ("r7", "r8")]
    assert all(book.mover(p) == "j" for p in book.active)
    for k in (0, 2, 4, 6):
        book.add_coupled(chain[k])
        book.goals.remove(chain[k])
    # four chains of two: r3-r4 docks forward onto r1-r2 and r7-r8 onto r5-r6; r3-r4 moving, nothing docks
    # onto it (r4->r5 waits), and r5-r6, holding, is not moved
    assert [p.key for p in book.assign_active(poses)] == [("r2", "r3"), ("r6", "r7")]
    assert [book.mover(p) for p in book.active] == ["j", "j"]


def test_the_seed_limit_counts_per_target_so_separate_targets_form_at_once():
    lines = [["a1", "a2", "a3", "a4"], ["b1", "b2", "b3", "b4"], ["c1", "c2", "c3"]]
    goals = [pr.make_pair(x, y, pr.ANCHOR, GEO) for line in lines for x, y in zip(line[:-1], line[1:])]
    poses = {n: (0.0, 0.0, 0.0) for line in lines for n in line}
    book = pr.PairBook(GEO, EPS, 0.005, max_seeds=1)
    book.set_goals(goals)
    # one seed per line, in each line's middle
    assert sorted(p.key for p in book.assign_active(poses)) == [("a2", "a3"), ("b2", "b3"), ("c1", "c2")]
    book.add_coupled(goals[1])                                  # a2-a3 formed: line a grows, no second seed
    book.goals.remove(goals[1])
    book.active = []
    keys = sorted(p.key for p in book.assign_active(poses))
    assert ("a1", "a2") in keys and ("a3", "a4") in keys and ("b2", "b3") in keys
    book = pr.PairBook(GEO, EPS, 0.005, max_seeds=1)            # one target: still one seed at a time
    book.set_goals(goals[:3])
    assert [p.key for p in book.assign_active(poses)] == [("a2", "a3")]


def test_a_tail_seed_grows_a_line_by_robots_backing_their_anchors_in():
    names = ["r%d" % k for k in range(1, 7)]
    chain = [pr.make_pair(a, b, pr.ANCHOR, GEO) for a, b in zip(names[:-1], names[1:])]
    poses = {n: (0.0, 0.0, 0.0) for n in names}
    book = pr.PairBook(GEO, EPS, 0.005, max_seeds=1, seed_at="tail")
    book.set_goals(chain)
    assert [p.key for p in book.assign_active(poses)] == [("r5", "r6")]      # the last pair seeds
    for k in (4, 3, 2, 1, 0):                                   # then every robot that joins backs in
        book.add_coupled(chain[k])
        book.goals.remove(chain[k])
        active = book.assign_active(poses)
        assert [p.key for p in active] == ([chain[k - 1].key] if k else [])
        assert all(book.mover(p) == "i" for p in active)
    book = pr.PairBook(GEO, EPS, 0.005, max_seeds=1)                    # the middle: the default
    book.set_goals(chain)
    assert [p.key for p in book.assign_active(poses)] == [("r3", "r4")]


def test_a_grid_forms_its_lines_in_parallel_then_joins_them_by_the_knob_pairs():
    # the 2x2 bridge: chains a1-a2 and b1-b2, knob pairs a1->b1 and a2->b2 between them
    anchors = [pr.make_pair("a1", "a2", pr.ANCHOR, GEO), pr.make_pair("b1", "b2", pr.ANCHOR, GEO)]
    knobs = [pr.make_pair("a1", "b1", pr.KNOB, GEO), pr.make_pair("a2", "b2", pr.KNOB, GEO)]
    poses = {n: (0.0, 0.0, 0.0) for n in ("a1", "a2", "b1", "b2")}
    book = pr.PairBook(GEO, EPS, 0.005, max_seeds=1)
    book.set_goals(knobs + anchors)                             # the knob pairs ranked first
    # one seed per chain, both at once; no knob pair while a chain is left to form
    assert sorted(p.key for p in book.assign_active(poses)) == [("a1", "a2"), ("b1", "b2")]
    book.add_coupled(anchors[0])
    book.goals.remove(anchors[0])
    assert [p.key for p in book.assign_active(poses)] == [("b1", "b2")]      # a1, a2 idle: b's chain first
    book.add_coupled(anchors[1])
    book.goals.remove(anchors[1])
    # the chains join: one knob pair at a time (the moving chain docks at one place)
    active = book.assign_active(poses)
    assert len(active) == 1 and active[0].type == pr.KNOB
    # a target of knob pairs alone (a row) still seeds as before
    row = [pr.make_pair("r1", "r2", pr.KNOB, GEO), pr.make_pair("r2", "r3", pr.KNOB, GEO)]
    book = pr.PairBook(GEO, EPS, 0.005, max_seeds=1)
    book.set_goals(row)
    assert len(book.assign_active({n: (0.0, 0.0, 0.0) for n in ("r1", "r2", "r3")})) == 1


def test_single_robots_grow_assemblies_first_and_an_assembly_takes_several_at_once():
    names = ["r1", "r2", "r3", "r4", "r5"]
    chain = [pr.make_pair(a, b, pr.ANCHOR, GEO) for a, b in zip(names[:-1], names[1:])]
    poses = {n: (0.0, 0.0, 0.0) for n in names}
    book = pr.PairBook(GEO, EPS, 0.005)
    book.add_coupled(chain[1])                                  # r2-r3
    book.set_goals([chain[0], chain[2], chain[3]], {chain[3].key: 0, chain[2].key: 1, chain[0].key: 2})
    active = book.assign_active(poses)
    # r1 and r4 dock onto r2-r3 at both ends (grow before seed r4-r5, which shares r4)
    assert sorted(p.key for p in active) == [("r1", "r2"), ("r3", "r4")]
    assert book.mover(chain[0]) == "i" and book.mover(chain[2]) == "j"
    robots = [r for p in active for r in p.robots]
    assert len(robots) == len(set(robots))
    book.active = [chain[3]]                                    # a pair being aligned keeps its place
    assert chain[3] in book.assign_active(poses)


def test_a_pair_inside_one_assembly_holds_on_both_sides():
    a, b, c, d = "a", "b", "c", "d"
    pairs = [pr.make_pair(a, b, pr.ANCHOR, GEO), pr.make_pair(c, d, pr.ANCHOR, GEO),
             pr.make_pair(c, a, pr.KNOB, GEO), pr.make_pair(d, b, pr.KNOB, GEO)]
    book = pr.PairBook(GEO, EPS, 0.005)
    for p in pairs[:3]:
        book.add_coupled(p)
    book.set_goals([pairs[3]])
    assert book.assign_active({n: (0.0, 0.0, 0.0) for n in "abcd"}) == [pairs[3]]
    assert book.mover(pairs[3]) is None


# ------------------------------------------------------------------- targets
def test_generated_targets_connect_as_expected():
    line = make_target("line", generate("line", 4, GEO), GEO)
    assert sorted(line.connections) == [(0, 1, pr.ANCHOR), (1, 2, pr.ANCHOR), (2, 3, pr.ANCHOR)]
    row = make_target("row", generate("row", 3, GEO), GEO)
    assert sorted(row.connections) == [(0, 1, pr.KNOB), (1, 2, pr.KNOB)]


def test_shipped_targets_load_and_mix_pair_types():
    targets = load_target_file(GEO)
    ell = targets["ell4"]
    kinds = sorted(k for _, _, k in ell.connections)
    assert kinds == [pr.ANCHOR, pr.ANCHOR, pr.KNOB]


@pytest.mark.parametrize("slots, fragment", [
    ([[0, 0, 0], [0.03, 0, 0]], "overlap"),
    ([[0, 0, 0], [0.2, 0, 0]], "connected"),
    ([[0, 0, 0], [-0.07, 0, 0.5]], "connected"),               # headings differ: no connection
    ([[0, 0, 0]], "at least two"),
    ([[0, 0, float("nan")], [-0.05, 0, 0]], "finite"),
])
def test_bad_targets_are_refused(slots, fragment):
    with pytest.raises(TargetError, match=fragment):
        make_target("t", slots, GEO)


def test_bad_target_files_name_the_key():
    from puzzlebot_mpc.targets import load_targets
    with pytest.raises(ConfigError, match="targets.bad"):
        load_targets({"bad": {"slots": [[0, 0, 0], [0.5, 0, 0]]}}, GEO)
    with pytest.raises(ConfigError, match="reserved"):
        load_targets({"line": {"slots": [[0, 0, 0], [-0.05, 0, 0]]}}, GEO)


def test_target_resolution_errors():
    with pytest.raises(TargetError, match="unknown target"):
        resolve_target("star", None, 3, {}, GEO)
    with pytest.raises(TargetError, match="either"):
        resolve_target("line", [(0, 0, 0), (-0.05, 0, 0)], 2, {}, GEO)
    with pytest.raises(TargetError, match="slots"):
        assign(make_target("line", generate("line", 3, GEO), GEO), ["a", "b"], np.zeros((2, 3)), GEO)


@pytest.mark.parametrize("seed", range(6))
def test_assignment_is_optimal_by_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = 3 + seed % 3
    robots = ["r%d" % k for k in range(n)]
    poses = np.column_stack([rng.uniform(-0.3, 0.3, (n, 2)), rng.uniform(-math.pi, math.pi, n)])
    target = make_target("line", generate("line", n, GEO), GEO)
    a = assign(target, robots, poses, GEO)
    # optimal for the chosen placement ...
    world = place(target.slots, *a.placement)
    cost = assignment_cost(poses, world, 1.0, L)
    chosen = sum(cost[robots.index(r), s] for r, s in a.slot_of.items())
    assert chosen == pytest.approx(brute_force_assignment(cost), abs=1e-12)
    assert chosen == pytest.approx(a.cost, abs=1e-12)
    # ... and no better permutation exists at any other candidate heading tried on a fine grid
    # that the search does not cover is allowed; but each permutation at the chosen heading is worse
    assert all(sum(cost[r, s] for r, s in enumerate(perm)) >= chosen - 1e-12 for perm in permutations(range(n)))
    # goal pairs follow the slots' connections
    slot_robot = {s: r for r, s in a.slot_of.items()}
    assert sorted(p.key for p in a.pairs) == sorted((slot_robot[i], slot_robot[j]) for i, j, _ in target.connections)


def test_mst_matches_brute_force_total_weight():
    rng = np.random.default_rng(7)
    pts = rng.uniform(0, 1, (5, 2))
    edges, paths = distance_mst(pts)
    total = sum(d for _, _, d in edges)
    # brute force over all spanning trees of 5 nodes (Pruefer sequences)
    best = math.inf
    import itertools
    for seq in itertools.product(range(5), repeat=3):
        degree = [1] * 5
        for s in seq:
            degree[s] += 1
        seq = list(seq)
        w = 0.0
        deg = degree[:]
        for s in seq:
            leaf = min(i for i in range(5) if deg[i] == 1)
            w += np.linalg.norm(pts[leaf] - pts[s])
            deg[leaf] -= 1
            deg[s] -= 1
        u, v = [i for i in range(5) if deg[i] == 1]
        w += np.linalg.norm(pts[u] - pts[v])
        best = min(best, w)
    assert total == pytest.approx(best, rel=1e-9)
    assert len(edges) == 4 and np.all(np.isfinite(paths))


def test_the_grid_generator_is_two_lines_joined_by_knobs():
    grid = make_target("grid", generate("grid", 8, GEO), GEO)
    anchors = sorted((a, b) for a, b, kind in grid.connections if kind == pr.ANCHOR)
    knobs = sorted((a, b) for a, b, kind in grid.connections if kind == pr.KNOB)
    assert anchors == [(0, 1), (1, 2), (2, 3), (4, 5), (5, 6), (6, 7)]
    # the second line is on the first's left (+y): its robots' right holes take the first line's left knobs
    assert knobs == [(0, 4), (1, 5), (2, 6), (3, 7)]
    for n in (3, 5, 2):
        with pytest.raises(TargetError, match="even number of robots, at least 4"):
            generate("grid", n, GEO)


def test_a_stalled_insertion_is_nudged_and_algorithm_2_still_decides_the_coupling():
    from puzzlebot_mpc import docking as dk
    from puzzlebot_mpc.settings import MPCSettings

    settings = MPCSettings(dock_insert_stall_time=1.0)
    book = pr.PairBook.from_settings(GEO, settings)
    pair = pr.make_pair("a", "o", pr.ANCHOR, GEO)
    book.set_goals([pair])
    poses = dict(zip(("a", "o"), opening_robot_behind(0.008)))       # the head in the mouth, 8 mm out
    book.assign_active(poses)
    book.movers[pair.key] = "j"                                        # the opening robot drives in
    phases = []
    for k in range(15):                                                # 1.5 s head_aligned, no deeper
        assert book.update(poses, 0.1 * k) == ([], []) and pair.status == pr.HEAD_ALIGNED
        phases.append(book.docking[pair.key].phase)
    assert phases.index(dk.NUDGE) == 10                               # head_aligned from t = 0: nudged at 1.0 s
    t = 1.4
    poses["a"], poses["o"] = opening_robot_behind(0.0, lateral=0.004)  # home, but C_a 4 mm off the axis:
    for _ in range(5):                                                 # not lined up, not coupled
        t += 0.1
        assert book.update(poses, t) == ([], [])
    assert pair.status == pr.HEAD_ALIGNED and book.docking[pair.key].phase == dk.APPROACH
    poses["a"], poses["o"] = opening_robot_behind(0.0)                 # lined up: coupled after the confirm steps
    newly = []
    for _ in range(settings.insert_confirm_steps):
        t += 0.1
        newly += book.update(poses, t)[0]
    assert newly == [pair] and pair.key in book.coupled


def test_a_knob_pair_is_coupled_only_with_the_knob_in_the_hole_for_the_confirm_steps():
    seating = pr.Seating(confirm_steps=2, knob=0.001)
    pair = pr.make_pair("k", "h", pr.KNOB, GEO)
    h = (0.0, 0.0, 0.0)
    off = (0.003, -GEO.body_side, 0.0)              # 3 mm along the side from the hole: pressed, not in
    assert pr.update_status(pair, off, h, GEO, 0.0015, seating) == pr.DECOUPLED
    home = (0.0005, -GEO.body_side - 0.0003, 0.0)
    assert pr.update_status(pair, home, h, GEO, 0.0015, seating) == pr.DECOUPLED      # first reading
    assert pr.update_status(pair, home, h, GEO, 0.0015, seating) == pr.HEAD_INSERTED
    # without the tolerance (Seating's default) the knob region decides at once, 3 mm off included
    loose = pr.make_pair("k", "h", pr.KNOB, GEO)
    assert pr.update_status(loose, off, h, GEO, 0.0015) == pr.HEAD_INSERTED


def test_the_knob_measure_is_the_gap_out_from_the_hole_side_and_the_offset_along_it():
    pair = pr.make_pair("k", "h", pr.KNOB, GEO)          # k's left knob in h's right hole: k on h's right
    h = (0.3, 0.1, 0.5)
    c, s = math.cos(h[2]), math.sin(h[2])

    def at(along, out, dth=0.0):                          # k's pose: its centre body_side + out to h's right
        x, y = along, -GEO.body_side - out
        return (h[0] + c * x - s * y, h[1] + s * x + c * y, h[2] + dth)
    gap, along, dth = pr.knob_measure(pair, at(0.002, 0.003), h)
    assert (gap, along, dth) == pytest.approx((0.003, 0.002, 0.0), abs=1e-12)
    assert pr.knob_offset(pair, at(0.002, 0.003), h) == pytest.approx(0.003)
    assert pr.knob_measure(pair, at(0.0, -0.001), h)[0] == pytest.approx(-0.001)    # pressed into the side
    assert pr.knob_measure(pair, at(0.0, 0.0, 0.05), h)[2] == pytest.approx(0.05)


def test_a_coupled_knob_pair_off_its_hole_is_lost_when_no_couple_runs_to_close_it():
    settings = MPCSettings()
    book = pr.PairBook.from_settings(GEO, settings)
    pair = pr.make_pair("k", "h", pr.KNOB, GEO)
    book.add_coupled(pair)
    h = (0.0, 0.0, 0.0)
    seated, open_ = (0.0, -GEO.body_side - 0.0005, 0.0), (0.0, -GEO.body_side - 0.003, 0.0)
    steps = int(round(settings.dock_repair_time / settings.dt))
    for k in range(2 * steps):                              # within the knob test's tolerance: kept
        assert book.update({"k": seated, "h": h}, now=settings.dt * k) == ([], [])
    t0, lost = 2 * steps * settings.dt, []
    for k in range(steps + 1):                              # the sides 3 mm apart for repair_time: lost
        lost += book.update({"k": open_, "h": h}, now=t0 + settings.dt * k)[1]
    assert lost == [pair] and pair.key not in book.coupled and pair.status == pr.DECOUPLED and not book.goals


@pytest.mark.parametrize("first", [pr.KNOB, pr.ANCHOR])
def test_a_bridge_forms_the_pairs_of_its_first_type_first(first):
    # a 2 x 2 bridge: anchor pairs f1->b1 and f2->b2 (front to back), knob pairs f1->f2 and b1->b2 (side by side)
    anchors = [pr.make_pair("f1", "b1", pr.ANCHOR, GEO), pr.make_pair("f2", "b2", pr.ANCHOR, GEO)]
    knobs = [pr.make_pair("f1", "f2", pr.KNOB, GEO), pr.make_pair("b1", "b2", pr.KNOB, GEO)]
    poses = {n: (0.0, 0.0, 0.0) for n in ("f1", "f2", "b1", "b2")}
    book = pr.PairBook(GEO, EPS, 0.005, max_seeds=1, first=first)
    book.set_goals(anchors + knobs)
    firsts, seconds = (knobs, anchors) if first == pr.KNOB else (anchors, knobs)
    # both parts (rows or chains) form at once: each is its own target for the seed limit
    assert sorted(p.key for p in book.assign_active(poses)) == sorted(p.key for p in firsts)
    for p in firsts:
        book.add_coupled(p)
        book.goals.remove(p)
    book.active = []
    # then one pair of the other type joins the two parts; the other closes the loop
    active = book.assign_active(poses)
    assert len(active) == 1 and active[0] in seconds
