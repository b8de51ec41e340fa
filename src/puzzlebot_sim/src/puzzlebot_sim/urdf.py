"""PuzzleBot and anchor URDFs generated from primitives (box, cylinder, sphere).

Robot (``robot_urdf``): ``base_link`` at the body centre, x forward, z up; the
body's bottom is ``ground_clearance`` above the floor. The body is a solid
block with voids carved out of it -- the front opening (mouth between two
lips, the slits behind them), the anchor holder's pocket and slot in the back
face, the hole on the right side, the corners of chamfered edges -- and
decomposed into boxes; a chamfer's face is a tilted box. The battery box
(behind the slits) and the knob on the left side are their own shapes; the
knob is its own link, ``knob``, on a prismatic joint along +y (``knob_joint``:
0 out, down to ``-knob_travel`` pressed into the side; the world's spring
pushes it out), or part of ``base_link`` when ``knob_travel`` is 0. Two
driven wheels (pilot robots: four) on continuous joints, two ball casters
(non-pilots; frictionless, set by the world) on fixed joints. A wheel's
collision shape is a sphere of the wheel radius (the world lets wheels and
casters touch only the terrain): one contact point and the exact rolling
radius, where Bullet's cylinder gives four points per wheel.

Anchor (``anchor_urdf``): a separate multibody resting in the holder.
``base`` (the block in the holder) -- ``neck_joint`` (revolute about y, the
soft beam's bending) -- ``head`` (middle bar and diamond head) -- two barbs
(side bars) on revolute joints about z at the head. The barb joints are
oriented so that a positive angle flares the barb (outward) on both sides;
zero is the rest angle.
"""

import math
import re

import pybullet as pb

from puzzlebot_common.errors import ConfigError
from puzzlebot_sim.anchor import AnchorGeometry
from puzzlebot_sim.params import URDF_MARGIN

#: Flags for pybullet.loadURDF of these URDFs: exact (implicit) cylinders and
#: the inertias written here (PyBullet otherwise derives them from the shapes).
URDF_FLAGS = pb.URDF_USE_IMPLICIT_CYLINDER | pb.URDF_USE_INERTIA_FROM_FILE


WHEEL_JOINTS = ("left_wheel_joint", "right_wheel_joint")
KNOB_JOINT = "knob_joint"          # prismatic, along +y: 0 = the knob out, -knob_travel = pressed flat
KNOB_INERTIA_RADIUS = 0.005        # m: the plunger's inertia as a 5 mm radius of gyration (a gram link)
PILOT_WHEEL_JOINTS = ("front_left_wheel_joint", "rear_left_wheel_joint",
                      "front_right_wheel_joint", "rear_right_wheel_joint")
CASTER_LINKS = ("front_caster", "rear_caster")
ANCHOR_JOINTS = ("neck_joint", "left_barb_joint", "right_barb_joint")

_COLORS = {"body": "0.2 0.45 0.85 1", "pilot": "0.95 0.55 0.1 1", "battery": "0.25 0.25 0.25 1",
           "lip": "0.1 0.3 0.7 1", "wheel": "0.1 0.1 0.1 1", "caster": "0.6 0.6 0.6 1",
           "knob": "0.9 0.9 0.2 1", "anchor": "0.55 0.55 0.55 1", "barb": "0.35 0.35 0.35 1"}


