"""The behaviour interface: a new behaviour is one Behavior subclass the manager runs like the shipped ones."""

import pytest

from puzzlebot_mpc.behaviors import (BEHAVIORS, FAILED, REGISTRY, RUNNING, SUCCEEDED, Behavior, BehaviorError,
                                     BehaviorManager, BehaviorRequest, Progress)
from puzzlebot_mpc.settings import MPCSettings

NAMES = ["pz1", "pz2", "pz3"]
RATE = 0.5      # rad/s


class Spin(Behavior):
    """Test behaviour: the named robots turn in place at RATE until they have turned ``distance`` rad."""

    name = "spin"

    def validate(self, poses=None):
        if self.req.distance <= 0:
            raise BehaviorError("spin needs a distance (angle [rad]) > 0")
        self.check_velocity(self.robots[0], (0.0, RATE))

    def start(self, now, poses, static):
        for r in self.robots:
            static.velocity[self.ctx.index[r]] = (0.0, RATE)
        return super().start(now, poses, static)

    def status(self, now, poses, newly, lost, elapsed):
        turned = RATE * elapsed
        if turned >= self.req.distance - 1e-9:
            return Progress(SUCCEEDED, "turned %.2f rad" % turned, [turned])
        return Progress(message="turning: %.2f rad" % turned, errors=[turned])


def spinning_manager():
    return BehaviorManager(NAMES, MPCSettings(), behaviors={**REGISTRY, Spin.name: Spin})


def test_a_registered_behaviour_runs_through_the_manager():
    m = spinning_manager()
    rid = m.request(BehaviorRequest("spin", ["pz2"], distance=1.0), now=0.0)
    obj = m.objectives(0.0)
    assert obj.velocity[1] == pytest.approx([0.0, RATE])
    assert obj.velocity[0] == pytest.approx([0.0, 0.0]) and obj.velocity[2] == pytest.approx([0.0, 0.0])
    assert (obj.velocity_mask > 0).all()                          # the others are held at rest
    s = m.update(1.0, {})
    assert (s.request_id, s.behavior, s.state, s.robots) == (rid, "spin", RUNNING, ["pz2"])
    assert s.message == "turning: 0.50 rad" and s.errors == pytest.approx([0.5])
    s = m.update(2.0, {})
    assert s.state == SUCCEEDED and s.message == "turned 1.00 rad"
    assert m.objectives(2.1).velocity[1] == pytest.approx([0.0, 0.0])   # at rest once it ended


def test_a_registered_behaviour_is_validated_and_times_out_like_the_others():
    m = spinning_manager()
    with pytest.raises(BehaviorError, match="spin needs a distance"):
        m.validate(BehaviorRequest("spin", ["pz1"]))
    with pytest.raises(BehaviorError, match="unknown robot"):      # the checks every request shares
        m.validate(BehaviorRequest("spin", ["pz7"], distance=1.0))
    m.request(BehaviorRequest("spin", ["pz1", "pz3"], distance=3.0, timeout=1.0), now=0.0)
    s = m.update(1.2, {})
    assert s.state == FAILED and s.message == "timeout after 1.20 s"


def test_the_registry_is_per_manager():
    with pytest.raises(BehaviorError) as e:
        BehaviorManager(NAMES, MPCSettings()).validate(BehaviorRequest("spin", distance=1.0))
    assert "unknown behaviour 'spin'; known: " + ", ".join(BEHAVIORS) in str(e.value)
    assert "spin" not in REGISTRY
    with pytest.raises(BehaviorError) as e:
        spinning_manager().validate(BehaviorRequest("fly"))
    assert str(e.value).endswith("drive_assembly, assembly_to_goal, spin")


def test_shipped_behaviours_are_registered_under_their_request_names():
    assert BEHAVIORS == ("go_to_goal", "follow_velocity", "stop", "couple", "decouple", "drive_assembly",
                         "assembly_to_goal")
    assert all(cls.name == name and issubclass(cls, Behavior) for name, cls in REGISTRY.items())


def test_go_to_goal_errors_after_it_ended_still_measure_to_its_goals():
    m = BehaviorManager(NAMES, MPCSettings())
    m.request(BehaviorRequest("go_to_goal", ["pz1"], [(0.3, 0.0)], tolerance=0.01), now=0.0)
    assert m.update(1.0, {"pz1": (0.295, 0.0, 0.0)}).state == SUCCEEDED
    s = m.update(1.1, {"pz1": (0.29, 0.0, 0.0)})
    assert s.state == SUCCEEDED and s.errors == pytest.approx([0.01])
