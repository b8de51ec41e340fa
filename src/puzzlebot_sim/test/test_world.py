import math
import xml.etree.ElementTree as ET
from dataclasses import replace

import pybullet as pb
import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import wrap_angle
from puzzlebot_common.robots import parse_robot_list
from puzzlebot_common.effects import ActuatorModel
from puzzlebot_sim.coupling import HEAD_INSERTED
from puzzlebot_sim.mocap import MocapModel
from puzzlebot_sim.params import AnchorParams, AnchorRestParams, RobotParams, SimParams, WorldParams
from puzzlebot_sim.scenario_starts import starts_from_config
from puzzlebot_sim.urdf import URDF_MARGIN, anchor_urdf, body_parts, robot_urdf
from puzzlebot_sim.world import RobotStart, SimWorld


def test_urdf_is_well_formed_with_wheels_and_casters():
    root = ET.fromstring(robot_urdf(RobotParams(), name="pz1"))
    links = {l.get("name") for l in root.findall("link")}
    assert {"base_link", "left_wheel", "right_wheel", "front_caster", "rear_caster"} <= links
    joints = {j.get("name"): j.get("type") for j in root.findall("joint")}
    assert joints["left_wheel_joint"] == "continuous"
    materials = {m.get("name") for m in root.iter("material")}
    assert {"mat_lip", "mat_knob", "mat_battery"} <= materials           # opening, side knob, battery box
    pilot = ET.fromstring(robot_urdf(RobotParams(), pilot=True))
    wheels = [j for j in pilot.findall("joint") if j.get("type") == "continuous"]
    assert len(wheels) == 4 and not [l for l in pilot.findall("link") if "caster" in l.get("name")]
    anchor = ET.fromstring(anchor_urdf(AnchorParams()))
    assert {j.get("name") for j in anchor.findall("joint")} == {"neck_joint", "left_barb_joint", "right_barb_joint"}


def test_body_has_no_part_thinner_than_bullets_margin():
    p = RobotParams()
    for lo, hi in body_parts(p)["shell"]:
        assert min(b - a for a, b in zip(lo, hi)) >= 2 * URDF_MARGIN - 1e-12
    with pytest.raises(ConfigError, match="thinner than 2.0 mm"):
        robot_urdf(replace(p, lip_depth=0.0012))
    with pytest.raises(ConfigError, match="radius 0.50 mm is below"):
        robot_urdf(replace(p, knob_radius=0.0005))


def test_chamfered_edges_are_what_bullet_collides_with():
    # 4 mm chamfers on the bottom edges, 12 mm on the top ones: a ray aimed at each corner of the
    # body (y = 10 mm, clear of the opening and holder) hits the 45-degree chamfer plane, not the corner
    p = replace(RobotParams(), bottom_chamfer=0.004, top_chamfer=0.012)
    h, hz = p.body_side / 2, p.body_height / 2
    for lo, hi in body_parts(p)["shell"]:                 # the corners are carved from the block
        for c, zs in ((p.bottom_chamfer, -1), (p.top_chamfer, 1)):
            corner_z = (hz - c) if zs > 0 else (-hz + c)
            in_z = lo[2] >= corner_z - 1e-9 if zs > 0 else hi[2] <= corner_z + 1e-9
            assert not (in_z and (hi[0] > h - c + 1e-9 or lo[0] < -h + c - 1e-9))
    with SimWorld(p, [RobotStart("pz1", 0, 0, 0)]) as w:
        w.run(0.2)
        centre = w.pose("pz1")[0]
        for sx in (1, -1):
            for c, sz in ((p.bottom_chamfer, -1), (p.top_chamfer, 1)):
                start = [centre[0] + sx * (h + 0.01), 0.01, centre[2] + sz * (hz + 0.01)]
                end = [centre[0], 0.01, centre[2]]
                hit = pb.rayTest(start, end, physicsClientId=w.client)[0]
                x, z = hit[3][0] - centre[0], hit[3][2] - centre[2]
                assert sx * x + sz * z == pytest.approx(h + hz - c, abs=0.0012)   # on the plane (margin 1 mm)
    with pytest.raises(ConfigError, match="bottom_chamfer: 1.0 mm is below"):
        RobotParams.from_dict({"bottom_chamfer": 0.001})
    with pytest.raises(ConfigError, match="bottom_chamfer: 9.0 mm would cut into the front opening"):
        RobotParams.from_dict({"bottom_chamfer": 0.009})
    with pytest.raises(ConfigError, match="top_chamfer: 21.0 mm would cut .* \\(must be below 20.0 mm"):
        RobotParams.from_dict({"top_chamfer": 0.021})


