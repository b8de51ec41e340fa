"""Several assemblies at once on the kinematic plant: a couple request with groups forms one line per group
in parallel, then assembly_to_goal leads each line to its own goal; bad requests."""

import math
from dataclasses import replace

import numpy as np
import pytest

from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.behaviors import FAILED, SUCCEEDED, BehaviorError, BehaviorRequest
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_mpc.targets import assign, generate, make_target, merge_assignments

from test_coupling_loop import GEO, KINEMATIC, START, Plant

GROUP_A = ["pz1", "pz2", "pz3", "pz4"]
GROUP_B = ["pz5", "pz6", "pz7", "pz8"]
NAMES = GROUP_A + GROUP_B
OFFSET_B = 0.4          # m: the second cluster stands this far to the left of the first
#: the coupling demo's scatter twice, the second one shifted sideways
STARTS = dict(START, **{b: (START[a][0], START[a][1] + OFFSET_B, START[a][2]) for a, b in zip(GROUP_A, GROUP_B)})


class Watched(Plant):
    """The plant, also recording which groups had an active pair at each step."""

    def run(self, req, max_time, watch=()):
        self.both_active = 0
        step = self.loop.step

        def counting(t):
            out = step(t)
            groups = {0 if p.robot_i in GROUP_A else 1 for p in self.loop.pairs.active}
            self.both_active += len(groups) == 2
            return out

        self.loop.step = counting
        try:
            return super().run(req, max_time, watch)
        finally:
            self.loop.step = step


