"""A Bullet world with PuzzleBots and their soft anchors, stepped at a fixed rate.

``SimWorld`` is the ROS-free simulation core: the sim node wraps it, and
experiments use it in-process (many worlds in parallel processes, no ROS).
Every PyBullet call passes this world's physics client id, so several worlds
can live in one process. The world never sleeps or reads the wall clock:
pacing belongs to the caller. For the same parameters, start poses, seed and
command sequence a world produces the same trajectory.

Typical use::

    with SimWorld(RobotParams(), [RobotStart("pz1", 0, 0, 0)], seed=3) as w:
        w.set_command("pz1", 0.05, 0.0)      # body velocity (m/s, rad/s)
        w.run(2.0)                           # simulated seconds
        x, y, yaw = w.pose2d("pz1")
        pairs = w.physical_pairs()           # which anchor sits in which opening

Units: metres, seconds, radians; poses in the ``world`` frame. A robot's
pose is its ``base_link`` (body centre, x forward); an anchor's pose is the
centre of its base block, axes parallel to the robot's at rest.
"""

import math
import os
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np
import pybullet as pb

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import wrap_angle, yaw_from_quaternion
from puzzlebot_common.kinematics import wheel_speeds
from puzzlebot_sim import coupling
from puzzlebot_sim.anchor import AnchorGeometry, BarbTorqueMap
from puzzlebot_sim.anchor_rest import AnchorRest, NoAnchorRest
from puzzlebot_sim.bullet_session import BulletSession
from puzzlebot_sim.mocap import MocapModel
from puzzlebot_sim.params import AnchorParams, AnchorRestParams, SimParams, WorldParams
from puzzlebot_sim.roll_stop import AnchorRollStop
from puzzlebot_sim.urdf import (CASTER_LINKS, KNOB_JOINT, PILOT_WHEEL_JOINTS, URDF_FLAGS, WHEEL_JOINTS, anchor_urdf,
                                robot_urdf)
from puzzlebot_sim.worlds import WORLDS

#: Collision groups: terrain, robot bodies, wheels and casters (terrain only), anchors.
GROUP_TERRAIN, GROUP_BODY, GROUP_WHEEL, GROUP_ANCHOR = 1, 2, 4, 8
_MASKS = {GROUP_TERRAIN: GROUP_TERRAIN | GROUP_BODY | GROUP_WHEEL | GROUP_ANCHOR,
          GROUP_BODY: GROUP_TERRAIN | GROUP_BODY | GROUP_ANCHOR,
          GROUP_WHEEL: GROUP_TERRAIN,
          GROUP_ANCHOR: GROUP_TERRAIN | GROUP_BODY | GROUP_ANCHOR}

#: An anchor's joint motors are re-set when a joint moved by more than this [rad].
ANCHOR_UPDATE_RAD = 0.002

#: Gravitational acceleration [m/s^2].
GRAVITY = 9.81

#: Tolerances of the start-pose check for robots placed coupled [m, rad].
MATE_POSITION_TOLERANCE = 0.001
MATE_YAW_TOLERANCE = 0.03


@dataclass
class RobotStart:
    """Where a robot starts: (x, y) [m] and yaw [rad] of its base_link in the world frame."""

    name: str
    x: float
    y: float
    yaw: float
    pilot: bool = False


@dataclass(eq=False)
class SimRobot:
    """One simulated robot (``SimWorld.robots[name]``): its Bullet bodies, command and motor settings."""

    name: str
    body: int                                    # Bullet body id of the robot
    wheels: List[int]                            # driven wheel joints, the left ones first
    n_left: int                                  # how many of ``wheels`` are on the left
    pilot: bool                                  # four driven wheels, no casters
    anchor: Optional[int] = None                 # Bullet body id of its anchor (None: no anchors, or frozen)
    plant: Optional[object] = None               # puzzlebot_common.effects.ActuatorPlant (None: ideal)
    command: Tuple[float, float] = (0.0, 0.0)    # commanded body velocity (m/s, rad/s)
    driven: Tuple[float, float] = (0.0, 0.0)     # body velocity the wheels are driven at (m/s, rad/s)
    wheel_targets: Optional[Tuple[float, float]] = None   # wheel speed setting (left, right) [rad/s]
    anchor_q: Optional[Tuple[float, float, float]] = None  # anchor joint angles at its last motor setting [rad]
    anchor_state: Optional[list] = None          # anchor joint states read this step (pb.getJointStates)
    knob: Optional[int] = None                   # the sprung knob's joint (None: the knob is rigid)


