"""Seeded anchor experiments and the speed benchmark, ROS-free.

Each trial builds its own :class:`SimWorld`, drives it with scripted body
velocities and reads the physical coupling off the simulated anchor (see
puzzlebot_sim.coupling); it returns a plain dict, so trials can run in
parallel processes and the scripts only print them. The seed decides the
small start perturbations listed with each trial; the physics itself is
deterministic.

Robot names: ``a`` carries the anchor that goes into the front opening of
``o`` (``o`` behind ``a``, both facing +x); chains are ``r1`` (front) .. ``rN``.
"""

import math
import time
from dataclasses import replace

import numpy as np
import pybullet as pb

from puzzlebot_sim.coupling import DECOUPLED, HEAD_INSERTED
from puzzlebot_sim.params import AnchorParams, AnchorRestParams, RobotParams, SimParams, WorldParams
from puzzlebot_sim.world import GRAVITY, RobotStart, SimWorld

#: Period of the scripted (open-loop) drivers of these trials [s]: how often they read the world and
#: set commands. Not the MPC's period (MPCSettings.dt), which the closed-loop trials use.
SCRIPT_DT = 0.05
#: Gap left between mated robots at a coupled start [m] (start-pose tolerance is 1 mm).
MATE_GAP = 0.0003
#: edge_lock_trial(stop="edge"): the back robot stops with its front this far from the edge [m].
EDGE_STOP = 0.004
#: chain_step_trial: the first robot starts with its leading face this far from the edge [m] ...
CHAIN_START_GAP = 0.005
#: ... plus, backing off, the free anchor sticking out of its back [m].
ANCHOR_OUT = 0.018
#: A robot counts as tipped over a stage edge beyond this pitch [rad] (edge lock, lock load).
EDGE_TIP_ANGLE = 0.15
#: A robot counts as upright on the floor within these tolerances [m, rad].
UPRIGHT_HEIGHT_TOLERANCE = 0.01
UPRIGHT_TILT = 0.3


def _world(starts, sim, robot, anchor, world="flat", world_params=None, anchor_rest=AnchorRestParams()):
    return SimWorld(robot, starts, world=world, physics_rate=sim.physics_rate, anchor_params=anchor,
                    world_params=world_params, solver_iterations=sim.solver_iterations, erp=sim.erp, seed=sim.seed,
                    anchor_rest=anchor_rest, tilted_solver_iterations=sim.tilted_solver_iterations,
                    tilt_threshold=sim.tilt_threshold)


def _status(w, anchor_robot, opening_robot):
    for p in w.physical_pairs():
        if p.anchor_robot == anchor_robot and p.opening_robot == opening_robot:
            return p.status
    return DECOUPLED


def mated_pair(robot, dy=0.0, dyaw=0.0):
    """Starts for a coupled pair: ``a`` at the origin facing +x, ``o`` right behind it with its opening
    on ``a``'s anchor, offset by ``dy`` [m] and ``dyaw`` [rad]."""
    return [RobotStart("a", 0.0, 0.0, 0.0), RobotStart("o", -(robot.body_side + MATE_GAP), dy, dyaw)]


def _mated_pair(rng, robot, lateral=0.0003, yaw=0.01):
    """mated_pair perturbed by the seed."""
    return mated_pair(robot, rng.uniform(-lateral, lateral), rng.uniform(-yaw, yaw))