def drive(world, seconds):
    world.run(seconds)


def test_robot_drives_straight_and_turns():
    with SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0), RobotStart("pz2", 0, 0.2, math.pi / 2)]) as w:
        drive(w, 0.5)
        w.set_command("pz1", 0.05, 0.0)
        w.set_command("pz2", 0.03, 1.0)
        drive(w, 2.0)
        x, y, yaw = w.pose2d("pz1")
        assert 0.08 < x < 0.12 and abs(y) < 0.003 and abs(yaw) < 0.02
        assert wrap_angle(w.pose2d("pz2")[2] - math.pi / 2) > 1.0  # turned left by more than 1 rad
        assert w.time == pytest.approx(2.5)


def test_knob_in_a_neighbours_hole_is_a_physical_knob_pair():
    # pz2 beside pz1 on its right: pz2's knob (left side) sits in pz1's hole (right side); pz3 is apart
    p = RobotParams()
    starts = [RobotStart("pz1", 0, 0, 0), RobotStart("pz2", 0, -p.body_side - 0.0002, 0),
              RobotStart("pz3", 0.2, 0, 0)]
    with SimWorld(p, starts) as w:
        w.run(0.3)
        pairs = w.physical_knob_pairs()
        assert [(q.anchor_robot, q.opening_robot, q.status, q.knob) for q in pairs] == [
            ("pz2", "pz1", HEAD_INSERTED, True)]
        assert not [q for q in w.physical_pairs() if q.knob]                  # anchor pairs stay separate


@pytest.mark.parametrize("v, dc_motor", [(0.05, False), (0.2, False), (0.05, True)])
def test_commanded_speed_is_driven_within_one_percent(v, dc_motor):
    # The wheels' collision spheres have the exact 10 mm radius and carry the weight (casters just
    # off the floor): no rolling-radius error, no slip. At 0.2 m/s (its no-load speed) the DC-motor
    # line does not get there; it is tested below.
    robot = replace(RobotParams(), wheel_no_load_speed=20.0) if dc_motor else RobotParams()
    for pilot in (False, True):
        with SimWorld(robot, [RobotStart("pz1", 0, 0, 0, pilot)]) as w:
            w.set_command("pz1", v, 0.0)
            w.run(0.5)
            x0, t0 = w.pose2d("pz1")[0], w.time
            w.run(1.0)
            speed = (w.pose2d("pz1")[0] - x0) / (w.time - t0)
            assert speed == pytest.approx(v, rel=0.01), (pilot, speed)


@pytest.mark.parametrize("v, dc_motor", [(0.05, False), (0.2, False), (0.05, True), (0.2, True)])
def test_robot_pushes_with_about_half_a_newton(v, dc_motor):
    # stalled against a wall the wheels slip (the wall's reaction pitches the robot and unloads them):
    # ideal motors spin them at the speed limit, 0.47 N; the DC-motor line leaves them 85 % of the stall
    # torque at the 3 rad/s they creep at, 0.42 N
    robot = replace(RobotParams(), wheel_no_load_speed=20.0) if dc_motor else RobotParams()
    with SimWorld(robot, [RobotStart("pz1", 0, 0, 0)]) as w:
        c = w.client
        wall = pb.createMultiBody(0, pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[0.01, 0.1, 0.05],
                                                             physicsClientId=c), -1, [0.04, 0, 0.05],
                                  physicsClientId=c)
        w.set_command("pz1", v, 0.0)
        w.run(1.0)
        force = sum(cp[9] for cp in pb.getContactPoints(w.robots["pz1"].body, wall, physicsClientId=c))
        assert 0.40 < force <= 0.52


