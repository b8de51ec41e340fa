"""Planar geometry: angles, SE(2) poses, convex polygons, the robot footprint.

Conventions: positions in metres, angles in radians, a pose is
``(x, y, theta)`` of a body frame in the world frame, theta counter-clockwise
from the world x axis. Polygons are (K, 2) arrays of vertices numbered
counter-clockwise.
"""

import math
from dataclasses import dataclass, fields

import numpy as np

from puzzlebot_common.params import from_mapping, require_positive


def wrap_angle(a):
    """Wrap an angle (float) or an array of angles to [-pi, pi)."""
    w = (np.asarray(a, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
    return float(w) if w.ndim == 0 else w


def rot(theta):
    """2x2 rotation matrix R(theta)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def transform_point(pose, p):
    """Express body-frame point ``p`` (x, y) of a body at ``pose`` in the world frame."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    return np.array([x + c * p[0] - s * p[1], y + s * p[0] + c * p[1]])


def inverse_transform_point(pose, q):
    """Express world point ``q`` in the body frame of a body at ``pose``."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    dx, dy = q[0] - x, q[1] - y
    return np.array([c * dx + s * dy, -s * dx + c * dy])


def compose(pose, rel):
    """Pose of a frame given relative to a body at ``pose`` (both (x, y, theta))."""
    p = transform_point(pose, rel[:2])
    return np.array([p[0], p[1], wrap_angle(pose[2] + rel[2])])


_HALFPLANES = {}        # (shape, bytes) of a polygon's vertices -> (G, h, row norms of G), read-only
_HALFPLANES_MAX = 256   # polygons kept (a robot's few constant ones; the cache is cleared when full)


def _halfplanes(vertices):
    """(G, h, row norms of G) of a convex polygon (see polygon_halfplanes), computed once per polygon:
    the coupling and footprint polygons are constant, and the pair bookkeeping asks for them every step."""
    a = np.asarray(vertices, dtype=float)
    key = (a.shape, a.tobytes())
    hp = _HALFPLANES.get(key)
    if hp is None:
        b = np.roll(a, -1, axis=0)
        g = np.stack([b[:, 1] - a[:, 1], -(b[:, 0] - a[:, 0])], axis=1)
        hp = (g, np.einsum("ij,ij->i", g, a), np.linalg.norm(g, axis=1))
        for x in hp:
            x.setflags(write=False)
        if len(_HALFPLANES) >= _HALFPLANES_MAX:
            _HALFPLANES.clear()
        _HALFPLANES[key] = hp
    return hp


def polygon_halfplanes(vertices):
    """Linear form of point-in-convex-polygon (paper, eq. "pip").

    For counter-clockwise vertices A_1..A_K returns ``(G, h)`` with
    ``G @ p <= h`` exactly when ``p`` lies inside or on the polygon. Row k is
    ``[y_{k+1} - y_k, -(x_{k+1} - x_k)] (p - A_k) <= 0``. The arrays are
    read-only (cached by the vertices' values).
    """
    g, h, _ = _halfplanes(vertices)
    return g, h


def signed_margin(vertices, p):
    """Distance by which ``p`` lies inside the convex polygon (negative outside).

    The minimum over edges of the signed distance to the edge line; for a
    point outside it is a lower bound (in magnitude) of the Euclidean distance.
    """
    g, h, norms = _halfplanes(vertices)
    return float(np.min((h - g @ np.asarray(p, dtype=float)) / norms))


def point_in_convex_polygon(vertices, p, eps=0.0):
    """True when ``p`` is inside the polygon grown by ``eps`` metres."""
    return signed_margin(vertices, p) >= -eps


def point_in_polygon(vertices, p):
    """True when ``p`` is inside the simple polygon ``vertices`` (convex or not, either orientation), by
    the crossing number of a ray towards +x; a point on an edge may fall either way.

    Independent of the linear form (polygon_halfplanes): the reference the coupling rows are tested against.
    """
    inside = False
    n = len(vertices)
    for i in range(n):
        (x1, y1), (x2, y2) = vertices[i], vertices[(i + 1) % n]
        if (y1 > p[1]) != (y2 > p[1]) and p[0] < x1 + (p[1] - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


@dataclass(frozen=True)
class RobotGeometry:
    """The robot's dimensions (metres, radians; defaults: facts.md), defined once for every package.

    The controller plans with them; the simulation's ``RobotParams`` (body
    side, wheel track, knob: the URDF) and the emulated motors
    (``MotorParams.wheel_base``) take their defaults from the class's fields.
    The robot's limits and the set-up's rates: :mod:`puzzlebot_common.hardware`.
    """

    body_side: float = 0.05        # L: square body, origin at its centre
    anchor_length: float = 0.0125  # l: anchor head point C' = C + [-l, 0]
    wheel_base: float = 0.04       # track used to split (v, w) into wheel speeds
    knob_radius: float = 0.0045    # side knob radius (facts.md); the knob is on the left (+y) side
    knob_tolerance: float = 0.002  # half-size of the square around a hole in which a coupled knob's
                                   # centre stays (the knob-hole coupling is rigid)
    opening_width: float = 0.012   # front opening width; the anchor enters only through it
    anchor_yaw_free: float = 0.5   # rad: yaw freedom of the anchor in its holder (+/-)
    knob_yaw_tolerance: float = 0.1  # rad: heading difference a knob still enters its hole with

    @classmethod
    def from_dict(cls, data, where="geometry"):
        return from_mapping(cls, data, where)

    def check(self, where="geometry"):
        require_positive(self, [f.name for f in fields(self)], where)

    def front_triangle(self):
        """Coupling polygon in the body frame (paper: the anchor point of a
        coupled pair stays in the triangle of this robot's centre and its
        front-right and front-left corners), counter-clockwise."""
        h = self.body_side / 2.0
        return np.array([[0.0, 0.0], [h, -h], [h, h]])

    def footprint(self):
        """Body square in the body frame, counter-clockwise."""
        h = self.body_side / 2.0
        return np.array([[-h, -h], [h, -h], [h, h], [-h, h]])

    def footprint_radius(self):
        """Distance from the body centre to the footprint's farthest corner [m] (its circumradius)."""
        return float(np.max(np.linalg.norm(self.footprint(), axis=1)))

    # Connection points (x, y, heading) in the body frame. A connection
    # point's heading points out of the body, so two points that meet face
    # each other (headings differ by pi) and the two robots have equal
    # headings when coupled.
    def anchor_point(self):
        """C_a: where the anchor leaves the back face (-x)."""
        return np.array([-self.body_side / 2.0, 0.0, math.pi])

    def opening_point(self):
        """C_o: centre of the front (+x) opening that receives another robot's anchor."""
        return np.array([self.body_side / 2.0, 0.0, 0.0])

    def anchor_head(self):
        """H_a = C_a + (-l, 0): the anchor head point (paper: C')."""
        return np.array([-self.body_side / 2.0 - self.anchor_length, 0.0])

    def knob_point(self):
        """Centre of the side knob, on the left (+y) face."""
        return np.array([0.0, self.body_side / 2.0, math.pi / 2.0])

    def hole_point(self):
        """Centre of the side hole, on the right (-y) face; a neighbour's knob goes in here."""
        return np.array([0.0, -self.body_side / 2.0, -math.pi / 2.0])

    def knob_region(self):
        """Square (counter-clockwise) around the hole in which a coupled knob's centre stays."""
        c, t = self.hole_point(), self.knob_tolerance
        return np.array([[c[0] - t, c[1] - t], [c[0] + t, c[1] - t], [c[0] + t, c[1] + t], [c[0] - t, c[1] + t]])


def yaw_from_quaternion(qx, qy, qz, qw):
    """Yaw (rotation about world z) of a quaternion, in [-pi, pi]."""
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def quaternion_from_yaw(yaw):
    """Quaternion (x, y, z, w) of a pure yaw rotation."""
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))