def coupling_trial(seed, driver="anchor", speed=0.05, gap=0.03, lateral=0.0005, yaw=0.02, anchor_yaw=0.3,
                   timeout=5.0, sim=SimParams(), robot=RobotParams(), anchor=AnchorParams()):
    """One robot drives at ``speed`` into the other's opening from an aligned start.

    ``driver``: "anchor" (a backs its anchor into o's opening) or "opening"
    (o drives forward onto a's anchor); the other robot is commanded to stand
    still. Seeded perturbations: o's lateral offset (+/- ``lateral`` m) and yaw
    (+/- ``yaw`` rad), the anchor's free yaw in its holder (+/- ``anchor_yaw``).
    Success: the anchor's tips seated in the slits (HEAD_INSERTED) within ``timeout``.
    """
    rng = np.random.default_rng(seed)
    dy, dyaw = rng.uniform(-lateral, lateral), rng.uniform(-yaw, yaw)
    starts = [RobotStart("a", 0.0, 0.0, 0.0), RobotStart("o", -(robot.body_side + gap), dy, dyaw)]
    with _world(starts, sim, robot, anchor) as w:
        w.reset_anchor("a", rng.uniform(-anchor_yaw, anchor_yaw))
        w.run(0.2)
        w.set_command("a", -speed, 0.0) if driver == "anchor" else w.set_command("o", speed, 0.0)
        t0 = w.time
        while w.time - t0 < timeout:
            w.run(SCRIPT_DT)
            if _status(w, "a", "o") == HEAD_INSERTED:
                return {"trial": "couple", "seed": seed, "driver": driver, "speed": speed, "success": True,
                        "time_s": round(w.time - t0, 3)}
        return {"trial": "couple", "seed": seed, "driver": driver, "speed": speed, "success": False,
                "time_s": None, "status": _status(w, "a", "o")}


def pullout_trial(seed, driver="opening", speed=0.05, duration=5.0, sim=SimParams(), robot=RobotParams(),
                  anchor=AnchorParams()):
    """Start coupled; one robot drives straight away from the other for ``duration``.

    ``driver``: "opening" (o backs away) or "anchor" (a drives forward); the
    other is commanded to stand still. Success: never decoupled. Also reports
    the largest barb flare (joint angle, rad) and the snap angle.
    """
    rng = np.random.default_rng(seed)
    with _world(_mated_pair(rng, robot), sim, robot, anchor) as w:
        w.run(0.2)
        w.set_command("o", -speed, 0.0) if driver == "opening" else w.set_command("a", speed, 0.0)
        t0, flare, lost = w.time, 0.0, None
        while w.time - t0 < duration:
            w.run(SCRIPT_DT)
            flare = max(flare, *w.anchor_joints("a")[1:])
            if lost is None and _status(w, "a", "o") == DECOUPLED:
                lost = round(w.time - t0, 3)
        snap = w._torque_map.snap_angle - anchor.barb_angle
        return {"trial": "pullout", "seed": seed, "driver": driver, "speed": speed, "success": lost is None,
                "decoupled_at_s": lost, "max_flare_rad": round(flare, 3), "snap_rad": round(snap, 3)}


def wiggle_trial(seed, v_bias=0.02, w_max=3.0, period=2.0, timeout=20.0, sim=SimParams(), robot=RobotParams(),
                 anchor=AnchorParams()):
    """Start coupled; the anchor robot wiggles (v = v_bias, w = w_max sin(B t), B = 2 pi / period).

    Seeded perturbations: the mated start and the sign of the first turn.
    Success: decoupled within ``timeout``; reports the time.
    """
    rng = np.random.default_rng(seed)
    sign = 1.0 if rng.random() < 0.5 else -1.0
    b = 2.0 * math.pi / period
    with _world(_mated_pair(rng, robot), sim, robot, anchor) as w:
        w.run(0.2)
        t0 = w.time
        while w.time - t0 < timeout:
            w.set_command("a", v_bias, sign * w_max * math.sin(b * (w.time - t0)))
            w.run(SCRIPT_DT)
            if _status(w, "a", "o") == DECOUPLED:
                return {"trial": "wiggle", "seed": seed, "success": True, "time_s": round(w.time - t0, 3)}
        return {"trial": "wiggle", "seed": seed, "success": False, "time_s": None}


def _pitch(w, name):
    """Pitch of a robot [rad], > 0 nose down."""
    return pb.getEulerFromQuaternion(w.pose(name)[1])[1]


def _upright_on_floor(w, name, robot):
    roll, pitch, _ = pb.getEulerFromQuaternion(w.pose(name)[1])
    return (w.pose(name)[0][2] < robot.body_centre_height + UPRIGHT_HEIGHT_TOLERANCE
            and abs(roll) < UPRIGHT_TILT and abs(pitch) < UPRIGHT_TILT)