# ------------------------------------------------------------- start checks
def _rect_corners(pose, x0, x1, y0, y1):
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([[pose[0] + c * x - s * y, pose[1] + s * x + c * y]
                     for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))])


def _convex_overlap(ca, cb):
    """Separating-axis test of two convex quadrilaterals (corner arrays)."""
    for poly in (ca, cb):
        for k in range(len(poly)):
            e = poly[(k + 1) % len(poly)] - poly[k]
            axis = np.array([-e[1], e[0]])
            a, b = ca @ axis, cb @ axis
            if a.max() <= b.min() + 1e-9 or b.max() <= a.min() + 1e-9:
                return False
    return True


def _squares_overlap(pa, pb_, side):
    h = side / 2.0
    return _convex_overlap(_rect_corners(pa, -h, h, -h, h), _rect_corners(pb_, -h, h, -h, h))


def mated(anchor_pose, opening_pose, body_side):
    """True when the opening robot sits right behind the anchor robot, facing the
    same way (back face on front face): the anchor then starts seated."""
    dx, dy = opening_pose[0] - anchor_pose[0], opening_pose[1] - anchor_pose[1]
    c, s = math.cos(anchor_pose[2]), math.sin(anchor_pose[2])
    along, across = c * dx + s * dy, -s * dx + c * dy
    return (abs(along + body_side) <= MATE_POSITION_TOLERANCE and abs(across) <= MATE_POSITION_TOLERANCE
            and abs(wrap_angle(opening_pose[2] - anchor_pose[2])) <= MATE_YAW_TOLERANCE)


def anchor_home_x(robot, anchor):
    """x [m] of the anchor base's centre in its robot's frame when pushed home in the holder."""
    return -robot.body_side / 2 + robot.holder_depth - anchor.base_radius


def anchor_reach(robot, anchor):
    """(how far the anchor sticks out of the back face when pushed home [m], its half width at rest [m])."""
    reach = -robot.body_side / 2 - (anchor_home_x(robot, anchor) - anchor.length)
    return max(reach, 0.0), AnchorGeometry(anchor).half_width()


def check_start_poses(starts, body_side, anchor_reach=0.0, anchor_half_width=0.0):
    """Raise ConfigError if robots (or an anchor and a robot) would start inside each other.

    ``anchor_reach``: how far the anchor sticks out of the back face [m]
    (0: no anchors). An anchor may start inside another robot only when that
    robot is mated behind it (see :func:`mated`): then it starts seated.
    """
    h = body_side / 2.0
    for a in range(len(starts)):
        for b in range(len(starts)):
            if a == b:
                continue
            p, q = starts[a], starts[b]
            pa, qa = (p.x, p.y, p.yaw), (q.x, q.y, q.yaw)
            if a < b and _squares_overlap(pa, qa, body_side):
                raise ConfigError("robots %s and %s are placed inside each other: centres %.1f mm apart, "
                                  "bodies are %.0f mm wide" % (p.name, q.name,
                                                               1e3 * math.hypot(p.x - q.x, p.y - q.y),
                                                               1e3 * body_side))
            if anchor_reach > 0 and not mated(pa, qa, body_side):
                anchor = _rect_corners(pa, -h - anchor_reach, -h, -anchor_half_width, anchor_half_width)
                if _convex_overlap(anchor, _rect_corners(qa, -h, h, -h, h)):
                    raise ConfigError("the anchor of robot %s would start inside robot %s: place %s clear of "
                                      "%s's back (>= %.1f mm) or mated behind it (coupled start)"
                                      % (p.name, q.name, q.name, p.name, 1e3 * anchor_reach))


