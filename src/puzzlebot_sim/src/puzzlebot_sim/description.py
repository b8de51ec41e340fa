"""``robot_description`` of a robot list: the simulation's own URDFs, one tree for rviz.

rviz's RobotModel display and robot_state_publisher read one URDF from the
parameter ``/robot_description``. This module builds it from the generator
the simulation loads into Bullet (``urdf.robot_urdf`` for each robot,
pilot or not, and ``urdf.anchor_urdf`` for its anchor), so rviz shows the
bodies Bullet simulates. Every link and joint is prefixed with the robot's
name (``pz1/base_link``, ``pz1/left_wheel_joint``, ``pz1/anchor``, ...):
the frames of the stack's tf tree (docs/interfaces.md).

The tree::

    world --floating--> <robot>/base_link --(the robot's joints)--> wheels, casters
                            |--<anchor joint>--> <robot>/anchor --> anchor_head --> barbs

- ``world`` -> ``<robot>/base_link`` is a floating joint: the pose comes from
  tf (the sim node or the lab driver publish it); robot_state_publisher skips
  floating joints.
- the anchor joint ``<robot>/anchor_joint``: ``anchor="tf"`` (the
  simulation) makes it floating as well, the sim node publishes
  ``<robot>/base_link`` -> ``<robot>/anchor`` where Bullet holds the anchor;
  ``anchor="nominal"`` (the lab, where nothing measures the anchor) fixes it at
  its rest pose in the holder (``world.anchor_home_x``, on the opening's
  height), so robot_state_publisher puts it on /tf_static; ``None``: no anchors.
- wheels (continuous), the sprung knob (prismatic) and the anchor's neck and barbs (revolute) move with
  /joint_states (the sim node publishes them, names as here); fixed joints
  (casters) go to /tf_static through robot_state_publisher.
"""

import xml.etree.ElementTree as ET

from puzzlebot_common.errors import ConfigError
from puzzlebot_sim.urdf import anchor_urdf, robot_urdf
from puzzlebot_sim.world import anchor_home_x

WORLD_LINK = "world"
ANCHOR_MODES = ("tf", "nominal", None)


def prefixed(name, robot):
    """``<robot>/<name>``: the stack's frame name of link ``name`` of ``robot`` (base_link ->
    pz1/base_link, like puzzlebot_common.names.base_frame)."""
    return "%s/%s" % (robot, name)


def anchor_link(name):
    """The description's name of the anchor URDF's link ``name``: its base is ``anchor`` (the frame
    names.anchor_frame), the others ``anchor_<name>``."""
    return "anchor" if name == "base" else "anchor_" + name


def _rename(root, link_name, joint_name):
    """Links, joints and their parent/child references of a parsed URDF renamed in place. Material
    names stay: the generators define each inline with its colour, the same name with the same colour."""
    for link in root.findall("link"):
        link.set("name", link_name(link.get("name")))
    for joint in root.findall("joint"):
        joint.set("name", joint_name(joint.get("name")))
        for tag in ("parent", "child"):
            ref = joint.find(tag)
            ref.set("link", link_name(ref.get("link")))
    return root


def _joint(name, kind, parent, child, xyz=(0.0, 0.0, 0.0)):
    joint = ET.Element("joint", name=name, type=kind)
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    ET.SubElement(joint, "origin", xyz="%.6g %.6g %.6g" % tuple(xyz), rpy="0 0 0")
    return joint


def robot_description(robots, robot_params, anchor_params=None, anchor="tf", name="puzzlebot"):
    """URDF text of every robot of ``robots`` (RobotSpec list: name, pilot) in one tree (module docstring).

    ``robot_params``: RobotParams (puzzlebot_sim config/robot.yaml ``robot``); ``anchor_params``:
    AnchorParams (``anchor``), needed unless ``anchor`` is None; ``anchor``: "tf", "nominal" or None.
    """
    if anchor not in ANCHOR_MODES:
        raise ConfigError("robot description: anchor must be one of 'tf', 'nominal' or none, got %r" % (anchor,))
    if anchor is not None and anchor_params is None:
        raise ConfigError("robot description: anchors need the anchor's parameters")
    if not robots:
        raise ConfigError("robot description: no robots")
    out = ET.Element("robot", name=name)
    ET.SubElement(out, "link", name=WORLD_LINK)
    kinds = {}
    for spec in robots:
        r = spec.name
        key = "pilot" if spec.pilot else "robot"
        if key not in kinds:
            kinds[key] = robot_urdf(robot_params, name=key, pilot=spec.pilot)
        body = _rename(ET.fromstring(kinds[key]), lambda n: prefixed(n, r), lambda n: prefixed(n, r))
        out.extend(list(body))
        out.append(_joint(prefixed("base_joint", r), "floating", WORLD_LINK, prefixed("base_link", r)))
        if anchor is None:
            continue
        if "anchor" not in kinds:
            kinds["anchor"] = anchor_urdf(anchor_params)
        part = _rename(ET.fromstring(kinds["anchor"]), lambda n: prefixed(anchor_link(n), r),
                       lambda n: prefixed("anchor_" + n, r))
        out.extend(list(part))
        rest = (anchor_home_x(robot_params, anchor_params), 0.0, robot_params.opening_z)
        out.append(_joint(prefixed("anchor_joint", r), "floating" if anchor == "tf" else "fixed",
                          prefixed("base_link", r), prefixed("anchor", r), rest if anchor == "nominal" else
                          (0.0, 0.0, 0.0)))
    ET.indent(out)
    return '<?xml version="1.0"?>\n' + ET.tostring(out, encoding="unicode") + "\n"



def moving_joints(robot, pilot, anchor=True, knob=True):
    """Names of the description's joints of ``robot`` that /joint_states moves: its wheels (pilots:
    four), the sprung knob's joint (``knob``: RobotParams.knob_travel > 0) and, with anchors, the
    anchor's neck and barbs (in urdf.WHEEL_JOINTS / PILOT_WHEEL_JOINTS, KNOB_JOINT, ANCHOR_JOINTS order)."""
    from puzzlebot_sim.urdf import ANCHOR_JOINTS, KNOB_JOINT, PILOT_WHEEL_JOINTS, WHEEL_JOINTS

    names = [prefixed(j, robot) for j in (PILOT_WHEEL_JOINTS if pilot else WHEEL_JOINTS)]
    if knob:
        names.append(prefixed(KNOB_JOINT, robot))
    if anchor:
        names += [prefixed("anchor_" + j, robot) for j in ANCHOR_JOINTS]
    return names
