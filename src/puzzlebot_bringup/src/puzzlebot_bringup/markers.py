"""The stack's rviz markers, built from what the nodes publish (no rospy).

One function, :func:`build_markers`, turns the current state into a
visualization_msgs/MarkerArray; the ``markers`` node only collects the inputs
(tf, topics) and publishes the result on /puzzlebot/markers. Because every
input is a recorded topic, the same markers come out of a replayed bag.

Namespaces (one owner: this module):

| ns | what | frame |
| --- | --- | --- |
| ``bodies`` | body boxes, coloured robot / pilot | ``<robot>/base_link`` |
| ``fronts`` | a line across the front face (the opening) | ``<robot>/base_link`` |
| ``labels`` | robot names, on the body's rear half | ``<robot>/base_link`` |
| ``anchors`` | anchor bar, barbs, head: the simulated anchor body in ``<robot>/anchor`` (sim), else the nominal anchor C_a -> H_a | ``<robot>/anchor`` or ``base_link`` |
| ``polygons`` | coupling polygon of each MPC connection pair (front triangle / knob region of robot_j), filled with the pair's status colour | ``<robot_j>/base_link`` |
| ``pairs`` | line from the pair's head (anchor head H_a or knob) to robot_j's connection point, status colour | world |
| ``physical`` | disc on the opening robot's front: anchor seated (sim physical pairs) or only in the opening | ``<robot_j>/base_link`` |
| ``predicted`` | MPC predicted path of each robot that moves: a line and a dot per control step (dots closer than a dot's size merged) | world |
| ``goals`` | go_to_goal goals | world |
| ``slots`` | target slots of a couple behaviour, placed on the largest coupled assembly | world |
| ``legend`` | what each colour means, one line per entry in its colour, at the view's top left | ``puzzlebot/view`` |
| ``stages`` | the world's stages (puzzlebot_common.stages: a step's, a gap's two), boxes up to their tops | world |

Markers in a robot's frame are frame-locked with stamp 0: rviz moves them
with the latest tf. World-frame markers need the robots' poses
(``poses``: name -> (x, y, z, yaw) of ``<robot>/base_link``).

The view: the node publishes the frame ``puzzlebot/view`` (names.VIEW_FRAME,
no rotation from ``world``) at the centre of the robots' bounding box
(:func:`view_centre`); the shipped rviz configuration's top-down camera
follows it, so the robots stay in the picture wherever they drive, and the
legend, drawn in that frame, stays at the same place on the screen.
"""

import math
from dataclasses import dataclass, fields, replace
from typing import Tuple

from geometry_msgs.msg import Point, Vector3
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from puzzlebot_common import names
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import compose, inverse_transform_point, transform_point
from puzzlebot_common.params import from_mapping
from puzzlebot_mpc.pairs import components
from puzzlebot_msgs.msg import ConnectionPair

Colour = Tuple[float, float, float, float]


