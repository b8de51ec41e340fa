"""rviz markers built from the stack's messages (puzzlebot_bringup/markers.py); no roscore."""

import math
import os

import pytest
from geometry_msgs.msg import Point, Pose2D
from visualization_msgs.msg import Marker

from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import RobotGeometry, transform_point
from puzzlebot_common.robots import RobotSpec
from puzzlebot_common.stages import WorldParams, stages
from puzzlebot_msgs.msg import (BehaviorObjectives, ConnectionPair, PredictedTrajectories,
                                RobotTrajectory)
from puzzlebot_bringup.markers import (AnchorShape, MarkerStyle, assemblies, build_markers, placed_slots,
                                       view_centre)

HERE = os.path.dirname(os.path.abspath(__file__))
GEO = RobotGeometry()
STYLE = MarkerStyle()
ROBOTS = [RobotSpec("pz1", pilot=True), RobotSpec("pz2"), RobotSpec("pz3")]
# pz2 right behind pz1 (coupled), pz3 further back, turned
POSES = {"pz1": (0.0, 0.0, 0.0255, 0.0), "pz2": (-0.05, 0.0, 0.0255, 0.0), "pz3": (-0.2, 0.05, 0.0255, 0.5)}


def pair(i, j, status, kind=ConnectionPair.TYPE_ANCHOR):
    return ConnectionPair(robot_i=i, robot_j=j, point_i=Pose2D(-0.025, 0.0, math.pi), point_j=Pose2D(0.025, 0.0, 0.0),
                          type=kind, anchor_robot=i if kind == ConnectionPair.TYPE_ANCHOR else "", status=status)


def xy(points):
    """Flat [x0, y0, x1, y1, ...] of points (pytest.approx compares flat sequences)."""
    return [c for p in points for c in ((p.x, p.y) if hasattr(p, "x") else tuple(p)[:2])]


def by_ns(array):
    out = {}
    for m in array.markers[1:]:
        out.setdefault(m.ns, []).append(m)
    return out


def test_shipped_style_parses_and_matches_the_defaults():
    style = MarkerStyle.from_dict(load_yaml(os.path.join(os.path.dirname(HERE), "config", "markers.yaml"))["markers"])
    assert style == MarkerStyle()           # the YAML states every default


@pytest.mark.parametrize("data, fragment", [({"robot": [1, 0, 0]}, "four numbers"), ({"pilot": [2, 0, 0, 1]}, "0..1"),
                                            ({"rate": 0.0}, "rate: must be > 0"), ({"colour": 1}, "unknown key")])
def test_bad_style_names_the_key(data, fragment):
    with pytest.raises(ConfigError) as e:
        MarkerStyle.from_dict(data)
    assert fragment in str(e.value)


def test_bodies_anchors_and_labels_in_the_robot_frames():
    out = build_markers(ROBOTS, GEO, STYLE, POSES)
    assert out.markers[0].action == Marker.DELETEALL
    ns = by_ns(out)
    assert [m.header.frame_id for m in ns["bodies"]] == ["pz1/base_link", "pz2/base_link", "pz3/base_link"]
    assert all(m.frame_locked and m.type == Marker.CUBE for m in ns["bodies"])
    rgba = lambda c: (c.r, c.g, c.b, c.a)
    assert rgba(ns["bodies"][0].color) == pytest.approx(STYLE.pilot)      # pz1 is a pilot
    assert rgba(ns["bodies"][1].color) == pytest.approx(STYLE.robot)
    assert ns["labels"][0].text == "pz1 (pilot)"
    nominal = ns["anchors"][1]                                          # no anchor shape: C_a -> H_a in base_link
    assert nominal.header.frame_id == "pz2/base_link"
    assert xy(nominal.points) == pytest.approx([-0.025, 0.0, -0.0375, 0.0])
    sim = by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, anchor_shape=AnchorShape(0.0243, 0.007, 0.65)))["anchors"]
    assert sim[0].header.frame_id == "pz1/anchor" and len(sim[0].points) == 6     # bar + two barbs
    assert sim[0].points[1].x == pytest.approx(-0.0243)


def test_the_worlds_stages_are_boxes_up_to_their_tops_in_the_world_frame():
    w = WorldParams()
    gap = by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, stages=stages("gap", w)))["stages"]
    assert len(gap) == 2 and all(m.header.frame_id == "world" and m.type == Marker.CUBE for m in gap)
    first, second = sorted(gap, key=lambda m: m.pose.position.x)
    assert first.pose.position.x + first.scale.x / 2 == pytest.approx(w.edge_x)               # the first's edge
    assert second.pose.position.x - second.scale.x / 2 == pytest.approx(w.edge_x + w.gap_width)  # the gap
    assert first.scale.z == pytest.approx(w.stage_height) and first.pose.position.z == pytest.approx(w.stage_height / 2)
    assert first.scale.y == pytest.approx(w.stage_width)
    legend = [m.text for m in by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, stages=stages("gap", w)))["legend"]]
    assert legend[-1] == "stage"
    flat = by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, stages=stages("flat", w)))
    assert "stages" not in flat and "stage" not in [m.text for m in flat["legend"]]