# ------------------------------------------------------------------ helpers
def carve(solid, voids, min_size=0.0):
    """Boxes covering ``solid`` minus the ``voids`` (all axis-aligned).

    Boxes are ``((x0, y0, z0), (x1, y1, z1))``. The region is cut into a grid
    at every box boundary and the solid cells are merged greedily into boxes;
    of the six axis orders of merging, the one whose thinnest box is at least
    ``min_size`` with the fewest boxes wins (else the one with the thickest
    thinnest box).
    """
    lo, hi = solid
    cuts = []
    for ax in range(3):
        values = {lo[ax], hi[ax]}
        for vlo, vhi in voids:
            for v in (vlo[ax], vhi[ax]):
                if lo[ax] < v < hi[ax]:
                    values.add(v)
        cuts.append(sorted(values))
    n = [len(c) - 1 for c in cuts]

    def is_void(cell):
        centre = [(cuts[a][cell[a]] + cuts[a][cell[a] + 1]) / 2 for a in range(3)]
        return any(all(vlo[a] < centre[a] < vhi[a] for a in range(3)) for vlo, vhi in voids)

    solid_cells = {(i, j, k) for i in range(n[0]) for j in range(n[1]) for k in range(n[2])
                   if not is_void((i, j, k))}

    def merge(order):
        free = set(solid_cells)
        boxes = []
        for start in sorted(free, key=lambda c: tuple(c[a] for a in reversed(order))):
            if start not in free:
                continue
            lo_c, hi_c = list(start), list(start)
            for ax in order:
                while True:
                    trial = list(hi_c)
                    trial[ax] += 1
                    layer = [(x, y, z) for x in range(lo_c[0], trial[0] + 1) for y in range(lo_c[1], trial[1] + 1)
                             for z in range(lo_c[2], trial[2] + 1)
                             if (x, y, z)[ax] == trial[ax]]
                    if trial[ax] >= n[ax] or not all(c in free for c in layer):
                        break
                    hi_c = trial
            for x in range(lo_c[0], hi_c[0] + 1):
                for y in range(lo_c[1], hi_c[1] + 1):
                    for z in range(lo_c[2], hi_c[2] + 1):
                        free.discard((x, y, z))
            boxes.append((tuple(cuts[a][lo_c[a]] for a in range(3)), tuple(cuts[a][hi_c[a] + 1] for a in range(3))))
        return boxes

    def thinnest(boxes):
        return min(min(b - a for a, b in zip(bl, bh)) for bl, bh in boxes)

    options = [merge(order) for order in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))]
    good = [b for b in options if thinnest(b) >= min_size - 1e-12]
    if good:
        return min(good, key=len)
    return max(options, key=thinnest)


def _box_inertia(m, x, y, z):
    return (m * (y * y + z * z) / 12.0, m * (x * x + z * z) / 12.0, m * (x * x + y * y) / 12.0)


def _inertial(mass, inertia, xyz=(0.0, 0.0, 0.0)):
    return ('<inertial><origin xyz="%.6g %.6g %.6g" rpy="0 0 0"/><mass value="%.6g"/>'
            '<inertia ixx="%.6g" ixy="0" ixz="0" iyy="%.6g" iyz="0" izz="%.6g"/></inertial>'
            % (xyz + (mass,) + tuple(inertia)))


def _shape(geometry, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0), color="body", visual=True, collision=True):
    origin = '<origin xyz="%.6g %.6g %.6g" rpy="%.10g %.10g %.10g"/>' % (tuple(xyz) + tuple(rpy))
    out = ""
    if visual:
        out += ('\n  <visual>%s<geometry>%s</geometry><material name="mat_%s"><color rgba="%s"/></material>'
                '</visual>' % (origin, geometry, color, _COLORS[color]))
    if collision:
        out += '\n  <collision>%s<geometry>%s</geometry></collision>' % (origin, geometry)
    return out


def _box(lo, hi, color):
    size = tuple(b - a for a, b in zip(lo, hi))
    centre = tuple((a + b) / 2 for a, b in zip(lo, hi))
    return _shape('<box size="%.6g %.6g %.6g"/>' % size, centre, color=color)


