"""A deadband threshold the robots share is fitted to all robots' windows together.

Each robot alone places a threshold only somewhere in the gap between its own
commanded magnitudes around it (the middle is taken), and the robots' gaps
differ. Here three robots share w_min = 0.25 rad/s: pz1 and pz3 are commanded
magnitudes far either side of it (0.2 / 0.32 and 0.24 / 0.34 rad/s, own values
0.26 and 0.29), pz2 also 0.248 and 0.252 (own value 0.25). The median of the
own values (0.26) would zero pz2's 0.252 rad/s, on which it turns; the robots'
summed cost brackets the threshold between 0.248 and 0.252. And a threshold
fitted on some windows only (a cross-validation fold) lies halfway between the
magnitudes those windows show zeroed and passing, whatever the others contain.
"""

import numpy as np
import pytest

import identify_synth as synth
from puzzlebot_common.effects import NOMINAL
from puzzlebot_mpc.identify import IdentifySettings, engine, fit
from puzzlebot_mpc.identify.data import RobotData

TRUTH = {"deadband": {"v_min": 0.0, "w_min": 0.25}}
V = 0.05            # m/s, every command
HOLD = 1.0          # s each turn rate is held
DT = 0.002          # s: simulation step (mocap samples every 5th)
DURATION = 45.0     # s per robot
LATE = 32.0         # s: after the start of the last of the 3 parts (30.7 s)
LARGE = [0.6, 0.8, 1.0, 1.2, 1.4, 1.6]   # rad/s: keeps the magnitudes near the threshold below their median
TURN_RATES = {"pz1": [0.1, 0.2, 0.32] + LARGE,
              "pz2": [0.1, 0.2, 0.248, 0.252] + LARGE,
              "pz3": [0.1, 0.24, 0.34] + LARGE}
BRACKET = (0.248, 0.252)        # the closest commanded magnitudes either side of the true threshold


def robot(name, rates, seed, late_rates=None):
    """``rates`` cycled, each held HOLD s with alternating sign, at 10 Hz; ``late_rates``: cycled
    instead from LATE s on (inside the last cross-validation part only)."""
    rng = np.random.default_rng(seed)
    n = int(DURATION * synth.CMD_RATE)
    per = int(HOLD * synth.CMD_RATE)
    cmds = []
    for i in range(n):
        t = i / synth.CMD_RATE
        seq = late_rates if late_rates is not None and t >= LATE else rates
        j = i // per
        cmds.append((t, V, seq[j % len(seq)] * (1 if j % 2 == 0 else -1)))
    poses, _ = synth.simulate(synth.model_of(TRUTH), cmds, DURATION, DT, pose0=(0.0, 0.0, 0.3))
    idx = np.arange(0, poses.shape[0], int(round(1.0 / (synth.MOCAP_RATE * DT))))
    p = poses[idx]
    c = np.array(cmds)
    return RobotData(name, idx * DT, p[:, 0] + rng.normal(0, synth.POS_NOISE, idx.size),
                     p[:, 1] + rng.normal(0, synth.POS_NOISE, idx.size),
                     p[:, 2] + rng.normal(0, synth.YAW_NOISE, idx.size), c[:, 0], c[:, 1], c[:, 2])


def fits_of(robots):
    settings = IdentifySettings()
    return [fit.RobotFit(r, settings) for r in robots], settings


def own_fits(fits, mask_of=lambda rf: None):
    return [rf.fit(["deadband"], dict(NOMINAL), mask_of(rf), new="deadband") for rf in fits]


def test_joint_threshold_is_bracketed_by_every_robots_commands():
    fits, _ = fits_of([robot(n, rates, seed) for seed, (n, rates) in enumerate(TURN_RATES.items())])
    own = own_fits(fits)
    assert [round(p["w_min"], 3) for p in own] == [0.26, 0.25, 0.29]
    assert np.median([p["w_min"] for p in own]) > BRACKET[1]      # the median zeroes pz2's 0.252 rad/s
    common = fit.common_values(fits, own, ["v_min", "w_min"])
    assert BRACKET[0] < common["w_min"] < BRACKET[1]
    assert fit.joint_threshold(fits, own, "w_min") == common["w_min"]


def test_thresholds_see_only_the_windows_of_their_masks():
    """pz2's commands near the threshold come only in the last part: fitted without it (the
    cross-validation fold that holds it out), each threshold lies halfway between the largest
    magnitude the training windows show zeroed and the smallest they show passing; the held-out
    commands do not move it."""
    rates = dict(TURN_RATES, pz2=[0.1, 0.2] + LARGE)
    robots = [robot(n, r, seed, TURN_RATES["pz2"] if n == "pz2" else None)
              for seed, (n, r) in enumerate(rates.items())]
    fits, settings = fits_of(robots)
    held_out = settings.cv_folds - 1
    assert all(rf.windows.te[rf.windows.fit_mask(held_out)].max() < LATE for rf in fits)
    own = own_fits(fits, lambda rf: rf.windows.fit_mask(held_out))
    # pz2 alone: 0.2 zeroed, 0.6 passing; pz1: 0.2 / 0.32; pz3: 0.24 / 0.34
    assert [p["w_min"] for p in own] == pytest.approx([0.26, 0.4, 0.29], abs=1e-12)
    masked = fit.joint_threshold(fits, own, "w_min", [rf.windows.fit_mask(held_out) for rf in fits])
    assert masked == pytest.approx(0.5 * (0.24 + 0.32), abs=1e-12)
    everything = fit.joint_threshold(fits, own_fits(fits), "w_min")
    assert BRACKET[0] < everything < BRACKET[1]


def test_a_shared_deadband_takes_the_joint_threshold():
    """The whole selection: the deadband is found and shared, its final threshold is the joint one,
    and the held-out predictions (each part with the joint threshold fitted on the others) are the
    true model's."""
    fits, settings = fits_of([robot(n, rates, seed) for seed, (n, rates) in enumerate(TURN_RATES.items())])
    sel = fit.trace_and_add(fits, settings, candidates=["deadband"])
    assert sel.names == ["deadband"] and sel.shared == ["deadband"]
    for p in sel.params:
        assert BRACKET[0] < p["w_min"] < BRACKET[1]
    true_errors = [rf.errors(dict(NOMINAL, **TRUTH["deadband"])) for rf in fits]
    # every part's threshold zeroes what the true one does: the same predictions
    assert engine.metric(sel.final_errors).rmse_yaw_rad == pytest.approx(engine.metric(true_errors).rmse_yaw_rad,
                                                                       rel=1e-9)