def _head_locked(w, anchor_robot, opening_robot, robot, anchor):
    """True when the anchor's head has risen above the slits' ceiling (into the lock slot)."""
    inv = pb.invertTransform(*w.pose(opening_robot))
    head = pb.multiplyTransforms(*inv, w.anchor_points(anchor_robot)[0], [0, 0, 0, 1])[0]
    return head[2] + anchor.head_height / 2 > robot.opening_z + robot.mouth_height / 2


def _edge_pair(rng, robot, holder_pilot=True):
    """The mated pair 30 mm back from the origin (the step world's edge ahead), ``o`` a pilot or not."""
    starts = [replace(s, x=s.x - 0.03) for s in _mated_pair(rng, robot)]
    starts[1] = replace(starts[1], pilot=holder_pilot)
    return starts


def edge_lock_trial(seed, speed=0.05, stage_height=0.05, hold_s=5.0, stop="tip", tip_angle=EDGE_TIP_ANGLE,
                    holder_pilot=True, sim=SimParams(), robot=RobotParams(), anchor=AnchorParams()):
    """A coupled pair on a stage drives forward until the front (anchor) robot ``a``
    goes over the edge; the back robot ``o`` holds it.

    ``stop="tip"``: both stop as soon as ``a`` tips (pitch > ``tip_angle``): ``a``
    ends over the edge, its centre of mass beyond it, held by the locked anchor
    (the edge lock). ``stop="edge"``: they drive on until ``o``'s front is 4 mm
    from the edge: ``a`` falls and hangs. ``holder_pilot``: ``o`` is a pilot
    (four driven wheels; a non-pilot's load goes onto its frictionless front
    caster and it is dragged). Seeded perturbation: the mated start.

    Success: ``a`` and ``o`` are never decoupled (checked every control period
    from the start to the end), after ``hold_s`` s ``a`` is over the edge
    (``stop="tip"``: centre beyond the edge and tipped; ``"edge"``: below the
    stage top) and ``o`` is still on the stage (centre behind the edge, level).
    """
    rng = np.random.default_rng(seed)
    wp = WorldParams(stage_height=stage_height)
    with _world(_edge_pair(rng, robot, holder_pilot), sim, robot, anchor, world="step", world_params=wp) as w:
        w.run(0.2)
        for n in ("a", "o"):
            w.set_command(n, speed, 0.0)
        t_end, decoupled_at = None, None
        while t_end is None or w.time - t_end < hold_s:
            w.run(SCRIPT_DT)
            if decoupled_at is None and _status(w, "a", "o") == DECOUPLED:
                decoupled_at = round(w.time, 2)
            if t_end is None and (_pitch(w, "a") > tip_angle if stop == "tip" else
                                  w.pose2d("o")[0] + robot.body_side / 2 >= wp.edge_x - EDGE_STOP):
                for n in ("a", "o"):
                    w.set_command(n, 0.0, 0.0)
                t_end = w.time
        (xa, _, za), (xo, _, zo) = w.pose("a")[0], w.pose("o")[0]
        over = (xa > wp.edge_x and _pitch(w, "a") > tip_angle) if stop == "tip" else za < stage_height
        held = xo < wp.edge_x and zo > stage_height and abs(_pitch(w, "o")) < UPRIGHT_TILT
        return {"trial": "edge_lock", "seed": seed, "stop": stop, "holder_pilot": holder_pilot,
                "success": bool(decoupled_at is None and over and held), "decoupled_at_s": decoupled_at,
                "front_pitch_rad": round(_pitch(w, "a"), 2), "front_beyond_edge_mm": round(1e3 * (xa - wp.edge_x), 1),
                "front_z_mm": round(1e3 * za, 1), "back_x_mm": round(1e3 * (xo - wp.edge_x), 1),
                "head_locked": _head_locked(w, "a", "o", robot, anchor), "status": _status(w, "a", "o")}


def _relative_pitch(orn_ref, orn):
    """Pitch [rad] of a body of orientation ``orn`` in the frame of one of orientation ``orn_ref``
    (quaternions xyzw, world frame), > 0: its x axis tips down relative to the reference's."""
    r = np.array(pb.getMatrixFromQuaternion(orn_ref)).reshape(3, 3)
    b = np.array(pb.getMatrixFromQuaternion(orn)).reshape(3, 3)
    rel = r.T @ b
    return math.atan2(-rel[2, 0], rel[0, 0])


