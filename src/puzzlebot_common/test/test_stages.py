"""The worlds' stages (puzzlebot_common.stages): one description for the simulation and the MPC."""

import math

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_common.stages import Stage, StageMap, WorldParams, stages


def test_the_worlds_stages_from_their_dimensions():
    w = WorldParams(edge_x=0.1, stage_length=0.5, stage_width=0.4, gap_width=0.05, stage_height=0.06)
    assert stages("flat", w) == []
    assert stages("step", w) == [Stage(-0.4, 0.1, -0.2, 0.2, 0.06)]
    first, second = stages("gap", w)
    assert first == Stage(-0.4, 0.1, -0.2, 0.2, 0.06)
    assert second.x_min == pytest.approx(0.15) and second.x_max == pytest.approx(0.65)
    with pytest.raises(ConfigError, match="unknown world 'moon'; known worlds: flat, step, gap"):
        stages("moon")


def test_stage_map_heights_and_boxes():
    m = StageMap(stages("gap"), 0.03)
    assert m.height(-0.1, 0.0) == 0.05 and m.height(0.02, 0.0) == 0.0 and m.height(-0.1, 0.31) == 0.0
    assert m.box(-0.1, 0.0) == pytest.approx((-0.57, -0.03, -0.27, 0.27))
    assert m.box(0.3, -0.2) == pytest.approx((0.07, 0.61, -0.27, 0.27))
    assert all(math.isinf(v) for v in m.box(0.02, 0.0))          # the gap: the floor, no edges
    assert not StageMap([], 0.03) and m
    narrow = StageMap([Stage(0.0, 0.04, 0.0, 1.0, 0.05)], 0.03)   # narrower than the footprint
    assert narrow.box(0.01, 0.5)[:2] == (0.02, 0.02)
    with pytest.raises(ValueError):
        StageMap([], -0.01)


def test_footprint_radius_is_the_body_square_s_half_diagonal():
    assert RobotGeometry().footprint_radius() == pytest.approx(0.025 * math.sqrt(2))
