"""Live tuning of the MPC's weights and limits (puzzlebot_mpc.tuning, ControlLoop.retune); no roscore."""

from dataclasses import replace

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_mpc.behaviors import BehaviorRequest
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_mpc.settings import MPCSettings
from puzzlebot_mpc.tuning import LIVE, REBUILD, REFUSED, TUNABLE, config_type, tuned

S = MPCSettings()


def test_description_starts_at_the_settings_and_documents_each_parameter():
    t = config_type(replace(S, v_max=0.04))
    assert set(t.defaults) == set(TUNABLE) | {REFUSED}
    assert t.defaults["v_max"] == 0.04 and t.type["butterfly"] == "bool" and t.type["w_rest"] == "double"
    params = {p["name"]: p for p in t.config_description["parameters"]}
    assert params["v_max"]["description"] == "m/s: |v| limit"                        # settings.py's comment
    assert t.min["w_rest"] == -float("inf")       # nothing clamped: the check refuses, with its reason
    assert t.all_level == LIVE | REBUILD


def test_a_change_is_validated_as_the_yaml_is():
    new, diff, rebuild = tuned(S, {"w_goal_terminal": 2e4, "goal_tolerance": S.goal_tolerance, REFUSED: ""})
    assert new.w_goal_terminal == 2e4 and diff == {"w_goal_terminal": 2e4} and rebuild
    new, diff, rebuild = tuned(S, {"goal_tolerance": 0.01})
    assert new.goal_tolerance == 0.01 and not rebuild                                  # read every step
    assert tuned(S, {"v_max": S.v_max}) == (S, {}, False)
    for change, reason in (({"v_max": 0.5}, "exceed the hardware limits"), ({"w_control": -1.0}, "must be >= 0"),
                           ({"v_max": 0.001}, "decouple_creep and decouple_settle_speed must be <= v_max")):
        with pytest.raises(ConfigError) as e:
            tuned(S, change)
        assert reason in str(e.value)


def test_retuned_loop_uses_the_new_limit_from_the_next_step():
    loop = ControlLoop(["pz1"], S)
    loop.on_pose("pz1", 0.0, 0.0, 0.0, 0.0)
    loop.request(BehaviorRequest("go_to_goal", ["pz1"], [(0.5, 0.0)]), 0.0)
    t = 0.0
    for _ in range(5):
        out = loop.step(t)
        t += 0.1
        loop.on_pose("pz1", t, 0.0, 0.0, 0.0)
    assert out.commands["pz1"][0] == pytest.approx(0.05, abs=1e-4)
    new, _, rebuild = tuned(loop.settings, {"v_max": 0.02})
    loop.retune(new, loop.build_mpc(new, loop.pair_keys()) if rebuild else None)
    out = loop.step(t)
    assert out.commands["pz1"][0] <= 0.02 + 1e-9 and loop.behaviors.settings.v_max == 0.02
