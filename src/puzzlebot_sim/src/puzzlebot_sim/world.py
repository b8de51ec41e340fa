"""A Bullet world with PuzzleBots, stepped at a fixed rate.

Every PyBullet call passes this world's physics client id, so several worlds
can live in one process (parallel trials). The world never sleeps or reads
the wall clock: pacing belongs to the caller.

Units: metres, seconds, radians; poses in the ``world`` frame.
"""

import math
import os
import tempfile
from dataclasses import dataclass

import numpy as np
import pybullet as pb
import pybullet_data

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.kinematics import wheel_speeds
from puzzlebot_sim.urdf import CASTER_LINKS, WHEEL_JOINTS, robot_urdf


@dataclass
class RobotStart:
    name: str
    x: float
    y: float
    yaw: float
    pilot: bool = False


def _flat(client, urdf_dir):
    plane = pb.loadURDF(os.path.join(pybullet_data.getDataPath(), "plane.urdf"), physicsClientId=client)
    pb.changeDynamics(plane, -1, lateralFriction=1.0, physicsClientId=client)
    return [plane]


#: World builders by name; each returns the static body ids it created.
WORLDS = {"flat": _flat}


def check_start_poses(starts, body_side):
    """Raise ConfigError if two robots' square bodies would overlap at start."""
    for a in range(len(starts)):
        for b in range(a + 1, len(starts)):
            p, q = starts[a], starts[b]
            if _squares_overlap((p.x, p.y, p.yaw), (q.x, q.y, q.yaw), body_side):
                raise ConfigError("robots %s and %s are placed inside each other: centres %.1f mm apart, "
                                  "bodies are %.0f mm wide" % (p.name, q.name,
                                                               1e3 * math.hypot(p.x - q.x, p.y - q.y),
                                                               1e3 * body_side))


def _squares_overlap(pa, pb_, side):
    """Separating-axis test of two squares of side ``side`` at planar poses."""
    def corners(pose):
        h = side / 2.0
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return np.array([[pose[0] + c * x - s * y, pose[1] + s * x + c * y]
                         for x, y in ((-h, -h), (h, -h), (h, h), (-h, h))])

    ca, cb = corners(pa), corners(pb_)
    for pose in (pa, pb_):
        for ang in (pose[2], pose[2] + math.pi / 2):
            axis = np.array([math.cos(ang), math.sin(ang)])
            a, b = ca @ axis, cb @ axis
            if a.max() <= b.min() + 1e-9 or b.max() <= a.min() + 1e-9:
                return False
    return True


class SimWorld:
    """PuzzleBots in a Bullet world. Commands are body velocities (v, w)."""

    def __init__(self, robot_params, starts, world="flat", physics_rate=400, gui=False):
        if world not in WORLDS:
            raise ConfigError("unknown world %r; known worlds: %s" % (world, ", ".join(sorted(WORLDS))))
        if not starts:
            raise ConfigError("no robots to simulate")
        names = [s.name for s in starts]
        if len(set(names)) != len(names):
            raise ConfigError("robot names must be unique, got %s" % names)
        check_start_poses(starts, robot_params.body_side)
        self.params = robot_params
        self.dt = 1.0 / physics_rate
        self.steps = 0
        self.client = pb.connect(pb.GUI if gui else pb.DIRECT)
        c = self.client
        pb.resetSimulation(physicsClientId=c)
        pb.setGravity(0, 0, -9.81, physicsClientId=c)
        pb.setTimeStep(self.dt, physicsClientId=c)
        pb.setRealTimeSimulation(0, physicsClientId=c)
        self._tmp = tempfile.TemporaryDirectory(prefix="puzzlebot_urdf_")
        self.static_bodies = WORLDS[world](c, self._tmp.name)
        self.robots = {}
        self._cmd = {}
        for s in starts:
            self.robots[s.name] = self._spawn(s)
            self._cmd[s.name] = (0.0, 0.0)

    # ----------------------------------------------------------------- setup
    def _spawn(self, s):
        c, p = self.client, self.params
        path = os.path.join(self._tmp.name, "%s.urdf" % s.name)
        with open(path, "w") as f:
            f.write(robot_urdf(p, name=s.name, pilot=s.pilot))
        body = pb.loadURDF(path, [s.x, s.y, p.body_centre_height + 1e-4],
                           pb.getQuaternionFromEuler([0, 0, s.yaw]), physicsClientId=c)
        joints = {}
        links = {}
        for j in range(pb.getNumJoints(body, physicsClientId=c)):
            info = pb.getJointInfo(body, j, physicsClientId=c)
            joints[info[1].decode()] = j
            links[info[12].decode()] = j
        wheels = [joints[n] for n in WHEEL_JOINTS]
        for j in wheels:
            pb.changeDynamics(body, j, lateralFriction=p.wheel_friction, physicsClientId=c)
        for name in CASTER_LINKS:
            pb.changeDynamics(body, links[name], lateralFriction=0.0, spinningFriction=0.0,
                              rollingFriction=0.0, physicsClientId=c)
        return {"body": body, "wheels": wheels}

    # --------------------------------------------------------------- control
    def set_command(self, name, v, w):
        """Body velocity command (m/s, rad/s) applied from the next step on."""
        if name not in self._cmd:
            raise KeyError("unknown robot %r" % name)
        self._cmd[name] = (float(v), float(w))

    def step(self):
        """Advance the world by one fixed step of ``dt`` seconds."""
        c, p = self.client, self.params
        for name, robot in self.robots.items():
            v, w = self._cmd[name]
            vl, vr = wheel_speeds(v, w, p.wheel_base)
            for joint, rim in zip(robot["wheels"], (vl, vr)):
                omega = max(-p.wheel_max_speed, min(p.wheel_max_speed, rim / p.wheel_radius))
                pb.setJointMotorControl2(robot["body"], joint, pb.VELOCITY_CONTROL, targetVelocity=omega,
                                         force=p.wheel_max_torque, physicsClientId=c)
        pb.stepSimulation(physicsClientId=c)
        self.steps += 1

    @property
    def time(self):
        """Simulated time since the start [s]."""
        return self.steps * self.dt

    # ------------------------------------------------------------- readouts
    def pose(self, name):
        """(position xyz [m], quaternion xyzw) of the robot's base_link in the world."""
        pos, orn = pb.getBasePositionAndOrientation(self.robots[name]["body"], physicsClientId=self.client)
        return pos, orn

    def pose2d(self, name):
        """Planar pose (x, y, yaw) of the robot [m, m, rad]."""
        pos, orn = self.pose(name)
        yaw = pb.getEulerFromQuaternion(orn, physicsClientId=self.client)[2]
        return (pos[0], pos[1], yaw)

    def close(self):
        if self.client is not None and pb.isConnected(physicsClientId=self.client):
            pb.disconnect(physicsClientId=self.client)
        self.client = None
        self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
