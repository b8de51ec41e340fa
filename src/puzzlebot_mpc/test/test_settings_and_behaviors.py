import math
from dataclasses import replace

import numpy as np
import pytest

from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_mpc import docking as dk
from puzzlebot_mpc import pairs as pr
from puzzlebot_mpc.behaviors import (FAILED, RUNNING, SUCCEEDED, BehaviorError, BehaviorManager,
                                     BehaviorRequest, partner_turn, wiggle)
from puzzlebot_mpc.settings import MPCSettings

import os

CONFIG = os.path.join(os.path.dirname(__file__), "..", "config", "mpc.yaml")


def test_shipped_config_loads():
    s = MPCSettings.from_dict(load_yaml(CONFIG)["mpc"])
    assert s.dt == 0.1 and s.constraint_horizon <= s.horizon


@pytest.mark.parametrize("data, fragment", [
    ({"horizon": 0}, "horizon"),
    ({"horizon": 3, "constraint_horizon": 5}, "constraint_horizon"),
    ({"v_max": "fast"}, "v_max"),
    ({"dt": float("nan")}, "dt"),
    ({"horizn": 3}, "unknown key"),
    ({"butterfly": 1}, "true or false"),
    ({"assembly_seed_at": "front"}, "assembly_seed_at"),
    ({"stage_standoff": -0.01}, "stage_standoff"),
])
def test_bad_settings_raise_config_error(data, fragment):
    with pytest.raises(ConfigError) as e:
        MPCSettings.from_dict(data)
    assert fragment in str(e.value)


def manager():
    return BehaviorManager(["pz1", "pz2", "pz3"], MPCSettings())


def control_step(m, poses, now):
    """One control step of manager ``m`` as control_loop.ControlLoop.step runs it: (status, objectives)."""
    m.pairs.update(poses, now)
    status = m.update(now, poses)
    m.pairs.assign_active(poses)
    return status, m.objectives(now, poses)


@pytest.mark.parametrize("req, fragment", [
    (BehaviorRequest("go_to_goal", ["pz9"], [(0, 0)]), "unknown robot"),
    (BehaviorRequest("fly"), "unknown behaviour"),
    (BehaviorRequest("go_to_goal", ["pz1", "pz2"], [(0, 0)]), "one goal per robot"),
    (BehaviorRequest("go_to_goal", ["pz1"], [(math.nan, 0)]), "not a finite"),
    (BehaviorRequest("go_to_goal", ["pz1", "pz1"], [(0, 0), (1, 1)]), "named twice"),
    (BehaviorRequest("follow_velocity", ["pz1"], velocities=[(1.0, 0.0)]), "exceeds the limits"),
    (BehaviorRequest("stop", timeout=-1.0), "timeout"),
])
def test_bad_requests_are_refused_and_change_nothing(req, fragment):
    m = manager()
    good = m.request(BehaviorRequest("go_to_goal", ["pz1"], [(0.1, 0.0)]), now=0.0)
    with pytest.raises(BehaviorError) as e:
        m.request(req, now=1.0)
    assert fragment in str(e.value)
    status = m.update(1.0, {"pz1": (0.0, 0.0, 0.0)})
    assert status.request_id == good and status.state == RUNNING
    assert m.objectives().goal_mask[0]


def test_go_to_goal_succeeds_within_tolerance_and_fails_on_timeout():
    m = manager()
    m.request(BehaviorRequest("go_to_goal", ["pz1", "pz2"], [(0.1, 0.0), (0.0, 0.1)], timeout=10.0), now=0.0)
    s = m.update(1.0, {"pz1": (0.1, 0.004, 0), "pz2": (0.0, 0.09, 0)})
    assert s.state == RUNNING and s.errors == pytest.approx([0.004, 0.01])
    s = m.update(2.0, {"pz1": (0.1, 0.004, 0), "pz2": (0.0, 0.097, 0)})
    assert s.state == SUCCEEDED
    m.request(BehaviorRequest("go_to_goal", ["pz3"], [(1.0, 1.0)], timeout=5.0), now=3.0)
    s = m.update(8.5, {"pz3": (0.0, 0.0, 0.0)})
    assert s.state == FAILED and "pz3" in s.message
    assert not m.objectives().goal_mask.any()  # stopped after the failure


