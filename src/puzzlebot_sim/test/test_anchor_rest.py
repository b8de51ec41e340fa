"""The geometry of the resting-anchor tests (puzzlebot_sim.anchor_rest), without a world; freezing
and waking in a world are tested in test_world.py."""

import math

import numpy as np

from puzzlebot_sim.anchor_rest import ANCHOR_MAX_YAW, AnchorRest, _obb_overlap, exposed_anchor_box
from puzzlebot_sim.params import AnchorParams, AnchorRestParams, RobotParams


def _rect(x, y, yaw, hx, hy):
    return (x, y, math.cos(yaw), math.sin(yaw), hx, hy)


def test_rectangles_overlap_within_the_clearance_only():
    a = _rect(0.0, 0.0, 0.0, 0.01, 0.005)
    assert _obb_overlap(a, _rect(0.019, 0.0, 0.0, 0.01, 0.005), 0.0)        # 1 mm into each other
    assert not _obb_overlap(a, _rect(0.025, 0.0, 0.0, 0.01, 0.005), 0.0)    # 5 mm apart
    assert _obb_overlap(a, _rect(0.025, 0.0, 0.0, 0.01, 0.005), 0.006)      # ... within a 6 mm clearance
    # turned by 45 degrees: the corner reaches 0.01 * sqrt(2) out, the sides do not
    b = _rect(0.0, 0.0, math.pi / 4, 0.01, 0.01)
    assert _obb_overlap(b, _rect(0.0235, 0.0, 0.0, 0.01, 0.01), 0.0)
    assert not _obb_overlap(b, _rect(0.0245, 0.0, 0.0, 0.01, 0.01), 0.0)


def test_exposed_box_covers_the_pulled_out_anchor_turned_to_its_largest_yaw():
    p, a = RobotParams(), AnchorParams()
    home_x = -p.body_side / 2 + p.holder_depth - a.base_radius
    x0, x1, half_width = exposed_anchor_box(p, a, home_x)
    assert x1 == -p.body_side / 2 and x0 < x1                          # behind the back face
    travel = p.holder_depth - p.holder_wall - 2 * a.base_radius
    tip = home_x - travel - a.length                                     # head tip, pulled out, straight back
    assert x0 < tip - a.barb_length                                      # a barb flipped backward fits
    assert half_width > (x1 - x0) * math.sin(ANCHOR_MAX_YAW) + a.barb_length   # swung, a barb flared out


def test_neighbour_search_finds_exactly_the_robots_within_reach_of_each_anchor():
    p, a = RobotParams(), AnchorParams()
    home_x = -p.body_side / 2 + p.holder_depth - a.base_radius
    names = ["r%d" % k for k in range(40)]
    rest = AnchorRest(AnchorRestParams(), p, a, home_x, None, None, dict.fromkeys(names), None, None, 9.81)
    rng = np.random.default_rng(4)
    poses = {n: ((x, y, 0.02), (0.0, 0.0, math.sin(t / 2), math.cos(t / 2)))
             for n, x, y, t in zip(names, *rng.uniform(0.0, 0.4, (2, 40)), rng.uniform(-math.pi, math.pi, 40))}
    zones = rest._zones(poses)
    far = rest._zone_radius + rest._box_radius + rest.params.clearance
    near = rest._near(zones)
    for n in names:
        box = zones[n][1]
        assert near[n] == [o for o in names if o != n
                           and (zones[o][0][0] - box[0]) ** 2 + (zones[o][0][1] - box[1]) ** 2 <= far * far]
    assert 0 < sum(map(len, near.values())) < 40 * 39          # some robots near each other, not all
