"""One control step of the MPC node, without ROS.

The node feeds measured poses in with :meth:`ControlLoop.on_pose` and calls
:meth:`ControlLoop.step` every ``dt``; the returned commands go to
``/<robot>/cmd_vel``. Poses are world-frame ``(x, y, yaw)`` with their
measurement stamps (seconds).

Each step also runs the pair bookkeeping of Algorithm 3: status updates of
the active pairs (Algorithm 2) and the coupled-pair watchdog, then the
conflict-free choice of active pairs, before the MPC solve.

Safety rules, applied every step:
- every pose passes the robot's pose gate (puzzlebot_common.pose_gate, bounds
  ``hardware_v_max`` / ``hardware_w_max``): a non-finite or implausible pose,
  a pose for an unknown robot or one older than the last accepted sample is
  rejected (the caller logs the returned reason);
- a robot without a pose newer than ``settings.pose_timeout``, or held by its
  gate (a rejection in the last ``reacquire_frames`` frames), is commanded to
  zero and left out of its behaviour and of new pairs until trusted poses return;
- a failed solve commands zero to every robot (``fallback == "stop"``), open-loop
  commands (the decoupling wiggle) included;
- with the world's stages (``stages``, puzzlebot_common.stages) and
  ``settings.edges``, every robot's footprint stays on the stage it stands on
  (the MPC's edge boxes), except the robots of a behaviour requested with
  ``cross_edges`` (down a step, over a gap).
"""

import math
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_common.pose_gate import PoseGate, PoseGateParams, Verdict
from puzzlebot_common.stages import StageMap
from puzzlebot_mpc.behaviors import FAILED, RUNNING, STOP, BehaviorError, BehaviorManager, BehaviorRequest
from puzzlebot_mpc.compensation import Compensation
from puzzlebot_mpc.controller import MPCResult, MultiRobotMPC
from puzzlebot_common.model import NX
from puzzlebot_mpc.pairs import PairBook


_TIME_EPS = 1e-6   # s: a start time this close to a control step's time is due at that step


@dataclass
class PoseSample:
    stamp: float   # s, measurement time
    x: float       # m, world frame
    y: float       # m
    yaw: float     # rad


class PoseBook:
    """Latest accepted pose of each robot, every frame through its pose gate (puzzlebot_common.pose_gate).

    A robot is *fresh* when its latest accepted pose is at most ``timeout``
    old and its gate does not hold it (no rejection in the last
    ``reacquire_frames`` frames) and no frame of it was rejected since the
    last control step (:meth:`step_done`: every rejection holds the robot for
    at least one step, however fast the good frames after it arrive): the
    controller plans only with those.
    """

    def __init__(self, names, timeout, v_max, w_max, gate_params=PoseGateParams()):
        """``v_max`` [m/s], ``w_max`` [rad/s]: the robots' own limits (settings.hardware_v_max, hardware_w_max)."""
        self.timeout = timeout
        self._poses: Dict[str, Optional[PoseSample]] = {n: None for n in names}
        self.gates = {n: PoseGate(n, v_max, w_max, gate_params) for n in names}
        self.last_verdict: Dict[str, Optional[Verdict]] = {n: None for n in names}
        self._rejected_since_step = set()

    def update(self, name, stamp, x, y, yaw, quaternion=None, z=0.0):
        """Judge a sample (``yaw`` [rad]; the ``quaternion`` (x, y, z, w) it came from and the height
        ``z`` [m], if given, are checked too); store it if accepted. Return None if accepted, else
        the reason it was rejected."""
        if name not in self._poses:
            return "pose for unknown robot %r" % name
        verdict = self.gates[name].check(stamp, x, y, yaw, quaternion, z)
        self.last_verdict[name] = verdict
        if not verdict.accepted:
            self._rejected_since_step.add(name)
            return "%s: %s" % (name, verdict.reason)
        self._poses[name] = PoseSample(float(stamp), float(x), float(y), float(verdict.yaw))
        return None

    def latest(self, name):
        return self._poses[name]

    def held(self, name):
        """True while the robot's pose gate holds it (recent rejections)."""
        return self.gates[name].held

    def step_done(self):
        """A control step has read the poses: rejections before it have held their robots once."""
        self._rejected_since_step.clear()

    def fresh(self, name, now):
        """(x, y, yaw) if the latest sample is at most ``timeout`` old and not held, else None."""
        p = self._poses[name]
        if p is None or now - p.stamp > self.timeout or self.gates[name].held or name in self._rejected_since_step:
            return None
        return (p.x, p.y, p.yaw)


