import math

import numpy as np
import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import (RobotGeometry, compose, inverse_transform_point, point_in_convex_polygon,
                                       point_in_polygon, polygon_halfplanes, quaternion_from_yaw, signed_margin,
                                       transform_point, wrap_angle, yaw_from_quaternion)
from puzzlebot_common.kinematics import body_velocity, wheel_speeds


def random_convex_polygon(rng):
    k = rng.integers(3, 8)
    angles = np.sort(rng.uniform(0, 2 * np.pi, k))
    radius = rng.uniform(0.01, 0.05)
    centre = rng.uniform(-0.1, 0.1, 2)
    return centre + radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)


def test_linear_pip_agrees_with_ray_casting_on_random_points():
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(200):
        poly = random_convex_polygon(rng)
        g, h = polygon_halfplanes(poly)
        for p in rng.uniform(-0.16, 0.16, (50, 2)):
            linear = bool(np.all(g @ p <= h))
            if abs(signed_margin(poly, p)) < 1e-9:
                continue  # on an edge: either answer is right
            assert linear == point_in_polygon(poly, p)
            checked += 1
    assert checked > 9000


def test_crossing_number_on_a_concave_polygon_either_way_round():
    """The reference itself: an L (concave, where a convex test fails) and its reverse."""
    ell = [(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0), (0.0, 2.0)]
    for poly in (ell, ell[::-1]):
        assert point_in_polygon(poly, (0.5, 0.5)) and point_in_polygon(poly, (0.5, 1.5))
        assert point_in_polygon(poly, (1.5, 0.5))
        assert not point_in_polygon(poly, (1.5, 1.5))           # the notch
        assert not point_in_polygon(poly, (-0.5, 0.5)) and not point_in_polygon(poly, (2.5, 0.5))
        assert not point_in_polygon(poly, (0.5, 2.5))


def test_front_triangle_contains_points_ahead_of_centre_only():
    tri = RobotGeometry().front_triangle()
    assert point_in_convex_polygon(tri, (0.02, 0.0))
    assert not point_in_convex_polygon(tri, (-0.005, 0.0))
    assert not point_in_convex_polygon(tri, (0.01, 0.02))
    assert point_in_convex_polygon(tri, (-0.001, 0.0), eps=0.0015)


@pytest.mark.parametrize("a, expected", [(0.0, 0.0), (math.pi, -math.pi), (-math.pi, -math.pi),
                                         (3 * math.pi / 2, -math.pi / 2), (-7.0, -7.0 + 2 * math.pi)])
def test_wrap_angle(a, expected):
    assert wrap_angle(a) == pytest.approx(expected)


def test_transforms_round_trip():
    pose = (0.3, -0.2, 2.1)
    p = np.array([0.025, -0.01])
    q = transform_point(pose, p)
    assert np.allclose(inverse_transform_point(pose, q), p)
    c = compose(pose, (0.025, 0.0, math.pi))
    assert c[2] == pytest.approx(wrap_angle(2.1 + math.pi))


def test_quaternion_yaw_round_trip():
    for yaw in np.linspace(-3.1, 3.1, 13):
        assert yaw_from_quaternion(*quaternion_from_yaw(yaw)) == pytest.approx(yaw)


def test_wheel_speed_round_trip():
    vl, vr = wheel_speeds(0.05, 1.0, 0.04)
    assert (vl, vr) == pytest.approx((0.03, 0.07))
    assert body_velocity(vl, vr, 0.04) == pytest.approx((0.05, 1.0))


def test_geometry_config_errors():
    assert RobotGeometry.from_dict({"body_side": 0.06}).body_side == 0.06
    with pytest.raises(ConfigError, match="geometry.body_side"):
        RobotGeometry.from_dict({"body_side": -1})
    with pytest.raises(ConfigError, match="unknown key"):
        RobotGeometry.from_dict({"side": 0.05})
    with pytest.raises(ConfigError, match="finite number"):
        RobotGeometry.from_dict({"anchor_length": "long"})
