"""Room to back off: how far a robot or an assembly can drive straight ahead or back before it comes to
another robot (the poses' robots). The MPC keeps no robots apart, so a knob pair's mover that backs off
checks (behaviors/couple.py, Couple.make_room)."""

import math


def clear_run(pose, others, ahead, reach, width):
    """How far [m] a robot at ``pose`` (x, y, theta) [m, rad, world] can drive straight ahead (``ahead``) or
    back before it comes to another robot: ``others`` are (x, y) centres [m, world]; one whose centre is
    less than ``width`` [m] off the line of travel stands in the way at its distance along it less
    ``reach`` [m] (the robot's own length that way from its centre plus the other's size). inf when nothing
    is in the way; negative when one is nearer than ``reach`` already."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    sign = 1.0 if ahead else -1.0
    run = math.inf
    for x, y in others:
        dx, dy = x - pose[0], y - pose[1]
        along, across = sign * (c * dx + s * dy), -s * dx + c * dy
        if along > 0.0 and abs(across) < width:
            run = min(run, along - reach)
    return run


def assembly_room(poses, members, ahead, geometry, exclude=()):
    """The least :func:`clear_run` [m] of the robots ``members`` (an assembly moving as one body) driving
    ahead (``ahead``) or back, past every other robot with a pose but those in ``exclude``: a robot reaches
    half its body forwards and its anchor's length further backwards, the others their footprint's
    circumradius (``geometry``: RobotGeometry). 0 when no member has a pose."""
    size, half = geometry.footprint_radius(), geometry.body_side / 2.0
    skip = set(members) | set(exclude)
    others = [p[:2] for n, p in poses.items() if p is not None and n not in skip]
    reach = half + size + (0.0 if ahead else geometry.anchor_length)
    runs = [clear_run(poses[m], others, ahead, reach, half + size) for m in members if poses.get(m) is not None]
    return min(runs) if runs else 0.0
