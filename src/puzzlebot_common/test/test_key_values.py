"""Command-line KEY=VALUE overrides (puzzlebot_common.params.key_values)."""

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.params import key_values


def test_values_are_json_when_they_can_be_else_strings():
    assert key_values(["a=0.015", " b =[2.0, 1.5]", "c=true", "d=pilot"], "--set") == \
        {"a": 0.015, "b": [2.0, 1.5], "c": True, "d": "pilot"}
    assert key_values([], "--set") == {}


@pytest.mark.parametrize("item", ["neck_max_torque", "=1"])
def test_an_item_without_key_and_value_names_the_option(item):
    with pytest.raises(ConfigError, match="--robot expects KEY=VALUE"):
        key_values([item], "--robot")
