"""Resting anchors frozen to their robot: a speed shortcut of SimWorld (AnchorRestParams, docs/sim.md).

An anchor that has rested in its holder for ``settle_time`` while nothing
can touch it leaves the Bullet world (``freeze``): its weight stays on the
robot and its pose follows the robot at the pose where it rested. It is put
back (``wake``) as soon as another robot or anchor comes within
``clearance`` of it, the robot tilts, the terrain under it changes, or the
robot's velocity changes by more than ``max_dv`` / ``max_dw`` within one
check period. Interacting anchors are therefore always simulated in full.

``AnchorRest`` is owned by a SimWorld, which calls ``update`` every check
period, ``apply_weights`` before every physics step, and reads ``frozen``
for a frozen anchor's pose, joints and points. ``NoAnchorRest`` is the same
interface with every anchor always simulated (anchor_rest disabled, no
anchors, or the GUI).

Units: metres, seconds, radians, newtons; poses in the world frame, a
frozen anchor's record in its robot's base_link frame.
"""

import math
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np
import pybullet as pb

from puzzlebot_common.geometry import yaw_from_quaternion
from puzzlebot_sim.anchor import AnchorGeometry

#: Largest yaw of an anchor in its holder assumed by the resting-anchor tests [rad] (about +/-0.5 rad).
ANCHOR_MAX_YAW = 0.6


@dataclass
class FrozenAnchor:
    """A frozen anchor, in its robot's base_link frame."""

    base: Tuple                   # (position, quaternion) of the anchor base
    q: Tuple[float, float, float]  # (neck, left barb, right barb) joint angles [rad] where it rested
    points: List                  # head tip, left barb tip, right barb tip [m]
    com: Tuple                    # the anchor's centre of mass [m]
    weight: List[float]           # its weight [N]


@dataclass
class _RestState:
    frozen: Optional[FrozenAnchor] = None
    calm_since: Optional[float] = None   # sim time [s] since the awake anchor rests
    last_velocity: Optional[Tuple] = None   # the robot's (linear, angular) velocity at the last check