# -------------------------------------------------------------------- world
class SimWorld(BulletSession):
    """PuzzleBots (and their anchors) in a Bullet world. Commands are body velocities (v, w).

    Arguments: ``robot_params`` (RobotParams), ``starts`` (RobotStart list),
    ``world`` (name in puzzlebot_sim.worlds.WORLDS), ``physics_rate`` [Hz],
    ``gui``; keyword-only: ``anchor_params`` (AnchorParams, None = robots
    without anchors), ``world_params`` (WorldParams), ``solver_iterations``,
    ``erp``, ``seed`` (mocap noise; the stepping defaults are SimParams'), ``actuator_model`` (a
    puzzlebot_common.effects.ActuatorModel applied to each robot's commands,
    its ``robots:`` entries by robot name; None = ideal), ``wheel_imbalance``
    (right wheel x (1 + k), left x (1 - k)),
    ``mocap`` (puzzlebot_sim.mocap.MocapModel), ``anchor_rest`` (AnchorRestParams:
    when resting anchors are frozen to their robot, puzzlebot_sim.anchor_rest; off
    with the GUI, which would not show them), ``tilted_solver_iterations`` (solver
    iterations while any robot is tilted by more than ``tilt_threshold`` rad: robots
    falling over an edge or hanging load the light anchor links with large impulses,
    which the solver needs more iterations for).

    ``robots``: name -> SimRobot (Bullet body ids, command, motor settings), in start order.
    """

    def __init__(self, robot_params, starts, world="flat", physics_rate=SimParams.physics_rate, gui=False, *,
                 anchor_params=AnchorParams(), world_params=None, solver_iterations=SimParams.solver_iterations,
                 erp=SimParams.erp, seed=0, actuator_model=None, wheel_imbalance=0.0, mocap=MocapModel(),
                 anchor_rest=AnchorRestParams(), tilted_solver_iterations=SimParams.tilted_solver_iterations,
                 tilt_threshold=SimParams.tilt_threshold):
        if world not in WORLDS:
            raise ConfigError("unknown world %r; known worlds: %s" % (world, ", ".join(sorted(WORLDS))))
        if not starts:
            raise ConfigError("no robots to simulate")
        names = [s.name for s in starts]
        if len(set(names)) != len(names):
            raise ConfigError("robot names must be unique, got %s" % names)
        self.params = robot_params
        self.anchor_params = anchor_params
        self.world_params = world_params or WorldParams()
        if self.world_params.stage_height < robot_params.body_height and world != "flat":
            raise ConfigError("world.stage_height (%g m) must be at least one robot height (%g m)"
                              % (self.world_params.stage_height, robot_params.body_height))
        self._anchor_geometry = None
        reach = half_width = 0.0
        if anchor_params is not None:
            self._anchor_geometry = AnchorGeometry(anchor_params)
            self._torque_map = BarbTorqueMap(anchor_params, robot_params.mouth_width, robot_params.lip_depth / 2)
            anchor_params.check_fits(robot_params)
            self._anchor_home_x = anchor_home_x(robot_params, anchor_params)
            reach, half_width = anchor_reach(robot_params, anchor_params)
        check_start_poses(starts, robot_params.body_side, reach, half_width)
        self.world_name = world
        self.dt = 1.0 / physics_rate
        self.steps = 0
        self.rng = np.random.default_rng(seed)
        self.seed = seed
        self.mocap = mocap
        self.wheel_imbalance = wheel_imbalance
        c = self._connect(gui, "puzzlebot_urdf_")
        # headless: the URDFs' visual shapes are not built (Bullet shows the collision shapes instead;
        # loading a robot takes 2.7 ms instead of 6.4, an anchor 1.6 instead of 2.0)
        self._urdf_flags = URDF_FLAGS if gui else URDF_FLAGS | pb.URDF_IGNORE_VISUAL_SHAPES
        pb.resetSimulation(physicsClientId=c)
        pb.setGravity(0, 0, -GRAVITY, physicsClientId=c)
        pb.setTimeStep(self.dt, physicsClientId=c)
        pb.setRealTimeSimulation(0, physicsClientId=c)
        pb.setPhysicsEngineParameter(numSolverIterations=solver_iterations, erp=erp, contactERP=erp,
                                     frictionERP=erp, deterministicOverlappingPairs=1, enableConeFriction=0,
                                     physicsClientId=c)
        self._solver_iterations = (solver_iterations, max(solver_iterations, tilted_solver_iterations))
        self._cos_tilt = math.cos(tilt_threshold)
        self._tilted = False
        self._monitor_steps = int(round(anchor_rest.check_period / self.dt))
        if self._monitor_steps < 1 or abs(self._monitor_steps * self.dt - anchor_rest.check_period) > 1e-9:
            raise ConfigError("anchor_rest.check_period (%g s) must be a whole number of physics steps (%g s)"
                              % (anchor_rest.check_period, self.dt))
        self.terrain = WORLDS[world](c, self.world_params)
        self.static_bodies = self.terrain.bodies
        for body in self.static_bodies:
            self._set_group(body, -1, GROUP_TERRAIN)
        self._urdf_paths = {}
        self._actuator_model = actuator_model
        self.robots = {s.name: self._spawn(s) for s in starts}      # name -> SimRobot, in start order
        self.names = names
        if anchor_params is not None and anchor_rest.enabled and not gui:
            self._rest = AnchorRest(anchor_rest, robot_params, anchor_params, self._anchor_home_x, c, self.terrain,
                                    self.robots, self._load_anchor, self._anchor_points_of, GRAVITY)
        else:
            self._rest = NoAnchorRest()
        self._roll_stop = AnchorRollStop(anchor_params.roll_limit if anchor_params is not None else 0.0, c)

    # ----------------------------------------------------------------- setup
    def _make_plant(self, name):
        """The robot's actuator plant: its own model (``ActuatorModel.for_robot``), None if it has no effect."""
        model = self._actuator_model.for_robot(name) if self._actuator_model is not None else None
        if model is None or not model.effects:
            return None
        from puzzlebot_common.effects import ActuatorPlant

        return ActuatorPlant(model)

    def _set_group(self, body, link, group):
        pb.setCollisionFilterGroupMask(body, link, group, _MASKS[group], physicsClientId=self.client)

    def _urdf(self, kind, make_text):
        """Path of this world's URDF of ``kind`` (written once; PyBullet caches files by path)."""
        path = self._urdf_paths.get(kind)
        if path is None:
            path = os.path.join(self._tmp.name, "%s.urdf" % kind)
            with open(path, "w") as f:
                f.write(make_text())
            self._urdf_paths[kind] = path
        return path

    def _spawn(self, s):
        c, p = self.client, self.params
        kind = "pilot" if s.pilot else "robot"
        path = self._urdf(kind, lambda: robot_urdf(p, name=kind, pilot=s.pilot))
        z0 = self.terrain.height(s.x, s.y)
        orn = pb.getQuaternionFromEuler([0, 0, s.yaw])
        body = pb.loadURDF(path, [s.x, s.y, z0 + p.body_centre_height + 1e-4], orn,
                           flags=self._urdf_flags, physicsClientId=c)
        joints, links = {}, {}
        for j in range(pb.getNumJoints(body, physicsClientId=c)):
            info = pb.getJointInfo(body, j, physicsClientId=c)
            joints[info[1].decode()] = j
            links[info[12].decode()] = j
        wheel_names = PILOT_WHEEL_JOINTS if s.pilot else WHEEL_JOINTS
        wheels = [joints[n] for n in wheel_names]
        # left wheels first, then right (pilot: front left, rear left, front right, rear right)
        n_left = len(wheels) // 2
        pb.changeDynamics(body, -1, lateralFriction=p.body_friction, physicsClientId=c)
        self._set_group(body, -1, GROUP_BODY)
        for j in wheels:
            pb.changeDynamics(body, j, lateralFriction=p.wheel_friction, jointDamping=p.wheel_back_emf_damping,
                              physicsClientId=c)
            self._set_group(body, j, GROUP_WHEEL)
        for name in CASTER_LINKS:
            if name in links:
                pb.changeDynamics(body, links[name], lateralFriction=0.0, spinningFriction=0.0,
                                  rollingFriction=0.0, physicsClientId=c)
                self._set_group(body, links[name], GROUP_WHEEL)
        robot = SimRobot(s.name, body, wheels, n_left, s.pilot)
        if KNOB_JOINT in joints:             # the sprung knob: a position motor whose force is the spring's
            robot.knob = joints[KNOB_JOINT]
            pb.changeDynamics(body, robot.knob, lateralFriction=p.body_friction, physicsClientId=c)
            self._set_group(body, robot.knob, GROUP_BODY)
            pb.setJointMotorControl2(body, robot.knob, pb.POSITION_CONTROL, targetPosition=0.0,
                                     force=p.knob_spring_force, physicsClientId=c)
        if self.anchor_params is not None:
            robot.anchor = self._spawn_anchor(s, z0)
        robot.plant = self._make_plant(s.name)
        return robot

    def _spawn_anchor(self, s, z0):
        p = self.params
        cy, sy = math.cos(s.yaw), math.sin(s.yaw)
        x = s.x + cy * self._anchor_home_x
        y = s.y + sy * self._anchor_home_x
        z = z0 + p.body_centre_height + p.opening_z + 1e-4
        return self._load_anchor([x, y, z], pb.getQuaternionFromEuler([0, 0, s.yaw]))

    def _load_anchor(self, position, orientation):
        c, a = self.client, self.anchor_params
        path = self._urdf("anchor", lambda: anchor_urdf(a))
        body = pb.loadURDF(path, position, orientation, flags=self._urdf_flags, physicsClientId=c)
        for link in range(-1, pb.getNumJoints(body, physicsClientId=c)):
            pb.changeDynamics(body, link, lateralFriction=a.barb_friction if link > 0 else a.friction,
                              physicsClientId=c)
            self._set_group(body, link, GROUP_ANCHOR)
        pb.changeDynamics(body, 0, lateralFriction=a.head_friction, physicsClientId=c)
        for j in range(pb.getNumJoints(body, physicsClientId=c)):
            pb.setJointMotorControl2(body, j, pb.VELOCITY_CONTROL, force=0, physicsClientId=c)
        return body

    def reset_anchor(self, name, yaw=0.0):
        """Put ``name``'s anchor back in its holder (pushed in, barbs at rest), turned by
        ``yaw`` [rad] relative to the robot (experiments: the anchor's free yaw)."""
        self._rest.release(name)
        c, robot = self.client, self.robots[name]
        body = robot.anchor
        if body is None:
            return
        rx, ry, ryaw = self.pose2d(name)
        z = self.pose(name)[0][2] + self.params.opening_z
        x = rx + math.cos(ryaw) * self._anchor_home_x
        y = ry + math.sin(ryaw) * self._anchor_home_x
        pb.resetBasePositionAndOrientation(body, [x, y, z], pb.getQuaternionFromEuler([0, 0, ryaw + yaw]),
                                           physicsClientId=c)
        pb.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=c)
        for j in range(3):
            pb.resetJointState(body, j, 0.0, 0.0, physicsClientId=c)
        robot.anchor_q = None

    # --------------------------------------------------------------- control
    def set_command(self, name, v, w):
        """Body velocity command (m/s, rad/s) from now on (through the actuator effects, if any)."""
        robot = self.robots.get(name)
        if robot is None:
            raise KeyError("unknown robot %r" % name)
        v, w = float(v), float(w)
        robot.command = (v, w)
        if robot.plant is not None:
            robot.plant.command(self.time, v, w)

    def driven_velocity(self, name):
        """The body velocity the wheels are driven at now (after the actuator effects)."""
        robot = self.robots.get(name)
        return robot.driven if robot is not None else (0.0, 0.0)

    def step(self, n=1):
        """Advance the world by ``n`` fixed steps of ``dt`` seconds."""
        for _ in range(n):
            self._apply_controls()
            pb.stepSimulation(physicsClientId=self.client)
            self.steps += 1
            if self.steps % self._monitor_steps == 0:
                self._monitor()

    def run(self, seconds):
        """Advance by ``seconds`` of simulated time (rounded to whole steps)."""
        self.step(int(round(seconds / self.dt)))

    def _apply_controls(self):
        c, p, t = self.client, self.params, self.time
        k = self.wheel_imbalance
        w_max, radius, torque = p.wheel_max_speed, p.wheel_radius, p.wheel_max_torque
        for robot in self.robots.values():
            if robot.plant is not None:
                v, w = robot.plant.advance(t, self.dt)
            else:
                v, w = robot.command
                if robot.wheel_targets is not None and robot.driven == (v, w):
                    continue                              # same command: the motors keep their setting
            robot.driven = (v, w)
            vl, vr = wheel_speeds(v, w, p.wheel_base)
            wl = max(-w_max, min(w_max, (1.0 - k) * vl / radius))
            wr = max(-w_max, min(w_max, (1.0 + k) * vr / radius))
            if (wl, wr) != robot.wheel_targets:           # Bullet keeps motor settings between steps
                robot.wheel_targets = (wl, wr)
                targets = [wl] * robot.n_left + [wr] * (len(robot.wheels) - robot.n_left)
                pb.setJointMotorControlArray(robot.body, robot.wheels, pb.VELOCITY_CONTROL,
                                             targetVelocities=targets, forces=[torque] * len(targets),
                                             physicsClientId=c)
        if self.anchor_params is not None:
            self._apply_anchor_torques()
            self._roll_stop.apply(self.robots, self._rest.frozen)
        self._rest.apply_weights()

    def _apply_anchor_torques(self):
        """Barb torque limits from the profile at the current angles (see puzzlebot_sim.anchor).

        An anchor's motors are re-set only when a joint moved by more than
        ANCHOR_UPDATE_RAD since the last setting (the limits change slowly
        with the angle); a resting anchor costs one state read per step.
        """
        c, a, tmap = self.client, self.anchor_params, self._torque_map
        joints = [0, 1, 2]
        for robot in self.robots.values():
            body = robot.anchor
            if body is None:
                continue
            states = pb.getJointStates(body, joints, physicsClientId=c)
            robot.anchor_state = states
            q = (states[0][0], states[1][0], states[2][0])
            last = robot.anchor_q
            if last is not None and max(abs(q[0] - last[0]), abs(q[1] - last[1]), abs(q[2] - last[2])) \
                    < ANCHOR_UPDATE_RAD:
                continue
            robot.anchor_q = q
            pb.setJointMotorControlArray(
                body, joints, pb.VELOCITY_CONTROL,
                targetVelocities=[-a.neck_servo_rate * q[0], -a.barb_servo_rate * q[1], -a.barb_servo_rate * q[2]],
                forces=[a.neck_max_torque, tmap.torque_at(q[1]), tmap.torque_at(q[2])], physicsClientId=c)

    @property
    def time(self):
        """Simulated time since the start [s]."""
        return self.steps * self.dt

    # ------------------------------------------------------ every check period
    def resting_anchors(self):
        """Names of the robots whose anchor is frozen at rest (see puzzlebot_sim.anchor_rest)."""
        return self._rest.resting()

    def _monitor(self):
        """Every check period: solver iterations for tilted robots, resting anchors."""
        poses = {n: self.pose(n) for n in self.names}
        tilted = any(1.0 - 2.0 * (orn[0] ** 2 + orn[1] ** 2) < self._cos_tilt for _, orn in poses.values())
        if tilted != self._tilted:
            self._tilted = tilted
            pb.setPhysicsEngineParameter(numSolverIterations=self._solver_iterations[tilted],
                                         physicsClientId=self.client)
        self._rest.update(poses, self.time)

    # ------------------------------------------------------- saved states
    def save_state(self):
        """Save the Bullet state to return to with :meth:`restore_state` (experiments: tests from one state).

        Every resting anchor is woken and resting is off from now on, so the
        set of bodies stays that of the saved state. Returns a handle for restore_state."""
        for name in self.names:
            if self._rest.frozen(name) is not None:
                self._rest.wake(name)
        self._rest = NoAnchorRest()
        return pb.saveState(physicsClientId=self.client), self.steps

    def restore_state(self, saved):
        """Return to a state of :meth:`save_state` (the bodies and the simulated time); every robot's
        command is (0, 0) and its motors are set again at the next step."""
        state_id, self.steps = saved
        pb.restoreState(state_id, physicsClientId=self.client)
        for name, robot in self.robots.items():
            robot.wheel_targets, robot.anchor_q = None, None
            self.set_command(name, 0.0, 0.0)

    def free_wheels(self, name):
        """Let ``name``'s wheels roll freely (motors off) until its command changes (experiments: a robot
        pushed or pulled along by others without resisting). Without actuator effects only."""
        robot = self.robots[name]
        if robot.plant is not None:
            raise RuntimeError("free_wheels: %s has actuator effects" % name)
        robot.driven = robot.command
        robot.wheel_targets = ("free",)
        pb.setJointMotorControlArray(robot.body, robot.wheels, pb.VELOCITY_CONTROL,
                                     targetVelocities=[0.0] * len(robot.wheels), forces=[0.0] * len(robot.wheels),
                                     physicsClientId=self.client)

    # ------------------------------------------------------------- readouts
    def pose(self, name):
        """(position xyz [m], quaternion xyzw) of the robot's base_link in the world."""
        return pb.getBasePositionAndOrientation(self.robots[name].body, physicsClientId=self.client)

    def pose2d(self, name):
        """Planar pose (x, y, yaw) of the robot [m, m, rad]."""
        pos, orn = self.pose(name)
        return (pos[0], pos[1], yaw_from_quaternion(*orn))

    def velocity(self, name):
        """Actual body velocity (v forward [m/s], w yaw rate [rad/s]) of the robot."""
        lin, ang = pb.getBaseVelocity(self.robots[name].body, physicsClientId=self.client)
        yaw = self.pose2d(name)[2]
        return (math.cos(yaw) * lin[0] + math.sin(yaw) * lin[1], ang[2])

    def anchor_pose(self, name):
        """(position xyz, quaternion xyzw) of the robot's anchor base, or None without anchors."""
        frozen = self._rest.frozen(name)
        if frozen is not None:
            return pb.multiplyTransforms(*self.pose(name), *frozen.base, physicsClientId=self.client)
        body = self.robots[name].anchor
        if body is None:
            return None
        return pb.getBasePositionAndOrientation(body, physicsClientId=self.client)

    def anchor_pose_in_base(self, name):
        """(position xyz, quaternion xyzw) of the robot's anchor base in its base_link, or None without
        anchors (the sim node's tf <robot>/base_link -> <robot>/anchor)."""
        frozen = self._rest.frozen(name)
        return frozen.base if frozen is not None else self.anchor_in_robot(name)

    def anchor_pose2d(self, name):
        pose = self.anchor_pose(name)
        if pose is None:
            return None
        pos, orn = pose
        return (pos[0], pos[1], yaw_from_quaternion(*orn))

    def wheel_angles(self, name):
        """Wheel joint angles [rad] of the robot, in urdf.WHEEL_JOINTS order (pilots: PILOT_WHEEL_JOINTS)."""
        robot = self.robots[name]
        return tuple(s[0] for s in pb.getJointStates(robot.body, robot.wheels, physicsClientId=self.client))

    def anchor_joints(self, name):
        """(neck, left barb, right barb) joint angles [rad]; barb 0 = rest, > 0 flared, < 0 folded."""
        frozen = self._rest.frozen(name)
        if frozen is not None:
            return frozen.q
        body = self.robots[name].anchor
        states = pb.getJointStates(body, [0, 1, 2], physicsClientId=self.client)
        return tuple(s[0] for s in states)

    def anchor_points(self, name):
        """World positions of the anchor's head tip and its two barb tips (centres)."""
        frozen = self._rest.frozen(name)
        if frozen is not None:
            pos, orn = self.pose(name)
            world = [pb.multiplyTransforms(pos, orn, q, [0, 0, 0, 1], physicsClientId=self.client)[0]
                     for q in frozen.points]
            return world[0], world[1:]
        return self._anchor_points_of(self.robots[name].anchor)

    def _anchor_points_of(self, body):
        a = self.anchor_params
        states = pb.getLinkStates(body, [0, 1, 2], physicsClientId=self.client)
        head_pos, head_orn = states[0][4], states[0][5]
        head_tip = pb.multiplyTransforms(head_pos, head_orn, [-(a.length - a.neck_x), 0, 0], [0, 0, 0, 1],
                                         physicsClientId=self.client)[0]
        tips = [pb.multiplyTransforms(st[4], st[5], [a.barb_length, 0, 0], [0, 0, 0, 1],
                                      physicsClientId=self.client)[0] for st in states[1:]]
        return head_tip, tips

    def physical_pairs(self, include_decoupled=False):
        """Anchor-opening pairs read off the simulated bodies (see puzzlebot_sim.coupling).

        Returns PhysicalPair(anchor_robot, opening_robot, status, reason) for every
        anchor whose head is in another robot's opening (sorted by names);
        with ``include_decoupled`` also the near pairs that are not.
        """
        if self.anchor_params is None:
            return []
        c, p = self.client, self.params
        reach = p.body_side * 1.5 + self.anchor_params.length
        tip_radius = self.anchor_params.barb_tip_radius
        poses = {n: self.pose(n) for n in self.names}
        out = []
        for a_name in self.names:
            pa = poses[a_name][0]
            points = None
            for o_name in self.names:
                if o_name == a_name:
                    continue
                po, oo = poses[o_name]
                if (pa[0] - po[0]) ** 2 + (pa[1] - po[1]) ** 2 + (pa[2] - po[2]) ** 2 > reach * reach:
                    continue
                if points is None:
                    head, tips = self.anchor_points(a_name)
                    points = [head] + tips
                inv_pos, inv_orn = pb.invertTransform(po, oo, physicsClientId=c)
                local = [pb.multiplyTransforms(inv_pos, inv_orn, q, [0, 0, 0, 1], physicsClientId=c)[0]
                         for q in points]
                status = coupling.classify(local[0], local[1:], p, tip_radius=tip_radius)
                if status != coupling.DECOUPLED or include_decoupled:
                    reason = coupling.unseated_reason(local[0], local[1:], p, tip_radius=tip_radius) \
                        if status == coupling.HEAD_ALIGNED else ""
                    out.append(coupling.PhysicalPair(a_name, o_name, status, reason=reason))
        return sorted(out, key=lambda q: (q.anchor_robot, q.opening_robot))

    def all_physical_pairs(self):
        """Anchor pairs (physical_pairs) followed by knob-hole pairs (physical_knob_pairs)."""
        return self.physical_pairs() + self.physical_knob_pairs()

    def anchor_in_robot(self, name):
        """(position xyz [m], quaternion xyzw) of ``name``'s anchor base in the robot's base_link, or None
        without an anchor."""
        anchor = self.anchor_pose(name)
        if anchor is None:
            return None
        inv = pb.invertTransform(*self.pose(name), physicsClientId=self.client)
        return pb.multiplyTransforms(*inv, *anchor, physicsClientId=self.client)

    def anchor_pullout(self, name):
        """How far [m] ``name``'s anchor base is out of its pushed-in position, along the robot's x
        axis (3-D: valid while the robot is tilted); None without an anchor."""
        local = self.anchor_in_robot(name)
        return None if local is None else self._anchor_home_x - local[0][0]

    def knob_depression(self, name):
        """How far [m] ``name``'s knob is pressed into its side (0: out, or a rigid knob)."""
        robot = self.robots[name]
        if robot.knob is None:
            return 0.0
        return max(0.0, -pb.getJointState(robot.body, robot.knob, physicsClientId=self.client)[0])

    def physical_knob_pairs(self):
        """Knob-hole pairs read off the robots' poses (puzzlebot_sim.coupling.classify_knob).

        Returns PhysicalPair(knob robot, hole robot, status, knob=True, reason) for
        every knob at least partly in a neighbour's side hole (sorted by names).
        """
        c, p = self.client, self.params
        poses = {n: self.pose(n) for n in self.names}
        inverse = {n: pb.invertTransform(*poses[n], physicsClientId=c) for n in self.names}
        out = []
        for k_name in self.names:
            knob = pb.multiplyTransforms(*poses[k_name], [0.0, p.body_side / 2.0, p.knob_z], [0, 0, 0, 1],
                                         physicsClientId=c)[0]
            for h_name in self.names:
                if h_name == k_name:
                    continue
                local = pb.multiplyTransforms(*inverse[h_name], knob, [0, 0, 0, 1], physicsClientId=c)[0]
                if coupling.classify_knob(local, p) == coupling.DECOUPLED:
                    continue
                pressed = self.knob_depression(k_name)
                out.append(coupling.PhysicalPair(k_name, h_name, coupling.classify_knob(local, p, depression=pressed),
                                                 knob=True, reason=coupling.knob_reason(local, p, depression=pressed)))
        return sorted(out, key=lambda q: (q.anchor_robot, q.opening_robot))

    def measure(self, name):
        """Mocap measurement of the robot: (position xyz, quaternion xyzw), or None if dropped.

        Applies ``mocap`` (puzzlebot_sim.mocap.MocapModel: noise, dropout, heading offset)
        and the actuator model's heading offset; draws from this world's seeded RNG.
        """
        plant = self.robots[name].plant
        return self.mocap.measure(self.pose(name), self.rng, self.client, plant.offset if plant is not None else 0.0)

    # ------------------------------------------------------------ lifecycle
    @classmethod
    def from_params(cls, sim, robot_params, starts, anchor_params=AnchorParams(), world_params=None,
                    actuator_model=None, gui=None, anchor_rest=AnchorRestParams()):
        """A world configured from the sim node's parameter sets (SimParams, ...)."""
        return cls(robot_params, starts, world=sim.world, physics_rate=sim.physics_rate,
                   gui=sim.gui if gui is None else gui,
                   anchor_params=anchor_params if sim.anchors else None, world_params=world_params,
                   solver_iterations=sim.solver_iterations, erp=sim.erp, seed=sim.seed,
                   actuator_model=actuator_model, wheel_imbalance=sim.wheel_imbalance,
                   mocap=MocapModel.from_sim(sim), anchor_rest=anchor_rest,
                   tilted_solver_iterations=sim.tilted_solver_iterations, tilt_threshold=sim.tilt_threshold)