def test_unrequested_robots_are_stopped():
    m = manager()
    m.request(BehaviorRequest("follow_velocity", ["pz2"], velocities=[(0.03, 0.2)]), now=0.0)
    o = m.objectives()
    assert (o.velocity_mask > 0).all()
    assert o.velocity[1] == pytest.approx([0.03, 0.2])
    assert o.velocity[0] == pytest.approx([0, 0]) and o.velocity[2] == pytest.approx([0, 0])


@pytest.mark.parametrize("docking", [False, True])
def test_seed_pair_partner_holds_while_the_mover_pushes_the_anchor_home(docking):
    # docking=True here is the straight push of puzzlebot_mpc.docking (dock_insert_by_mpc false)
    settings = MPCSettings(docking=docking, dock_insert_by_mpc=not docking)
    m = BehaviorManager(["pz1", "pz2"], settings)

    def step(now, poses):
        return control_step(m, poses, now)[1].velocity_mask

    far = {"pz1": (0.0, 0.0, 0.0), "pz2": (-0.15, 0.0, 0.0)}
    m.request(BehaviorRequest("couple", ["pz1", "pz2"], target="line", timeout=60.0), now=0.0, poses=far)
    assert (step(0.1, far) == 0.0).all()                               # lining up: both move
    (pair,) = m.pairs.active
    a, o = pair.robot_i, pair.robot_j                                  # o docks (the opening robot)
    inside = {a: (0.0, 0.0, 0.0), o: (-m.geometry.body_side - 0.008, 0.0, 0.0)}   # head 8 mm in
    mask = step(0.2, inside)
    assert pair.status == 1                                            # head_aligned
    assert mask[m.index[a]] == pytest.approx([math.sqrt(settings.hold_scale)] * 2)   # a holds still
    if not docking:
        assert mask[m.index[o]] == pytest.approx([0.0, 0.0])          # o pushes: the MPC's alignment cost
        return
    # the docking manoeuvre pushes o straight in: its command is sent as is, the MPC tracks it, and the
    # pair's alignment cost is off while it does
    obj = m.objectives(0.2, inside)
    assert m.pairs.docking[pair.key].phase == "push"
    assert obj.open_loop[m.index[o]] == pytest.approx((settings.dock_push_speed, 0.0))
    assert mask[m.index[o]] == pytest.approx([1.0, 1.0])
    assert not [p for p in obj.pairs if p.active]


@pytest.mark.parametrize("brace", [MPCSettings().dock_brace_speed, 0.0])
def test_during_a_nudge_the_anchor_robots_assembly_braces(brace):
    """A line's end robot pz2 (coupled to pz1) is docked onto by pz3 driving forwards; the insertion stalls
    with the head at the lips, so pz3 is nudged straight in and pz2's line backs into it at
    dock_brace_speed."""
    settings = MPCSettings(dock_brace_speed=brace)
    m = BehaviorManager(["pz1", "pz2", "pz3"], settings)
    side = m.geometry.body_side
    seated = {"pz1": (side, 0.0, 0.0), "pz2": (0.0, 0.0, 0.0)}
    m.pairs.add_coupled(pr.make_pair("pz1", "pz2", pr.ANCHOR, m.geometry))
    poses = dict(seated, pz3=(-0.15, 0.0, 0.0))
    m.request(BehaviorRequest("couple", ["pz1", "pz2", "pz3"], target="line", timeout=60.0), now=0.0, poses=poses)
    poses["pz3"] = (-side - 0.011, 0.0, 0.0)                           # the head at pz3's lips, 11 mm out

    def step(now):
        return control_step(m, poses, now)[1]

    step(0.1)                                                          # pz2->pz3 becomes active ...
    obj = step(0.2)
    (pair,) = m.pairs.active
    assert pair.robots == ("pz2", "pz3") and m.pairs.mover(pair) == "j" and pair.status == 1
    assert not obj.open_loop                                           # ... head_aligned: the MPC inserts
    for k in range(3, 3 + int(round(settings.dock_insert_stall_time / settings.dt)) + 1):
        obj = step(0.1 * k)                                            # no deeper for insert_stall_time
    assert m.pairs.docking[pair.key].phase == "nudge"
    assert obj.open_loop[m.index["pz3"]] == pytest.approx((settings.dock_push_speed, 0.0))
    for r in ("pz2", "pz1"):                                           # the whole line backs in as one body
        if brace:
            assert obj.open_loop[m.index[r]] == pytest.approx((-brace, 0.0))
        else:
            assert m.index[r] not in obj.open_loop