def gap_pair_trial(seed, speed=0.03, timeout=20.0, sim=SimParams(), robot=RobotParams(), anchor=AnchorParams()):
    """A coupled pair drives across the gap world's 40 mm gap (the bridge's crossing, one column of it).

    The mated pair starts 40 mm behind the first stage's edge, both robots
    driving forwards at ``speed``; ``a`` (anchor robot, in front) goes over
    the gap first, hanging on its anchor in ``o``'s opening while its wheels
    are over the gap. Success: within ``timeout`` both robots are on the
    second stage (centres beyond its edge, level within UPRIGHT_TILT) and the
    pair never came apart. Reported: the largest nose-down pitch of ``a``
    [rad] and where it comes from, at that moment: ``a``'s pitch on the
    anchor's base (the holder's play), the base's on the head (the neck's
    bending) and the head's in ``o``'s opening (turning in the mouth), each
    > 0 nose down; their sum is ``a``'s pitch relative to ``o`` (``o``'s own
    pitch then: ``back_pitch_rad``). Seeded
    perturbation: the mated start.
    """
    rng = np.random.default_rng(seed)
    wp = WorldParams()
    far_edge = wp.edge_x + wp.gap_width
    starts = [replace(s, x=s.x + wp.edge_x - 0.04) for s in _mated_pair(rng, robot)]
    with _world(starts, sim, robot, anchor, world="gap", world_params=wp) as w:
        w.run(0.2)
        for n in ("a", "o"):
            w.set_command(n, speed, 0.0)
        worst, decoupled_at, crossed_at = (0.0,) * 5, None, None
        while w.time < timeout and crossed_at is None:
            w.run(SCRIPT_DT)
            if decoupled_at is None and _status(w, "a", "o") == DECOUPLED:
                decoupled_at = round(w.time, 2)
            pa = _pitch(w, "a")
            if pa > worst[0]:
                base = w.anchor_pose("a")[1]
                head = pb.getLinkState(w.robots["a"].anchor, 0, physicsClientId=w.client)[1]   # the neck's child
                worst = (pa, _relative_pitch(base, w.pose("a")[1]), _relative_pitch(head, base),
                         _relative_pitch(w.pose("o")[1], head), _pitch(w, "o"))
            if all(w.pose2d(n)[0] > far_edge and abs(_pitch(w, n)) < UPRIGHT_TILT for n in ("a", "o")):
                crossed_at = round(w.time, 2)
        return {"trial": "gap", "seed": seed, "success": crossed_at is not None and decoupled_at is None,
                "time_s": crossed_at, "decoupled_at_s": decoupled_at,
                "front_max_pitch_rad": round(worst[0], 2), "pitch_in_holder_rad": round(worst[1], 2),
                "pitch_at_neck_rad": round(worst[2], 2), "pitch_in_opening_rad": round(worst[3], 2),
                "back_pitch_rad": round(worst[4], 2),
                "front_x_mm": round(1e3 * (w.pose2d("a")[0] - wp.edge_x), 1),
                "front_z_mm": round(1e3 * w.pose("a")[0][2], 1)}


