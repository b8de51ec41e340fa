"""Does a coupled pair hold one robot's pull? The test behind Bullet's "seated" (docs/results.md, section 6).

The facts' definition of a coupled anchor: a robot cannot pull it out
directly (a robot pushes about 0.5 N, a seated anchor holds 0.6 N at 4 mm).
:func:`pull_pairs` puts that to every anchor pair of an assembly, one at a
time, from one saved Bullet state: one robot of the pair drives away from
the other at ``speed`` for ``seconds`` while its partner holds (commanded
zero) and every other robot's wheels roll freely, so the pair carries one
robot's pull and the rest of the assembly only rolls along. Both
directions: the anchor robot forwards, then the opening robot backwards.
The pair *holds* when Bullet still has the anchor in the opening at the end
(seated, or stalled on a barb: ``HEAD_ALIGNED``).

The world is restored to the saved state after each pull and at the end;
resting anchors are off from the first save on (SimWorld.save_state).
Units: m, s, mm in the records.
"""

import math

from puzzlebot_sim.coupling import DECOUPLED, STATUS_NAMES

#: m/s: the pulling robot's command (the anchor trials' pull-out speed: anchor_trials pullout)
PULL_SPEED = 0.05
#: s: how long it pulls (a held pair has stalled well before)
PULL_SECONDS = 5.0
#: the two pulls of a pair: which robot drives, and its direction (+1 forwards)
PULLS = (("anchor", 1.0), ("opening", -1.0))


def _pair_record(world, anchor_robot, opening_robot):
    """Bullet's view of one anchor pair now: (status, why not seated: "" if seated or not in the opening)."""
    for p in world.physical_pairs(include_decoupled=True):
        if (p.anchor_robot, p.opening_robot) == (anchor_robot, opening_robot):
            return p.status, p.reason
    return DECOUPLED, ""


def _gap(world, anchor_robot, opening_robot):
    """Distance between the anchor robot's and the opening robot's centres [m]."""
    pa, po = world.pose2d(anchor_robot), world.pose2d(opening_robot)
    return math.hypot(pa[0] - po[0], pa[1] - po[1])


def pull_pairs(world, pairs, speed=PULL_SPEED, seconds=PULL_SECONDS):
    """Pull every (anchor robot, opening robot) in ``pairs`` apart, one robot at a time (module docstring).

    Returns one dict per pair: ``pair`` ("A-B"), ``before`` (Bullet's status name before), ``reason`` (why
    not seated, "" if seated), and per pull ("anchor", "opening"): ``held`` (bool) and ``stretch_mm`` (how
    far the robots' centres moved apart)."""
    state = world.save_state()
    out = []
    try:
        for a, o in pairs:
            world.restore_state(state)
            status, reason = _pair_record(world, a, o)
            rec = {"pair": "%s-%s" % (a, o), "before": STATUS_NAMES[status], "reason": reason}
            for driver, sign in PULLS:
                world.restore_state(state)
                d0 = _gap(world, a, o)
                mover = a if driver == "anchor" else o
                world.set_command(mover, sign * speed, 0.0)
                world.step(1)
                for name in world.names:
                    if name not in (a, o):
                        world.free_wheels(name)
                world.run(seconds)
                after = _pair_record(world, a, o)[0]
                rec[driver] = {"held": after != DECOUPLED, "stretch_mm": round(1e3 * (_gap(world, a, o) - d0), 1)}
            out.append(rec)
    finally:
        world.restore_state(state)
    return out