def test_dc_motor_line_slows_the_robot_near_v_max():
    robot = replace(RobotParams(), wheel_no_load_speed=20.0)
    assert robot.wheel_back_emf_damping == pytest.approx(robot.wheel_max_torque / robot.wheel_no_load_speed)
    assert RobotParams().wheel_back_emf_damping == 0.0
    with SimWorld(robot, [RobotStart("pz1", 0, 0, 0)]) as w:
        w.set_command("pz1", 0.2, 0.0)
        w.run(1.0)
        x0, t0 = w.pose2d("pz1")[0], w.time
        w.run(0.5)
        speed = (w.pose2d("pz1")[0] - x0) / (w.time - t0)
        assert 0.15 < speed < 0.2                   # approaches the no-load speed, never quite there
        w.set_command("pz1", 0.05, 0.0)
        w.run(0.5)                                  # braking has the full torque: down to the command
        x0, t0 = w.pose2d("pz1")[0], w.time
        w.run(0.5)
        assert (w.pose2d("pz1")[0] - x0) / (w.time - t0) == pytest.approx(0.05, rel=0.01)
    with pytest.raises(ConfigError, match="wheel_no_load_speed"):
        replace(RobotParams(), wheel_no_load_speed=10.0).check()


def test_deterministic_for_same_commands_and_seed():
    def run():
        mocap = MocapModel(position_std=0.001, yaw_std=0.01, dropout=0.2)
        with SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0.3)], seed=7, mocap=mocap) as w:
            w.set_command("pz1", 0.04, 0.7)
            out = []
            for _ in range(20):
                w.run(0.05)
                out.append(w.measure("pz1"))
            return w.pose2d("pz1"), w.anchor_pose2d("pz1"), out
    assert run() == run()


def test_mocap_effects():
    mocap = MocapModel(position_std=0.002, dropout=0.3, heading_offset=0.1)
    with SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0.0)], seed=1, mocap=mocap) as w:
        w.run(0.2)
        got = [w.measure("pz1") for _ in range(400)]
        measured = [m for m in got if m is not None]
        assert 0.2 < 1 - len(measured) / len(got) < 0.4
        x, y, yaw = w.pose2d("pz1")
        errors = [m[0][0] - x for m in measured]
        assert 0.0015 < (sum(e * e for e in errors) / len(errors)) ** 0.5 < 0.0025
        yaws = [pb.getEulerFromQuaternion(m[1])[2] for m in measured]
        assert all(abs(wrap_angle(v - yaw - 0.1)) < 1e-6 for v in yaws)


def test_actuator_effects_delay_and_wheel_imbalance():
    model = ActuatorModel().add("input_delay", {"delay_s": 0.3}).add("heading_offset", {"offset_rad": 0.05})
    with SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0)], actuator_model=model) as w:
        w.run(0.1)
        w.set_command("pz1", 0.05, 0.0)
        w.run(0.25)
        assert abs(w.pose2d("pz1")[0]) < 0.001                 # still waiting for the delayed command
        w.run(0.5)
        assert w.pose2d("pz1")[0] > 0.01
        assert w.driven_velocity("pz1") == pytest.approx((0.05, 0.0))
        yaw = pb.getEulerFromQuaternion(w.measure("pz1")[1])[2]
        assert yaw - w.pose2d("pz1")[2] == pytest.approx(0.05, abs=1e-6)
    with SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0)], wheel_imbalance=0.05) as w:
        w.set_command("pz1", 0.05, 0.0)
        w.run(2.0)
        assert w.pose2d("pz1")[2] > 0.2                          # right wheel faster: curves left


