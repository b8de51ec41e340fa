"""Bad mocap frames into the control loop (no ROS): the affected robot is held at zero, the others go on.

A kinematic plant at 100 Hz feeds the loop; every fault of
puzzlebot_common.mocap_faults, as one frame and as a burst of 10, hits pz1
in turn. The same faults through the MPC node: rostest mpc_bad_frames.
"""

import pytest

from puzzlebot_common.geometry import yaw_from_quaternion
from puzzlebot_common.mocap_faults import FAULTS, clean
from puzzlebot_common.model import unicycle_arc
from puzzlebot_common.pose_gate import PoseGateParams
from puzzlebot_mpc.behaviors import BehaviorError, BehaviorRequest
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_mpc.settings import MPCSettings

NAMES = ["pz1", "pz2", "pz3"]
FRAME = 0.01                  # s, mocap period
N_GOOD = PoseGateParams().reacquire_frames
CASES = [(fault, burst) for fault in sorted(FAULTS) for burst in (1, 10)]
SPACING = 0.6                 # s between two faults


def feed(loop, name, t, pose, fault=None):
    f = FAULTS[fault][0](t, *pose) if fault else clean(t, *pose)
    return loop.on_pose(name, f.stamp, f.x, f.y, yaw_from_quaternion(*f.q), quaternion=f.q, z=f.z)


@pytest.fixture(scope="module")
def run():
    """Every case once, in one closed-loop run; returns (steps, reasons, schedule)."""
    loop = ControlLoop(NAMES, MPCSettings())
    poses = {n: (0.0, 0.15 * i, 0.0) for i, n in enumerate(NAMES)}
    for n, p in poses.items():
        feed(loop, n, 0.0, p)
    loop.request(BehaviorRequest("follow_velocity", NAMES, velocities=[(0.03, 0.3)] * 3), 0.0)
    schedule = {}                      # frame index -> fault, for pz1
    starts = []
    for i, (fault, burst) in enumerate(CASES):
        k0 = int(round((1.0 + SPACING * i) / FRAME)) + 3            # 30 ms after a control step
        starts.append((fault, burst, k0 * FRAME))
        for k in range(k0, k0 + burst):
            schedule[k] = fault
    steps, reasons = [], []            # (t, commands, held) per control step; pz1's rejection reasons
    n_frames = int(round((1.0 + SPACING * len(CASES) + 1.0) / FRAME))
    out = None
    for k in range(n_frames + 1):
        t = k * FRAME
        if k % 10 == 0:
            out = loop.step(t)
            steps.append((t, out.commands, loop.poses.held("pz1"), out.stale))
        for n in NAMES:
            v, w = out.commands[n]
            poses[n] = unicycle_arc(poses[n], v, w, FRAME)
        for n in NAMES:
            reason = feed(loop, n, t + FRAME, poses[n], schedule.get(k + 1) if n == "pz1" else None)
            if reason:
                assert n == "pz1", reason
                reasons.append((t + FRAME, reason))
    return steps, reasons, starts, loop


def test_others_never_stop(run):
    steps = run[0]
    for t, cmds, _, _ in steps:
        if t >= 1.0:
            assert cmds["pz2"][0] > 0.02 and cmds["pz3"][0] > 0.02, t


@pytest.mark.parametrize("case", range(len(CASES)))
def test_the_affected_robot_is_held_at_zero_then_resumes(run, case):
    steps, reasons, starts, _ = run
    fault, burst, t0 = starts[case]
    t_good = t0 + burst * FRAME                       # first good frame
    t_trusted = t_good + (N_GOOD - 1) * FRAME         # the hold ends with this frame
    window = [(t, c, held, stale) for t, c, held, stale in steps if t0 < t <= t_trusted + 0.1 + 1e-9]
    zero = [(t, stale) for t, c, held, stale in window if c["pz1"] == (0.0, 0.0)]
    assert zero, (fault, burst, window)               # at least one control step held pz1 at zero
    assert all("pz1" in stale for _, stale in zero)
    resumed = next(t for t, c, _, _ in steps if t > t_trusted and c["pz1"][0] > 0)
    assert resumed - t_good <= 0.3, (fault, burst, resumed - t_good)
    named = [r for t, r in reasons if t0 - 1e-9 <= t < t_good]
    assert len(named) == burst and all(r.startswith("pz1: ") for r in named)


def test_a_held_robot_is_left_out_of_the_pairs_and_refused_by_new_behaviours():
    loop = ControlLoop(["pz1", "pz2"], MPCSettings())
    start = {"pz1": (0.0, 0.0, 0.0), "pz2": (-0.065, 0.012, 0.0)}       # couple2's start poses
    for n, p in start.items():
        feed(loop, n, 0.0, p)
    loop.request(BehaviorRequest("couple", ["pz1", "pz2"], target="line"), 0.0)
    loop.step(0.0)
    assert len(loop.pairs.active) == 1
    feed(loop, "pz2", FRAME, start["pz2"])
    feed(loop, "pz1", FRAME, start["pz1"], "heading flipped by pi")
    out = loop.step(FRAME)
    assert loop.pairs.active == [] and "pz1" in out.stale
    assert out.commands["pz1"] == (0.0, 0.0)
    with pytest.raises(BehaviorError, match="no fresh, finite pose for pz1"):
        loop.request(BehaviorRequest("couple", ["pz1", "pz2"], target="line"), FRAME)
    for k in range(2, 2 + N_GOOD):
        for n, p in start.items():
            feed(loop, n, k * FRAME, p)
    out = loop.step((1 + N_GOOD) * FRAME)
    assert len(loop.pairs.active) == 1 and out.stale == []


def test_a_rejected_frame_holds_the_robot_for_one_step_however_fast_good_frames_follow():
    loop = ControlLoop(["pz1", "pz2"], MPCSettings())
    start = {"pz1": (0.0, 0.0, 0.0), "pz2": (0.0, 0.15, 0.0)}
    for n, p in start.items():
        feed(loop, n, 0.0, p)
    loop.request(BehaviorRequest("follow_velocity", ["pz1", "pz2"], velocities=[(0.03, 0.0)] * 2), 0.0)
    assert loop.step(0.0).commands["pz1"] != (0.0, 0.0)
    feed(loop, "pz1", FRAME, start["pz1"], "heading flipped by pi")
    for k in range(2, 3 + 2 * N_GOOD):              # the gate's hold is over before the next step
        for n, p in start.items():
            feed(loop, n, k * FRAME, p)
    assert loop.step((3 + 2 * N_GOOD) * FRAME).commands["pz1"] == (0.0, 0.0)
    for n, p in start.items():
        feed(loop, n, (4 + 2 * N_GOOD) * FRAME, p)
    assert loop.step((4 + 2 * N_GOOD) * FRAME).commands["pz1"] != (0.0, 0.0)   # once only