def _joint(name, kind, parent, child, xyz, axis="0 1 0", rpy=(0.0, 0.0, 0.0), limit=None):
    lim = ""
    if limit is not None:
        lim = '<limit lower="%.6g" upper="%.6g" effort="1" velocity="100"/>' % limit
    return ('<joint name="%s" type="%s"><parent link="%s"/><child link="%s"/>'
            '<origin xyz="%.6g %.6g %.6g" rpy="%.10g %.10g %.10g"/><axis xyz="%s"/>%s</joint>'
            % ((name, kind, parent, child) + tuple(xyz) + tuple(rpy) + (axis, lim)))


def _document(name, links, joints):
    text = '<?xml version="1.0"?>\n<robot name="%s">\n%s\n%s\n</robot>\n' % (
        name, "\n".join(links), "\n".join(joints))
    check_features(text, name)
    return text


def check_features(text, name="robot"):
    """Raise ConfigError if a collision box is thinner than 2 x URDF_MARGIN or a
    collision cylinder/sphere has a radius below URDF_MARGIN (Bullet would
    inflate it): the parameters describe a part too small to simulate."""
    for block in re.findall(r"<collision>.*?</collision>", text):
        box = re.search(r'<box size="([^"]+)"', block)
        if box:
            size = [float(v) for v in box.group(1).split()]
            if min(size) < 2 * URDF_MARGIN - 1e-9:
                raise ConfigError("%s: a collision box of %s mm is thinner than %.1f mm (Bullet's margin would "
                                  "inflate it); check the robot/anchor dimensions"
                                  % (name, " x ".join("%.2f" % (1e3 * v) for v in size), 2e3 * URDF_MARGIN))
        radius = re.search(r'radius="([^"]+)"', block)
        if radius and float(radius.group(1)) < URDF_MARGIN - 1e-9:
            raise ConfigError("%s: a collision cylinder/sphere of radius %.2f mm is below %.1f mm (Bullet's margin "
                              "would inflate it); check the robot/anchor dimensions"
                              % (name, 1e3 * float(radius.group(1)), 1e3 * URDF_MARGIN))


# -------------------------------------------------------------------- robot
def body_parts(p):
    """Boxes of the robot body in base_link: {"shell": [...], "lips": [...], "battery": box}.

    The shell (body minus mouth/slits, lock slot, holder pocket and slot, side hole) and
    the lips are collision shapes; the battery box is drawn, and its front face
    is the slits' back wall (solid shell behind the cavity).
    """
    h, hz = p.body_side / 2.0, p.body_height / 2.0
    zo, mz = p.opening_z, p.mouth_height / 2.0
    half_slit = p.slit_width / 2.0
    battery_front = h - p.cavity_depth
    battery = ((battery_front - p.battery_x, -p.battery_y / 2, zo - p.battery_z / 2),
               (battery_front, p.battery_y / 2, zo + p.battery_z / 2))
    voids = [
        ((battery_front, -half_slit, zo - mz), (h, half_slit, zo + mz)),                    # mouth + slits
        ((battery_front, -p.lock_width / 2, zo + mz),
         (h - p.lip_depth - p.lock_sill, p.lock_width / 2, zo + mz + p.lock_height)),       # lock slot
        ((-h + p.holder_wall, -p.holder_width / 2, zo - p.holder_height / 2),
         (-h + p.holder_depth, p.holder_width / 2, zo + p.holder_height / 2)),               # holder pocket
        ((-h, -p.holder_slot_width / 2, zo - p.holder_slot_height / 2),
         (-h + p.holder_wall, p.holder_slot_width / 2, zo + p.holder_slot_height / 2)),      # holder slot
        ((-p.hole_width / 2, -h, p.knob_z - p.hole_height / 2),
         (p.hole_width / 2, -h + p.hole_depth, p.knob_z + p.hole_height / 2)),               # side hole
    ]
    for c, z0, z1 in ((p.bottom_chamfer, -hz, -hz + p.bottom_chamfer), (p.top_chamfer, hz - p.top_chamfer, hz)):
        if c > 0.0:                                                                          # chamfered edges
            voids += [((-h, -h, z0), (-h + c, h, z1)), ((h - c, -h, z0), (h, h, z1))]
    f = p.side_fillet
    if f > 0.0:                                                                              # rounded corners
        voids += [((sx * h - (sx > 0) * f, sy * h - (sy > 0) * f, -hz),
                   (sx * h + (sx < 0) * f, sy * h + (sy < 0) * f, hz)) for sx in (1, -1) for sy in (1, -1)]
    shell = carve(((-h, -h, -hz), (h, h, hz)), voids, 2 * URDF_MARGIN)
    r_e = p.lip_depth / 2.0
    lips = []
    for sign in (1, -1):
        y0, y1 = sorted((sign * (p.mouth_width / 2 + r_e), sign * half_slit))
        lips.append(((h - p.lip_depth, y0, zo - mz), (h, y1, zo + mz)))
    return {"shell": shell, "lips": lips, "battery": battery}