def wait_for_the_seat_monitor(m, poses, pair):
    """Steps manager ``m`` (a couple running, ``pair`` coupled but open in ``poses``) every 0.1 s from 0.1 s:
    the couple waits for the pair to close until the seat monitor takes it out of the coupled pairs (open
    for dock_repair_time). Returns k, the next step's index (its time 0.1 k s)."""
    status = control_step(m, poses, 0.1)[0]
    assert status.state == RUNNING and "waiting for %s-%s to close" % pair.key in status.message
    k = 2
    while pair.key in m.pairs.coupled:
        status = control_step(m, poses, 0.1 * k)[0]
        assert status.state == RUNNING and k < 30
        k += 1
    return k


def test_a_couple_does_not_succeed_while_a_coupled_pair_is_open_and_the_monitor_reseats_it():
    """Every goal pair coupled, but pz1-pz2's faces 5 mm apart (a barb on the lip, pulled open by a robot
    docking elsewhere): the couple runs on, the seat monitor sends the pair back to be pushed home, and the
    couple succeeds once it is."""
    settings = MPCSettings()
    m = BehaviorManager(["pz1", "pz2"], settings)
    side = m.geometry.body_side
    pair = pr.make_pair("pz1", "pz2", pr.ANCHOR, m.geometry)
    m.pairs.add_coupled(pair)
    poses = {"pz1": (side + 0.005, 0.0, 0.0), "pz2": (0.0, 0.0, 0.0)}
    m.request(BehaviorRequest("couple", ["pz1", "pz2"], target="line", timeout=60.0), now=0.0, poses=poses)

    def step(now):
        return control_step(m, poses, now)[0]

    k = wait_for_the_seat_monitor(m, poses, pair)
    assert m.pairs.docking[pair.key].phase == "push" and m.pairs.goals == [pair]
    poses["pz1"] = (side, 0.0, 0.0)                                    # pushed home
    for _ in range(settings.dock_home_steps + 2):
        status = step(0.1 * k)
        k += 1
    assert status.state == SUCCEEDED and pair.key in m.pairs.coupled


def test_a_knob_pair_pushed_off_its_hole_goes_back_to_the_goals_and_the_couple_waits_for_it():
    """Every goal pair coupled, but the knob pair's sides 3 mm apart (pushed open by a row docking behind
    it): the couple does not succeed; after dock_repair_time the pair is a goal again (decoupled: its
    approach closes it), and once the knob is back in its hole for the confirm steps the couple succeeds.
    Within the knob test's tolerance nothing happens."""
    settings = MPCSettings()
    m = BehaviorManager(["k1", "k2"], settings)
    side = m.geometry.body_side
    pair = pr.make_pair("k1", "k2", pr.KNOB, m.geometry)
    m.pairs.add_coupled(pair)
    home = (0.0, -side, 0.0)                                           # k1 right of k2: k1's knob in k2's hole
    assert pr.knob_offset(pair, home, (0.0, 0.0, 0.0)) == pytest.approx(0.0, abs=1e-12)
    poses = {"k1": (0.0, -side - 0.003, 0.0), "k2": (0.0, 0.0, 0.0)}
    m.request(BehaviorRequest("couple", ["k1", "k2"], target="row", timeout=60.0), now=0.0, poses=poses)

    def step(now):
        return control_step(m, poses, now)[0]

    k = wait_for_the_seat_monitor(m, poses, pair)
    assert k * 0.1 >= settings.dock_repair_time
    assert m.pairs.goals == [pair] and pair.status == pr.DECOUPLED and m.pairs.reseats == 1
    poses["k1"] = (0.0, -side - 0.5 * settings.knob_seat_tolerance, 0.0)    # back in, within the tolerance
    for _ in range(settings.insert_confirm_steps + 1):
        status = step(0.1 * k)
        k += 1
    assert status.state == SUCCEEDED and pair.key in m.pairs.coupled
    for _ in range(int(2 * settings.dock_repair_time / 0.1)):          # seated within the tolerance: kept
        control_step(m, poses, 0.1 * k)
        k += 1
    assert pair.key in m.pairs.coupled and m.pairs.reseats == 1