def test_coupled_start_and_physical_pairs():
    starts = [RobotStart("a", 0, 0, 0), RobotStart("o", -0.0503, 0, 0), RobotStart("x", 0, 0.2, 0)]
    with SimWorld(RobotParams(), starts) as w:
        w.run(0.3)
        pairs = w.physical_pairs()
        assert [(p.anchor_robot, p.opening_robot, p.status) for p in pairs] == [("a", "o", HEAD_INSERTED)]
        ax, ay, ayaw = w.anchor_pose2d("a")
        assert -0.022 < ax < -0.012 and abs(ay) < 0.001           # in its holder, behind the body centre


def test_worlds_place_robots_on_the_stages():
    wp = WorldParams(stage_height=0.06)
    with SimWorld(RobotParams(), [RobotStart("pz1", -0.1, 0, 0)], world="step", world_params=wp) as w:
        w.run(0.3)
        assert w.pose("pz1")[0][2] == pytest.approx(0.06 + RobotParams().body_centre_height, abs=0.002)
    with SimWorld(RobotParams(), [RobotStart("pz1", -0.1, 0, 0), RobotStart("pz2", 0.1, 0, math.pi)],
                  world="gap") as w:
        w.run(0.3)
        for n in ("pz1", "pz2"):
            assert w.pose(n)[0][2] > 0.05
    with pytest.raises(ConfigError, match="at least one robot height"):
        SimWorld(RobotParams(), [RobotStart("pz1", -0.1, 0, 0)], world="step",
                 world_params=WorldParams(stage_height=0.03))


def test_bad_setup_gives_clear_errors():
    with pytest.raises(ConfigError, match="unknown world 'moon'"):
        SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0)], world="moon")
    with pytest.raises(ConfigError, match="inside each other"):
        SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0), RobotStart("pz2", 0.03, 0.01, 0.5)])
    with pytest.raises(ConfigError, match="the anchor of robot pz1 would start inside robot pz2"):
        SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0), RobotStart("pz2", -0.06, 0.0, 0.0)])
    with pytest.raises(ConfigError, match="robot.wheel_radius"):
        RobotParams.from_dict({"wheel_radius": 0})
    with pytest.raises(ConfigError, match="integer multiple"):
        SimParams.from_dict({"physics_rate": 250, "pose_rate": 100})
    with pytest.raises(ConfigError, match="anchor.backward_profile_mm: must start at 0 and increase"):
        AnchorParams.from_dict({"backward_profile_mm": [0.0, 2.0, 1.0], "backward_profile_n": [0.0, 0.1, 0.2]})
    with pytest.raises(ConfigError, match="whole number of physics steps"):
        SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0)], anchor_rest=AnchorRestParams(check_period=0.0123))
    with pytest.raises(ConfigError, match="anchor_rest.clearance: must be > 0"):
        AnchorRestParams.from_dict({"clearance": -0.01})
    robots = parse_robot_list(["pz1", "pz2"])
    with pytest.raises(ConfigError, match="no start pose for robot pz2"):
        starts_from_config(robots, {"pz1": [0, 0, 0]})
    with pytest.raises(ConfigError, match="not in the robot list"):
        starts_from_config(robots, {"pz1": [0, 0, 0], "pz2": [1, 0, 0], "pz7": [2, 0, 0]})
    with pytest.raises(ConfigError, match="three finite numbers"):
        starts_from_config(robots, {"pz1": [0, 0, 0], "pz2": [1, "a", 0]})


def _pitch(world, name):
    return pb.getEulerFromQuaternion(world.pose(name)[1])[1]