def chamfer_faces(p):
    """Faces of the chamfered edges as boxes 2 mm thick, in base_link: [(centre, pitch, size)].

    A 45-degree chamfer of size c on an edge of the body's bottom or top, at the
    front and at the back; the box's outer face is the chamfer plane, the rest
    lies inside the body (whose corner ``body_parts`` carves away).
    """
    h, hz, t = p.body_side / 2.0, p.body_height / 2.0, 2 * URDF_MARGIN
    inward = t / 2 / math.sqrt(2.0)            # box centre behind the plane, along each axis
    faces = []
    for c, sz in ((p.bottom_chamfer, -1), (p.top_chamfer, 1)):
        if c <= 0.0:
            continue
        for sx in (1, -1):
            mid_x, mid_z = sx * (h - c / 2), sz * (hz - c / 2)          # the chamfer plane's midpoint
            faces.append(((mid_x - sx * inward, 0.0, mid_z - sz * inward), sz * sx * math.pi / 4,
                          (c * math.sqrt(2.0), p.body_side, t)))
    return faces


def corner_edges(p):
    """Rounded vertical corner edges (``side_fillet``): [(x, y, radius)] of vertical cylinders, base_link; the
    cylinders span the body's height between its bottom and top chamfers."""
    f, h = p.side_fillet, p.body_side / 2.0
    if f <= 0.0:
        return []
    return [(sx * (h - f), sy * (h - f), f) for sx in (1, -1) for sy in (1, -1)]


def lip_edges(p):
    """Rounded inner lip ends: [(x, y, radius)] of vertical cylinders, base_link."""
    r_e = p.lip_depth / 2.0
    h = p.body_side / 2.0
    return [(h - r_e, sign * (p.mouth_width / 2 + r_e), r_e) for sign in (1, -1)]