def _obb_overlap(a, b, grow):
    """True when oriented rectangle ``a`` grown by ``grow`` [m] overlaps rectangle ``b``.

    Rectangles are (centre x, centre y, cos yaw, sin yaw, half length, half width)."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    for ux, uy in ((a[2], a[3]), (-a[3], a[2]), (b[2], b[3]), (-b[3], b[2])):
        ra = (a[4] + grow) * abs(a[2] * ux + a[3] * uy) + (a[5] + grow) * abs(-a[3] * ux + a[2] * uy)
        rb = b[4] * abs(b[2] * ux + b[3] * uy) + b[5] * abs(-b[3] * ux + b[2] * uy)
        if abs(dx * ux + dy * uy) > ra + rb:
            return False
    return True


def exposed_anchor_box(p, a, anchor_home_x):
    """Where the anchor can be outside its robot's back face, in the robot's frame:
    (x0, x1, half width) [m], for any travel in the holder, any barb angle and a yaw
    of up to ANCHOR_MAX_YAW. ``p``: RobotParams, ``a``: AnchorParams, ``anchor_home_x``:
    x of the pushed-in anchor base in base_link [m]."""
    h = p.body_side / 2.0
    travel = p.holder_depth - p.holder_wall - 2 * a.base_radius
    tip_out = -h - (anchor_home_x - travel - a.length)                 # head tip pulled out
    reach = tip_out + a.barb_length + a.barb_tip_radius                # + a barb flipped backward
    lever = reach + h + (anchor_home_x - travel)                       # ball centre to the far end
    half_width = lever * math.sin(ANCHOR_MAX_YAW) + AnchorGeometry(a).hinge[1] + a.barb_length + a.barb_tip_radius
    return (-h - reach, -h, half_width)


def _carried(position, lin, ang, point):
    """Velocity [m/s] of ``point`` carried along by a body at ``position`` moving at (lin, ang)."""
    r = [point[k] - position[k] for k in range(3)]
    return [lin[0] + ang[1] * r[2] - ang[2] * r[1], lin[1] + ang[2] * r[0] - ang[0] * r[2],
            lin[2] + ang[0] * r[1] - ang[1] * r[0]]


class AnchorRest:
    """Freezes resting anchors of ``robots`` (name -> world.SimRobot, the world's own dict) and wakes them.

    ``params`` (AnchorRestParams), ``robot_params`` (RobotParams), ``anchor_params``
    (AnchorParams), ``anchor_home_x`` (x of the pushed-in anchor base in base_link [m]),
    ``client`` (the world's physics client), ``terrain`` (its worlds.Terrain: ``height(x, y)``),
    ``load_anchor(position, orientation)`` (puts an anchor body into the world, returns its id),
    ``anchor_points_of(body)`` (world positions of an anchor body's head tip and barb tips),
    ``gravity`` [m/s^2].
    """

    def __init__(self, params, robot_params, anchor_params, anchor_home_x, client, terrain, robots,
                 load_anchor, anchor_points_of, gravity):
        self.params = params
        self._p, self._a = robot_params, anchor_params
        self._client, self._terrain, self._robots = client, terrain, robots
        self._load_anchor, self._anchor_points_of = load_anchor, anchor_points_of
        self._gravity = gravity
        self._state = {name: _RestState() for name in robots}
        self._exposed = exposed_anchor_box(robot_params, anchor_params, anchor_home_x)
        box = self._exposed
        half = ((box[1] - box[0]) / 2.0, box[2])
        self._zone_radius = max(math.hypot(robot_params.body_side / 2, robot_params.body_side / 2),
                                abs(box[0] + box[1]) / 2.0 + math.hypot(*half))
        self._box_radius = math.hypot(*half)

    # ------------------------------------------------------------ readouts
    def frozen(self, name):
        """``name``'s FrozenAnchor, or None while its anchor is simulated."""
        return self._state[name].frozen

    def resting(self):
        """Names of the robots whose anchor is frozen, in the world's order."""
        return [n for n, st in self._state.items() if st.frozen is not None]

    # ------------------------------------------------------------- physics
    def apply_weights(self):
        """Before a physics step: a frozen anchor's weight stays on its robot."""
        for name, robot in self._robots.items():
            frozen = self._state[name].frozen
            if frozen is not None:
                pb.applyExternalForce(robot.body, -1, frozen.weight, frozen.com, pb.LINK_FRAME,
                                      physicsClientId=self._client)

    def update(self, poses, time):
        """Every check period: freeze anchors that rest with nothing near; wake frozen ones that something
        may disturb. ``poses``: name -> (position, quaternion) of every robot now, ``time``: sim time [s]."""
        c, rest = self._client, self.params
        zones = self._zones(poses)
        near = self._near(zones)
        for name, robot in self._robots.items():
            state = self._state[name]
            lin, ang = pb.getBaseVelocity(robot.body, physicsClientId=c)
            last, state.last_velocity = state.last_velocity, (lin, ang)
            steady = (last is not None and math.dist(lin, last[0]) <= rest.max_dv
                      and abs(ang[2] - last[1][2]) <= rest.max_dw)
            quiet = steady and self._anchor_clear(name, zones, poses, near[name])
            if state.frozen is not None:
                if not quiet:
                    self.wake(name)
            elif quiet and robot.anchor is not None and self._anchor_calm(robot, poses[name][0], lin, ang):
                if state.calm_since is None:
                    state.calm_since = time
                elif time - state.calm_since >= rest.settle_time - 1e-9:
                    self._freeze(name, poses[name])
            else:
                state.calm_since = None

    def release(self, name):
        """Wake ``name``'s anchor if frozen and restart its rest timer (the world resets the anchor)."""
        if self._state[name].frozen is not None:
            self.wake(name)
        self._state[name].calm_since = None

    def wake(self, name):
        """Put ``name``'s frozen anchor back into the Bullet world where it rested, moving with the robot."""
        c, robot, state = self._client, self._robots[name], self._state[name]
        frozen = state.frozen
        pos, orn = pb.getBasePositionAndOrientation(robot.body, physicsClientId=c)
        a_pos, a_orn = pb.multiplyTransforms(pos, orn, *frozen.base, physicsClientId=c)
        body = self._load_anchor(a_pos, a_orn)
        lin, ang = pb.getBaseVelocity(robot.body, physicsClientId=c)
        pb.resetBaseVelocity(body, _carried(pos, lin, ang, a_pos), ang, physicsClientId=c)
        for j, q in enumerate(frozen.q):
            pb.resetJointState(body, j, q, 0.0, physicsClientId=c)
        robot.anchor = body
        robot.anchor_q = None
        state.frozen = None
        state.calm_since = None

    def _freeze(self, name, pose):
        """Take ``name``'s resting anchor out of the Bullet world; it follows the robot from now on."""
        c, a, robot, state = self._client, self._a, self._robots[name], self._state[name]
        body = robot.anchor
        inv_pos, inv_orn = pb.invertTransform(*pose, physicsClientId=c)

        def local(position, orientation=(0, 0, 0, 1)):
            return pb.multiplyTransforms(inv_pos, inv_orn, position, orientation, physicsClientId=c)
        base = pb.getBasePositionAndOrientation(body, physicsClientId=c)
        links = pb.getLinkStates(body, [0, 1, 2], physicsClientId=c)
        masses = [a.base_mass, a.head_mass, a.barb_mass, a.barb_mass]
        centres = [base[0]] + [st[0] for st in links]
        com = [sum(m * p[k] for m, p in zip(masses, centres)) / sum(masses) for k in range(3)]
        head, tips = self._anchor_points_of(body)
        gravity_local = local([0, 0, -self._gravity * a.mass])[0]
        origin_local = local([0, 0, 0])[0]
        q = tuple(st[0] for st in pb.getJointStates(body, [0, 1, 2], physicsClientId=c))
        state.frozen = FrozenAnchor(base=local(*base), q=q, points=[local(p)[0] for p in [head] + list(tips)],
                                    com=local(com)[0],
                                    weight=[gravity_local[k] - origin_local[k] for k in range(3)])
        pb.removeBody(body, physicsClientId=c)
        robot.anchor = None
        robot.anchor_state = None
        state.calm_since = None

    # --------------------------------------------------------------- tests
    def _zones(self, poses):
        """Per robot: its body and its exposed anchor box as (centre, c, s, half x, half y) in the world."""
        h = self._p.body_side / 2.0
        x0, x1, hw = self._exposed
        zones = {}
        for name in self._robots:
            (x, y, _), orn = poses[name]
            yaw = yaw_from_quaternion(*orn)
            c, s = math.cos(yaw), math.sin(yaw)
            ax = (x0 + x1) / 2.0
            zones[name] = ((x, y, c, s, h, h), (x + c * ax, y + s * ax, c, s, (x1 - x0) / 2.0, hw))
        return zones

    def _near(self, zones):
        """Per robot: the other robots whose body centre is close enough to its exposed anchor box for
        their body or anchor to matter (all pairs at once; the box tests of ``_anchor_clear`` follow)."""
        names = list(zones)
        boxes = np.array([zones[n][1][:2] for n in names])
        bodies = np.array([zones[n][0][:2] for n in names])
        far = self._zone_radius + self._box_radius + self.params.clearance
        d2 = (bodies[None, :, 0] - boxes[:, None, 0]) ** 2 + (bodies[None, :, 1] - boxes[:, None, 1]) ** 2
        np.fill_diagonal(d2, np.inf)
        near = {n: [] for n in names}
        for i, j in zip(*(k.tolist() for k in np.nonzero(d2 <= far * far))):    # row by row, in robot order
            near[names[i]].append(names[j])
        return near

    def _anchor_clear(self, name, zones, poses, near):
        """True when no other robot or anchor is within the clearance of ``name``'s anchor,
        the robot is level and the terrain under the anchor is the robot's. ``near``: the robots
        that may be that close (``_near``)."""
        rest = self.params
        box = zones[name][1]
        grow = rest.clearance
        for other in near:
            body, anchor = zones[other]
            if _obb_overlap(box, body, grow) or _obb_overlap(box, anchor, grow):
                return False
        (x, y, z), orn = poses[name]
        if 1.0 - 2.0 * (orn[0] ** 2 + orn[1] ** 2) < math.cos(rest.max_tilt):
            return False                                  # tilted: the anchor may slide or hang
        ground = self._terrain.height(x, y)
        if abs(z - ground - self._p.body_centre_height) > self._p.ground_clearance:
            return False                                  # lifted or falling
        cx, cy, c, s, hx, hy = box
        for dx, dy in ((0, 0), (-1, -1), (-1, 1), (1, -1), (1, 1)):
            px, py = dx * (hx + grow), dy * (hy + grow)
            if self._terrain.height(cx + c * px - s * py, cy + s * px + c * py) != ground:
                return False                              # an edge or a step under the anchor
        return True

    def _anchor_calm(self, robot, position, lin, ang):
        """True when the awake anchor rests in its holder: joints near rest, no motion relative to the robot."""
        rest, states = self.params, robot.anchor_state
        if states is None:
            return False
        if any(abs(st[0]) > rest.max_joint_angle or abs(st[1]) > rest.max_rel_rate for st in states):
            return False
        c = self._client
        a_pos = pb.getBasePositionAndOrientation(robot.anchor, physicsClientId=c)[0]
        a_lin, a_ang = pb.getBaseVelocity(robot.anchor, physicsClientId=c)
        return (math.dist(a_lin, _carried(position, lin, ang, a_pos)) <= rest.max_rel_speed
                and math.dist(a_ang, ang) <= rest.max_rel_rate)


class NoAnchorRest:
    """Every anchor always simulated in full: the AnchorRest interface, doing nothing."""

    def frozen(self, name):
        return None

    def resting(self):
        return []

    def apply_weights(self):
        pass

    def update(self, poses, time):
        pass

    def release(self, name):
        pass