def bridge_with_pairs_coupled(close):
    """A manager coupling four robots standing as a 2 x 2 grid (rows pz1 pz3 and pz2 pz4 side by side,
    pz1's anchor in pz2's mouth, pz3's in pz4's) with every goal pair coupled but those of type ``close``
    (ANCHOR: one anchor pair; KNOB: one knob pair): (manager, poses, the pair left to close)."""
    settings = MPCSettings()
    m = BehaviorManager(["pz1", "pz2", "pz3", "pz4"], settings)
    side = m.geometry.body_side
    poses = {"pz1": (0.0, 0.0, 0.0), "pz2": (-side, 0.0, 0.0), "pz3": (0.0, side, 0.0), "pz4": (-side, side, 0.0)}
    m.request(BehaviorRequest("couple", list(poses), target="grid", timeout=60.0), now=0.0, poses=poses)
    goals = sorted(m.pairs.goals, key=lambda q: q.key)
    left = [q for q in goals if q.type == close][0]
    for q in goals:
        if q is not left:
            m.pairs.add_coupled(q)
            m.pairs.goals.remove(q)
    return m, poses, left


def test_the_second_anchor_pair_between_two_rows_frees_the_opening_robots_row_to_turn_onto_it():
    """Both rows formed (knob pairs) and joined by one anchor pair: closing the other (a loop) leaves the
    opening robot's row free for the alignment cost, turning about the coupled anchor pair; the anchor
    robot's row holds. A knob pair closing a loop still holds on both sides."""
    m, poses, closing = bridge_with_pairs_coupled(pr.ANCHOR)
    o = closing.robot_j
    row = set(m.pairs.row_of(o))
    (hinge,) = [q for q in m.pairs.coupled.values() if q.type == pr.ANCHOR]
    px, py, _ = poses[hinge.robot_j]
    px += m.geometry.body_side / 2                                      # the coupled anchor pair's mouth
    c, sn = math.cos(0.1), math.sin(0.1)
    for r in row:                                                       # the row turned 0.1 rad about it
        x, y, th = poses[r]
        poses[r] = (px + c * (x - px) - sn * (y - py), py + sn * (x - px) + c * (y - py), th + 0.1)
    obj = control_step(m, poses, 0.1)[1]
    assert m.pairs.active == [closing] and m.pairs.mover(closing) is None
    assert len(row) == 2 and closing.robot_i not in row
    for r in poses:
        assert (not np.any(obj.velocity_mask[m.index[r]])) == (r in row), r
    k, poses, closing = bridge_with_pairs_coupled(pr.KNOB)
    obj = control_step(k, poses, 0.1)[1]
    assert k.pairs.active == [closing] and k.pairs.mover(closing) is None
    assert all(np.all(obj.velocity_mask[k.index[r]]) for r in poses)


def test_an_anchor_pair_reseated_inside_a_loop_keeps_its_alignment_cost():
    """A 2 x 2 grid with every pair coupled; one anchor pair between the rows opens 5 mm (pushed out by a
    neighbour). The seat monitor sends it back to be pushed home, but it closes a loop: nobody can push it,
    so its alignment cost stays on (it is not counted as driven by its docking) and no robot gets a docking
    command."""
    m, poses, left = bridge_with_pairs_coupled(pr.ANCHOR)
    m.pairs.add_coupled(left)
    m.pairs.goals.remove(left)
    (pair,) = [q for q in m.pairs.coupled.values() if q.type == pr.ANCHOR and q.robot_j == "pz2"]
    px, py, _ = poses["pz4"]
    px += m.geometry.body_side / 2                                      # pz4's mouth: the row turns about it
    c, sn = math.cos(-0.1), math.sin(-0.1)
    for r in ("pz2", "pz4"):
        x, y, th = poses[r]
        poses[r] = (px + c * (x - px) - sn * (y - py), py + sn * (x - px) + c * (y - py), th - 0.1)
    assert dk.seat_measure(pair, poses["pz1"], poses["pz2"])[0] > m.settings.dock_repair_gap
    wait_for_the_seat_monitor(m, poses, pair)
    assert m.pairs.docking[pair.key].phase == "push" and m.pairs.goals == [pair]
    obj = control_step(m, poses, 5.0)[1]
    assert m.pairs.active == [pair] and m.pairs.mover(pair) is None
    (slot,) = [q for q in obj.pairs if (q.i, q.j) == (m.index[pair.robot_i], m.index[pair.robot_j])]
    assert slot.active
    assert not obj.open_loop


