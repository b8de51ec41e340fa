"""PuzzleBot URDF generated from primitives (box, cylinder, sphere).

Frames: ``base_link`` at the body centre, x forward, z up; the body's bottom
is ``ground_clearance`` above the floor when the wheels touch it. Links:
body (box), left/right wheel (cylinders on continuous joints about y), front
and rear ball casters (spheres, made frictionless by the world).
"""

import math

WHEEL_JOINTS = ("left_wheel_joint", "right_wheel_joint")
CASTER_LINKS = ("front_caster", "rear_caster")


def _box_inertia(m, x, y, z):
    return (m * (y * y + z * z) / 12.0, m * (x * x + z * z) / 12.0, m * (x * x + y * y) / 12.0)


def _cyl_inertia(m, r, length):
    # axis along the link's z before the visual/collision rotation
    side = m * (3 * r * r + length * length) / 12.0
    return (side, side, 0.5 * m * r * r)


def _inertial(mass, ixx, iyy, izz, rpy="0 0 0"):
    return ('<inertial><origin xyz="0 0 0" rpy="%s"/><mass value="%.6g"/>'
            '<inertia ixx="%.6g" ixy="0" ixz="0" iyy="%.6g" iyz="0" izz="%.6g"/></inertial>'
            % (rpy, mass, ixx, iyy, izz))


def _shape(kind, geometry, xyz="0 0 0", rpy="0 0 0", color="0.8 0.8 0.8 1"):
    origin = '<origin xyz="%s" rpy="%s"/>' % (xyz, rpy)
    return ('<visual>%s<geometry>%s</geometry><material name="%s"><color rgba="%s"/></material></visual>'
            '<collision>%s<geometry>%s</geometry></collision>' % (origin, geometry, kind, color, origin, geometry))


def robot_urdf(p, name="puzzlebot", pilot=False):
    """URDF text for a robot with parameters ``p`` (:class:`RobotParams`)."""
    zc = p.body_centre_height
    body_color = "0.95 0.55 0.1 1" if pilot else "0.2 0.45 0.85 1"
    links = []
    joints = []
    ixx, iyy, izz = _box_inertia(p.body_mass, p.body_side, p.body_side, p.body_height)
    links.append('<link name="base_link">%s%s</link>' % (
        _inertial(p.body_mass, ixx, iyy, izz),
        _shape("body", '<box size="%g %g %g"/>' % (p.body_side, p.body_side, p.body_height),
               color=body_color)))
    wheel_rpy = "%.10f 0 0" % (-math.pi / 2)
    for side, sign in (("left", 1), ("right", -1)):
        ixx, iyy, izz = _cyl_inertia(p.wheel_mass, p.wheel_radius, p.wheel_width)
        links.append('<link name="%s_wheel">%s%s</link>' % (
            side, _inertial(p.wheel_mass, ixx, izz, iyy),
            _shape("wheel", '<cylinder radius="%g" length="%g"/>' % (p.wheel_radius, p.wheel_width),
                   rpy=wheel_rpy, color="0.1 0.1 0.1 1")))
        joints.append('<joint name="%s_wheel_joint" type="continuous"><parent link="base_link"/>'
                      '<child link="%s_wheel"/><origin xyz="0 %g %g" rpy="0 0 0"/><axis xyz="0 1 0"/>'
                      '</joint>' % (side, side, sign * p.wheel_y, p.wheel_radius - zc))
    caster_mass = 0.001
    i_s = 0.4 * caster_mass * p.caster_radius ** 2
    for link, sign in zip(CASTER_LINKS, (1, -1)):
        links.append('<link name="%s">%s%s</link>' % (
            link, _inertial(caster_mass, i_s, i_s, i_s),
            _shape("caster", '<sphere radius="%g"/>' % p.caster_radius, color="0.6 0.6 0.6 1")))
        joints.append('<joint name="%s_joint" type="fixed"><parent link="base_link"/><child link="%s"/>'
                      '<origin xyz="%g 0 %g" rpy="0 0 0"/></joint>'
                      % (link, link, sign * p.caster_x, p.caster_radius - zc))
    return '<?xml version="1.0"?>\n<robot name="%s">\n%s\n%s\n</robot>\n' % (
        name, "\n".join(links), "\n".join(joints))