def lock_load_trial(seed, stage_height=0.15, ramp_n_per_s=0.5, settle_s=2.0, max_load_n=6.0, tip_timeout=10.0,
                    sim=SimParams(), robot=RobotParams(), anchor=AnchorParams()):
    """How much load the edge lock holds (the paper's "holds up to 500 g").

    The edge-lock start (:func:`edge_lock_trial`, ``stop="tip"``) on a stage
    ``stage_height`` high: once the front robot ``a`` has tipped over the edge
    and the pair stopped, the back robot ``o`` is clamped to the world (the
    rig's table) and, after ``settle_s``, a downward force on ``a``'s centre
    of mass grows at ``ramp_n_per_s`` (weights added to the hanging robot)
    until the pair decouples or the force reaches ``max_load_n``. (If ``a``
    has not tipped after ``tip_timeout`` s the load starts anyway.)

    Reports the extra load held at the separation (``held_n``, and as a mass
    in g, ``held_g``, plus the robot's own mass in ``total_g``) and whether the
    head was in the lock slot when the ramp started. Seeded perturbation: the
    mated start. ``success``: the lock still held at ``max_load_n``. It is a
    measurement: compare ``total_g`` with the hardware's 500 g.
    """
    rng = np.random.default_rng(seed)
    wp = WorldParams(stage_height=stage_height)
    with _world(_edge_pair(rng, robot), sim, robot, anchor, world="step", world_params=wp) as w:
        c, body = w.client, w.robots["a"].body
        w.run(0.2)
        for n in ("a", "o"):
            w.set_command(n, 0.05, 0.0)
        t0 = w.time
        while _pitch(w, "a") < EDGE_TIP_ANGLE and w.time - t0 < tip_timeout:
            w.run(SCRIPT_DT)
        for n in ("a", "o"):
            w.set_command(n, 0.0, 0.0)
        position, orientation = w.pose("o")
        pb.createConstraint(w.robots["o"].body, -1, -1, -1, pb.JOINT_FIXED, [0, 0, 0], [0, 0, 0], position,
                            [0, 0, 0, 1], orientation, physicsClientId=c)
        w.run(settle_s)
        locked = _head_locked(w, "a", "o", robot, anchor)
        load, held = 0.0, None
        mass = sum(pb.getDynamicsInfo(body, link, physicsClientId=c)[0]
                   for link in range(-1, pb.getNumJoints(body, physicsClientId=c)))
        while _status(w, "a", "o") != DECOUPLED:
            held = load
            if load >= max_load_n:
                break
            load = min(max_load_n, load + ramp_n_per_s * SCRIPT_DT)
            for _ in range(int(round(SCRIPT_DT / w.dt))):
                pb.applyExternalForce(body, -1, [0.0, 0.0, -load], w.pose("a")[0], pb.WORLD_FRAME,
                                      physicsClientId=c)
                w.step()
        held = held or 0.0
        return {"trial": "lock_load", "seed": seed, "success": held >= max_load_n, "head_locked_at_start": locked,
                "held_n": round(held, 3), "held_g": round(1e3 * held / GRAVITY, 1),
                "total_g": round(1e3 * (held / GRAVITY + mass), 1),
                "front_pitch_rad": round(_pitch(w, "a"), 2), "time_s": None}