def test_resting_anchor_is_frozen_follows_its_robot_and_wakes_when_approached():
    rest_off = AnchorRestParams(enabled=False)
    starts = [RobotStart("a", 0, 0, 0), RobotStart("o", -0.2, 0, 0)]
    with SimWorld(RobotParams(), starts) as w, SimWorld(RobotParams(), starts, anchor_rest=rest_off) as ref:
        w.run(1.0)
        ref.run(1.0)
        assert w.resting_anchors() == ["a", "o"] and ref.resting_anchors() == []
        # the frozen anchor's weight stays on its robot: same posture as with the anchor simulated
        assert _pitch(w, "a") == pytest.approx(_pitch(ref, "a"), abs=2e-4)
        before = w.anchor_pose2d("a")
        w.set_command("a", 0.0, 1.0)                 # a sudden turn wakes it (yaw-rate change > max_dw)
        w.run(0.04)
        assert "a" not in w.resting_anchors()
        w.set_command("a", 0.0, 0.0)
        w.run(1.0)
        assert "a" in w.resting_anchors()            # at rest again after the disturbance
        x, y, yaw = w.pose2d("a")
        ax, ay, ayaw = w.anchor_pose2d("a")
        local = (math.cos(yaw) * (ax - x) + math.sin(yaw) * (ay - y), wrap_angle(ayaw - yaw))
        assert -0.02 < local[0] < -0.012 and abs(local[1]) < 0.05  # still in its holder
        assert before != w.anchor_pose2d("a")
        # the opening robot drives onto the frozen anchor: it wakes before contact and couples
        w.set_command("o", 0.05, 0.0)
        woke = None
        for _ in range(80):
            w.run(0.05)
            if woke is None and "a" not in w.resting_anchors():
                woke = w.time
                gap = -0.025 - 0.0133 - (w.pose2d("o")[0] + 0.025)   # a's anchor tip to o's front face
                assert gap > RobotParams().mouth_width
            if [(p.anchor_robot, p.status) for p in w.physical_pairs()] == [("a", HEAD_INSERTED)]:
                break
        assert woke is not None
        assert [(p.anchor_robot, p.opening_robot, p.status) for p in w.physical_pairs()] == [("a", "o", HEAD_INSERTED)]
        w.reset_anchor("o", 0.2)                     # experiments may reset a frozen anchor
        assert "o" not in w.resting_anchors()


def test_actuator_effects_per_robot():
    """model.yaml robots: entries: each robot's plant is its own model (pz2's delay replaces the shared
    one; pz3's own empty-effect model leaves it ideal)."""
    model = ActuatorModel().add("input_delay", {"delay_s": 0.3})
    model.add_for_robot("pz2", "input_delay", {"delay_s": 0.05})
    model.add_for_robot("pz3", "input_delay", {"delay_s": 0.0})
    starts = [RobotStart("pz1", 0, 0, 0), RobotStart("pz2", 0, 0.3, 0), RobotStart("pz3", 0, 0.6, 0)]
    with SimWorld(RobotParams(), starts, actuator_model=model) as w:
        for n in ("pz1", "pz2", "pz3"):
            w.set_command(n, 0.05, 0.0)
        w.run(0.1)
        assert w.driven_velocity("pz1") == (0.0, 0.0)
        assert w.driven_velocity("pz2") == pytest.approx((0.05, 0.0))
        assert w.driven_velocity("pz3") == pytest.approx((0.05, 0.0))


HEAD_OUT = 0.0133      # m: the anchor's head tip behind its robot's back face, pushed in (AnchorParams.length, its comment)


def head_height_at_a_mouth(robot):
    """A robot at rest with its anchor's head 1 mm before a partner's mouth (both on the flat floor, in a line,
    their centres body_side + HEAD_OUT + 1 mm apart): the head tip's height [m] in the partner's frame, after
    0.5 s."""
    with SimWorld(robot, [RobotStart("a", 0, 0, 0), RobotStart("o", -centres_apart(robot), 0, 0)]) as w:
        w.run(0.5)
        head = w.anchor_points("a")[0]
        inv = pb.invertTransform(*w.pose("o"), physicsClientId=w.client)
        local = pb.multiplyTransforms(*inv, head, [0, 0, 0, 1], physicsClientId=w.client)[0]
        assert robot.body_side / 2 < local[0] < robot.body_side / 2 + 0.003   # at the mouth, not in it
        return local[2]


def centres_apart(robot):
    """m: how far apart head_height_at_a_mouth puts its two robots' centres."""
    return robot.body_side + HEAD_OUT + 0.001


