"""How far two coupled robots fold concave, measured in Bullet.

At the foot of the step the chain must fold concave: the robot coming down
slopes up from the robot already on the floor, and the two close towards
each other over the coupling. In the model, that fold stops where the
bodies' top edges meet or where the anchor stops pitching in its holder.
Beyond that point the top corners become a fulcrum that levers the anchor
out (notes/sim-trials.md, "Why the chain is a beam"). How far the real robots fold
is not in the sources, so it is one of the things to measure on them
(docs/lab-measurements.md, item 3).

The measurement copies the bench test. Two robots are coupled on the floor:
``a``'s anchor is in the opening of ``o`` behind it. The coupling is pressed
down (``press_force`` on each robot's inner bottom edge), and the two outer
top edges are lifted (``lift_force`` on each) until the fold stops. Both
forces ramp up together, then hold. The fold is ``o``'s pitch minus ``a``'s
[rad], positive when concave (the tops closing), averaged over the hold.
"""

from dataclasses import dataclass
from typing import Optional

import pybullet as pb

from puzzlebot_sim.coupling import HEAD_INSERTED
from puzzlebot_sim.params import AnchorParams, AnchorRestParams, RobotParams, SimParams
from puzzlebot_experiments.trials import mated_pair
from puzzlebot_sim.world import SimWorld


@dataclass(frozen=True)
class FoldLoads:
    """The loads of the bench test [N, s].

    ``lift_force`` up on each outer top edge and ``press_force`` down on each
    inner bottom edge ramp up together over ``ramp_time``, then hold for
    ``hold_time``: the fold is averaged over the hold. A robot weighs 0.67 N,
    so about 0.33 N lifts its far end; 0.6 N lifts it well clear, so the fold
    is stopped by the bodies and the anchor, not by gravity. Then, in a
    second run, the lift ramps on to ``max_lift`` over ``break_time`` with the
    same press, to find the lift that levers the anchor out of the opening.
    """
    lift_force: float = 0.6
    press_force: float = 1.0
    ramp_time: float = 4.8
    hold_time: float = 1.2
    max_lift: float = 2.0
    break_time: float = 8.0


@dataclass(frozen=True)
class Fold:
    """``fold`` [rad]: the concave fold held under ``lift_force``; ``anchor_pitch`` [rad]: ``a``'s anchor
    base in its holder then (positive: head up); ``coupled``: the anchor still seated in the opening at
    the end of the hold; ``separation_lift`` [N]: the lift at which the anchor left the opening in the
    ramp to ``max_lift`` (None: it held), and ``separation_fold`` [rad] the fold just before."""
    fold: float
    anchor_pitch: float
    coupled: bool
    separation_lift: Optional[float]
    separation_fold: Optional[float]


def _pitch(pose):
    return pb.getEulerFromQuaternion(pose[1])[1]


def _coupled(w):
    return any(p.anchor_robot == "a" and p.status == HEAD_INSERTED for p in w.physical_pairs())


def _bench(robot, anchor, physics_rate, press_at, lift_at, seconds, watch):
    """Run the bench test for ``seconds``: ``press_at(t)`` and ``lift_at(t)`` [N] at time t [s] from the
    start of the loads; ``watch(world, t, lift)`` after each step, True to stop."""
    half_x, half_z = robot.body_side / 2.0, robot.body_height / 2.0
    # (robot, x of its outer edge in its frame): a's front and o's back are lifted, the inner edges pressed
    ends = (("a", half_x), ("o", -half_x))
    with SimWorld(robot, mated_pair(robot), physics_rate=physics_rate, anchor_params=anchor,
                  anchor_rest=AnchorRestParams(enabled=False)) as w:
        w.run(0.3)
        c = w.client
        for k in range(int(round(seconds * physics_rate))):
            t = k / float(physics_rate)
            lift = lift_at(t)
            for name, x in ends:
                body, (position, orientation) = w.robots[name].body, w.pose(name)
                for point, force in (([x, 0.0, half_z], lift), ([-x, 0.0, -half_z], -press_at(t))):
                    at = pb.multiplyTransforms(position, orientation, point, [0, 0, 0, 1], physicsClientId=c)[0]
                    pb.applyExternalForce(body, -1, [0.0, 0.0, force], at, pb.WORLD_FRAME, physicsClientId=c)
            w.step(1)
            if watch(w, t, lift):
                return


def _fold(w):
    return _pitch(w.pose("o")) - _pitch(w.pose("a"))


def measure_concave_fold(robot=RobotParams(), anchor=AnchorParams(), loads=FoldLoads(),
                         physics_rate=SimParams.physics_rate):
    """Fold of a coupled pair of ``robot`` (with ``anchor``) under ``loads``; see the module's docstring."""
    anchor.check_fits(robot)
    held = {"fold": [], "pitch": [], "coupled": False}

    def share(t):
        return min(1.0, t / loads.ramp_time)

    def hold(w, t, lift):
        if t >= loads.ramp_time:
            held["fold"].append(_fold(w))
            held["pitch"].append(_pitch(w.anchor_in_robot("a")))
            held["coupled"] = _coupled(w)
        return False

    _bench(robot, anchor, physics_rate, lambda t: share(t) * loads.press_force,
           lambda t: share(t) * loads.lift_force, loads.ramp_time + loads.hold_time, hold)
    broke = {"lift": None, "fold": None, "last": 0.0}

    def ramp(w, t, lift):
        if not _coupled(w):
            broke["lift"], broke["fold"] = lift, broke["last"]
            return True
        broke["last"] = _fold(w)
        return False

    _bench(robot, anchor, physics_rate, lambda t: share(t) * loads.press_force,
           lambda t: loads.max_lift * min(1.0, t / loads.break_time), loads.break_time, ramp)
    n = len(held["fold"])
    return Fold(fold=sum(held["fold"]) / n, anchor_pitch=sum(held["pitch"]) / n, coupled=held["coupled"],
                separation_lift=broke["lift"], separation_fold=broke["fold"])