@dataclass(frozen=True)
class MarkerStyle:
    """Colours (r, g, b, a in 0..1) and sizes (m) of the markers; config/markers.yaml documents each."""

    rate: float = 10.0
    body_height: float = 0.045
    robot: Colour = (0.35, 0.55, 0.85, 0.7)
    pilot: Colour = (1.0, 0.55, 0.1, 0.7)
    front: Colour = (1.0, 1.0, 1.0, 1.0)
    anchor: Colour = (0.85, 0.85, 0.85, 1.0)
    anchor_width: float = 0.0025
    label: Colour = (1.0, 1.0, 1.0, 1.0)
    label_height: float = 0.012
    decoupled: Colour = (0.9, 0.2, 0.2, 1.0)
    head_aligned: Colour = (0.95, 0.75, 0.1, 1.0)
    head_inserted: Colour = (0.1, 0.8, 0.2, 1.0)
    polygon_fill_alpha: float = 0.45
    pair_line_width: float = 0.003
    seated: Colour = (0.0, 0.9, 0.9, 1.0)
    in_opening: Colour = (0.9, 0.2, 0.9, 1.0)
    physical_radius: float = 0.004
    predicted: Colour = (1.0, 1.0, 1.0, 1.0)
    predicted_width: float = 0.003
    predicted_dot: float = 0.004
    goal: Colour = (0.75, 0.3, 0.95, 0.9)
    goal_radius: float = 0.008
    slot: Colour = (0.8, 0.7, 1.0, 0.7)
    slot_width: float = 0.0015
    stage: Colour = (0.75, 0.7, 0.6, 0.35)
    z_lift: float = 0.001
    legend_x: float = -0.19
    legend_y: float = 0.22
    legend_height: float = 0.011
    legend_spacing: float = 0.016
    view_smoothing: float = 0.0

    @classmethod
    def from_dict(cls, data, where="markers"):
        style = from_mapping(cls, data, where)
        return replace(style, **{f.name: tuple(float(c) for c in getattr(style, f.name))
                                 for f in fields(cls) if f.type is Colour})

    def check(self, where="markers"):
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type is Colour:
                if not isinstance(value, (list, tuple)) or len(value) != 4 or not all(
                        isinstance(c, (int, float)) and not isinstance(c, bool) and 0.0 <= c <= 1.0 for c in value):
                    raise ConfigError("%s.%s: expected a colour [r, g, b, a] of four numbers in 0..1, got %r"
                                      % (where, f.name, value))
            elif f.name not in ("z_lift", "polygon_fill_alpha", "legend_x", "legend_y", "view_smoothing") and \
                    not value > 0:
                raise ConfigError("%s.%s: must be > 0, got %r" % (where, f.name, value))
        if not 0.0 <= self.polygon_fill_alpha <= 1.0 or self.z_lift < 0:
            raise ConfigError("%s: polygon_fill_alpha must be in 0..1 and z_lift >= 0" % where)
        if not 0.0 <= self.view_smoothing < 1.0:
            raise ConfigError("%s.view_smoothing: must be in [0, 1), got %r" % (where, self.view_smoothing))

    def status_colour(self, status):
        return {ConnectionPair.STATUS_DECOUPLED: self.decoupled, ConnectionPair.STATUS_HEAD_ALIGNED: self.head_aligned,
                ConnectionPair.STATUS_HEAD_INSERTED: self.head_inserted}.get(status, self.decoupled)


@dataclass(frozen=True)
class AnchorShape:
    """The simulated anchor body in its frame <robot>/anchor: bar from the base (origin) to the
    head tip at (-length, 0), barbs hinged at the head pointing back at ``barb_angle``
    (puzzlebot_sim robot.yaml ``anchor``)."""

    length: float
    barb_length: float
    barb_angle: float


def _colour(c, alpha=None):
    return ColorRGBA(float(c[0]), float(c[1]), float(c[2]), float(c[3] if alpha is None else alpha))


def _marker(ns, mid, mtype, frame, colour, scale=(1.0, 1.0, 1.0), locked=False):
    m = Marker(ns=ns, id=mid, type=mtype, action=Marker.ADD)
    m.header.frame_id = frame
    m.frame_locked = locked
    m.pose.orientation.w = 1.0
    m.scale = Vector3(*scale)
    m.color = _colour(colour)
    return m


def _pt(x, y, z):
    return Point(float(x), float(y), float(z))


def _fan(vertices, z):
    """Triangle list of a convex polygon (fan from the first vertex)."""
    out = []
    for k in range(1, len(vertices) - 1):
        out += [_pt(*vertices[0], z), _pt(*vertices[k], z), _pt(*vertices[k + 1], z)]
    return out


def _closed(vertices, z):
    return [_pt(x, y, z) for x, y in vertices] + [_pt(*vertices[0], z)]


def _spaced(points, spacing):
    """The first of ``points`` [(x, y)] and every next one at least ``spacing`` [m] from the last kept
    (dots of a predicted path that do not pile up where the robot is slow)."""
    out = points[:1]
    for p in points[1:]:
        if math.hypot(p[0] - out[-1][0], p[1] - out[-1][1]) >= spacing:
            out.append(p)
    return out