def test_at_rest_a_partners_anchor_head_meets_the_mouth_low_by_the_bodies_pitch_and_the_anchors_sag():
    # The body rests on its wheels and one caster, pitched by caster_clearance / caster_x; two robots in a
    # line, both pitched so, see the head below the mouth's centre line by that pitch times the distance
    # between their centres, plus the anchor's sag in its holder. The mouth leaves the head
    # (mouth_height - head_height) / 2 = 1.5 mm up and down (docs/sim.md, "The rest pitch").
    p = RobotParams()
    room = (p.mouth_height - AnchorParams().head_height) / 2
    low = {c: p.opening_z - head_height_at_a_mouth(replace(p, caster_clearance=c)) for c in (0.0005, 0.0003)}
    assert low[0.0005] - low[0.0003] == pytest.approx(0.0002 / p.caster_x * centres_apart(p), abs=0.0001)
    assert low[p.caster_clearance] > room                 # the shipped model: 2.5 mm low, on the mouth's floor


def _slide_alongside(p):
    """pz2 (knob on its left) drives along pz1's right side on a line closing in 0.06 rad, from 30 mm
    behind and 3 mm out: the knob meets pz1's corner at a glancing angle. Returns pz2's knob pair with pz1
    (None: no knob at the hole) and the knob's depression [m] once pz2 has stopped."""
    starts = [RobotStart("pz1", 0, 0, 0), RobotStart("pz2", -0.03, -p.body_side - 0.003, 0.06)]
    with SimWorld(p, starts) as w:
        w.run(0.3)
        w.set_command("pz2", 0.02, 0.0)
        for _ in range(40):
            w.run(0.1)
            if [q for q in w.physical_knob_pairs() if q.status == HEAD_INSERTED]:
                break
        w.set_command("pz2", 0.0, 0.0)
        w.run(0.5)
        pairs = [q for q in w.physical_knob_pairs() if (q.anchor_robot, q.opening_robot) == ("pz2", "pz1")]
        return (pairs[0] if pairs else None), w.knob_depression("pz2")


def test_a_sprung_knob_slides_along_the_side_into_the_hole():
    # the knob (knob_travel > 0) is pressed in by pz1's corner and side, then springs into the hole
    pair, pressed = _slide_alongside(RobotParams())
    assert pair is not None and pair.status == HEAD_INSERTED, pair
    assert pressed < 0.001


def test_a_rigid_knob_on_the_same_path_does_not_get_in():
    # the same path with a rigid knob: it cannot pass pz1's corner, so the pair does not seat
    pair, _ = _slide_alongside(RobotParams(knob_travel=0.0))
    assert pair is None or pair.status != HEAD_INSERTED, pair


def test_the_sprung_knob_leaves_the_robots_mass_and_centre_of_mass_as_the_rigid_one():
    # the plunger is a link of its own; the body's inertial origin balances it, so the robot's total
    # mass and centre of mass (knob out) are those of the robot with the knob part of its body
    def mass_and_centre(p):
        root = ET.fromstring(robot_urdf(p))
        origins = {j.find("child").get("link"): [float(v) for v in j.find("origin").get("xyz").split()]
                   for j in root.findall("joint")}
        total, moment = 0.0, [0.0, 0.0, 0.0]
        for link in root.findall("link"):
            inertial = link.find("inertial")
            m = float(inertial.find("mass").get("value"))
            xyz = [float(v) for v in inertial.find("origin").get("xyz").split()]
            at = [a + b for a, b in zip(origins.get(link.get("name"), [0.0, 0.0, 0.0]), xyz)]
            total += m
            moment = [mo + m * a for mo, a in zip(moment, at)]
        return total, [mo / total for mo in moment]

    sprung, rigid = mass_and_centre(RobotParams()), mass_and_centre(RobotParams(knob_travel=0.0))
    assert sprung[0] == pytest.approx(rigid[0])
    assert sprung[1] == pytest.approx(rigid[1], abs=1e-9)