def test_pairs_polygons_and_physical_state_coloured_by_status():
    pairs = [pair("pz1", "pz2", ConnectionPair.STATUS_HEAD_INSERTED), pair("pz2", "pz3", ConnectionPair.STATUS_DECOUPLED)]
    physical = [pair("pz1", "pz2", ConnectionPair.STATUS_HEAD_INSERTED)]
    ns = by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, pairs, physical))
    fill, outline = ns["polygons"][0], ns["polygons"][1]
    assert fill.header.frame_id == "pz2/base_link" and fill.type == Marker.TRIANGLE_LIST
    assert xy(fill.points) == pytest.approx(xy(GEO.front_triangle()))
    assert fill.color.a == pytest.approx(STYLE.polygon_fill_alpha)
    assert (outline.color.r, outline.color.g) == pytest.approx(STYLE.head_inserted[:2])
    assert (ns["polygons"][2].color.r, ns["polygons"][2].color.g) == pytest.approx(STYLE.decoupled[:2])
    line = ns["pairs"][1]                       # pz2's anchor head -> pz3's opening, in the world
    head = transform_point(POSES["pz2"][:2] + (0.0,), GEO.anchor_head())
    opening = transform_point((POSES["pz3"][0], POSES["pz3"][1], POSES["pz3"][3]), (0.025, 0.0))
    assert xy(line.points) == pytest.approx(xy([head, opening]))
    assert ns["physical"][0].header.frame_id == "pz2/base_link"
    assert (ns["physical"][0].color.g, ns["physical"][0].color.b) == pytest.approx(STYLE.seated[1:3])
    knob = by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, [pair("pz1", "pz3", 0, ConnectionPair.TYPE_KNOB)]))
    assert xy(knob["polygons"][1].points[:4]) == pytest.approx(xy(GEO.knob_region()))


def test_predicted_paths_and_goals_in_the_world_robots_without_pose_skipped():
    pred = PredictedTrajectories(robots=[RobotTrajectory(robot="pz1", poses=[Pose2D(0, 0, 0), Pose2D(0.01, 0, 0)]),
                                         RobotTrajectory(robot="pz9", poses=[Pose2D(1, 1, 0)])])
    obj = BehaviorObjectives(behavior="go_to_goal", goal_robots=["pz3"], goals=[Point(0.3, -0.1, 0.0)])
    ns = by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, predicted=pred, objectives=obj))
    line, dots = ns["predicted"]                      # pz1's path: a line and a dot per step; pz9 has no pose
    assert line.header.frame_id == dots.header.frame_id == "world"
    assert (line.type, dots.type) == (Marker.LINE_STRIP, Marker.POINTS)
    assert xy(line.points) == pytest.approx([0, 0, 0.01, 0]) and xy(dots.points) == pytest.approx([0.01, 0])
    still = PredictedTrajectories(robots=[RobotTrajectory(robot="pz1", poses=[Pose2D(0, 0, 0)] * 11)])
    assert "predicted" not in by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, predicted=still))   # at rest
    assert (ns["goals"][0].pose.position.x, ns["goals"][0].pose.position.y) == pytest.approx((0.3, -0.1))
    assert "slots" not in ns


def test_target_slots_are_placed_on_the_largest_coupled_assembly():
    # a line of three assigned somewhere else and turned; pz1-pz2 are coupled: the slots follow them
    slots = [(1.0, 1.0, math.pi / 2), (1.0, 0.95, math.pi / 2), (1.0, 0.90, math.pi / 2)]
    robots = ["pz1", "pz2", "pz3"]
    coupled = [pair("pz1", "pz2", ConnectionPair.STATUS_HEAD_INSERTED)]
    assert assemblies(robots, coupled)[0] == ["pz1", "pz2"]
    placed = placed_slots(robots, slots, POSES, coupled)
    assert placed["pz1"] == pytest.approx((0.0, 0.0, 0.0))
    assert placed["pz2"] == pytest.approx((-0.05, 0.0, 0.0))
    assert placed["pz3"] == pytest.approx((-0.10, 0.0, 0.0))
    # nothing coupled: anchored on the first robot in slot order
    assert placed_slots(["pz3", "pz1", "pz2"], slots, POSES, [])["pz3"] == pytest.approx((-0.2, 0.05, 0.5))
    assert placed_slots(robots, slots, {}, coupled) == {}
    obj = BehaviorObjectives(behavior="couple", target="line", slot_robots=robots, slots=[Pose2D(*s) for s in slots])
    ns = by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, coupled, objectives=obj))
    assert len(ns["slots"]) == 3 and len(ns["slots"][2].points) == 10      # 4 edges + heading tick


def test_legend_in_the_view_frame_one_line_per_colour():
    ns = by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, anchor_shape=AnchorShape(0.02, 0.005, 0.5)))
    legend = ns["legend"]
    texts = [m.text for m in legend]
    assert {m.header.frame_id for m in legend} == {"puzzlebot/view"}
    assert "pilot robot" in texts and "pair coupled (MPC)" in texts and "anchor seated (Bullet)" in texts
    coupled = legend[texts.index("pair coupled (MPC)")]
    assert (coupled.color.r, coupled.color.g, coupled.color.b) == pytest.approx(STYLE.head_inserted[:3])
    ys = [m.pose.position.y for m in legend]
    assert ys == sorted(ys, reverse=True) and len(set(ys)) == len(ys)       # one line each, top down
    # the lab (no physical pairs, no pilot): no Bullet entries, no pilot entry
    lab = [m.text for m in by_ns(build_markers([RobotSpec("p21")], GEO, STYLE, {}))["legend"]]
    assert not any("Bullet" in t for t in lab) and "pilot robot" not in lab
    assert "legend" not in by_ns(build_markers(ROBOTS, GEO, STYLE, POSES, legend=False))


def test_view_centre_is_the_middle_of_the_robots_bounding_box():
    assert view_centre(POSES) == pytest.approx((-0.1, 0.025))
    assert view_centre({}) == (0.0, 0.0)
    assert view_centre({}, previous=(0.3, 0.1)) == (0.3, 0.1)                # nobody seen: the view stays
    assert view_centre(POSES, previous=(0.1, 0.025), smoothing=0.5) == pytest.approx((0.0, 0.025))