def _head_point(pair, geometry):
    """Body-frame head of robot_i: the anchor head H_a (anchor pairs) or the knob centre."""
    if pair.type == ConnectionPair.TYPE_KNOB:
        return geometry.knob_point()[:2]
    return geometry.anchor_head()


def _polygon(pair, geometry):
    return geometry.knob_region() if pair.type == ConnectionPair.TYPE_KNOB else geometry.front_triangle()


def assemblies(robot_names, pairs):
    """Groups of robots joined by coupled (head_inserted) pairs, largest first (ties: list order)."""
    coupled = [p for p in pairs if p.status == ConnectionPair.STATUS_HEAD_INSERTED]
    order = {n: k for k, n in enumerate(robot_names)}
    return sorted(components(robot_names, coupled), key=lambda g: (-len(g), min(order[n] for n in g)))


def placed_slots(slot_robots, slots, poses, pairs):
    """Target slots moved onto the robots: {robot: (x, y, heading)} in the world.

    The assignment's slots are only meaningful relative to each other (the
    assembly forms where the robots meet), so the target is drawn anchored on
    the first robot (slot order) of the largest coupled assembly: its slot
    coincides with its current pose and the other slots show where the others
    belong. Only robots with a pose can be the reference; empty if none has one.
    """
    present = [r for r in slot_robots if r in poses]
    if not present:
        return {}
    ref = assemblies(present, pairs)[0][0]
    slot = dict(zip(slot_robots, slots))
    px, py, _, pth = poses[ref]
    out = {}
    for r in slot_robots:
        rel = inverse_transform_point(slot[ref], slot[r][:2])        # slot r in the frame of ref's slot
        out[r] = tuple(float(v) for v in compose((px, py, pth), (rel[0], rel[1], slot[r][2] - slot[ref][2])))
    return out


def view_centre(poses, previous=None, smoothing=0.0):
    """(x, y) [m, world] of the view frame: the centre of the bounding box of the robots' positions
    (``poses``: name -> (x, y, z, yaw)); ``previous`` (the last centre, or None) when no robot has a
    pose, else moved towards the new centre by 1 - ``smoothing`` (0: at once)."""
    if not poses:
        return previous if previous is not None else (0.0, 0.0)
    xs, ys = [p[0] for p in poses.values()], [p[1] for p in poses.values()]
    centre = ((min(xs) + max(xs)) / 2.0, (min(ys) + max(ys)) / 2.0)
    if previous is None or smoothing <= 0:
        return centre
    return tuple(smoothing * a + (1.0 - smoothing) * b for a, b in zip(previous, centre))


def legend_entries(style, robots, physical=True, stages=False):
    """(text, colour) lines of the legend: bodies, pair statuses, the physical seating (``physical``:
    the simulation publishes it), anchors, predicted paths, goals, target slots and (``stages``: the
    world has some) the stages."""
    out = [("robot", style.robot)]
    if any(r.pilot for r in robots):
        out.append(("pilot robot", style.pilot))
    out += [("pair decoupled", style.decoupled), ("pair head aligned", style.head_aligned),
            ("pair coupled (MPC)", style.head_inserted)]
    if physical:
        out += [("anchor seated (Bullet)", style.seated), ("anchor in opening (Bullet)", style.in_opening)]
    out += [("anchor", style.anchor), ("predicted path (MPC)", style.predicted), ("goal", style.goal),
            ("target slot", style.slot)]
    if stages:
        out.append(("stage", style.stage))
    return out


def legend_markers(style, robots, physical=True, stages=False):
    """The legend: one TEXT_VIEW_FACING marker per entry, in names.VIEW_FRAME from (legend_x, legend_y)
    downwards (style), each in its colour."""
    out = []
    for k, (text, colour) in enumerate(legend_entries(style, robots, physical, stages)):
        m = _marker("legend", k, Marker.TEXT_VIEW_FACING, names.VIEW_FRAME, colour, (0, 0, style.legend_height),
                    locked=True)
        m.color = _colour(colour, 1.0)
        m.pose.position = _pt(style.legend_x, style.legend_y - k * style.legend_spacing, style.body_height)
        m.text = text
        out.append(m)
    return out