def ahead(pose, distance, left):
    """The point ``distance`` [m] ahead of ``pose`` along its heading and ``left`` [m] to its left."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return (pose[0] + distance * c - left * s, pose[1] + distance * s + left * c)


@pytest.fixture(scope="module")
def run():
    loop = ControlLoop(NAMES, KINEMATIC)
    plant = Watched(loop, STARTS)
    res = {"couple": plant.run(BehaviorRequest("couple", NAMES, target="line", timeout=120.0, groups=[4, 4]),
                               125.0)}
    res["both_active"] = plant.both_active
    res["coupled"] = sorted(loop.pairs.coupled)
    goals = [ahead(plant.poses["pz1"], 0.3, -0.04), ahead(plant.poses["pz5"], 0.3, 0.04)]
    res["goals"] = goals
    res["drive"] = plant.run(BehaviorRequest("assembly_to_goal", ["pz1", "pz5"], goals=goals, tolerance=0.01,
                                             timeout=60.0), 65.0, watch=list(loop.pairs.coupled))
    res["end"] = dict(plant.poses)
    res["coupled_after_drive"] = sorted(loop.pairs.coupled)
    res["min_margin"] = plant.min_margin
    res["failures"] = plant.failures
    return res


def test_each_group_forms_its_own_line_in_parallel(run):
    status, elapsed = run["couple"]
    assert status.state == SUCCEEDED, status.message
    assert len(run["coupled"]) == 6
    for a, b in run["coupled"]:                          # no pair across the groups
        assert (a in GROUP_A) == (b in GROUP_A)
    assert run["both_active"] > 10                       # the two lines formed at the same time


def test_each_line_drives_to_its_own_goal_with_every_pair_held(run):
    status, _ = run["drive"]
    assert status.state == SUCCEEDED, status.message
    for lead, goal in zip(("pz1", "pz5"), run["goals"]):
        p = run["end"][lead]
        assert math.hypot(p[0] - goal[0], p[1] - goal[1]) <= 0.01
    assert run["coupled_after_drive"] == run["coupled"]
    assert run["min_margin"] >= 0.0                      # every head stayed inside its polygon
    assert run["failures"] == 0


def test_merged_assignment_numbers_the_slots_on():
    line = make_target("line", generate("line", 4, GEO), GEO)
    a = assign(line, GROUP_A, np.array([STARTS[r] for r in GROUP_A]), GEO)
    b = assign(line, GROUP_B, np.array([STARTS[r] for r in GROUP_B]), GEO)
    m = merge_assignments([a, b])
    assert m.robots == NAMES and len(m.pairs) == 6 and m.slots_world.shape == (8, 3)
    assert sorted(m.slot_of.values()) == list(range(8))
    for r in NAMES:                                      # each robot keeps its slot as placed
        own = a if r in GROUP_A else b
        assert np.allclose(m.slots_world[m.slot_of[r]], own.slots_world[own.slot_of[r]])
    assert m.cost == pytest.approx(a.cost + b.cost)


def stopped_loop():
    loop = ControlLoop(NAMES, KINEMATIC)
    for n, p in STARTS.items():
        loop.on_pose(n, 0.0, *p)
    return loop


@pytest.mark.parametrize("req, fragment", [
    (BehaviorRequest("couple", NAMES, target="line", groups=[4, 3]), "adding up to the 8"),
    (BehaviorRequest("couple", NAMES, target="line", groups=[7, 1]), "counts >= 2"),
    (BehaviorRequest("couple", NAMES[:4], slots=[(0, 0, 0), (-0.05, 0, 0), (-0.1, 0, 0), (-0.15, 0, 0)],
                     groups=[2, 2]), "not slots"),
    (BehaviorRequest("couple", NAMES, target="row", groups=[2, 6]), None),   # valid: a row of 2 and of 6
    (BehaviorRequest("assembly_to_goal", ["pz1", "pz5"], goals=[(0.3, 0.0)]), "one goal per robot"),
    (BehaviorRequest("assembly_to_goal", ["pz1"], goals=[(math.nan, 0.0)]), "not a finite"),
])
def test_group_and_goal_requests_are_checked(req, fragment):
    loop = stopped_loop()
    if fragment is None:
        loop.request(req, 0.0)
        return
    with pytest.raises(BehaviorError) as e:
        loop.request(req, 0.0)
    assert fragment in str(e.value)


def test_two_leads_of_one_assembly_are_refused():
    loop = stopped_loop()
    for a, b in zip(GROUP_A[:-1], GROUP_A[1:]):
        loop.pairs.add_coupled(pr.make_pair(a, b, pr.ANCHOR, GEO))
    with pytest.raises(BehaviorError) as e:
        loop.request(BehaviorRequest("assembly_to_goal", ["pz1", "pz3"], goals=[(0.3, 0.0), (0.3, 0.1)]), 0.0)
    assert "lead the same assembly" in str(e.value)


def test_a_lost_pair_fails_the_drive():
    loop = stopped_loop()
    loop.pairs.add_coupled(pr.make_pair("pz1", "pz2", pr.ANCHOR, GEO))   # not where the poses are: lost
    plant = Plant(loop, STARTS)
    status, _ = plant.run(BehaviorRequest("assembly_to_goal", ["pz1"], goals=[(0.3, 0.0)], timeout=5.0), 6.0)
    assert status.state == FAILED and "lost" in status.message


def test_a_pair_lost_part_way_fails_the_drive_without_an_error():
    loop = ControlLoop(["pz1", "pz2"], KINEMATIC)
    front = (0.0, 0.0, 0.0)
    loop.on_pose("pz1", 0.0, *front)
    loop.on_pose("pz2", 0.0, -GEO.body_side, 0.0, 0.0)          # coupled behind pz1
    loop.pairs.add_coupled(pr.make_pair("pz1", "pz2", pr.ANCHOR, GEO))
    rid = loop.request(BehaviorRequest("assembly_to_goal", ["pz1"], goals=[(0.3, 0.0)], timeout=5.0), 0.0)
    status = loop.step(0.0).status                                # driving: the distance to the goal is known
    for k in range(1, 11):                                        # then pz2 is pulled back off the anchor
        loop.on_pose("pz1", 0.1 * k, *front)
        loop.on_pose("pz2", 0.1 * k, -GEO.body_side - 0.005 * k, 0.0, 0.0)
        status = loop.step(0.1 * k).status
        if status.state == FAILED:
            break
    assert status.request_id == rid and status.state == FAILED and "lost" in status.message


def test_a_lead_that_passes_its_goal_fails_at_once():
    loop = ControlLoop(["pz1"], replace(KINEMATIC, assembly_turn_rate=1e-6))   # a lead that cannot turn
    plant = Plant(loop, {"pz1": (0.0, 0.0, 0.0)})
    status, elapsed = plant.run(BehaviorRequest("assembly_to_goal", ["pz1"], goals=[(0.1, 0.03)], tolerance=0.01,
                                                timeout=30.0), 31.0)
    assert status.state == FAILED and "passed the goal: pz1" in status.message and elapsed < 10.0


def test_a_line_led_by_its_back_robot_is_driven_from_its_front():
    line = {r: (-k * GEO.body_side, 0.0, 0.0) for k, r in enumerate(GROUP_A)}     # pz1 in front
    loop = ControlLoop(GROUP_A, KINEMATIC)
    for a, b in zip(GROUP_A[:-1], GROUP_A[1:]):
        loop.pairs.add_coupled(pr.make_pair(a, b, pr.ANCHOR, GEO))
    plant = Plant(loop, line)
    goal = (line["pz4"][0] + 0.4, 0.02)         # 2 cm to the side: the line converges onto it like a train
    loop.request(BehaviorRequest("assembly_to_goal", ["pz4"], goals=[goal], tolerance=0.01, timeout=60.0), plant.t)
    assert "driven by pz1" in loop.step(plant.t).status.message
    status, _ = plant.run(BehaviorRequest("assembly_to_goal", ["pz4"], goals=[goal], tolerance=0.01,
                                          timeout=60.0), 61.0)
    assert status.state == SUCCEEDED, status.message
    p = plant.poses["pz4"]
    assert math.hypot(p[0] - goal[0], p[1] - goal[1]) <= 0.01 and len(loop.pairs.coupled) == 3