@dataclass
class StepOutput:
    commands: Dict[str, Tuple[float, float]]   # robot -> (v [m/s], w [rad/s])
    result: MPCResult
    status: object                             # behaviors.BehaviorStatus
    stale: List[str]                           # robots stopped for lack of a fresh pose
    poses: Dict[str, Optional[Tuple[float, float, float]]]
    pairs: list = None                         # every known ConnectionPair (coupled, goals, decoupling)
    newly_coupled: list = None
    lost: list = None


class ControlLoop:
    """Poses in, behaviour objectives, MPC solve, commands out."""

    def __init__(self, robot_names, settings, geometry=None, targets=None, actuator_model=None,
                 pose_gate=PoseGateParams(), stages=()):
        self.names = list(robot_names)
        self.settings = settings
        self.geometry = geometry or RobotGeometry()
        self.stages = list(stages)      # puzzlebot_common.stages.Stage: the world's stages (none: the floor)
        self.stage_map = self._stage_map(settings)
        self.poses = PoseBook(self.names, settings.pose_timeout, settings.hardware_v_max, settings.hardware_w_max,
                              pose_gate)
        self.pairs = PairBook.from_settings(self.geometry, settings)
        self.behaviors = BehaviorManager(self.names, settings, self.geometry, self.pairs, targets)
        self._pending = []              # (request id, BehaviorRequest) waiting to start, in order
        self.mpc = MultiRobotMPC(settings, len(self.names)).setup()
        self._last_cmd = np.zeros((len(self.names), 2))
        # Identified actuator effects (effects.ActuatorModel), per robot; a null compensation without
        # one (the plain unicycle): see compensation.py.
        self.compensation = Compensation.create(actuator_model, self.names, settings)

    def on_pose(self, name, stamp, x, y, yaw, quaternion=None, z=0.0):
        yaw = self.compensation.body_yaw(name, stamp, yaw)     # measured yaw -> body heading
        return self.poses.update(name, stamp, x, y, yaw, quaternion, z)

    def fresh_poses(self, now):
        return {name: self.poses.fresh(name, now) for name in self.names}

    def request(self, req, now):
        """Start a behaviour now, or queue it; return its request id (BehaviorError: refused).

        ``req.queue`` false and ``req.start_time`` not in the future: validated
        against the current poses and started now (BehaviorManager.request);
        it replaces the running behaviour and cancels every queued request.
        Otherwise the request passes the state-free checks now
        (BehaviorManager.validate) and waits: for ``start_time`` [s, ROS time]
        and, with ``queue``, for the running behaviour and those queued before
        it to end. It starts at the first control step where both hold, with
        the poses of that step, so a script of behaviours runs the same way
        whatever the timing of the calls (lockstep simulation: repeatable). A
        queued request is dropped if one before it fails, and reported FAILED
        if its state checks fail when it is due.
        """
        if not math.isfinite(req.start_time) or req.start_time < 0:
            raise BehaviorError("start_time must be finite and >= 0 (got %r)" % req.start_time)
        if not req.queue and req.start_time <= now + _TIME_EPS:
            request_id = self.behaviors.request(req, now, self.fresh_poses(now))
            self._pending.clear()
            return request_id
        self.behaviors.validate(req)
        if req.queue and not self._pending and self.behaviors.state == FAILED:
            raise BehaviorError("queue: the current behaviour (request %d) failed; nothing to queue behind"
                                % self.behaviors.request_id)
        request_id = self.behaviors.new_id()
        self._pending.append((request_id, req))
        return request_id

    def pending(self):
        """Ids of the requests waiting to start, in order."""
        return [request_id for request_id, _ in self._pending]

    def cancel(self, request_id, now):
        """Cancel request ``request_id`` at ``now`` [s]: a queued one leaves the queue ("queued"); the
        running one is replaced by ``stop`` ("running": every robot comes to rest, the coupled pairs
        stay held, the requests queued behind it are dropped, as for any request that starts at
        once). None: it is neither queued nor running (ended, or unknown)."""
        for k, (rid, _) in enumerate(self._pending):
            if rid == request_id:
                del self._pending[k]
                return "queued"
        if self.behaviors.request_id == request_id and self.behaviors.state == RUNNING:
            self.request(BehaviorRequest(STOP), now)
            return "running"
        return None

    def _start_due(self, now, poses):
        """Start the queued requests that are due (see request)."""
        while self._pending:
            request_id, req = self._pending[0]
            if req.start_time > now + _TIME_EPS or (req.queue and self.behaviors.state == RUNNING):
                return
            self._pending.pop(0)
            if req.queue and self.behaviors.state == FAILED:
                dropped = [request_id] + self.pending()
                self._pending.clear()
                self.behaviors.note("; queued request(s) %s dropped" % ", ".join(map(str, dropped)))
                return
            try:
                self.behaviors.request(req, now, poses, request_id=request_id)
            except BehaviorError as e:
                self.behaviors.refuse(request_id, req, "refused when due: %s" % e)

    def retune(self, settings, mpc=None):
        """Use ``settings`` (MPCSettings with the same dt, horizon and solver: puzzlebot_mpc.tuning) from
        the next step, and ``mpc``: a MultiRobotMPC built for them (see :meth:`build_mpc`) when the change
        reaches the MPC's problem; None keeps the current one (a change the behaviours read every step)."""
        self.settings = settings
        self.stage_map = self._stage_map(settings)
        self.behaviors.set_settings(settings)
        if mpc is not None:
            self.mpc = mpc

    def _stage_map(self, settings):
        """The StageMap the edge boxes come from (the footprint's circumradius + ``edge_margin`` inside
        every edge); None without stages or with ``edges`` off."""
        if not (settings.edges and self.stages):
            return None
        return StageMap(self.stages, self.geometry.footprint_radius() + settings.edge_margin)

    def edge_boxes(self, poses):
        """(N, 4) edge boxes (x_lo, x_hi, y_lo, y_hi) [m] of the robots at ``poses`` (name -> pose or None):
        the stage each stands on, shrunk by the footprint; +-inf on the floor, for a robot without a pose
        and for the robots the running behaviour lets cross (``cross_edges``). None without stages."""
        if self.stage_map is None:
            return None
        free = (-math.inf, math.inf, -math.inf, math.inf)
        crossing = self.behaviors.crossing()
        return np.array([free if poses[m] is None or m in crossing else self.stage_map.box(*poses[m][:2])
                         for m in self.names])

    def build_mpc(self, settings, keys):
        """A MultiRobotMPC for ``settings``, with the structure of pair slots ``keys`` (pair_keys()) built;
        slow (CasADi builds the problem): call it outside the node's lock, then :meth:`retune`."""
        mpc = MultiRobotMPC(settings, len(self.names)).setup()
        mpc.prepare(keys)
        return mpc

    def pair_keys(self):
        """The current pair slots as robot index tuples (the MPC structure's key)."""
        index = {n: i for i, n in enumerate(self.names)}
        return [(index[p.robot_i], index[p.robot_j]) for p in self.behaviors.pair_slots()]

    def step(self, now):
        n = len(self.names)
        poses = self.fresh_poses(now)
        self.poses.step_done()
        self._start_due(now, poses)
        newly, lost = self.pairs.update(poses, now)
        status = self.behaviors.update(now, poses, newly, lost)
        stale = [name for name in self.names if poses[name] is None]
        if len(stale) == n:
            self._last_cmd[:] = 0.0
            result = MPCResult(np.zeros((n, 2)), np.zeros((n, self.settings.horizon + 1, NX)),
                               False, "no fresh pose for any robot", 0.0, 0, float("nan"), fallback="stop")
            self.compensation.to_commands(result, now, stale)     # remember the zero commands
            return self._output(result, status, stale, poses, newly, lost)
        if self.behaviors.coupling():
            self.pairs.assign_active(poses)
        obj = self.behaviors.objectives(now, poses)
        obj.edge_box = self.edge_boxes(poses)
        x0 = np.zeros((n, NX))
        for i, name in enumerate(self.names):
            pose = poses[name]
            if pose is None:
                obj.goal_mask[i], obj.velocity_mask[i] = False, 1.0
                obj.velocity[i] = 0.0
                self._last_cmd[i] = 0.0
                latest = self.poses.latest(name)
                pose = (latest.x, latest.y, latest.yaw) if latest else (0.0, 0.0, 0.0)
            x0[i, :3] = pose
            x0[i, 3:] = self._last_cmd[i]
        # actuator model: plan from where the robots will be
        self.compensation.initial_states(x0, now, {m: self.poses.latest(m).stamp for m in self.names
                                                   if m not in stale}, stale)
        if stale:
            for p in obj.pairs:     # no alignment towards a robot whose pose is unknown
                if self.names[p.i] in stale or self.names[p.j] in stale:
                    p.active = False
        result = self.mpc.make_step(x0, obj)
        if result.success:              # open-loop commands (the wiggle) only while the MPC runs normally
            for i, (v, w) in obj.open_loop.items():
                result.commands[i] = (v, w)
        for i, name in enumerate(self.names):
            if poses[name] is None:
                result.commands[i] = 0.0
        self._last_cmd = result.commands.copy()
        self.compensation.to_commands(result, now, stale)         # actuator model: planned velocities -> commands
        return self._output(result, status, stale, poses, newly, lost)

    def _output(self, result, status, stale, poses, newly, lost):
        commands = {name: (float(result.commands[i, 0]), float(result.commands[i, 1]))
                    for i, name in enumerate(self.names)}
        return StepOutput(commands, result, status, stale, poses, self.behaviors.pair_slots(), newly, lost)