def stage_markers(stage_list, style):
    """One translucent CUBE per stage (puzzlebot_common.stages.Stage), in the world frame, from the floor
    up to the stage's top: a step's edge and a gap show where the robots stand."""
    out = []
    for k, st in enumerate(stage_list):
        m = _marker("stages", k, Marker.CUBE, names.WORLD_FRAME, style.stage,
                    (st.x_max - st.x_min, st.y_max - st.y_min, st.height))
        m.pose.position = _pt((st.x_min + st.x_max) / 2.0, (st.y_min + st.y_max) / 2.0, st.height / 2.0)
        out.append(m)
    return out


def build_markers(robots, geometry, style, poses, pairs=(), physical=(), predicted=None, objectives=None,
                  anchor_shape=None, legend=True, stages=()):
    """The MarkerArray of the current state (see the module docstring).

    robots: parsed robot list (RobotSpec: name, pilot); geometry: RobotGeometry;
    style: MarkerStyle; poses: {robot: (x, y, z, yaw)} of base_link in the world
    (robots without a pose get no world-frame markers); pairs: MPC ConnectionPair
    messages; physical: the sim's physical ConnectionPair messages; predicted:
    PredictedTrajectories or None; objectives: BehaviorObjectives or None;
    anchor_shape: AnchorShape to draw the anchor body in <robot>/anchor (sim), or
    None for the nominal anchor in base_link; legend: add the legend (its physical
    entries when ``anchor_shape`` is given: the simulation); stages: the world's
    stages (puzzlebot_common.stages.stages), drawn as boxes.
    """
    out = MarkerArray()
    clear = Marker(action=Marker.DELETEALL)
    clear.header.frame_id = names.WORLD_FRAME
    out.markers.append(clear)
    h = style.body_height / 2.0
    top = h + style.z_lift
    L = geometry.body_side
    add = out.markers.append
    out.markers.extend(stage_markers(stages, style))
    for k, r in enumerate(robots):
        base = names.base_frame(r.name)
        m = _marker("bodies", k, Marker.CUBE, base, style.pilot if r.pilot else style.robot,
                    (L, L, style.body_height), locked=True)
        add(m)
        m = _marker("fronts", k, Marker.LINE_LIST, base, style.front, (style.anchor_width, 0, 0), locked=True)
        m.points = [_pt(L / 2, -geometry.opening_width, top), _pt(L / 2, geometry.opening_width, top)]
        add(m)
        m = _marker("labels", k, Marker.TEXT_VIEW_FACING, base, style.label, (0, 0, style.label_height), locked=True)
        m.pose.position.x = -L / 4          # on the rear half: the predicted path leaves from the centre forward
        m.pose.position.z = h + 2 * style.label_height
        m.text = r.name + (" (pilot)" if r.pilot else "")
        add(m)
        if anchor_shape is not None:
            a = anchor_shape
            tip = (-a.length, 0.0)
            m = _marker("anchors", k, Marker.LINE_LIST, names.anchor_frame(r.name), style.anchor,
                        (style.anchor_width, 0, 0), locked=True)
            m.points = [_pt(0, 0, 0), _pt(*tip, 0)]
            for side in (1.0, -1.0):
                end = (tip[0] + a.barb_length * math.cos(a.barb_angle), side * a.barb_length * math.sin(a.barb_angle))
                m.points += [_pt(*tip, 0), _pt(*end, 0)]
        else:
            c, head = geometry.anchor_point(), geometry.anchor_head()
            m = _marker("anchors", k, Marker.LINE_LIST, base, style.anchor, (style.anchor_width, 0, 0), locked=True)
            m.points = [_pt(c[0], c[1], 0), _pt(head[0], head[1], 0)]
        add(m)

    for k, p in enumerate(pairs):
        colour = style.status_colour(p.status)
        poly = _polygon(p, geometry)
        frame = names.base_frame(p.robot_j)
        m = _marker("polygons", 2 * k, Marker.TRIANGLE_LIST, frame, colour, locked=True)
        m.color = _colour(colour, style.polygon_fill_alpha)
        m.points = _fan(poly, top + style.z_lift)
        add(m)
        m = _marker("polygons", 2 * k + 1, Marker.LINE_STRIP, frame, colour, (style.anchor_width, 0, 0), locked=True)
        m.points = _closed(poly, top + 2 * style.z_lift)
        add(m)
        if p.robot_i in poses and p.robot_j in poses:
            pi, pj = poses[p.robot_i], poses[p.robot_j]
            a = transform_point((pi[0], pi[1], pi[3]), _head_point(p, geometry))
            b = transform_point((pj[0], pj[1], pj[3]), (p.point_j.x, p.point_j.y))
            z = max(pi[2], pj[2]) + top + 3 * style.z_lift
            m = _marker("pairs", k, Marker.LINE_LIST, names.WORLD_FRAME, colour, (style.pair_line_width, 0, 0))
            m.points = [_pt(a[0], a[1], z), _pt(b[0], b[1], z)]
            add(m)

    for k, p in enumerate(physical):
        seated = p.status == ConnectionPair.STATUS_HEAD_INSERTED
        m = _marker("physical", k, Marker.CYLINDER, names.base_frame(p.robot_j), style.seated if seated else
                    style.in_opening, (2 * style.physical_radius, 2 * style.physical_radius, style.z_lift),
                    locked=True)
        m.pose.position.x = L / 2 - style.physical_radius
        m.pose.position.z = top + 4 * style.z_lift
        add(m)

    for k, t in enumerate(predicted.robots if predicted is not None else []):
        if t.robot not in poses or not t.poses:
            continue
        dots = _spaced([(q.x, q.y) for q in t.poses], style.predicted_dot)
        if len(dots) < 2:               # a robot planned to stay where it is: no path to draw
            continue
        z = poses[t.robot][2] + top + 5 * style.z_lift
        m = _marker("predicted", 2 * k, Marker.LINE_STRIP, names.WORLD_FRAME, style.predicted,
                    (style.predicted_width, 0, 0))
        m.points = [_pt(q.x, q.y, z) for q in t.poses]
        add(m)
        m = _marker("predicted", 2 * k + 1, Marker.POINTS, names.WORLD_FRAME, style.predicted,
                    (style.predicted_dot, style.predicted_dot, 0))
        m.points = [_pt(x, y, z) for x, y in dots[1:]]
        add(m)

    if objectives is not None:
        for k, (r, g) in enumerate(zip(objectives.goal_robots, objectives.goals)):
            z = (poses[r][2] - h if r in poses else 0.0) + style.z_lift
            m = _marker("goals", k, Marker.CYLINDER, names.WORLD_FRAME, style.goal,
                        (2 * style.goal_radius, 2 * style.goal_radius, style.z_lift))
            m.pose.position = _pt(g.x, g.y, z)
            add(m)
        slots = placed_slots(list(objectives.slot_robots), [(s.x, s.y, s.theta) for s in objectives.slots],
                             poses, pairs)
        for k, r in enumerate(objectives.slot_robots):
            if r not in slots:
                continue
            x, y, th = slots[r]
            z = poses[r][2] - h + 2 * style.z_lift if r in poses else style.z_lift
            corners = [transform_point((x, y, th), v) for v in geometry.footprint()]
            front = transform_point((x, y, th), (L / 2, 0.0))
            m = _marker("slots", k, Marker.LINE_LIST, names.WORLD_FRAME, style.slot, (style.slot_width, 0, 0))
            for a, b in zip(corners, corners[1:] + corners[:1]):
                m.points += [_pt(a[0], a[1], z), _pt(b[0], b[1], z)]
            m.points += [_pt(x, y, z), _pt(front[0], front[1], z)]
            add(m)
    if legend:
        out.markers += legend_markers(style, robots, physical=anchor_shape is not None, stages=bool(stages))
    return out

