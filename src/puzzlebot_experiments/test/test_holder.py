"""The anchor's play in its holder (puzzlebot_experiments.holder and scripts/holder_play)."""

import json
import os
import subprocess
import sys
from dataclasses import replace

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_experiments.holder import PAPER, holder_pitch, measure_holder_play
from puzzlebot_sim.params import AnchorParams, RobotParams
from puzzlebot_sim.urdf import anchor_urdf

SCRIPT = os.path.join(os.path.dirname(__file__), "..", "scripts", "holder_play")
KEEL = replace(AnchorParams(), keel_height=0.0075)


def test_the_default_holder_travels_yaws_and_pitches_more_than_the_papers():
    play = measure_holder_play()
    # the pocket's 5 mm of travel, plus the ball nesting into the retaining wall's slot
    assert 0.005 < play.x_travel < 0.007 and play.y_play < 0.001
    # about +/-0.25 rad with the 5 mm slot: less than the real holder's +/-0.5 rad, because a wider
    # slot lets Bullet pull the anchor's ball through it while wiggling (docs/sim.md)
    assert 0.2 < -play.yaw_out[0] < 0.32 and 0.2 < play.yaw_out[1] < 0.32
    # pushed in, the collar's flat ends square the anchor up against the pocket's walls
    assert max(abs(v) for v in play.yaw_in) < 0.6 * min(abs(v) for v in play.yaw_out)
    # the ball and 2 mm collar pitch well beyond the paper's < 0.1 rad (notes/sim-trials.md, "The lock and the
    # holder's pitch"), and where the base settles under one load depends on where it started
    assert min(play.pitch_up, -play.pitch_down) > 0.18 > PAPER["pitch"]
    assert 0.0 < play.pitch_spread < 0.15
    assert [r[0] for r in play.rows()][0] == "x travel [mm]" and len(play.rows()) == 6


def test_a_keel_holds_the_anchors_pitch_in_its_holder_to_the_papers_limit():
    # a 7.5 mm keel, stopped by the pocket's floor and ceiling, keeps the pitch near the paper's < 0.1 rad
    pitches = holder_pitch(RobotParams(), KEEL, True) + holder_pitch(RobotParams(), KEEL, False)
    assert len(pitches) == 10 and max(abs(p) for p in pitches) < 0.12
    assert anchor_urdf(KEEL).count("<collision>") == anchor_urdf(AnchorParams()).count("<collision>") + 1
    for bad in (0.001, 0.0082):
        with pytest.raises(ConfigError, match="keel_height: 0 \\(no keel\\) or from 0.002 m"):
            measure_holder_play(anchor=replace(AnchorParams(), keel_height=bad))


def test_holder_play_command_prints_the_play_and_rejects_bad_overrides():
    out = subprocess.run([sys.executable, SCRIPT, "--anchor", "keel_height=0.0075", "--json"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    play = json.loads(out.stdout.strip().splitlines()[-1])
    assert set(play) >= {"x_travel", "y_play", "yaw_out", "yaw_in", "pitch_up", "pitch_down"}
    assert max(abs(play["pitch_up"]), abs(play["pitch_down"])) < 0.12
    bad = subprocess.run([sys.executable, SCRIPT, "--robot", "holder_depth=0.1"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "holder_depth" in bad.stderr and "Traceback" not in bad.stderr
