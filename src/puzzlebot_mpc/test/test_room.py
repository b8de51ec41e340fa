"""Room to back off (puzzlebot_mpc.room)."""

import pytest

from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_mpc import room

GEO = RobotGeometry()


def test_clear_run_is_the_room_to_the_nearest_robot_in_the_way():
    pose = (0.0, 0.0, 0.5)
    ahead = (0.1 * 0.8776, 0.1 * 0.4794)                   # 0.1 m straight ahead (heading 0.5 rad)
    assert room.clear_run(pose, [ahead], True, 0.06, 0.06) == pytest.approx(0.04, abs=1e-4)
    assert room.clear_run(pose, [ahead], False, 0.06, 0.06) == float("inf")      # behind: nothing
    aside = (ahead[0] - 0.07 * 0.4794, ahead[1] + 0.07 * 0.8776)              # 70 mm off the line of travel
    assert room.clear_run(pose, [aside], True, 0.06, 0.06) == float("inf")
    assert room.clear_run(pose, [aside, ahead, (0.03 * 0.8776, 0.03 * 0.4794)], True, 0.06, 0.06) \
        == pytest.approx(-0.03, abs=1e-4)                                     # one nearer than reach already


def test_an_assemblys_room_is_its_least_members_and_counts_the_anchor_backwards():
    L, size = GEO.body_side, GEO.footprint_radius()
    poses = {"a": (0.0, 0.0, 0.0), "b": (-L, 0.0, 0.0), "c": (-L - 0.2, 0.0, 0.0), "d": (0.3, 0.0, 0.0),
             "e": None}
    back = room.assembly_room(poses, ["a", "b"], False, GEO)
    assert back == pytest.approx(0.2 - L / 2 - GEO.anchor_length - size)       # b's anchor to c
    assert room.assembly_room(poses, ["a", "b"], True, GEO) == pytest.approx(0.3 - L / 2 - size)
    assert room.assembly_room(poses, ["a", "b"], False, GEO, exclude=["c"]) == float("inf")
    assert room.assembly_room(poses, ["e"], True, GEO) == 0.0
