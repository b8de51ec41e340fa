"""robot_description of a robot list (puzzlebot_sim.description): the simulation's URDFs in one tree."""

import xml.etree.ElementTree as ET
from collections import Counter

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.robots import parse_robot_list
from puzzlebot_sim.config import load_model
from puzzlebot_sim.description import moving_joints, robot_description
from puzzlebot_sim.urdf import anchor_urdf, robot_urdf
from puzzlebot_sim.world import anchor_home_x

ROBOT, ANCHOR = load_model()
ROBOTS = parse_robot_list([{"name": "pz1", "pilot": True}, {"name": "pz2"}])


def parse(text):
    root = ET.fromstring(text)
    links = [link.get("name") for link in root.findall("link")]
    joints = {j.get("name"): (j.get("type"), j.find("parent").get("link"), j.find("child").get("link"),
                              j.find("origin").get("xyz")) for j in root.findall("joint")}
    return root, links, joints


def test_one_tree_rooted_at_world_with_every_robot_and_anchor():
    root, links, joints = parse(robot_description(ROBOTS, ROBOT, ANCHOR))
    assert len(links) == len(set(links))                                   # prefixed: no name twice
    children = Counter(c for _, _, c, _ in joints.values())
    assert set(links) - set(children) == {"world"}                         # one root ...
    assert max(children.values()) == 1                                     # ... and a tree
    assert joints["pz1/base_joint"][:3] == ("floating", "world", "pz1/base_link")
    assert joints["pz2/anchor_joint"][:3] == ("floating", "pz2/base_link", "pz2/anchor")
    assert joints["pz2/anchor_neck_joint"][1:3] == ("pz2/anchor", "pz2/anchor_head")


def test_the_same_links_as_the_urdfs_the_simulation_loads():
    _, links, _ = parse(robot_description(ROBOTS, ROBOT, ANCHOR))
    pilot = [link.get("name") for link in ET.fromstring(robot_urdf(ROBOT, pilot=True)).findall("link")]
    robot = [link.get("name") for link in ET.fromstring(robot_urdf(ROBOT)).findall("link")]
    anchor = [link.get("name") for link in ET.fromstring(anchor_urdf(ANCHOR)).findall("link")]
    assert [n for n in links if n.startswith("pz1/") and "anchor" not in n] == ["pz1/" + n for n in pilot]
    assert [n for n in links if n.startswith("pz2/") and "anchor" not in n] == ["pz2/" + n for n in robot]
    assert len([n for n in links if n.startswith("pz2/anchor")]) == len(anchor)
    assert "pz1/front_left_wheel" in links and "pz2/left_wheel" in links and "pz2/front_caster" in links
    # the same geometry: every visual of the simulated robot, moved to its prefixed link
    sim_boxes = sorted(b.get("size") for b in ET.fromstring(robot_urdf(ROBOT)).iter("box"))
    root = ET.fromstring(robot_description(ROBOTS[1:], ROBOT, ANCHOR, anchor=None))
    assert sorted(b.get("size") for b in root.iter("box")) == sim_boxes


def test_nominal_anchor_is_fixed_at_its_rest_pose_in_the_holder():
    _, _, joints = parse(robot_description(ROBOTS, ROBOT, ANCHOR, anchor="nominal"))
    kind, parent, child, xyz = joints["pz1/anchor_joint"]
    assert (kind, parent, child) == ("fixed", "pz1/base_link", "pz1/anchor")
    assert [float(v) for v in xyz.split()] == pytest.approx([anchor_home_x(ROBOT, ANCHOR), 0.0, ROBOT.opening_z])
    _, links, joints = parse(robot_description(ROBOTS, ROBOT, ANCHOR, anchor=None))
    assert not any("anchor" in n for n in links) and "pz1/anchor_joint" not in joints


def test_moving_joints_are_joints_of_the_description():
    _, _, joints = parse(robot_description(ROBOTS, ROBOT, ANCHOR))
    for r in ROBOTS:
        names = moving_joints(r.name, r.pilot)
        assert len(names) == (4 if r.pilot else 2) + 1 + 3           # wheels, the sprung knob, the anchor
        assert all(joints[n][0] in ("continuous", "revolute", "prismatic") for n in names)
        assert joints["%s/knob_joint" % r.name][0] == "prismatic"
        assert "%s/knob_joint" % r.name not in moving_joints(r.name, r.pilot, knob=False)


@pytest.mark.parametrize("kwargs, fragment", [({"anchor": "tf", "anchor_params": None}, "anchor's parameters"),
                                              ({"anchor": "bent"}, "must be one of")])
def test_bad_arguments_are_refused(kwargs, fragment):
    with pytest.raises(ConfigError) as e:
        robot_description(ROBOTS, ROBOT, **dict({"anchor_params": ANCHOR}, **kwargs))
    assert fragment in str(e.value)
    with pytest.raises(ConfigError):
        robot_description([], ROBOT, ANCHOR)
