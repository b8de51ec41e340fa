"""The anchor's play in its holder, measured in Bullet, beside the paper's figures.

The paper gives the holder's limits on the hardware: the anchor yaws freely
within about +/-0.5 rad, travels within 5 mm along x, moves < 0.5 mm along y
and pitches < 0.1 rad. The model's holder is a pocket with a retaining wall
(RobotParams ``holder_*``) around a ball-and-collar base (AnchorParams), and
its play comes out of the contacts, so it is measured here the way one would
measure it on a robot: one robot standing on the floor, small loads on its
anchor, the anchor base's pose read in the robot's ``base_link`` frame once
it has settled.

Each measurement runs in its own Bullet world (DIRECT), with resting anchors
never frozen. Loads are applied in the world frame with the robot facing +x,
so +x is the robot's forward (pushing the anchor into its holder) and -x
pulls it out toward the holder's stop.
"""

from dataclasses import asdict, dataclass
from typing import Tuple

import pybullet as pb

from puzzlebot_sim.params import AnchorParams, AnchorRestParams, RobotParams, SimParams
from puzzlebot_sim.world import RobotStart, SimWorld

# the paper's holder (facts.md, "anchor freedom in its holder"): rad, m, m, rad
PAPER = {"yaw": 0.5, "x_travel": 0.005, "y_play": 0.0005, "pitch": 0.1}


@dataclass(frozen=True)
class HolderLoads:
    """The loads of the measurement, and how long it lasts.

    ``seat_force`` [N] pushes the anchor base in (+x) or pulls it out (-x);
    ``yaw_torque`` [N m] turns it about z while pulled out or pushed in;
    ``side_force`` [N] pushes it along y while pulled out; ``pitch_pull`` [N]
    and ``head_force`` [N] act on the head tip, out along -x and up or down
    along z. Each load is applied once after each of the ``starts`` [s] of
    unloaded settling (the base sticks by friction wherever the contacts
    leave it, so one reading is not the play: the pitch under the same load
    lands anywhere in 0.2-0.29 rad); the pose is read ``settle_time`` [s]
    after the load starts, averaged over ``average_time`` [s]. The defaults
    are small against the robot's 0.5 N push, so they show the play, not
    what the holder gives under a fall.
    """
    seat_force: float = 0.02
    yaw_torque: float = 3e-4
    side_force: float = 0.05
    pitch_pull: float = 0.1
    head_force: float = 0.2
    starts: Tuple[float, ...] = (0.0, 0.05, 0.1, 0.15, 0.2)
    settle_time: float = 2.0
    average_time: float = 1.0


@dataclass(frozen=True)
class HolderPlay:
    """The anchor base's play in its holder, in the robot's frame: the extremes over the starts.

    ``x_in`` / ``x_out`` [m]: base centre along x, pushed in (largest) /
    pulled out (smallest), ``x_travel`` their difference; ``y_play`` [m]: the
    spread of the base's y under +/-``side_force``, pulled out; ``yaw_out`` /
    ``yaw_in`` [rad]: (clockwise, anticlockwise) extreme yaw under
    -/+``yaw_torque``, pulled out / pushed in; ``pitch_up`` / ``pitch_down``
    [rad]: extreme pitch, pulled out, with the head pushed up (positive) /
    down (negative); ``pitch_spread`` [rad]: the widest range of pitch over
    the starts under one load.
    """
    x_in: float
    x_out: float
    y_play: float
    yaw_out: Tuple[float, float]
    yaw_in: Tuple[float, float]
    pitch_up: float
    pitch_down: float
    pitch_spread: float

    @property
    def x_travel(self):
        return self.x_in - self.x_out

    def rows(self):
        """(quantity, model, paper) rows for a table, in mm and rad."""
        return [
            ("x travel [mm]", "%.2f" % (1e3 * self.x_travel), "within %g" % (1e3 * PAPER["x_travel"])),
            ("y play, pulled out [mm]", "%.2f" % (1e3 * self.y_play), "< %g" % (1e3 * PAPER["y_play"])),
            ("yaw, pulled out [rad]", "%+.2f / %+.2f" % self.yaw_out, "about +/-%g" % PAPER["yaw"]),
            ("yaw, pushed in [rad]", "%+.2f / %+.2f" % self.yaw_in, "-"),
            ("pitch, head up / down [rad]", "%+.2f / %+.2f" % (self.pitch_up, self.pitch_down),
             "< %g" % PAPER["pitch"]),
            ("pitch spread under one load [rad]", "%.2f" % self.pitch_spread, "-"),
        ]

    def as_dict(self):
        d = asdict(self)
        d["x_travel"] = self.x_travel
        return d