def chain_step_trial(seed, n=3, speed=0.05, stage_height=0.05, timeout=30.0, direction="backward", pilot=None,
                     floor_speed=0.01, tip_angle=0.2, sim=SimParams(), robot=RobotParams(), anchor=AnchorParams()):
    """A chain of ``n`` coupled robots goes down the stage edge onto the floor.

    Chain ``r1`` .. ``rN``: ``r(k)``'s anchor sits in ``r(k+1)``'s opening (all
    facing the same way). ``direction="forward"``: the chain faces the edge and
    drives forward (``r1`` goes over first, nose first; every anchor robot drops
    below its opening robot, so every lock engages). ``"backward"``: the chain
    faces away from the edge and backs off it (``rN`` goes first, back first,
    and ladders down the stage face; a robot on the floor keeps driving and
    pulls the next one down); once the last robot tips over the edge (pitch
    beyond ``tip_angle``) the others slow to ``floor_speed`` (its anchor sits
    above the opening it is in, so that pair is held by the barbs only). ``pilot``: index
    (0-based) of the pilot in the chain, -1 for none; default: the robot that
    goes down first.

    Success: within ``timeout`` every robot stands upright on the floor and no
    pair was ever decoupled. Seeded perturbation: small lateral offsets.

    Also reports ``first_separation`` (None if no pair came apart): the pair
    (``"r2>r3"``: r2's anchor in r3's opening), when, every robot's pitch
    then, and that pair's largest barb angle and anchor pull-out in its holder
    (base travel out of the pushed-in position, mm) up to the separation:
    barbs beyond the snap angle mean the anchor was pulled out through the
    force profile; a large pull-out with barbs below it means it slipped.
    """
    rng = np.random.default_rng(seed)
    names = ["r%d" % (i + 1) for i in range(n)]
    backward = direction == "backward"
    if pilot is None:
        pilot = n - 1 if backward else 0
    yaw = math.pi if backward else 0.0
    step = robot.body_side + MATE_GAP
    # the robot nearest the edge starts with its leading face (plus anchor) 5 mm from it
    lead = -(robot.body_side / 2 + CHAIN_START_GAP + (ANCHOR_OUT if backward else 0.0))
    xs = [lead - (n - 1 - i) * step for i in range(n)] if backward else [lead - i * step for i in range(n)]
    starts = [RobotStart(nm, xs[i], rng.uniform(-0.0003, 0.0003) if i else 0.0, yaw, pilot=(i == pilot))
              for i, nm in enumerate(names)]
    wp = WorldParams(stage_height=stage_height)
    v = -speed if backward else speed
    with _world(starts, sim, robot, anchor, world="step", world_params=wp) as w:
        w.run(0.2)
        t0, decoupled, slow, first = w.time, set(), False, None
        barb, pulled = [0.0] * (n - 1), [0.0] * (n - 1)
        for nm in names:
            w.set_command(nm, v, 0.0)
        while w.time - t0 < timeout:
            if backward and not slow and abs(_pitch(w, names[0])) > tip_angle:
                slow = True                    # the last robot tips over the edge: the others only creep
                for nm in names[1:]:
                    w.set_command(nm, -floor_speed, 0.0)
            w.run(SCRIPT_DT)
            for i in range(n - 1):
                barb[i] = max(barb[i], *w.anchor_joints(names[i])[1:])
                pulled[i] = max(pulled[i], w.anchor_pullout(names[i]))
            now = {i for i in range(n - 1) if _status(w, names[i], names[i + 1]) == DECOUPLED}
            if now and first is None:
                i = min(now)
                first = {"pair": "%s>%s" % (names[i], names[i + 1]), "time_s": round(w.time - t0, 2),
                         "pitch_rad": {nm: round(_pitch(w, nm), 2) for nm in names},
                         "max_barb_rad": round(barb[i], 2), "snap_rad": round(w._torque_map.snap_angle
                                                                             - anchor.barb_angle, 2),
                         "max_pullout_mm": round(1e3 * pulled[i], 1)}
            decoupled |= now
            if all(_upright_on_floor(w, nm, robot) for nm in names):
                break
        down = [_upright_on_floor(w, nm, robot) for nm in names]
        return {"trial": "chain_step", "seed": seed, "robots": n, "direction": direction, "pilot": pilot,
                "success": bool(all(down) and not decoupled), "upright_on_floor": sum(down),
                "pairs_ever_decoupled": len(decoupled),
                "time_s": round(w.time - t0, 2) if all(down) else None, "timeout_s": timeout,
                "first_separation": first}