def test_an_anchor_pair_closing_a_loop_is_coupled_once_its_faces_have_touched_for_the_loop_time():
    """Nobody can push and pull the second anchor pair between two rows: it is coupled when it has looked
    seated (faces within dock_loop_gap, head through the opening) for dock_loop_time, even 3 mm off its
    axis (past Algorithm 2's lining-up tolerance); faces 2 mm apart (a barb on the lip) never are."""
    settings = MPCSettings()
    geo = RobotGeometry()

    def closes(gap, lateral, seconds):
        book = pr.PairBook.from_settings(geo, settings)
        pair = pr.make_pair("a", "o", pr.ANCHOR, geo)
        book.set_goals([pair])
        book.active, book.movers[pair.key] = [pair], None           # a loop closure: both sides hold
        pair.status = pr.HEAD_ALIGNED
        poses = {"a": (0.0, 0.0, 0.0), "o": (-geo.body_side - gap, lateral, 0.0)}
        t = 0.0
        while t <= seconds:
            book.update(poses, t)
            if pair.key in book.coupled:
                return t
            t = round(t + 0.1, 6)
        return None

    assert settings.dock_loop_gap < 0.002 and settings.insert_lateral_tolerance < 0.003
    t = closes(0.0, 0.003, 3.0)
    assert t is not None and t >= settings.dock_loop_time
    assert closes(0.002, 0.003, 5.0) is None
    assert closes(0.0, 0.009, 5.0) is None                          # the head outside the opening


def test_a_knob_mover_with_a_robot_behind_it_stops_and_its_partner_pulls_ahead_instead():
    """Rows forming in a column of rows (the grid's start): the mover pz2, beside its partner and off its
    lane, would back off for a run into the robot behind it; it stops clearance short of it and its
    partner pz1 drives ahead while it has room."""
    settings = MPCSettings()
    side, lane, clearance = RobotGeometry().body_side, settings.knob_lane(), settings.backoff_clearance

    def velocities(behind_gap, ahead_gap):
        """pz2 beside pz1's left side, 25 mm out; pz3 behind pz2 and pz4 ahead of pz1, the gaps [m] between
        the bodies (pz3's anchor included) along the line of travel."""
        m = BehaviorManager(["pz1", "pz2", "pz3", "pz4"], settings)
        geo = m.geometry
        size = geo.footprint_radius()
        y = side + 0.025
        poses = {"pz1": (0.0, 0.0, 0.0), "pz2": (0.0, y, 0.0),
                 "pz3": (-(side / 2 + geo.anchor_length + size + behind_gap), y, 0.0),
                 "pz4": (side / 2 + size + ahead_gap, 0.0, 0.0)}
        m.request(BehaviorRequest("couple", ["pz1", "pz2"], target="row", timeout=60.0), now=0.0, poses=poses)
        obj = control_step(m, poses, 0.1)[1]
        (pair,) = m.pairs.active
        assert pair.type == pr.KNOB and m.pairs.mover(pair) == "j" and pair.robot_j == "pz2"
        return obj.velocity[m.index["pz2"]], obj.velocity[m.index["pz1"]], obj.velocity_mask[m.index["pz1"]]

    mover, holder, _ = velocities(0.1, 0.1)                              # room behind: the mover backs
    assert mover[0] == pytest.approx(-lane.speed) and holder[0] == pytest.approx(0.0)
    mover, holder, mask = velocities(clearance - 0.002, 0.1)        # the robot behind: the partner goes
    assert tuple(mover) == (0.0, 0.0) and tuple(holder) == pytest.approx((lane.speed, 0.0))
    assert tuple(mask) == (1.0, 1.0)
    mover, holder, _ = velocities(clearance - 0.002, clearance - 0.002)   # no room either way
    assert tuple(mover) == (0.0, 0.0) and holder[0] == pytest.approx(0.0)