def _pose6(world):
    """Robot "a"'s anchor base in its base_link: (x, y, z) [m], (roll, pitch, yaw) [rad]."""
    position, orientation = world.anchor_in_robot("a")
    return tuple(position) + tuple(pb.getEulerFromQuaternion(orientation, physicsClientId=world.client))


def _settled(robot, anchor, loads, physics_rate, push):
    """Mean poses of the anchor in its robot (_pose6), one per start, while ``push(world)`` loads it."""
    settle = int(round(loads.settle_time * physics_rate))
    average = max(1, int(round(loads.average_time * physics_rate)))
    poses = []
    for start in loads.starts:
        with SimWorld(robot, [RobotStart("a", 0.0, 0.0, 0.0)], physics_rate=physics_rate, anchor_params=anchor,
                      anchor_rest=AnchorRestParams(enabled=False)) as world:
            world.run(start)
            total = [0.0] * 6
            for k in range(settle + average):
                push(world)
                world.step(1)
                if k >= settle:
                    total = [t + v for t, v in zip(total, _pose6(world))]
            poses.append([t / average for t in total])
    return poses


def _on_base(force, torque=(0.0, 0.0, 0.0)):
    def push(world):
        body, c = world.robots["a"].anchor, world.client
        pb.applyExternalForce(body, -1, force, world.anchor_pose("a")[0], pb.WORLD_FRAME, physicsClientId=c)
        if any(torque):
            pb.applyExternalTorque(body, -1, torque, pb.WORLD_FRAME, physicsClientId=c)
    return push


def _on_head(force):
    def push(world):
        head = world.anchor_points("a")[0]
        pb.applyExternalForce(world.robots["a"].anchor, 0, force, head, pb.WORLD_FRAME,
                              physicsClientId=world.client)
    return push


def holder_yaw(robot, anchor, pulled_out, sign, loads=HolderLoads(), physics_rate=SimParams.physics_rate):
    """Yaws [rad] of the anchor base relative to its robot under ``sign`` x ``yaw_torque``, one per start."""
    f = -loads.seat_force if pulled_out else loads.seat_force
    push = _on_base([f, 0, 0], [0, 0, sign * loads.yaw_torque])
    return [pose[5] for pose in _settled(robot, anchor, loads, physics_rate, push)]


def holder_pitch(robot, anchor, head_up, loads=HolderLoads(), physics_rate=SimParams.physics_rate):
    """Pitches [rad] of the anchor base relative to its robot, pulled out, the head pushed up or down,
    one per start."""
    fz = loads.head_force if head_up else -loads.head_force
    return [pose[4] for pose in _settled(robot, anchor, loads, physics_rate, _on_head([-loads.pitch_pull, 0, fz]))]


def measure_holder_play(robot=RobotParams(), anchor=AnchorParams(), loads=HolderLoads(),
                        physics_rate=SimParams.physics_rate, progress=None):
    """HolderPlay of ``anchor`` in ``robot``'s holder (ten loads, each after every start).

    ``progress``: optional callable taking a short text, called before each load.
    """
    anchor.check_fits(robot)
    say = progress or (lambda text: None)

    def base(label, force, axis):
        say(label)
        return [pose[axis] for pose in _settled(robot, anchor, loads, physics_rate, _on_base(force))]

    x_in = max(base("pushed in", [loads.seat_force, 0, 0], 0))
    x_out = min(base("pulled out", [-loads.seat_force, 0, 0], 0))
    y_plus = base("pushed along +y", [-loads.seat_force, loads.side_force, 0], 1)
    y_minus = base("pushed along -y", [-loads.seat_force, -loads.side_force, 0], 1)
    yaws = {}
    for out in (True, False):
        say("yaw, %s" % ("pulled out" if out else "pushed in"))
        yaws[out] = (min(holder_yaw(robot, anchor, out, -1, loads, physics_rate)),
                     max(holder_yaw(robot, anchor, out, 1, loads, physics_rate)))
    say("pitch")
    up, down = (holder_pitch(robot, anchor, h, loads, physics_rate) for h in (True, False))
    return HolderPlay(x_in=x_in, x_out=x_out, y_play=max(y_plus) - min(y_minus), yaw_out=yaws[True],
                      yaw_in=yaws[False], pitch_up=max(up), pitch_down=min(down),
                      pitch_spread=max(max(up) - min(up), max(down) - min(down)))