def speed_test(robots, sim_seconds, seed=0, sim=SimParams(), robot=RobotParams(), anchor=AnchorParams(),
               anchor_rest=AnchorRestParams()):
    """Wall-clock speed of a headless world of ``robots`` robots with anchors.

    Layout on a grid 0.2 m apart: half of the robots (rounded up to a pair)
    stand in coupled pairs, the others alone; every robot drives (v = 0.03
    m/s, gentle seeded turns), so every anchor rides in its holder and the
    coupled ones carry load. Returns robots, sim_seconds, wall_seconds,
    real_time_factor (sim / wall), cpu_seconds, the coupled pairs and the
    anchors frozen at rest (``anchor_rest``) at the end.
    """
    rng = np.random.default_rng(seed)
    coupled = min(robots, 2 * int(math.ceil(robots / 4.0)))
    cells = coupled // 2 + (robots - coupled)
    cols = max(1, int(math.ceil(math.sqrt(cells))))
    starts = []
    for k in range(cells):
        cx, cy = 0.2 * (k % cols), 0.2 * (k // cols)
        starts.append(RobotStart("r%d" % len(starts), cx, cy, 0.0))
        if k < coupled // 2:
            starts.append(RobotStart("r%d" % len(starts), cx - robot.body_side - MATE_GAP, cy, 0.0))
    w = _world(starts, replace(sim, seed=seed), robot, anchor, anchor_rest=anchor_rest)
    try:
        turns = {s.name: rng.uniform(-0.3, 0.3) for s in starts}
        for s in starts:
            w.set_command(s.name, 0.03, turns[s.name])
        wall0, cpu0 = time.perf_counter(), time.process_time()
        w.run(sim_seconds)
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        pairs = len(w.physical_pairs())
        resting = len(w.resting_anchors())
    finally:
        w.close()
    return {"robots": robots, "sim_seconds": sim_seconds, "wall_seconds": round(wall, 4),
            "real_time_factor": round(sim_seconds / wall, 2), "cpu_seconds": round(cpu, 4),
            "coupled_pairs_at_end": pairs, "resting_anchors_at_end": resting}


def summarize(results):
    """Success count, rate and mean time of a list of trial dicts."""
    ok = [r for r in results if r["success"]]
    times = [r["time_s"] for r in ok if r.get("time_s") is not None]
    return {"trials": len(results), "successes": len(ok), "rate": len(ok) / len(results) if results else 0.0,
            "mean_time_s": round(float(np.mean(times)), 3) if times else None}


def seat_pull_trial(seed, chain=3, speed=0.03, lateral=0.002, anchor_yaw=0.3, standoff=0.016, push_s=2.5,
                    pull_speed=0.02, pull_s=1.0, heading_gain=2.0, sim=SimParams(), robot=RobotParams(),
                    anchor=AnchorParams()):
    """What a pull tells about a pushed-home anchor (puzzlebot_mpc.docking's seated band).

    A robot ``d`` stands ``standoff`` behind a mated chain of ``chain``
    robots, offset sideways by up to +/- ``lateral`` and facing it; the
    chain's last anchor is turned in its holder by up to +/- ``anchor_yaw``
    (seeded). ``d`` pushes straight in at ``speed`` holding the chain's
    heading for ``push_s``, then backs away at ``pull_speed`` for ``pull_s``
    and pushes home again for ``push_s``. Records whether the faces got home,
    the anchor's state in Bullet after the push and after the second push, and
    how far the pull stretched the pair before it stalled (the gap's growth
    [m]). Success: home and seated in Bullet after the second push.
    """
    rng = np.random.default_rng(seed)
    gap0 = robot.body_side + MATE_GAP
    starts = [RobotStart("c%d" % k, -k * gap0, 0.0, 0.0) for k in range(chain)]
    last = "c%d" % (chain - 1)
    dy, dyaw, ayaw = rng.uniform(-lateral, lateral), rng.uniform(-0.03, 0.03), rng.uniform(-anchor_yaw, anchor_yaw)
    starts.append(RobotStart("d", -(chain - 1) * gap0 - robot.body_side - standoff, dy, dyaw))

    def gap(w, lateral=False):
        pa, pd = w.pose2d(last), w.pose2d("d")
        c, s = math.cos(pd[2]), math.sin(pd[2])
        if lateral:
            return -s * (pa[0] - pd[0]) + c * (pa[1] - pd[1])
        return c * (pa[0] - pd[0]) + s * (pa[1] - pd[1]) - robot.body_side

    def drive(w, v, seconds):
        t0 = w.time
        while w.time - t0 < seconds - 1e-9:
            dth = math.remainder(w.pose2d(last)[2] - w.pose2d("d")[2], 2 * math.pi)
            w.set_command("d", v, max(-1.0, min(1.0, heading_gain * dth)))
            w.run(SCRIPT_DT)

    with _world(starts, sim, robot, anchor) as w:
        w.reset_anchor(last, ayaw)
        w.run(0.3)
        drive(w, speed, push_s)
        home_gap, pushed = gap(w), _status(w, last, "d")
        drive(w, -pull_speed, pull_s)
        growth = gap(w) - home_gap
        drive(w, speed, push_s)
        repushed = _status(w, last, "d")
        return {"trial": "seatpull", "seed": seed, "success": gap(w) < 0.003 and repushed == HEAD_INSERTED,
                "gap_after_push_mm": round(1e3 * home_gap, 2), "seated_after_push": pushed == HEAD_INSERTED,
                "seated_after_repush": repushed == HEAD_INSERTED, "gap_after_repush_mm": round(1e3 * gap(w), 2),
                "lateral_after_repush_mm": round(1e3 * gap(w, lateral=True), 2),
                "pull_growth_mm": round(1e3 * growth, 2), "lateral_mm": round(1e3 * dy, 2),
                "anchor_yaw_rad": round(ayaw, 3)}