def test_a_seed_pairs_holder_only_turns_with_another_robot_close_by():
    """The MPC keeps no robots apart: a holder that drove to line up would run into its neighbour."""
    settings = MPCSettings()
    far = {"pz1": (0.0, 0.0, 0.0), "pz2": (-0.15, 0.0, 0.0)}

    def holder_mask(neighbour, clearance=settings.seed_holder_clearance):
        m = BehaviorManager(["pz1", "pz2", "pz3"], replace(settings, seed_holder_clearance=clearance))
        poses = dict(far, pz3=neighbour)
        m.request(BehaviorRequest("couple", ["pz1", "pz2"], target="line", timeout=60.0), now=0.0, poses=poses)
        m.pairs.update(poses, 0.1)
        m.update(0.1, poses)
        m.pairs.assign_active(poses)
        (pair,) = m.pairs.active
        mask = m.objectives(0.1, poses).velocity_mask
        assert pair.robot_j == "pz2" and mask[m.index["pz2"]] == pytest.approx([0.0, 0.0])   # pz2 docks
        return mask[m.index["pz1"]]

    in_front = (settings.seed_holder_clearance - 0.01, 0.0, 0.0)     # pz3 just inside the clearance of pz1
    assert holder_mask(in_front) == pytest.approx([math.sqrt(settings.hold_scale), 0.0])   # pz1 only turns
    assert holder_mask((0.5, 0.5, 0.0)) == pytest.approx([0.0, 0.0])                      # nobody near: drives
    assert holder_mask(in_front, clearance=0.0) == pytest.approx([0.0, 0.0])              # 0: always drives


def test_a_robot_waiting_for_a_busy_partner_stands_ready_lined_up_in_front_of_it():
    """A line grown from its tail: pz3 docks onto pz4 (backing in); pz2, whose partner pz3 is busy, drives to
    where its anchor point is stage_standoff in front of pz3's opening, on pz3's axis; pz1 waits in place."""
    settings = replace(MPCSettings(), assembly_seed_at="tail", stage_standoff=0.04)
    geo = RobotGeometry()
    L = geo.body_side
    poses = {"pz1": (0.4, 0.05, 0.0), "pz2": (0.3, 0.05, 0.0), "pz3": (0.12, 0.0, 0.3), "pz4": (0.0, 0.0, 0.3)}
    m = BehaviorManager(list(poses), settings)
    m.request(BehaviorRequest("couple", list(poses), target="line", timeout=60.0), now=0.0, poses=poses)
    m.update(0.1, poses)
    m.pairs.add_coupled(m.pairs.goals[-1])                             # pz3->pz4 coupled: pz2 -> pz3 grows next
    m.pairs.goals.pop()
    m.pairs.assign_active(poses)
    assert [p.key for p in m.pairs.active] == [("pz2", "pz3")] and m.pairs.mover(m.pairs.active[0]) == "i"
    m.pairs.active = []                                                # stand-in for a pair still under way:
    busy = m.pairs.find("pz3", "pz4")                                  # pz3 docking onto pz4
    m.pairs.remove_coupled(busy.key)
    m.pairs.goals.append(busy)
    m.pairs.active = [busy]
    obj = m.objectives(0.2, poses)
    k2, k1 = m.index["pz2"], m.index["pz1"]
    c, s = math.cos(0.3), math.sin(0.3)
    d = L + 0.04                                                       # centre to centre, on pz3's axis
    assert obj.goal_mask[k2] and obj.goal[k2] == pytest.approx([0.12 + d * c, d * s])
    assert list(obj.velocity_mask[k2]) == [0.0, 0.0]
    assert not obj.goal_mask[k1]                                       # its partner pz2 is single and idle
    off = BehaviorManager(list(poses), replace(settings, stage_standoff=0.0))
    off.request(BehaviorRequest("couple", list(poses), target="line", timeout=60.0), now=0.0, poses=poses)
    off.update(0.1, poses)
    off.pairs.active = [off.pairs.find("pz3", "pz4")]
    assert not off.objectives(0.2, poses).goal_mask.any()              # 0: everyone waits in place


# ------------------------------------------------- decouple: the partner turns the other way

SHARE = 0.3


def wiggling_settings(share=SHARE):
    return replace(MPCSettings(), wiggle_partner_turn=share, wiggle_cycles=0.5, wiggle_period=2.0,
                   decouple_reseat_time=0.5, wiggle_heading_amplitude=0.55)


