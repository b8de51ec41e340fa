import csv
import os
from dataclasses import replace

import pytest

from puzzlebot_sim.params import AnchorParams, RobotParams
from puzzlebot_experiments.rig import ForceRig, characterise


def test_simulated_rig_reproduces_the_paper_figures(tmp_path):
    profile = characterise(str(tmp_path), RobotParams(), AnchorParams())
    s = profile.summary()
    assert s["forward_peak_n"] < 0.2                      # pushed in easily
    assert 0.5 <= s["backward_at_4mm_n"] <= 0.7            # 0.6 N at 4 mm (paper)
    assert profile.at("backward", 3.0) > 0.35              # needs > 3 mm to come out
    with open(tmp_path / "force_profile.csv") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["displacement_mm", "forward_n", "backward_n"]
    assert len(rows) == 52 and rows[1][0] == "0.0" and rows[-1][0] == "5.0"
    assert os.path.getsize(tmp_path / "force_profile.png") > 10000


def test_rig_measures_the_simulation_not_the_table():
    # Same table, barbs that snap through earlier (shorter): the measured backward curve ends
    # where the geometry says, not where the table does (the snapped barbs' remaining torque zeroed
    # so that the snap shows as a drop).
    a = replace(AnchorParams(), barb_length=0.0055, length=0.0228, barb_post_snap_ratio=0.0)
    with ForceRig(RobotParams(), a) as rig:
        back = rig.push("backward")
        snap_mm = rig.map.snap_mm
    assert snap_mm < 4.8
    k = int(round(snap_mm / 0.1))
    assert max(back[:k]) > 0.5 and max(back[k + 2:]) < 0.1


def test_snapped_barbs_still_hold_a_straight_pull():
    # past the profile's 5 mm the barbs snap through but keep barb_post_snap_ratio of their torque (docs/sim.md):
    # a straight pull meets a second peak above a robot's 0.5 N push before the tips pass the lips; with the
    # ratio at 0 (the rig's slippage taken for the robot) nothing resists after the snap
    def after_snap(ratio):
        with ForceRig(RobotParams(), replace(AnchorParams(), barb_post_snap_ratio=ratio)) as rig:
            back = rig.push("backward", max_mm=8.0, step_mm=0.25)
        return max(back[22:])                                  # beyond 5.5 mm
    assert after_snap(AnchorParams().barb_post_snap_ratio) > 0.7
    assert after_snap(0.0) < 0.05
