"""How far two coupled robots fold concave (puzzlebot_experiments.fold and scripts/fold_limit)."""

import json
import os
import subprocess
import sys
from dataclasses import replace

from puzzlebot_experiments.fold import measure_concave_fold
from puzzlebot_sim.params import RobotParams

SCRIPT = os.path.join(os.path.dirname(__file__), "..", "scripts", "fold_limit")


def test_square_tops_stop_the_fold_and_a_top_chamfer_lets_the_pair_fold_further():
    square = measure_concave_fold()
    chamfered = measure_concave_fold(replace(RobotParams(), top_chamfer=0.012))
    # square tops meet at about a third of a radian (notes/sim-trials.md, "Why the chain is a beam")
    assert square.coupled and 0.25 < square.fold < 0.45
    assert chamfered.coupled and chamfered.fold > square.fold + 0.15
    # lifted harder, the top corners lever the anchor out of the opening, past the fold held at 0.6 N
    assert 0.7 < square.separation_lift < 1.5 and square.separation_fold > square.fold


def test_fold_limit_command_prints_json_and_rejects_bad_overrides():
    out = subprocess.run([sys.executable, SCRIPT, "--json"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    fold = json.loads(out.stdout.strip().splitlines()[-1])
    assert set(fold) == {"fold", "anchor_pitch", "coupled", "separation_lift", "separation_fold"}
    assert fold["coupled"] is True and 0.25 < fold["fold"] < 0.45
    bad = subprocess.run([sys.executable, SCRIPT, "--robot", "top_chamfer=0.001"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "top_chamfer" in bad.stderr and "Traceback" not in bad.stderr