@pytest.mark.parametrize("data, fragment", [
    ({"wiggle_partner_turn": 1.5}, "wiggle_partner_turn"),
    ({"wiggle_partner_turn": -0.1}, "wiggle_partner_turn"),
])
def test_partner_turn_outside_0_1_is_refused(data, fragment):
    with pytest.raises(ConfigError, match=fragment):
        MPCSettings.from_dict(data)


def test_partner_turns_against_the_swing_only_while_it_is_alone_and_a_swing_runs():
    s = wiggling_settings()
    assert partner_turn(s, 2.0, "wiggle", 1) == pytest.approx(-SHARE * 2.0)
    assert partner_turn(s, -1.0, "wiggle", 1) == pytest.approx(SHARE)
    assert partner_turn(s, 2.0, "reseat", 1) is None           # between swings the MPC drives it
    assert partner_turn(s, 2.0, "wiggle", 2) is None           # in an assembly it does not turn in place
    assert partner_turn(wiggling_settings(0.0), 2.0, "wiggle", 1) is None


def decoupling(names, coupled):
    """A manager running ``decouple`` of the first coupled pair; robots in a line along -x, facing +x."""
    geo = RobotGeometry()
    m = BehaviorManager(list(names), wiggling_settings(), geo)
    for a, o in coupled:
        m.pairs.add_coupled(pr.make_pair(a, o, pr.ANCHOR, geo, status=pr.HEAD_INSERTED))
    poses = {n: (-0.0503 * k, 0.0, 0.0) for k, n in enumerate(names)}
    m.request(BehaviorRequest("decouple", pair=list(coupled[0])), now=0.0, poses=poses)
    return m, poses


def test_a_lone_partner_counter_turns_through_each_swing_and_not_while_reseating():
    m, poses = decoupling(["pz1", "pz2"], [("pz1", "pz2")])
    s = m.settings
    seen = []
    for k in range(15):                                      # one attempt: a 1 s swing, then 0.5 s reseat
        t = 0.1 * k
        rel = s.wiggle_heading_amplitude * math.sin(math.pi * t) if t < 1.0 else 0.0
        poses["pz1"] = (0.0, 0.0, rel)                       # scripted: the swing follows its reference
        obj = m.objectives(now=t, poses=poses)
        v, w, phase = wiggle(s, t, rel)
        assert obj.open_loop[0] == pytest.approx((v, w))     # the anchor robot wiggles
        if phase == "wiggle":
            assert obj.open_loop[1] == pytest.approx((0.0, -SHARE * w))
            seen.append(math.copysign(1.0, w) if abs(w) > 1e-6 else 0.0)
        else:
            assert 1 not in obj.open_loop                    # reseat: the MPC drives the partner again
    assert 1.0 in seen and -1.0 in seen                      # both ways, always against the anchor robot


def test_a_partner_with_an_assembly_behind_it_is_not_turned_in_place():
    m, poses = decoupling(["pz1", "pz2", "pz3"], [("pz1", "pz2"), ("pz2", "pz3")])
    for k in range(10):
        obj = m.objectives(now=0.1 * k, poses=poses)
        assert 0 in obj.open_loop and 1 not in obj.open_loop


def test_a_coupled_knob_pairs_constraint_is_tightened_from_where_its_knob_is():
    """The manager hands the MPC a coupled knob pair 1.5 mm open with its region tightened only to
    knob_hold_step further in (pairs.constraint_margin); a coupled anchor pair keeps pip_margin (None)."""
    settings = MPCSettings()
    m = BehaviorManager(["k1", "k2", "a"], settings)
    side = m.geometry.body_side
    knob, anchor = pr.make_pair("k1", "k2", pr.KNOB, m.geometry), pr.make_pair("a", "k2", pr.ANCHOR, m.geometry)
    m.pairs.add_coupled(knob)
    m.pairs.add_coupled(anchor)
    poses = {"k1": (0.0, -side - 0.0015, 0.0), "k2": (0.0, 0.0, 0.0), "a": (side, 0.0, 0.0)}
    margins = {(o.i, o.j): o.margin for o in m.objectives(0.0, poses).pairs}
    inside = m.geometry.knob_tolerance - 0.0015
    assert margins[(0, 1)] == pytest.approx(inside + settings.knob_hold_step, abs=1e-4)
    assert margins[(0, 1)] < m.geometry.knob_tolerance - settings.knob_hold
    assert margins[(2, 1)] is None