def robot_urdf(p, name="puzzlebot", pilot=False):
    """URDF text for a robot with parameters ``p`` (:class:`RobotParams`)."""
    zc = p.body_centre_height
    parts = body_parts(p)
    body = "".join(_box(lo, hi, "pilot" if pilot else "body") for lo, hi in parts["shell"])
    body += "".join(_box(lo, hi, "lip") for lo, hi in parts["lips"])
    lo, hi = parts["battery"]
    body += _shape('<box size="%.6g %.6g %.6g"/>' % tuple(b - a for a, b in zip(lo, hi)),
                   tuple((a + b) / 2 for a, b in zip(lo, hi)), color="battery", collision=False)
    for centre, pitch, size in chamfer_faces(p):
        body += _shape('<box size="%.6g %.6g %.6g"/>' % size, centre, (0.0, pitch, 0.0), color="pilot" if pilot
                       else "body")
    z0, z1 = -p.body_height / 2.0 + p.bottom_chamfer, p.body_height / 2.0 - p.top_chamfer
    for x, y, r in corner_edges(p):
        body += _shape('<cylinder radius="%.6g" length="%.6g"/>' % (r, z1 - z0), (x, y, (z0 + z1) / 2.0),
                       color="pilot" if pilot else "body")
    for x, y, r in lip_edges(p):
        body += _shape('<cylinder radius="%.6g" length="%.6g"/>' % (r, p.mouth_height), (x, y, p.opening_z),
                       color="lip")
    knob = '<cylinder radius="%.6g" length="%.6g"/>' % (p.knob_radius, p.knob_height)
    links, joints = [], []
    m_body = p.body_mass - (4 if pilot else 2) * p.wheel_mass
    if p.knob_travel > 0.0:             # the sprung knob: a plunger on a prismatic joint along +y
        m_body -= p.knob_mass
        i_k = p.knob_mass * max(p.knob_radius, KNOB_INERTIA_RADIUS) ** 2
        links.append('<link name="knob">%s%s</link>' % (_inertial(p.knob_mass, (i_k, i_k, i_k)),
                                                          _shape(knob, color="knob")))
        joints.append(_joint(KNOB_JOINT, "prismatic", "base_link", "knob", (0.0, p.body_side / 2, p.knob_z),
                             axis="0 1 0", limit=(-p.knob_travel, 0.0)))
    else:
        body += _shape(knob, (0.0, p.body_side / 2, p.knob_z), color="knob")
    # the body's centre of mass where the plunger's own leaves the robot's at the body centre (out, at rest)
    com = (0.0, -p.knob_mass * p.body_side / 2 / m_body, -p.knob_mass * p.knob_z / m_body) \
        if p.knob_travel > 0.0 else (0.0, 0.0, 0.0)
    links.insert(0, '<link name="base_link">%s%s</link>' % (
        _inertial(m_body, _box_inertia(m_body, p.body_side, p.body_side, p.body_height), com), body))
    wheel_rpy = (-math.pi / 2, 0.0, 0.0)
    # about the axle: the wheel's own inertia plus the gear motor's reflected rotor inertia; the same
    # about the other axes (Bullet rejects tensors that break the triangle inequality)
    axial = max(p.wheel_inertia, 0.5 * p.wheel_mass * p.wheel_radius ** 2)
    across = max(axial, p.wheel_mass * (3 * p.wheel_radius ** 2 + p.wheel_width ** 2) / 12.0)
    if pilot:
        wheels = [(n.replace("_joint", ""), x, s) for n, x, s in zip(
            PILOT_WHEEL_JOINTS, (p.pilot_wheel_x, -p.pilot_wheel_x) * 2, (1, 1, -1, -1))]
    else:
        wheels = [("left_wheel", 0.0, 1), ("right_wheel", 0.0, -1)]
    for link, x, sign in wheels:
        # visual: the real cylinder; collision: a sphere of the wheel's radius (one contact point, exact
        # rolling radius); the world lets wheels touch the terrain only, so its width does not matter
        links.append('<link name="%s">%s%s%s</link>' % (
            link, _inertial(p.wheel_mass, (across, axial, across)),
            _shape('<cylinder radius="%.6g" length="%.6g"/>' % (p.wheel_radius, p.wheel_width),
                   rpy=wheel_rpy, color="wheel", collision=False),
            _shape('<sphere radius="%.6g"/>' % p.wheel_radius, visual=False)))
        joints.append(_joint(link + "_joint", "continuous", "base_link", link,
                             (x, sign * p.wheel_y, p.wheel_radius - zc)))
    if not pilot:
        caster_mass = 0.001
        i_s = 0.4 * caster_mass * p.caster_radius ** 2
        for link, sign in zip(CASTER_LINKS, (1, -1)):
            links.append('<link name="%s">%s%s</link>' % (
                link, _inertial(caster_mass, (i_s, i_s, i_s)),
                _shape('<sphere radius="%.6g"/>' % p.caster_radius, color="caster")))
            joints.append(_joint(link + "_joint", "fixed", "base_link", link,
                                 (sign * p.caster_x, 0.0, p.caster_clearance + p.caster_radius - zc)))
    return _document(name, links, joints)


# ------------------------------------------------------------------- anchor
def anchor_urdf(a, name="anchor"):
    """URDF text of the soft anchor with parameters ``a`` (:class:`AnchorParams`).

    The links' inertias are raised to at least mass x ``inertia_radius``^2
    about every axis: millimetre links of a gram are ill-conditioned for
    Bullet's iterative solver, which then fails to hold the joint motors' torques.
    """
    g = AnchorGeometry(a)

    def floor(mass, inertia):
        return tuple(max(i, mass * a.inertia_radius ** 2) for i in inertia)
    bar_y, bar_z = a.bar_width, a.bar_height
    # base link: block + bar stub up to the neck
    base = _shape('<sphere radius="%.6g"/>' % a.base_radius, color="anchor")
    base += _shape('<box size="%.6g %.6g %.6g"/>' % (2 * a.base_radius, a.collar_width, a.collar_height),
                   color="anchor")
    if a.keel_height:
        base += _shape('<box size="%.6g %.6g %.6g"/>' % (2 * a.base_radius, 2 * URDF_MARGIN, a.keel_height),
                       color="anchor")
    stub_len = a.neck_x - a.base_radius / 2
    base += _shape('<box size="%.6g %.6g %.6g"/>' % (stub_len, bar_y, bar_z),
                   (-a.base_radius / 2 - stub_len / 2, 0, 0), color="anchor")
    i_ball = 0.4 * a.base_mass * a.base_radius ** 2
    links = ['<link name="base">%s%s</link>' % (_inertial(a.base_mass, floor(a.base_mass, (i_ball,) * 3)), base)]
    # head link (frame at the neck): bar from the neck to the head centre, diamond head
    head_cx = g.head_centre_x + a.neck_x            # in the neck frame
    bar_len = -head_cx
    head = _shape('<box size="%.6g %.6g %.6g"/>' % (bar_len, bar_y, bar_z), (-bar_len / 2, 0, 0), color="anchor")
    side = a.head_width / math.sqrt(2.0)
    head += _shape('<box size="%.6g %.6g %.6g"/>' % (side, side, a.head_height), (head_cx, 0, 0),
                   (0, 0, math.pi / 4), color="anchor")
    links.append('<link name="head">%s%s</link>' % (
        _inertial(a.head_mass, floor(a.head_mass, _box_inertia(a.head_mass, bar_len, a.head_width, a.head_height)),
                  (head_cx / 2, 0, 0)), head))
    joints = [_joint("neck_joint", "revolute", "base", "head", (-a.neck_x, 0, 0), axis="0 1 0",
                     limit=(-a.neck_limit, a.neck_limit))]
    # barbs: link frame at the hinge, x along the barb at rest
    hx, hy = g.hinge
    lo, hi = a.barb_fold_limit - a.barb_angle, a.barb_flip_limit - a.barb_angle
    i_b = floor(a.barb_mass, _box_inertia(a.barb_mass, a.barb_length, a.barb_thickness, a.barb_height))
    for link, sign in (("left_barb", 1), ("right_barb", -1)):
        links.append('<link name="%s">%s%s</link>' % (
            link, _inertial(a.barb_mass, i_b, (a.barb_length / 2, 0, 0)),
            _shape('<box size="%.6g %.6g %.6g"/>' % (a.barb_length, a.barb_thickness, a.barb_height),
                   (a.barb_length / 2, 0, 0), color="barb")
            + _shape('<cylinder radius="%.6g" length="%.6g"/>' % (a.barb_tip_radius, a.barb_height),
                     (a.barb_length, 0, 0), color="barb")))
        joints.append(_joint(link + "_joint", "revolute", "head", link, (hx + a.neck_x, sign * hy, 0),
                             axis="0 0 %d" % sign, rpy=(0, 0, sign * a.barb_angle), limit=(lo, hi)))
    return _document(name, links, joints)
